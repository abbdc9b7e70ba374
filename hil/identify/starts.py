"""Where a fit starts again when its first optimum has not explained what the sensors can see.

Levenberg-Marquardt finds the nearest minimum. In the hidden-truth draws (docs/identify.md section 6) four
of nine fits stopped in one where the delay sat at 0 and joint friction, damping and capstan friction made
up for it, leaving 0.02-0.6 mm of the cable lengths unexplained, where the fits that reached the truth
left 6e-5 mm: the encoders' own quantization. A model that can follow the arm exactly (the draws) tells
its local minima by that gap; a model that cannot (a real arm) leaves more in every minimum, and a restart
then costs time and can only lower the objective, as the best of all starts is kept.

- :func:`settled_m`: the length error a fit that reached its data's own noise leaves: the encoders'
  quantization (one count of 8192 per rotor turn, through the gear, on the spool) as a uniform error's RMS
  (q / sqrt(12)), times :data:`SETTLED_FACTOR` for what else the sensors add (a CAN frame a tick late).
- :func:`restart_points`: the starts: a scrambled Sobol sequence (seeded, so a fit is repeatable) over the
  half of the search box around the first start, in the optimizer's coordinates (each parameter in its
  own size: a factor of 0.58-1.73 on a relative row's preset; an absolute row between halfway down to its
  lower bound and halfway up to its upper).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import scipy.stats.qmc
from numpy.typing import NDArray

from hil.identify.motor_data import MotorData

__all__ = ["SETTLED_FACTOR", "restart_points", "settled_m"]

SETTLED_FACTOR = 10.0
"""How far above the encoders' quantization RMS a fit may stay and still count as having explained what
the sensors see. Of the hidden-truth fits, those that reached the truth left 1.0x (6.2e-5 mm against the
prototype's 6.2e-5 mm, held out); draw 8 from its 2 ms delay start, within 3.7 %, left 18x on its fitted
samples; the wrong minima left 160x (draw 5, 0.01 mm held out) to 10 000x (draw 7). A fit between 10x and
those (draw 1: within 0.4 %, 93x held out) is started again at a cost in time only."""


def settled_m(recordings: Sequence[MotorData]) -> float:
    """The fitted cable lengths' RMS error below which a fit has nothing left to explain (the largest of
    the recordings' quantization RMS, times :data:`SETTLED_FACTOR`); NaN when no recording says."""
    quanta = [r.length_quantum_m for r in recordings if math.isfinite(r.length_quantum_m)]
    return max(quanta) / math.sqrt(12.0) * SETTLED_FACTOR if quanta else math.nan


def restart_points(
    x0: NDArray[np.float64], lower: NDArray[np.float64], upper: NDArray[np.float64], n: int, seed: int = 0
) -> list[NDArray[np.float64]]:
    """``n`` starts in the half of the box ``[lower, upper]`` around ``x0`` (optimizer coordinates).

    Raises:
        ValueError: shapes that differ, a start outside its box, or a negative ``n``.
    """
    x0, lower, upper = (np.asarray(v, dtype=np.float64).ravel() for v in (x0, lower, upper))
    if not x0.shape == lower.shape == upper.shape:
        raise ValueError("the start and its bounds must have the same length")
    if np.any(x0 < lower) or np.any(x0 > upper):
        raise ValueError("the start lies outside its bounds")
    if n < 0:
        raise ValueError(f"n must be >= 0, got {n}")
    if n == 0 or x0.size == 0:
        return []
    lo = x0 - 0.5 * (x0 - lower)
    hi = x0 + 0.5 * (upper - x0)
    sobol = scipy.stats.qmc.Sobol(d=x0.size, scramble=True, seed=seed)
    unit = sobol.random(1 << max(0, math.ceil(math.log2(n))))[:n]  # a power of two keeps it balanced
    return [lo + u * (hi - lo) for u in unit]
