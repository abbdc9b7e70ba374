"""load (eq. 16, Fig. 2F): the heaviest object held per diameter at a fixed cable force."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..spiral import SpiralDesign
from .common import G, Progress, Row, pct, pyplot, save_figure, sized
from .grasp import GraspOutcome, GraspSetup, grasp_firmware, grasp_trial_job
from .parallel import parallel_map


@dataclass(frozen=True)
class LoadParams:
    """Attributes:
    diameters_m: object diameters.
    forces_n: wrap tensions (the cable force F_max of eq. 16).
    placements: ``(gap, depth)`` candidates: centre at ``(gap + d/2, −(depth + d/2))``; the best of them.
    load_rate_n_per_s: growth of the extra downward force.
    """

    diameters_m: tuple[float, ...] = (0.013, 0.017, 0.022, 0.03)
    forces_n: tuple[float, ...] = (5.0, 10.0)
    placements: tuple[tuple[float, float], ...] = ((0.03, 0.09), (0.02, 0.07), (0.04, 0.09))
    load_rate_n_per_s: float = 2.0


@dataclass(frozen=True)
class LoadResult:
    """The heaviest object held per diameter and wrap force, against M(φ, d, F_max)."""

    params: LoadParams
    seed: int
    outcomes: tuple[GraspOutcome, ...]
    bounds_kg: tuple[tuple[float, float, float], ...]  # (force, diameter, M bound)

    def rows(self) -> list[dict[str, float]]:
        """Per (force, diameter): the best held mass over placements (NaN: never held) and the bound."""
        out = []
        for force, d, bound in self.bounds_kg:
            held = [
                o.setup.mass_kg + o.load_n / G
                for o in self.outcomes
                if o.setup.diameter_m == d
                and o.setup.firmware is not None
                and o.setup.firmware.grasp.wrap_n == force
                and not math.isnan(o.load_n)
            ]
            best = max(held) if held else math.nan
            out.append(
                {
                    "force_n": force,
                    "diameter_m": d,
                    "held_kg": best,
                    "bound_kg": bound,
                    "ratio": best / bound if held else math.nan,
                }
            )
        return out

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        return {
            "experiment": "load",
            "seed": self.seed,
            "rows": self.rows(),
            "trials": len(self.outcomes),
            "outcomes": [o.as_dict() for o in self.outcomes],
            "params": dataclasses.asdict(self.params),
        }


def load(
    design: SpiralDesign | None = None,
    params: LoadParams | None = None,
    seed: int = 0,
    progress: Progress | None = None,
    jobs: int = 1,
) -> LoadResult:
    """Grasp (strategy on) a 20 g cylinder, remove its support, then grow a downward force on it until it
    slips out: the heaviest load held per diameter at a fixed wrap tension F, against eq. (16)."""
    design = design or SpiralDesign.paper_prototype()
    p = params or LoadParams()
    setups = []
    bounds = []
    for force in p.forces_n:
        fw = grasp_firmware(grasp_wrap_n=force)
        for d in p.diameters_m:
            bounds.append((force, d, design.max_load_kg(d, force)))
            for gap, depth in p.placements:
                setups.append(
                    GraspSetup(
                        gap + d / 2,
                        -(depth + d / 2),
                        d,
                        strategy_on=True,
                        hold_s=0.5,
                        firmware=fw,
                        load_rate_n_per_s=p.load_rate_n_per_s,
                        seed=seed,
                    )
                )
    outcomes = parallel_map(grasp_trial_job, [(s, design) for s in setups], jobs, progress)
    return LoadResult(p, seed, tuple(outcomes), tuple(bounds))


def run_at_size(design: SpiralDesign, size: str, seed: int, progress: Progress | None, jobs: int) -> Any:
    """Run the experiment at ``size`` (see :data:`~hil.experiments.common.SIZES`)."""
    p = sized(
        size,
        LoadParams(diameters_m=(0.02,), forces_n=(5.0,), placements=((0.03, 0.09),)),
        LoadParams(),
        LoadParams(diameters_m=(0.013, 0.016, 0.02, 0.025, 0.03, 0.04), forces_n=(5.0, 10.0, 15.0)),
    )
    return load(design, p, seed, progress, jobs)


def table_rows(r: LoadResult) -> list[Row]:
    """The result\'s numbers next to the paper\'s, one row each."""
    rows: list[Row] = []
    for row in r.rows():
        held = row["held_kg"]
        rows.append(
            (
                f"F = {row['force_n']:g} N, d = {row['diameter_m'] * 1000:g} mm: heaviest held",
                "not held" if math.isnan(held) else f"{held * 1000:.0f} g ({pct(row['ratio'])} of the bound)",
                f"M <= {row['bound_kg'] * 1000:.0f} g (eq. 16)",
            )
        )
    return rows


def describe_samples(r: LoadResult) -> str:
    """The result\'s sample counts, in words."""
    p = r.params
    return (
        f"{len(p.forces_n)} forces x {len(p.diameters_m)} diameters x {len(p.placements)} placements = "
        f"{len(r.outcomes)} grasps, load growing at {p.load_rate_n_per_s:g} N/s"
    )


def plot_figure(r: LoadResult, out: Path, design: SpiralDesign | None = None) -> Path:
    """Write the figure into the directory ``out``; returns its path (``load.png``)."""
    plt = pyplot()
    design = design or SpiralDesign.paper_prototype()
    fig, ax = plt.subplots(figsize=(6.5, 4.2))
    dd = np.linspace(0.005, max(r.params.diameters_m) * 1.3, 100)
    for k, force in enumerate(r.params.forces_n):
        colour = f"C{k}"
        ax.plot(
            dd * 1000,
            [design.max_load_kg(float(d), force) * 1000 for d in dd],
            "--",
            color=colour,
            lw=1,
            label=f"bound M(φ, d, {force:g} N)",
        )
        rows = [x for x in r.rows() if x["force_n"] == force]
        ax.plot(
            [x["diameter_m"] * 1000 for x in rows],
            [x["held_kg"] * 1000 for x in rows],
            "o-",
            color=colour,
            label=f"held in simulation, F = {force:g} N",
        )
    ax.set_xlabel("object diameter [mm]")
    ax.set_ylabel("mass held [g]")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)
    ax.set_title("load: heaviest object held vs. the bound of eq. (16)", fontsize=10)
    return save_figure(fig, out / "load.png")
