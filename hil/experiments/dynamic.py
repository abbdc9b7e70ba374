"""dynamic (Fig. S11): a current step grasping a pen, and objects thrown at the hanging arm."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from controller.config import FirmwareConfig, MappingConfig

from ..model_config import ModelConfig, ObjectConfig
from ..plant_types import PhysicsExtremes
from ..spiral import SpiralDesign
from .common import (
    DEFAULT_MODEL,
    FAR_M,
    MS,
    OBJ,
    Progress,
    Row,
    extremes_rows,
    pyplot,
    save_figure,
    sized,
    worst_extremes,
)
from .parallel import parallel_map
from .rig import contact_units, contact_wrap_deg, direct_rig, world_m


@dataclass(frozen=True)
class DynamicParams:
    """Attributes:
    step_tensions_n: cable 0 tension steps (54 N = 3 A, the current limit) for the pen grasp.
    pen: ``(x, z)`` of the pen's centre relative to the base (beside the hanging arm, near its tip).
    pen_diameter_m, pen_length_m, pen_mass_kg: the pen.
    throw_speeds_m_s: speeds of the thrown object (horizontal, toward the arm, from its +x side).
    throw_from: ``(x, z)`` where the thrown object starts.
    window_ms: how long each run is watched.
    """

    step_tensions_n: tuple[float, ...] = (20.0, 54.0)
    pen: tuple[float, float] = (0.02, -0.17)
    pen_diameter_m: float = 0.010
    pen_length_m: float = 0.14
    pen_mass_kg: float = 0.015
    throw_speeds_m_s: tuple[float, ...] = (1.0, 2.0, 4.0)
    throw_from: tuple[float, float] = (0.04, -0.12)
    window_ms: int = 400


@dataclass(frozen=True)
class DynamicRun:
    """One pen grasp or one throw."""

    kind: str  # "pen" or "throw"
    value: float  # step tension [N] or throw speed [m/s]
    first_contact_ms: float
    half_wrap_ms: float  # from the step (pen) or the first contact (throw) to a >= 180° wrap; NaN: never
    max_wrap_deg: float
    held_after_ms: float  # pen: released at the half wrap, still touching the arm this long after
    held: bool
    extremes: PhysicsExtremes  # the worst physics of the run
    wrap_trace: tuple[float, ...] = field(repr=False)


@dataclass(frozen=True)
class DynamicResult:
    """Fig. S11: how fast a current step grasps a pen; whether a thrown object is captured passively."""

    params: DynamicParams
    seed: int
    runs: tuple[DynamicRun, ...]

    @property
    def extremes(self) -> PhysicsExtremes:
        """The worst physics over every run."""
        return worst_extremes(r.extremes for r in self.runs)

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        pens = [r for r in self.runs if r.kind == "pen"]
        throws = [r for r in self.runs if r.kind == "throw"]
        fastest = min((r.half_wrap_ms for r in pens if not math.isnan(r.half_wrap_ms)), default=math.nan)
        return {
            "experiment": "dynamic",
            "seed": self.seed,
            "pen_half_wrap_ms": fastest,
            "pen_held": any(r.held for r in pens),
            "captured": sum(r.held for r in throws),
            "throws": len(throws),
            "extremes": self.extremes.as_dict(),
            "runs": [
                {k: v for k, v in dataclasses.asdict(r).items() if k != "wrap_trace"} for r in self.runs
            ],
            "params": dataclasses.asdict(self.params),
        }


def _dynamic_run(args: tuple[str, float, DynamicParams, int, ModelConfig]) -> DynamicRun:
    kind, value, p, seed, model = args
    pen = kind == "pen"
    if pen:
        obj = ObjectConfig(
            OBJ, radius_m=p.pen_diameter_m / 2, length_m=p.pen_length_m, pos_m=FAR_M, mass_kg=p.pen_mass_kg
        )
    else:
        obj = ObjectConfig(OBJ, radius_m=0.01, length_m=0.06, pos_m=FAR_M, mass_kg=0.01)
    # A step, not a ramp: the slew limiter opened, the ceiling at the 3 A current limit.
    fw = FirmwareConfig(mapping=MappingConfig(tension_max_n=54.0, slew_n_per_s=100_000.0))
    rig = direct_rig(SpiralDesign.paper_prototype(), fw, objects=(obj,), seed=seed, model=model)
    plant = rig.plant
    if pen:
        plant.hold_object(OBJ, world_m(*p.pen))
        rig.run(200 * MS)
        rig.set_tensions([value, fw.mapping.pretension_n, fw.mapping.pretension_n])
    else:
        plant.hold_object(OBJ)
        rig.run(300 * MS)
        plant.hold_object(OBJ, world_m(*p.throw_from))
        plant.release_object(OBJ)
        plant.set_object_velocity(OBJ, (-value, 0.0, 0.3))
    t0 = rig.now_us
    first = math.nan
    half = math.nan
    released = math.nan
    trace = []
    max_wrap = 0.0
    for _ in range(p.window_ms):
        rig.step()
        units = contact_units(plant, OBJ)
        wrap = contact_wrap_deg(plant, OBJ)
        trace.append(wrap)
        max_wrap = max(max_wrap, wrap)
        t = (rig.now_us - t0) / MS
        if units and math.isnan(first):
            first = t
        if math.isnan(half) and wrap >= 180.0 and len(units) >= 3:
            half = t if pen else t - first
            if pen:
                plant.release_object(OBJ)
                released = t
    last_touch = t if contact_units(plant, OBJ) else math.nan
    extremes = plant.extremes()
    rig.close()
    if pen:
        held_after = (last_touch - released) if not math.isnan(released) else math.nan
        held = not math.isnan(held_after)
    else:
        held_after = math.nan
        held = not math.isnan(half) and not math.isnan(last_touch)
    return DynamicRun(kind, value, first, half, max_wrap, held_after, held, extremes, tuple(trace))


def dynamic(
    params: DynamicParams | None = None,
    seed: int = 0,
    progress: Progress | None = None,
    jobs: int = 1,
    model: ModelConfig = DEFAULT_MODEL,
) -> DynamicResult:
    """Fig. S11: a current step on cable 0 (DIRECT) against a pen on its support beside the tip (time to
    a half wrap, then the pen is let go); objects thrown at the hanging arm (passive capture); on the
    plant ``model``."""
    p = params or DynamicParams()
    items: list[tuple[str, float, DynamicParams, int, ModelConfig]] = [
        ("pen", t, p, seed, model) for t in p.step_tensions_n
    ]
    items += [("throw", v, p, seed, model) for v in p.throw_speeds_m_s]
    return DynamicResult(p, seed, tuple(parallel_map(_dynamic_run, items, jobs, progress)))


def run_at_size(
    design: SpiralDesign,
    size: str,
    seed: int,
    progress: Progress | None,
    jobs: int,
    model: ModelConfig = DEFAULT_MODEL,
) -> Any:
    """Run the experiment at ``size`` (see :data:`~hil.experiments.common.SIZES`) on ``model``."""
    p = sized(
        size,
        DynamicParams(step_tensions_n=(54.0,), throw_speeds_m_s=(2.0,), window_ms=150),
        DynamicParams(),
        DynamicParams(
            step_tensions_n=(10.0, 20.0, 35.0, 54.0), throw_speeds_m_s=(0.5, 1.0, 2.0, 3.0, 4.0, 6.0)
        ),
    )
    return dynamic(p, seed, progress, jobs, model)


def table_rows(r: DynamicResult) -> list[Row]:
    """The result\'s numbers next to the paper\'s, one row each."""
    rows: list[Row] = []
    for run in r.runs:
        if run.kind == "pen":
            rows.append(
                (
                    f"pen, step to {run.value:g} N: step -> half wrap",
                    "never" if math.isnan(run.half_wrap_ms) else f"{run.half_wrap_ms:.0f} ms",
                    "0.06 s to grasp (45 cm arm, Fig. S11A)",
                )
            )
            rows.append(("  pen kept once let go", "yes" if run.held else "no (thrown)", "moved to the base"))
        else:
            rows.append(
                (
                    f"object thrown at {run.value:g} m/s: contact -> half wrap",
                    "never" if math.isnan(run.half_wrap_ms) else f"{run.half_wrap_ms:.0f} ms",
                    "captured within 120 ms (Fig. S11B)",
                )
            )
            rows.append(
                ("  largest wrap, captured", f"{run.max_wrap_deg:.0f}°, {'yes' if run.held else 'no'}", "")
            )
    rows.extend(extremes_rows(r.extremes))
    return rows


def describe_samples(r: DynamicResult) -> str:
    """The result\'s sample counts, in words."""
    pens = sum(1 for x in r.runs if x.kind == "pen")
    return f"{pens} pen steps and {len(r.runs) - pens} throws, {r.params.window_ms} ms each"


def plot_figure(r: DynamicResult, out: Path) -> Path:
    """Write the figure into the directory ``out``; returns its path (``dynamic.png``)."""
    plt = pyplot()
    fig, (a, b) = plt.subplots(1, 2, figsize=(10, 4))
    for run in r.runs:
        ax = a if run.kind == "pen" else b
        t = np.arange(1, len(run.wrap_trace) + 1)
        unit = "N step" if run.kind == "pen" else "m/s"
        ax.plot(t, run.wrap_trace, lw=1, label=f"{run.value:g} {unit}")
    a.axvline(60, color="k", ls=":", label="paper: 0.06 s")
    b.axvline(120, color="k", ls=":", label="paper: 120 ms")
    for ax, title in (
        (a, "pen beside the tip: current step on cable 0"),
        (b, "object thrown at the hanging arm"),
    ):
        ax.axhline(180, color="r", ls="--", lw=0.8)
        ax.set_xlabel("time [ms]" + (" from the step" if ax is a else " from the throw"))
        ax.set_ylabel("wrap angle of the contacts [°]")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
        ax.set_title(title, fontsize=9)
    return save_figure(fig, out / "dynamic.png")
