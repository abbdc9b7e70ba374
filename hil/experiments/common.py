"""What every experiment shares: units, the scene's geometry, the sizes, and the table and figure helpers."""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path
from typing import Any, TypeVar

Progress = Callable[[int, int], None]
"""``progress(done, total)``: work units done so far (trials or simulated milliseconds)."""

T = TypeVar("T")

MS = 1000
"""Microseconds per millisecond (board time is in µs)."""
S = 1_000_000
"""Microseconds per second."""
G = 9.80665
"""Standard gravity [m/s²]."""
DRONE_Z_M = 1.0
BASE_Z_M = DRONE_Z_M - 0.02  # the mount is 20 mm under the drone (DroneConfig.mount_offset_m)
FAR_M = (0.6, 0.0, 0.4)  # where an object waits, out of reach, until its trial places it
OBJ = "target"
"""Name of the one object of a trial in the plant's scene."""
HELD_DROP_MM = 60.0
"""A released object counts as held if it ends up less than this below where it was let go (the wrap
settles and swings it by a few centimetres; a dropped object falls far more) ..."""
HELD_SPEED_M_S = 0.05
"""... and is not moving faster than this at the end (not slipping out)."""

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
