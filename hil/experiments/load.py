"""load (eq. 16, Fig. 2F): the mass a grasp holds against the wrap force, per contact friction, next to
the bound ``M(φ, d, F)``.

Each trial: a 20 g cylinder grasped with the strategy on at wrap force F, its support removed at HOLD,
held ``hold_s``, then a downward force on it grows until it comes out (moved 60 mm down, or no contact
left). Held mass = 20 g + that force / g. The arm's and the object's friction are both set to μ (MuJoCo
takes the larger of the two). Per μ, the OLS slope of held mass against F over the trials that held the
object, with its 95 % interval, beside eq. (16)'s slope ``dM/dF = (1 − d/((d + δ(0))·e^{kπ}))/g``.
Trials whose grasp did not hold the 20 g object are left out of the fit and counted.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from hil.experiments.base import Conditions, Experiment, Sizes
from hil.experiments.common import G, Row, extremes_rows, pyplot, save_figure
from hil.experiments.geometry import ArmFootprint, design_scale, gap_depth_placements
from hil.experiments.outcomes import GraspOutcomes, grasp_trials
from hil.experiments.stats import Slope, ols_slope
from hil.trial.grasp import GraspOutcome, GraspSetup, grasp_firmware


@dataclass(frozen=True)
class LoadParams:
    """Attributes:
    diameter_m: the object's diameter.
    forces_n: wrap forces F (eq. 16's F_max), within the firmware's 20 N ceiling.
    frictions: contact friction μ of the arm's and the object's surfaces.
    gap_range_m: horizontal gap between the arm's axis and the object's near surface, low and high.
    depth_range_m: depth of the object's top below the base, low and high.
    grid: cells over (gap, depth); one jittered placement per cell, the same for every F and μ.
    clearance_m: smallest gap kept between the object and the packed or straight arm.
    ramp_s: the downward load grows from 0 to twice eq. (16)'s bound in this time.
    mass_kg: object mass (without the load).
    hold_s: the released object is held this long before the load grows.
    """

    diameter_m: float = 0.02
    forces_n: tuple[float, ...] = (2.5, 5.0, 10.0, 20.0)
    frictions: tuple[float, ...] = (0.0, 0.3, 0.8)
    gap_range_m: tuple[float, float] = (0.015, 0.045)
    depth_range_m: tuple[float, float] = (0.06, 0.12)
    grid: tuple[int, int] = (2, 2)
    clearance_m: float = 0.002
    ramp_s: float = 4.0
    mass_kg: float = 0.02
    hold_s: float = 0.5


def _friction(o: GraspOutcome) -> float:
    return o.setup.model.arm.geom_friction


def _force(o: GraspOutcome) -> float:
    fw = o.setup.firmware
    return fw.grasp.wrap_n if fw is not None else math.nan


def held_kg(o: GraspOutcome) -> float:
    """Mass held by one trial: the object's plus the load at which it came out (NaN: not held)."""
    return o.setup.mass_kg + o.load_n / G


@dataclass(frozen=True)
class LoadResult(GraspOutcomes):
    """Held mass against wrap force per friction, its slope, and eq. (16)'s (a
    :class:`~hil.experiments.base.Result`)."""

    params: LoadParams
    seed: int
    bound_slope_kg_per_n: float
    outcomes: tuple[GraspOutcome, ...]

    def _select(self, mu: float) -> list[GraspOutcome]:
        return [o for o in self.outcomes if _friction(o) == mu]

    def slope(self, mu: float) -> Slope:
        """OLS slope of held mass [kg] against wrap force [N] over the trials at ``mu`` that held."""
        sel = [o for o in self._select(mu) if not math.isnan(o.load_n)]
        return ols_slope([_force(o) for o in sel], [held_kg(o) for o in sel])

    def rows(self) -> list[dict[str, Any]]:
        """Per friction and force: trials, held, mean held mass [kg], and the bound [kg]."""
        out = []
        d = self.params.diameter_m
        for mu in self.params.frictions:
            for f in self.params.forces_n:
                sel = [o for o in self._select(mu) if _force(o) == f]
                held = [held_kg(o) for o in sel if not math.isnan(o.load_n)]
                out.append(
                    {
                        "friction": mu,
                        "force_n": f,
                        "n": len(sel),
                        "held": len(held),
                        "held_kg_mean": float(np.mean(held)) if held else math.nan,
                        "bound_kg": self.bound_slope_kg_per_n * f,
                        "diameter_m": d,
                    }
                )
        return out

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        return {
            "experiment": "load",
            "seed": self.seed,
            "bound_slope_kg_per_n": self.bound_slope_kg_per_n,
            "slopes": [{"friction": mu, **self.slope(mu).as_dict()} for mu in self.params.frictions],
            "rows": self.rows(),
            "penetration_m": self.extremes.penetration_m,
            **self.outcomes_dict(),
            "params": dataclasses.asdict(self.params),
        }

    def table_rows(self) -> list[Row]:
        """The result's numbers next to the paper's, one row each."""
        bound = self.bound_slope_kg_per_n * 1000
        rows: list[Row] = []
        for mu in self.params.frictions:
            s = self.slope(mu)
            rows.append(
                (
                    f"μ = {mu:g}: slope of held mass vs wrap force (95 % CI), n held",
                    f"{s.slope * 1000:.1f} g/N ({s.low * 1000:.1f} to {s.high * 1000:.1f}), {s.n}",
                    f"dM/dF = {bound:.1f} g/N (eq. 16, an upper bound)",
                )
            )
            for row in self.rows():
                if row["friction"] != mu:
                    continue
                rows.append(
                    (
                        f"  F = {row['force_n']:g} N: mean held mass, held / n",
                        f"{_g(row['held_kg_mean'])}, {row['held']} / {row['n']}",
                        f"M <= {row['bound_kg'] * 1000:.0f} g",
                    )
                )
        rows.extend(extremes_rows(self.extremes))
        rows.extend(self.placement_rows())
        return rows

    def describe_samples(self) -> str:
        """Wrap forces, frictions, placements and grasps, in words."""
        p = self.params
        return (
            f"{len(p.forces_n)} wrap forces x {len(p.frictions)} frictions x {p.grid[0] * p.grid[1]} "
            "placements = "
            f"{len(self.outcomes)} grasps of a {p.diameter_m * 1000:g} mm cylinder, "
            "load growing to twice the bound "
            f"in {p.ramp_s:g} s"
        )

    def figure(self, out: Path) -> Path:
        """Write the figure into the directory ``out``; returns its path (``load.png``)."""
        plt = pyplot()
        fig, ax = plt.subplots(figsize=(6.5, 4.2))
        ff = np.linspace(0.0, max(self.params.forces_n) * 1.05, 50)
        ax.plot(ff, self.bound_slope_kg_per_n * ff * 1000, "k--", lw=1, label="bound M(φ, d, F) (eq. 16)")
        for k, mu in enumerate(self.params.frictions):
            colour = f"C{k}"
            sel = [o for o in self.outcomes if _friction(o) == mu and not math.isnan(o.load_n)]
            ax.plot([_force(o) for o in sel], [held_kg(o) * 1000 for o in sel], "o", color=colour, alpha=0.5)
            s = self.slope(mu)
            if not math.isnan(s.slope):
                ax.plot(
                    ff, (s.intercept + s.slope * ff) * 1000, "-", color=colour, label=f"μ = {mu:g}: OLS fit"
                )
        ax.set_xlabel("wrap force F [N]")
        ax.set_ylabel("mass held [g]")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
        ax.set_title(f"load: mass held vs wrap force, d = {self.params.diameter_m * 1000:g} mm", fontsize=10)
        return save_figure(fig, out / "load.png")


def load(p: LoadParams, on: Conditions) -> LoadResult:
    """Grasp (strategy on) a cylinder at each wrap force and friction, at jittered placements, remove its
    support, then grow a downward force on it until it comes out (see the module); on the plant
    ``on.model`` with its friction replaced by each μ."""
    design, model, seed = on.design, on.model, on.seed
    s = design_scale(design)
    if s != 1.0:
        p = dataclasses.replace(
            p,
            diameter_m=p.diameter_m * s,
            gap_range_m=(p.gap_range_m[0] * s, p.gap_range_m[1] * s),
            depth_range_m=(p.depth_range_m[0] * s, p.depth_range_m[1] * s),
        )
    d = p.diameter_m
    bound_slope = design.max_load_kg(d, 1.0)  # eq. (16) is proportional to F
    foot = ArmFootprint.of(design, model)
    spots = gap_depth_placements(foot, d, p.gap_range_m, p.depth_range_m, p.grid, p.clearance_m, seed)
    setups: list[GraspSetup] = []
    for mu in p.frictions:
        variant = dataclasses.replace(model, arm=dataclasses.replace(model.arm, geom_friction=mu))
        for f in p.forces_n:
            cap_n = 2.0 * bound_slope * f * G
            weigh = GraspSetup(  # strategy on; placed at each spot below
                x_m=math.nan,
                z_m=math.nan,
                diameter_m=d,
                mass_kg=p.mass_kg,
                hold_s=p.hold_s,
                load_rate_n_per_s=cap_n / p.ramp_s,
                load_cap_n=cap_n,
                object_friction=mu,
                firmware=grasp_firmware(grasp_wrap_n=f),
                model=variant,
                seed=seed,
            )
            setups += [dataclasses.replace(weigh, x_m=x, z_m=z) for x, z in spots]
    return LoadResult(p, seed, bound_slope, grasp_trials(setups, on))


def _g(kg: float) -> str:
    return "not held" if math.isnan(kg) else f"{kg * 1000:.0f} g"


EXPERIMENT = Experiment(
    "load",
    "held mass against wrap force 2.5-20 N at three frictions: slope and interval vs. eq. 16",
    # tiny: 2 forces at μ = 0.8, one placement; default: 4 forces x 3 frictions x 4 placements; large: 9
    # placements
    Sizes(
        LoadParams(
            forces_n=(5.0, 10.0),
            frictions=(0.8,),
            gap_range_m=(0.03, 0.03),
            depth_range_m=(0.09, 0.09),
            grid=(1, 1),
        ),
        LoadParams(),
        LoadParams(grid=(3, 3)),
    ),
    load,
)
"""The load experiment (:mod:`hil.experiments.catalogue`)."""
