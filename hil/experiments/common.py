"""What every experiment shares: the plant model it runs on, the sizes, and the table and figure helpers (the
scene and its units are :mod:`hil.trial.scene`'s)."""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeVar

from hil.sim.config import PHYSICS_STEPS_S, ModelConfig
from hil.sim.types import PhysicsExtremes

if TYPE_CHECKING:
    from hil.render import Pictures
    from hil.sim.spiral import SpiralDesign
    from hil.trial.grasp import GraspOutcome

Progress = Callable[[int, int], None]
"""``progress(done, total)``: work units done so far (trials or simulated milliseconds)."""

T = TypeVar("T")

G = 9.80665
"""Standard gravity [m/s²]."""

BOARD_MODEL = ModelConfig()
"""The plant's default model as the real-time board runs it: a 1 ms step (one per control tick), contacts
and joint limits at 2 ms."""
EXPERIMENT_STEP_S = PHYSICS_STEPS_S["fine"]
"""The experiments' physics step: four per 1 ms control tick."""
DEFAULT_MODEL = BOARD_MODEL.with_physics(EXPERIMENT_STEP_S)
"""What an experiment runs on unless given a preset or a variant: the plant's default model at a 0.25 ms
step with 0.5 ms contacts and joint limits (:meth:`ModelConfig.with_physics`). The board's 1 ms step lets a
fast grasp's whipping tip sink up to 2.8 mm into the object and the joints pass their limits by 8°; this
keeps both inside their goals (< 1 mm or < 10 % of the radius; < 1°) at four times the run time."""
PHYSICS = PHYSICS_STEPS_S
"""``--physics`` choices: the physics step; :meth:`ModelConfig.with_physics` sets the constraints from it."""

SIZES = ("tiny", "default", "large")
"""``tiny``: a smoke test of seconds; ``default``: the documented run (< 5 min on 2 cores); ``large``."""

Row = tuple[str, str, str]
"""``(quantity, ours, the paper's)``."""


def sized(size: str, tiny: T, default: T, large: T) -> T:
    """The one of ``tiny``, ``default``, ``large`` that ``size`` names.

    Raises:
        ValueError: ``size`` is not one of :data:`SIZES`.
    """
    if size not in SIZES:
        raise ValueError(f"size must be one of {', '.join(SIZES)}, got {size!r}")
    return {"tiny": tiny, "default": default, "large": large}[size]


def pct(x: float) -> str:
    """A share as a whole percentage for a table (``n/a`` for NaN)."""
    return "n/a" if math.isnan(x) else f"{100 * x:.0f} %"


def mm(x: float) -> str:
    """A length in metres as millimetres for a table (``none`` for NaN)."""
    return "none" if math.isnan(x) else f"{1000 * x:.1f} mm"


NO_EXTREMES = PhysicsExtremes(0.0, 0.0, 0.0, 0.0)
"""What an experiment with no trial reports."""


def worst_extremes(extremes: Iterable[PhysicsExtremes]) -> PhysicsExtremes:
    """The field-wise largest of several trials' :meth:`hil.sim.plant.Plant.extremes`."""
    out = NO_EXTREMES
    for e in extremes:
        out = PhysicsExtremes(
            max(out.penetration_m, e.penetration_m),
            max(out.penetration_ratio, e.penetration_ratio),
            max(out.tension_n, e.tension_n),
            max(out.limit_overshoot_rad, e.limit_overshoot_rad),
        )
    return out


def extremes_rows(e: PhysicsExtremes) -> list[Row]:
    """Table rows of the worst physics over an experiment's trials (is the figure trustworthy?)."""
    return [
        (
            "largest arm-object penetration (all trials)",
            f"{1000 * e.penetration_m:.2f} mm ({100 * e.penetration_ratio:.0f} % of the object's radius)",
            "goal < 1 mm or < 10 % of the radius",
        ),
        ("largest cable tension (all trials)", f"{e.tension_n:.1f} N", ""),
        ("largest joint overshoot past its limit", f"{math.degrees(e.limit_overshoot_rad):.2f}°", ""),
    ]


def pyplot() -> Any:
    """matplotlib's pyplot on the file-only Agg backend (imported on first use: plotting is optional)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def save_figure(fig: Any, path: Path) -> Path:
    """Write ``fig`` as a PNG to ``path`` (creating its directory), close it and return ``path``."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    pyplot().close(fig)
    return path


def grasp_pictures(
    outcomes: Sequence[GraspOutcome], design: SpiralDesign, out_dir: Path, name: str
) -> list[tuple[str, Pictures]]:
    """Pictures of an experiment's representative grasps: its first that succeeded and its first that did
    not, each run again filmed and checked to be the recorded trial (:func:`hil.render.film_grasp_trial`).

    Returns:
        ``[(heading, Pictures), ...]`` for :func:`hil.report.write_index` (empty with no grasp).
    """
    from hil.render import (  # only for a report
        NO_GL,
        RERUN,
        Pictures,
        film_grasp_trial,
        gl_backends,
        render_film,
    )

    if not gl_backends():  # MUJOCO_GL=disable: no trial is run again for nothing
        return [("", Pictures(note=NO_GL))]

    picks = [
        (label, o)
        for label, o in (
            ("succeeded", next((o for o in outcomes if o.success), None)),
            ("did not succeed", next((o for o in outcomes if not o.success), None)),
        )
        if o is not None
    ]
    out: list[tuple[str, Pictures]] = []
    for label, o in picks:
        s = o.setup
        heading = (
            f"a grasp that {label}: {1000 * s.diameter_m:.0f} mm object at x = {1000 * s.x_m:.0f} mm, "
            f"z = {1000 * s.z_m:.0f} mm, strategy {'on' if s.strategy_on else 'off'}; ended {o.state}"
        )
        film, note = film_grasp_trial(s, design, o.as_dict())
        slug = "held" if o.success else "failed"
        pictures = (
            Pictures(note=note)
            if film is None
            else render_film(film, out_dir, f"{name}-{slug}", source=RERUN)
        )
        out.append((heading, pictures))
    return out
