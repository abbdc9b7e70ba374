"""grasp-range (eq. 14, 15): the force that pulls a grasped object out, against its diameter, next to
d_min (the packed spiral's hole) and d_max (the whole length wrapping half the object).

Each trial: a free 20 g cylinder on its support, grasped with the strategy on; its support is removed at
HOLD; after ``hold_s`` a force on it along +x (horizontal, away from the arm's axis, the side the object
is on) grows at a fixed rate until the object comes out (moved 60 mm along the force, or no contact
left). A grasp that did not hold the object counts as a pull-out force of 0 N. Per diameter: the mean
pull-out force over the placements with its percentile bootstrap 95 % interval.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from hil.experiments.base import Conditions, Experiment, Sizes
from hil.experiments.common import Row, extremes_rows, mm, pyplot, save_figure
from hil.experiments.geometry import ArmFootprint, design_scale, gap_depth_placements
from hil.experiments.outcomes import GraspOutcomes, grasp_trials
from hil.experiments.stats import bootstrap_interval
from hil.trial.grasp import GraspOutcome, GraspSetup, grasp_firmware

PULL_DIR = (1.0, 0.0, 0.0)
"""The pull-out force's direction: horizontal, away from the arm's axis (+x, the object's side)."""


@dataclass(frozen=True)
class GraspRangeParams:
    """Attributes:
    diameters_m: cylinders to try (around d_min = 12.8 mm and up to d_max = 123 mm on the prototype; on
        another arm these, the gaps and the depths are scaled by its length:
        :func:`~hil.experiments.geometry.design_scale`).
    gap_range_m: horizontal gap between the arm's axis and the cylinder's near surface, low and high.
    depth_range_m: depth of the cylinder's top below the base, low and high.
    grid: cells over (gap, depth); one jittered placement per cell.
    clearance_m: smallest gap kept between the object and the packed or straight arm.
    wrap_n: wrap tension of the grasp.
    pull_rate_n_per_s: growth of the pull-out force.
    pull_cap_n: the force stops growing here (a pull-out force of ``pull_cap_n`` means "not pulled out").
    mass_kg: object mass.
    hold_s: the released object is held this long before the pull starts.
    resamples: bootstrap resamples.
    """

    diameters_m: tuple[float, ...] = (0.006, 0.009, 0.013, 0.018, 0.026, 0.036, 0.05, 0.07, 0.1, 0.13)
    gap_range_m: tuple[float, float] = (0.005, 0.045)
    depth_range_m: tuple[float, float] = (0.04, 0.12)
    grid: tuple[int, int] = (3, 2)
    clearance_m: float = 0.002
    wrap_n: float = 10.0
    pull_rate_n_per_s: float = 5.0
    pull_cap_n: float = 20.0
    mass_kg: float = 0.02
    hold_s: float = 0.5
    resamples: int = 10_000


@dataclass(frozen=True)
class GraspRangeResult(GraspOutcomes):
    """Pull-out force per diameter with its bootstrap interval, against d_min and d_max (a
    :class:`~hil.experiments.base.Result`)."""

    params: GraspRangeParams
    seed: int
    d_min_paper_m: float
    d_max_paper_m: float
    outcomes: tuple[GraspOutcome, ...]

    def per_diameter(self) -> list[dict[str, Any]]:
        """Per diameter: trials, held, wrapped >= 180°, mean and median pull-out force [N] (0 N for a grasp
        that did not hold) with the mean's bootstrap 95 % interval."""
        out = []
        for k, d in enumerate(self.params.diameters_m):
            sel = [o for o in self.outcomes if o.setup.diameter_m == d]
            forces = [pull_out_n(o) for o in sel]
            seed = self.seed * 1000 + k
            lo, hi = bootstrap_interval(forces, "mean", 0.95, self.params.resamples, seed)
            out.append(
                {
                    "diameter_m": d,
                    "n": len(sel),
                    "held": sum(o.held for o in sel),
                    "wrapped": sum(o.success for o in sel),
                    "pull_out_mean_n": float(np.mean(forces)) if forces else math.nan,
                    "pull_out_median_n": float(np.median(forces)) if forces else math.nan,
                    "pull_out_ci95_n": [lo, hi],
                }
            )
        return out

    def _held_range(self) -> list[float]:
        """Diameters whose mean pull-out interval lies above 0 N."""
        return [r["diameter_m"] for r in self.per_diameter() if r["pull_out_ci95_n"][0] > 0.0]

    @property
    def d_min_sim_m(self) -> float:
        """Smallest diameter whose mean pull-out force's 95 % interval excludes 0 (NaN if none)."""
        ok = self._held_range()
        return min(ok) if ok else math.nan

    @property
    def d_max_sim_m(self) -> float:
        """Largest diameter whose mean pull-out force's 95 % interval excludes 0 (NaN if none)."""
        ok = self._held_range()
        return max(ok) if ok else math.nan

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        return {
            "experiment": "grasp-range",
            "seed": self.seed,
            "pull_direction": list(PULL_DIR),
            "d_min_paper_m": self.d_min_paper_m,
            "d_max_paper_m": self.d_max_paper_m,
            "d_min_sim_m": self.d_min_sim_m,
            "d_max_sim_m": self.d_max_sim_m,
            "per_diameter": self.per_diameter(),
            "penetration_m": self.extremes.penetration_m,
            **self.outcomes_dict(),
            "params": dataclasses.asdict(self.params),
        }

    def table_rows(self) -> list[Row]:
        """The result's numbers next to the paper's, one row each."""
        rows: list[Row] = [
            (
                "smallest diameter pulled out only by a force > 0 (95 % CI)",
                mm(self.d_min_sim_m),
                f"d_min = {mm(self.d_min_paper_m)} (eq. 14: the packed spiral's hole)",
            ),
            (
                "largest such diameter",
                mm(self.d_max_sim_m),
                f"d_max = {mm(self.d_max_paper_m)} (eq. 15: whole length wraps half way)",
            ),
        ]
        for row in self.per_diameter():
            d = row["diameter_m"]
            lo, hi = row["pull_out_ci95_n"]
            where = (
                "< d_min" if d < self.d_min_paper_m else "> d_max" if d > self.d_max_paper_m else "in range"
            )
            rows.append(
                (
                    f"  {d * 1000:g} mm: mean pull-out force (95 % CI); held, wrapped / n",
                    f"{row['pull_out_mean_n']:.2f} N ({lo:.2f}-{hi:.2f}); "
                    f"{row['held']}, {row['wrapped']} / {row['n']}",
                    where,
                )
            )
        rows.extend(extremes_rows(self.extremes))
        rows.extend(self.placement_rows())
        return rows

    def describe_samples(self) -> str:
        """Diameters, placements and grasps, the pull and the bootstrap, in words."""
        p = self.params
        return (
            f"{len(p.diameters_m)} diameters x {p.grid[0] * p.grid[1]} placements = "
            f"{len(self.outcomes)} grasps (strategy on, {p.wrap_n:g} N wrap), pulled along +x at "
            f"{p.pull_rate_n_per_s:g} N/s up to {p.pull_cap_n:g} N; "
            f"bootstrap {p.resamples} resamples"
        )

    def figure(self, out: Path) -> Path:
        """Write the figure into the directory ``out``; returns its path (``grasp-range.png``)."""
        plt = pyplot()
        fig, ax = plt.subplots(figsize=(6.5, 4.2))
        ax.plot(
            [o.setup.diameter_m * 1000 for o in self.outcomes],
            [pull_out_n(o) for o in self.outcomes],
            "o",
            alpha=0.4,
            label="each placement (0 N: not held)",
        )
        rows = self.per_diameter()
        ds = np.array([row["diameter_m"] * 1000 for row in rows])
        mean = np.array([row["pull_out_mean_n"] for row in rows])
        lo = np.array([row["pull_out_ci95_n"][0] for row in rows])
        hi = np.array([row["pull_out_ci95_n"][1] for row in rows])
        ax.errorbar(
            ds, mean, yerr=[mean - lo, hi - mean], fmt="k-", capsize=3, label="mean, bootstrap 95 % CI"
        )
        ax.axvline(
            self.d_min_paper_m * 1000, color="g", ls=":", label=f"d_min = {self.d_min_paper_m * 1000:.1f} mm"
        )
        ax.axvline(
            self.d_max_paper_m * 1000, color="m", ls=":", label=f"d_max = {self.d_max_paper_m * 1000:.0f} mm"
        )
        ax.set_xscale("log")
        ax.set_xlabel("cylinder diameter [mm]")
        ax.set_ylabel("pull-out force along +x [N]")
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=7)
        ax.set_title("grasp range: force that pulls a grasped object out", fontsize=10)
        return save_figure(fig, out / "grasp-range.png")


def pull_out_n(o: GraspOutcome) -> float:
    """The force that pulled the object out of one trial's grasp; 0 N if the grasp did not hold it."""
    return 0.0 if math.isnan(o.load_n) else o.load_n


def grasp_range(p: GraspRangeParams, on: Conditions) -> GraspRangeResult:
    """Free cylinders of many diameters, each at jittered placements clear of the packed and straight arm,
    grasped with the strategy on, released, then pulled out along +x (see the module); on the plant
    ``on.model``; against the paper's d_min (eq. 14) and d_max (eq. 15)."""
    design, model, seed = on.design, on.model, on.seed
    s = design_scale(design)
    if s != 1.0:
        p = dataclasses.replace(
            p,
            diameters_m=tuple(d * s for d in p.diameters_m),
            gap_range_m=(p.gap_range_m[0] * s, p.gap_range_m[1] * s),
            depth_range_m=(p.depth_range_m[0] * s, p.depth_range_m[1] * s),
        )
    fw = grasp_firmware(grasp_wrap_n=p.wrap_n)
    foot = ArmFootprint.of(design, model)
    setups: list[GraspSetup] = []
    for d in p.diameters_m:
        pull = GraspSetup(  # strategy on; placed at each spot below
            x_m=math.nan,
            z_m=math.nan,
            diameter_m=d,
            mass_kg=p.mass_kg,
            hold_s=p.hold_s,
            load_rate_n_per_s=p.pull_rate_n_per_s,
            load_cap_n=p.pull_cap_n,
            load_dir=PULL_DIR,
            firmware=fw,
            model=model,
            seed=seed,
        )
        spots = gap_depth_placements(foot, d, p.gap_range_m, p.depth_range_m, p.grid, p.clearance_m, seed)
        setups += [dataclasses.replace(pull, x_m=x, z_m=z) for x, z in spots]
    return GraspRangeResult(p, seed, design.d_min_m, design.d_max_m, grasp_trials(setups, on))


EXPERIMENT = Experiment(
    "grasp-range",
    "pull-out force against diameter (bootstrap intervals) vs. d_min, d_max (eq. 14, 15)",
    # tiny: one 20 mm cylinder, one placement; default: 10 diameters x 6 placements; large: x 12 placements
    Sizes(
        GraspRangeParams(
            diameters_m=(0.02,), gap_range_m=(0.03, 0.03), depth_range_m=(0.1, 0.1), grid=(1, 1)
        ),
        GraspRangeParams(),
        GraspRangeParams(grid=(4, 3)),
    ),
    grasp_range,
)
"""The grasp-range experiment (:mod:`hil.experiments.catalogue`)."""
