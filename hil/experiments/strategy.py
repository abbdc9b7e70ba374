"""strategy (Note S4, Fig. S6, Fig. 3C): objects on a grid grasped with the strategy on and off."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..spiral import SpiralDesign
from .common import Progress, Row, pct, pyplot, save_figure, sized
from .grasp import GraspOutcome, GraspSetup, grasp_trial_job
from .parallel import parallel_map


@dataclass(frozen=True)
class StrategyParams:
    """Attributes:
    diameters_m: the three object diameters.
    xs_m: grid of horizontal distances of the object's centre from the arm's axis (target side, +x).
    zs_m: grid of heights of the object's centre relative to the base (negative = below).
    mass_kg: object mass.
    hold_s: how long a released object must stay to count as grasped.
    """

    diameters_m: tuple[float, ...] = (0.016, 0.024, 0.036)
    xs_m: tuple[float, ...] = (0.03, 0.05, 0.07, 0.09)
    zs_m: tuple[float, ...] = (-0.07, -0.10, -0.13, -0.16)
    mass_kg: float = 0.02
    hold_s: float = 0.6


@dataclass(frozen=True)
class StrategyResult:
    """Every placement grasped with the strategy on and off."""

    params: StrategyParams
    seed: int
    outcomes: tuple[GraspOutcome, ...]

    def _share(self, on: bool, d: float | None = None) -> float:
        sel = [
            o for o in self.outcomes if o.setup.strategy_on == on and (d is None or o.setup.diameter_m == d)
        ]
        return sum(o.held for o in sel) / len(sel) if sel else math.nan

    @property
    def success_on(self) -> float:
        """Share of placements grasped and held with the strategy on."""
        return self._share(True)

    @property
    def success_off(self) -> float:
        """Share of placements grasped and held with the strategy off."""
        return self._share(False)

    def per_diameter(self) -> list[dict[str, float]]:
        """Success rates per diameter."""
        return [
            {"diameter_m": d, "success_on": self._share(True, d), "success_off": self._share(False, d)}
            for d in self.params.diameters_m
        ]

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        return {
            "experiment": "strategy",
            "seed": self.seed,
            "success_on": self.success_on,
            "success_off": self.success_off,
            "trials": len(self.outcomes),
            "per_diameter": self.per_diameter(),
            "only_on": sum(
                1 for o in self.outcomes if o.setup.strategy_on and o.held and not self._twin(o).held
            ),
            "only_off": sum(
                1 for o in self.outcomes if not o.setup.strategy_on and o.held and not self._twin(o).held
            ),
            "outcomes": [o.as_dict() for o in self.outcomes],
            "params": dataclasses.asdict(self.params),
        }

    def _twin(self, o: GraspOutcome) -> GraspOutcome:
        s = o.setup
        return next(
            t
            for t in self.outcomes
            if t.setup.strategy_on != s.strategy_on
            and (t.setup.x_m, t.setup.z_m, t.setup.diameter_m) == (s.x_m, s.z_m, s.diameter_m)
        )


def strategy(
    design: SpiralDesign | None = None,
    params: StrategyParams | None = None,
    seed: int = 0,
    progress: Progress | None = None,
    jobs: int = 1,
) -> StrategyResult:
    """Objects of three diameters on a grid beside the arm, grasped through the firmware's GRASP mode with
    the strategy on and off (Note S4, Fig. S6, Fig. 3C)."""
    design = design or SpiralDesign.paper_prototype()
    p = params or StrategyParams()
    setups = [
        GraspSetup(x, z, d, strategy_on=on, mass_kg=p.mass_kg, hold_s=p.hold_s, seed=seed)
        for d in p.diameters_m
        for z in p.zs_m
        for x in p.xs_m
        for on in (True, False)
    ]
    return StrategyResult(
        p, seed, tuple(parallel_map(grasp_trial_job, [(s, design) for s in setups], jobs, progress))
    )


def run_at_size(design: SpiralDesign, size: str, seed: int, progress: Progress | None, jobs: int) -> Any:
    """Run the experiment at ``size`` (see :data:`~hil.experiments.common.SIZES`)."""
    p = sized(
        size,
        StrategyParams(diameters_m=(0.02,), xs_m=(0.04,), zs_m=(-0.11,)),
        StrategyParams(),
        StrategyParams(
            xs_m=(0.02, 0.035, 0.05, 0.065, 0.08, 0.095),
            zs_m=(-0.06, -0.08, -0.1, -0.12, -0.14, -0.16, -0.18),
        ),
    )
    return strategy(design, p, seed, progress, jobs)


def table_rows(r: StrategyResult) -> list[Row]:
    """The result\'s numbers next to the paper\'s, one row each."""
    d = r.as_dict()
    rows: list[Row] = [
        (
            "placements grasped and held, strategy on",
            pct(r.success_on),
            "wider range than off (Fig. S6, 3C)",
        ),
        ("placements grasped and held, strategy off", pct(r.success_off), "only objects near the tip"),
        ("held only with the strategy on / only off", f"{d['only_on']} / {d['only_off']}", "on > off"),
    ]
    for row in r.per_diameter():
        rows.append(
            (
                f"  diameter {row['diameter_m'] * 1000:g} mm: on / off",
                f"{pct(row['success_on'])} / {pct(row['success_off'])}",
                "",
            )
        )
    return rows


def describe_samples(r: StrategyResult) -> str:
    """The result\'s sample counts, in words."""
    p = r.params
    return (
        f"{len(p.diameters_m)} diameters x {len(p.xs_m) * len(p.zs_m)} placements x 2 strategies = "
        f"{len(r.outcomes)} grasps ({1000 * p.mass_kg:g} g objects, held {p.hold_s:g} s after release)"
    )


def plot_figure(r: StrategyResult, out: Path) -> Path:
    """Write the figure into the directory ``out``; returns its path (``strategy.png``)."""
    plt = pyplot()
    ds = r.params.diameters_m
    fig, axes = plt.subplots(1, len(ds), figsize=(3.8 * len(ds), 4.6), squeeze=False)
    for ax, d in zip(axes[0], ds, strict=True):
        for o in r.outcomes:
            s = o.setup
            if s.diameter_m != d or not s.strategy_on:
                continue
            twin = r._twin(o)
            on, off = o.held, twin.held
            marker, colour = (
                ("o", "tab:green")
                if on and off
                else ("^", "tab:blue")
                if on
                else ("v", "tab:orange")
                if off
                else ("x", "0.6")
            )
            ax.plot(s.x_m * 1000, s.z_m * 1000, marker=marker, color=colour, ms=9, ls="")
            ax.add_patch(plt.Circle((s.x_m * 1000, s.z_m * 1000), d * 500, fill=False, color=colour, lw=0.6))
        ax.plot([0, 0], [0, -223], "k-", lw=3, alpha=0.3)
        ax.set_title(
            f"d = {d * 1000:g} mm: on {pct(r._share(True, d))}, off {pct(r._share(False, d))}", fontsize=9
        )
        ax.set_aspect("equal")
        ax.set_xlim(-15, 125)
        ax.set_ylim(-235, 10)
        ax.grid(alpha=0.3)
        ax.set_xlabel("object centre from the arm's axis [mm]", fontsize=8)
        ax.set_ylabel("object centre below the base [mm]", fontsize=8)
    handles = [
        plt.Line2D([], [], marker=m, color=c, ls="", label=lab)
        for m, c, lab in (
            ("o", "tab:green", "both"),
            ("^", "tab:blue", "strategy on only"),
            ("v", "tab:orange", "strategy off only"),
            ("x", "0.6", "neither"),
        )
    ]
    axes[0][0].legend(handles=handles, fontsize=7, loc="lower left")
    fig.suptitle("grasp-range map: grasped and held against gravity (hanging arm in grey)", fontsize=10)
    return save_figure(fig, out / "strategy.png")
