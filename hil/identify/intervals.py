"""A fitted parameter's 95 % interval, and whether the data identify it.

:func:`mujoco.sysid.calculate_intervals` assumes independent residuals; a simulated arm's errors are smooth
in time, so its intervals are far too narrow. :func:`hac_covariance` is the heteroskedasticity-and-
autocorrelation-consistent one (a Newey-West sandwich around the same Jacobian, each window's bandwidth read
from its residual's autocorrelation); :func:`estimates` turns it into intervals (Student's t on the effective
number of samples, computed by the caller) and decides identifiability.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Final

import numpy as np
from numpy.typing import NDArray

from hil.sim.uncertain import IdParam

__all__ = [
    "IDENTIFIED_WITHIN",
    "NUMERICAL_FLOOR_X",
    "TRADES_AGAINST",
    "TWIN_TARGET_M",
    "ParamEstimate",
    "estimates",
    "fd_floor",
    "hac_covariance",
    "remaining_step",
    "si_interval",
    "unexplained",
]

FloatArray = NDArray[np.float64]

NUMERICAL_FLOOR_X: Final = 1e-4
"""The smallest half-width of an interval, in the optimizer's coordinates, when the caller names no solver
step (:func:`estimates`' ``floor_x``). The fit passes its finite-difference step (:func:`fd_floor`)."""


def fd_floor(x: FloatArray, fd_step: float) -> FloatArray:
    """The solver's finite-difference step at ``x``, per parameter, in the optimizer's coordinates
    (``fd_step`` times ``max(1, |x|)``, as :func:`mujoco.minimize.jacobian_fd` steps): the smallest
    half-width an interval may claim.

    The Jacobian is a secant over this step. Where the objective is not smooth on a smaller scale, the
    secant's slope is not the gradient, and the point where the solver stops can lie anywhere within about a
    step of the minimum. It is not smooth there: a command delay interpolated between 1 ms periods against
    ticks that start late, dry friction's stick and slip. Measured (docs/identify.md section 7): one draw's
    cable-length error against its delay, every other value true, rises from 0.062 µm (the encoders'
    quantization) to 0.105 µm at 4 µs shorter and to 0.297 µm at 4 µs longer with the loop's lateness in
    the recording, symmetrically (0.105 and 0.107 µm) without it; the delay's step is 10 µs, and its fits
    stopped 0.1-11 µs from the truth with statistical intervals of ±0.1-3 µs. On a smooth objective the
    floor only widens an interval that was narrower than the solver can resolve.
    """
    return fd_step * np.maximum(1.0, np.abs(np.asarray(x, dtype=np.float64)))


@dataclass(frozen=True, slots=True)
class ParamEstimate:
    """One parameter after the fit.

    Attributes:
        name: its name.
        unit: its SI unit.
        preset: the value it started from.
        value: the fitted value.
        interval: the 95 % interval (autocorrelation-consistent) [unit]; symmetric in the optimizer's
            coordinate, so a relative parameter's is symmetric in its logarithm.
        naive_interval: the toolbox's, which assumes independent residuals.
        identifiable: the data pin it down (the interval within :data:`IDENTIFIED_WITHIN` of the value).
        why: when not identifiable, why (the interval, or the parameter it trades against).
        at_bound: the fit stopped at a search bound.
        hac_interval: the autocorrelation-consistent interval alone, before it is widened by how far the
            fit stopped from its local minimum (:func:`remaining_step`); ``interval`` when it stopped there.
    """

    name: str
    unit: str
    preset: float
    value: float
    interval: tuple[float, float]
    naive_interval: tuple[float, float]
    identifiable: bool
    why: str
    at_bound: bool
    hac_interval: tuple[float, float] = (math.nan, math.nan)

    @property
    def half_width(self) -> float:
        """Half the 95 % interval's width [unit]."""
        return 0.5 * (self.interval[1] - self.interval[0])

    @property
    def naive_half_width(self) -> float:
        """Half the toolbox's interval's width [unit]."""
        return 0.5 * (self.naive_interval[1] - self.naive_interval[0])

    def covers(self, value: float) -> bool:
        """``value`` lies in the 95 % interval."""
        return self.interval[0] <= value <= self.interval[1]


def hac_covariance(
    jac: FloatArray, res: FloatArray, blocks: Sequence[tuple[int, int, int]]
) -> tuple[FloatArray, float]:
    """Newey-West sandwich covariance of a least-squares estimate with autocorrelated residuals.

    Args:
        jac: (N, p) Jacobian of the residual.
        res: (N,) residual at the optimum.
        blocks: per window, (first row, rows, channels per sample): rows are sample-major.

    Returns:
        The (p, p) covariance and the effective number of independent samples.
    """
    h = jac.T @ jac
    h_inv = np.linalg.pinv(h)
    p = jac.shape[1]
    s = np.zeros((p, p))
    n_eff = 0.0
    for first, rows, ch in blocks:
        if rows == 0:
            continue
        m = rows // ch
        g = (jac[first : first + rows] * res[first : first + rows, None]).reshape(m, ch, p).sum(axis=1)
        r = res[first : first + rows].reshape(m, ch)
        lag = _bandwidth(r)
        s += g.T @ g
        for lag_k in range(1, lag + 1):
            w = 1.0 - lag_k / (lag + 1.0)
            gamma = g[lag_k:].T @ g[:-lag_k]
            s += w * (gamma + gamma.T)
        n_eff += m / max(1.0, _integrated_time(r))
    cov = h_inv @ s @ h_inv
    return cov, n_eff


def _acf(r: FloatArray, max_lag: int) -> FloatArray:
    x = r - r.mean(axis=0)
    denom = float((x * x).sum())
    if denom <= 0:
        return np.zeros(max_lag + 1)
    return np.array([float((x[k:] * x[: len(x) - k]).sum()) / denom for k in range(max_lag + 1)])


def _bandwidth(r: FloatArray) -> int:
    """Lags that still correlate: twice the first lag where the autocorrelation drops below 0.05."""
    m = len(r)
    rho = _acf(r, max(1, m // 3))
    below = np.nonzero(rho < 0.05)[0]
    first = int(below[0]) if len(below) else m // 3
    return int(min(m // 3, max(1, 2 * first)))


def _integrated_time(r: FloatArray) -> float:
    """1 + 2 Σ ρ_k up to the first negative ρ (samples per independent sample)."""
    m = len(r)
    rho = _acf(r, max(1, m // 3))
    total = 1.0
    for k in range(1, len(rho)):
        if rho[k] <= 0:
            break
        total += 2.0 * rho[k]
    return total


def remaining_step(
    jac: FloatArray, res: FloatArray, x: FloatArray, lower: FloatArray, upper: FloatArray
) -> FloatArray:
    """How far, per parameter, the fit stopped from its local minimum: the Gauss-Newton step from ``x``
    (the least-squares solution of ``jac @ step = -res``), kept inside the search box, in absolute value.

    Levenberg-Marquardt can stop before the minimum: at its iteration cap, or when its steps no longer
    lower the objective. The statistical interval is centred on the minimum, so around the point where the
    fit stopped it must be widened by the distance between the two; by the triangle inequality an interval
    of half-width ``remaining + half`` around the stopping point holds every value ``half`` holds around
    the minimum. At the minimum the gradient ``jac.T @ res`` vanishes and so does the step. A step along a
    valley (two parameters trading) can reach the box's edge: such a parameter is not identified anyway,
    and the wide interval says so.
    """
    if jac.size == 0:
        return np.zeros_like(x)
    step = -np.linalg.lstsq(jac, res, rcond=None)[0]
    step = np.where(np.isfinite(step), step, np.inf)
    return np.abs(np.clip(x + step, lower, upper) - x)


TWIN_TARGET_M: Final = 3e-4
"""The twin's accuracy target (issue 23: held-out cable lengths within 0.3 mm RMS): the bound on what a fit
may leave unexplained when the recordings do not say their sensors' noise."""

IDENTIFIED_WITHIN: Final = 0.10
"""The largest half-width of a 95 % interval, as a fraction of the fitted value, at which a parameter is
called identified. It is what "identified" promises (issue 23: every parameter the fit calls identifiable
within 10 % of the truth): an interval that covers the truth and is this narrow puts the value within
10 % of it. One rule for every parameter; the per-parameter thresholds it replaces (8-40 %, and an
absolute 2 mN·m on a joint friction of about 0.3 mN·m) called values identified that their own intervals
put 30 % or 600 % away from the truth."""

TRADES_AGAINST: Final = 0.95
"""|correlation| between two fitted parameters above which neither counts as identified."""


def estimates(
    preset_values: Mapping[str, float],
    rows: Sequence[IdParam],
    x: FloatArray,
    half_x: FloatArray,
    naive_x: FloatArray,
    corr: FloatArray,
    unconverged_after: int | None = None,
    unexplained: str | None = None,
    remaining_x: FloatArray | None = None,
    floor_x: FloatArray | float = NUMERICAL_FLOOR_X,
) -> tuple[ParamEstimate, ...]:
    """The fitted values and intervals in SI, from the optimizer's coordinates.

    A parameter is identified only when its interval's half-width is within :data:`IDENTIFIED_WITHIN` of
    its value, it is not at a bound,
    it does not trade against another one (|correlation| above :data:`TRADES_AGAINST`: a narrow interval
    along a valley says how flat the valley's floor is, not where on it the truth is) and the fit
    converged (``unconverged_after`` None): an interval at a point still moving is no interval. Nor is any
    parameter identified when the model does not explain the data (``unexplained``: why, from the fit's
    error): every interval is conditional on the model being right, and a wrong model's best compromise is
    not the arm's value, however narrow its interval. ``remaining_x`` (:func:`remaining_step`, optimizer
    coordinates) widens each interval by how far the fit stopped from its local minimum; ``floor_x`` is the
    smallest half-width before that (the solver's finite-difference step: :func:`fd_floor`).
    """
    out = []
    half_x = np.maximum(half_x, floor_x)
    more = np.zeros_like(half_x) if remaining_x is None else np.asarray(remaining_x, dtype=np.float64)
    for i, p in enumerate(rows):
        v0 = preset_values[p.name]
        value = p.value_at(float(x[i]), v0)
        hac = si_interval(p, v0, float(x[i]), float(half_x[i]))
        interval = si_interval(p, v0, float(x[i]), float(half_x[i] + more[i]))
        naive = si_interval(p, v0, float(x[i]), float(naive_x[i]) if i < len(naive_x) else math.nan)
        half = 0.5 * (interval[1] - interval[0])
        limit = IDENTIFIED_WITHIN * abs(value)
        lo, hi = p.x_bounds(v0)
        at_bound = math.isclose(float(x[i]), lo, abs_tol=1e-6) or math.isclose(float(x[i]), hi, abs_tol=1e-6)
        partners = [rows[j].name for j in range(len(rows)) if j != i and abs(corr[i, j]) > TRADES_AGAINST]
        reasons = []
        if not (math.isfinite(half) and half <= limit):
            stopped = 0.5 * (hac[1] - hac[0]) <= limit if more[i] > 0 else False
            reasons.append(
                f"95 % interval ±{half:.3g} {p.unit} is wider than ±{limit:.3g}".replace("  ", " ")
                + (" (the fit stopped short of its minimum)" if stopped else "")
            )
        if partners:
            reasons.append(f"trades against {', '.join(partners)}")
        if at_bound:
            reasons.append("at its bound")
        if unconverged_after is not None:
            reasons.append(f"the fit had not converged after {unconverged_after} iterations")
        if unexplained is not None:
            reasons.append(unexplained)
        out.append(
            ParamEstimate(
                p.name, p.unit, v0, value, interval, naive, not reasons, "; ".join(reasons), at_bound, hac
            )
        )
    return tuple(out)


def si_interval(p: IdParam, v0: float, x: float, half: float) -> tuple[float, float]:
    if not math.isfinite(half):
        return (math.nan, math.nan)
    lo, hi = p.from_x(x - half, v0), p.from_x(x + half, v0)
    return (min(lo, hi), max(lo, hi))


def unexplained(rms_m: float, within_m: float | None, noise_m: float) -> str | None:
    """Why the fit does not explain the data it saw, or None when it does.

    Args:
        rms_m: the fitted cable lengths' RMS error on the samples the fit saw.
        within_m: the bound the user set, or None for the sensors' own noise.
        noise_m: the sensors' own noise (:func:`~hil.identify.starts.settled_m`; NaN when unknown, and
            the bound is then the twin's accuracy target, :data:`TWIN_TARGET_M`).
    """
    if not math.isfinite(rms_m):
        return "the fitted model's cable lengths could not be compared with the recording"
    at_noise = within_m is None
    bound = within_m if within_m is not None else noise_m if math.isfinite(noise_m) else TWIN_TARGET_M
    if rms_m <= bound:
        return None
    if at_noise:
        return (
            f"the fit leaves {rms_m * 1e6:.3g} um RMS of the fitted cable lengths unexplained, more than the "
            f"sensors' own noise ({bound * 1e6:.2g} um): it stopped in a minimum that is not the arm's, or "
            "the model cannot follow this arm; the value is the model's best stand-in, not the arm's "
            "property (--restarts may find the arm's minimum)"
        )
    return (
        f"the model leaves {rms_m * 1e3:.3g} mm RMS of the fitted cable lengths unexplained (more than "
        f"{bound * 1e3:.3g} mm): the value is a compromise of a model that cannot follow this arm"
    )
