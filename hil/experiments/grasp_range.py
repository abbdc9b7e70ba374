"""grasp-range (eq. 14, 15): the smallest and largest cylinders the arm wraps half way around."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..spiral import SpiralDesign
from .common import Progress, Row, mm, pyplot, save_figure, sized
from .grasp import GraspOutcome, GraspSetup, grasp_firmware, grasp_trial_job
from .parallel import parallel_map


@dataclass(frozen=True)
class GraspRangeParams:
    """Attributes:
    diameters_m: cylinders to try.
    gaps_m: horizontal gap between the hanging arm's axis and the cylinder's near surface.
    drops_m: depth of the cylinder's top below the base.
    half_wrap_deg: the wrap that counts ("at least half way around", eq. 15).
    wrap_n: wrap tension (a geometric question: more than the grasp default, well within 3 A).
    """

    diameters_m: tuple[float, ...] = (0.004, 0.006, 0.009, 0.013, 0.018, 0.026, 0.036, 0.05, 0.07, 0.1, 0.13)
    gaps_m: tuple[float, ...] = (0.02, 0.04)
    drops_m: tuple[float, ...] = (0.06, 0.09)
    half_wrap_deg: float = 180.0
    wrap_n: float = 15.0


@dataclass(frozen=True)
class GraspRangeResult:
    """The best wrap around each diameter, and the smallest and largest wrapped half way."""

    params: GraspRangeParams
    seed: int
    d_min_paper_m: float
    d_max_paper_m: float
    outcomes: tuple[GraspOutcome, ...]

    def best_wrap_deg(self) -> list[tuple[float, float]]:
        """``(diameter, best wrap angle over placements and strategies)`` per diameter."""
        out = []
        for d in self.params.diameters_m:
            wraps = [o.wrap_deg for o in self.outcomes if o.setup.diameter_m == d and o.state == "HOLD"]
            out.append((d, max(wraps, default=0.0)))
        return out

    @property
    def d_min_sim_m(self) -> float:
        """Smallest diameter wrapped at least half way (NaN if none)."""
        ok = [d for d, w in self.best_wrap_deg() if w >= self.params.half_wrap_deg]
        return min(ok) if ok else math.nan

    @property
    def d_max_sim_m(self) -> float:
        """Largest diameter wrapped at least half way (NaN if none)."""
        ok = [d for d, w in self.best_wrap_deg() if w >= self.params.half_wrap_deg]
        return max(ok) if ok else math.nan

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        return {
            "experiment": "grasp-range",
            "seed": self.seed,
            "d_min_paper_m": self.d_min_paper_m,
            "d_max_paper_m": self.d_max_paper_m,
            "d_min_sim_m": self.d_min_sim_m,
            "d_max_sim_m": self.d_max_sim_m,
            "best_wrap_deg": [{"diameter_m": d, "wrap_deg": w} for d, w in self.best_wrap_deg()],
            "trials": len(self.outcomes),
            "outcomes": [o.as_dict() for o in self.outcomes],
            "params": dataclasses.asdict(self.params),
        }


def grasp_range(
    design: SpiralDesign | None = None,
    params: GraspRangeParams | None = None,
    seed: int = 0,
    progress: Progress | None = None,
    jobs: int = 1,
) -> GraspRangeResult:
    """Cylinders of many diameters, fixed beside the arm (held on their support throughout), grasped with
    the strategy on and off; the wrap angle of the contacts once the grasp holds, against the paper's
    d_min (eq. 14) and d_max (eq. 15)."""
    design = design or SpiralDesign.paper_prototype()
    p = params or GraspRangeParams()
    fw = grasp_firmware(grasp_wrap_n=p.wrap_n)
    setups = [
        GraspSetup(
            gap + d / 2, -(drop + d / 2), d, strategy_on=on, hold_s=0.3, release=False, firmware=fw, seed=seed
        )
        for d in p.diameters_m
        for gap in p.gaps_m
        for drop in p.drops_m
        for on in (True, False)
    ]
    outcomes = parallel_map(grasp_trial_job, [(s, design) for s in setups], jobs, progress)
    return GraspRangeResult(p, seed, design.d_min_m, design.d_max_m, tuple(outcomes))


def run_at_size(design: SpiralDesign, size: str, seed: int, progress: Progress | None, jobs: int) -> Any:
    """Run the experiment at ``size`` (see :data:`~hil.experiments.common.SIZES`)."""
    p = sized(
        size,
        GraspRangeParams(diameters_m=(0.013,), gaps_m=(0.02,), drops_m=(0.06,)),
        GraspRangeParams(),
        GraspRangeParams(gaps_m=(0.015, 0.03, 0.045), drops_m=(0.0, 0.04, 0.07, 0.1)),
    )
    return grasp_range(design, p, seed, progress, jobs)


def table_rows(r: GraspRangeResult) -> list[Row]:
    """The result\'s numbers next to the paper\'s, one row each."""
    rows: list[Row] = [
        (
            "smallest diameter wrapped >= half way",
            mm(r.d_min_sim_m),
            f"d_min = {mm(r.d_min_paper_m)} (eq. 14)",
        ),
        (
            "largest diameter wrapped >= half way",
            mm(r.d_max_sim_m),
            f"d_max = {mm(r.d_max_paper_m)} (eq. 15)",
        ),
    ]
    for d, w in r.best_wrap_deg():
        rows.append(
            (f"  best wrap around {d * 1000:g} mm", f"{w:.0f}°", "" if d > r.d_min_paper_m else "< d_min")
        )
    return rows


def describe_samples(r: GraspRangeResult) -> str:
    """The result\'s sample counts, in words."""
    p = r.params
    return (
        f"{len(p.diameters_m)} diameters x {len(p.gaps_m) * len(p.drops_m)} placements x 2 strategies = "
        f"{len(r.outcomes)} grasps of fixed cylinders at {p.wrap_n:g} N"
    )


def plot_figure(r: GraspRangeResult, out: Path) -> Path:
    """Write the figure into the directory ``out``; returns its path (``grasp-range.png``)."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(6.5, 4.2))
    for on, marker in ((True, "^"), (False, "v")):
        xs = [o.setup.diameter_m * 1000 for o in r.outcomes if o.setup.strategy_on == on]
        ys = [o.wrap_deg for o in r.outcomes if o.setup.strategy_on == on]
        ax.plot(xs, ys, marker, ls="", alpha=0.5, label=f"strategy {'on' if on else 'off'} (each placement)")
    best = r.best_wrap_deg()
    ax.plot([d * 1000 for d, _ in best], [w for _, w in best], "k-", lw=1.2, label="best")
    ax.axhline(r.params.half_wrap_deg, color="r", ls="--", lw=1, label="half way (eq. 15)")
    ax.axvline(r.d_min_paper_m * 1000, color="g", ls=":", label=f"d_min = {r.d_min_paper_m * 1000:.1f} mm")
    ax.axvline(r.d_max_paper_m * 1000, color="m", ls=":", label=f"d_max = {r.d_max_paper_m * 1000:.0f} mm")
    ax.set_xscale("log")
    ax.set_xlabel("cylinder diameter [mm]")
    ax.set_ylabel("wrap angle of the contacts [°]")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=7)
    ax.set_title("grasp range: how far the arm wraps around fixed cylinders", fontsize=10)
    return save_figure(fig, out / "grasp-range.png")
