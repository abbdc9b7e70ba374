"""The statistics the experiments print beside their numbers: intervals for a rate, a mean or median and a
slope, and McNemar's exact test for paired binary outcomes.

Pure functions of their inputs (the bootstrap takes a seed), no SciPy at run time: the exact binomial sum
and the Student t quantile (regularised incomplete beta, inverted by bisection) are written out here; the
normal quantile is the standard library's. Each is checked against SciPy (which ``mujoco[sysid]``
installs) in ``tests/hil/experiments/test_stats.py``: the Wilson interval against
``binomtest(...).proportion_ci(method="wilson")`` and McNemar against the exact ``binomtest(k, n, 0.5)`` to
1e-12, the t quantile against ``t.ppf`` and the slope against ``linregress``, the bootstrap against
``scipy.stats.bootstrap(method="percentile")`` within its resampling noise.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from statistics import NormalDist

import numpy as np

__all__ = [
    "Slope",
    "bootstrap_interval",
    "cochran_armitage",
    "mcnemar_exact",
    "ols_slope",
    "student_t_quantile",
    "wilson_interval",
]


def _check_confidence(confidence: float) -> None:
    if not (math.isfinite(confidence) and 0.0 < confidence < 1.0):
        raise ValueError(f"confidence must be in (0, 1), got {confidence!r}")


def wilson_interval(successes: int, n: int, confidence: float = 0.95) -> tuple[float, float]:
    """Wilson score interval of a rate ``successes / n``.

    Returns ``(nan, nan)`` for ``n == 0`` (no trials, no rate).

    Raises:
        ValueError: ``successes`` outside ``0..n``, or ``confidence`` outside (0, 1).
    """
    _check_confidence(confidence)
    if n < 0 or not 0 <= successes <= max(n, 0):
        raise ValueError(f"need 0 <= successes <= n, got {successes} of {n}")
    if n == 0:
        return (math.nan, math.nan)
    z = NormalDist().inv_cdf(0.5 + confidence / 2.0)
    p = successes / n
    z2n = z * z / n
    centre = (p + z2n / 2.0) / (1.0 + z2n)
    half = z / (1.0 + z2n) * math.sqrt(p * (1.0 - p) / n + z2n / (4.0 * n))
    # Clamp the rounding at the ends (0 and n successes give exactly 0 and 1).
    return (max(0.0, centre - half), min(1.0, centre + half))


def mcnemar_exact(only_a: int, only_b: int) -> float:
    """Two-sided exact McNemar p-value from the discordant pairs of a paired binary comparison.

    Under the null hypothesis each discordant pair is A-only or B-only with probability 1/2, so the
    smaller count follows Binomial(n, 1/2) with ``n = only_a + only_b``; the p-value doubles its tail
    (capped at 1). No discordant pair: 1.

    Args:
        only_a: pairs where only A succeeded.
        only_b: pairs where only B succeeded.

    Raises:
        ValueError: a negative count.
    """
    if only_a < 0 or only_b < 0:
        raise ValueError(f"discordant counts must be >= 0, got {only_a}, {only_b}")
    n = only_a + only_b
    if n == 0:
        return 1.0
    k = min(only_a, only_b)
    tail = sum(math.comb(n, i) for i in range(k + 1)) / 2.0**n
    return min(1.0, 2.0 * tail)


def cochran_armitage(
    successes: Sequence[int], totals: Sequence[int], scores: Sequence[float]
) -> tuple[float, float]:
    """Cochran-Armitage test for a linear trend of a success rate across ordered groups.

    ``z = Σ s_i (k_i − n_i p̄) / sqrt(p̄ (1 − p̄) (Σ n_i s_i² − (Σ n_i s_i)² / N))`` with the pooled rate
    ``p̄``; ``z > 0``: the rate grows with the score. The p-value is two-sided, from the normal
    approximation. No spread to test (every trial alike, or one score): ``(0.0, 1.0)``.

    Args:
        successes: per group, its successes ``k_i``.
        totals: per group, its trials ``n_i``.
        scores: per group, its score ``s_i`` (e.g. the array's size).

    Returns:
        ``(z, p)``.

    Raises:
        ValueError: lengths differ, or a count is negative or above its total.
    """
    if not len(successes) == len(totals) == len(scores):
        raise ValueError("successes, totals and scores need one entry per group")
    for k, n in zip(successes, totals, strict=True):
        if n < 0 or not 0 <= k <= n:
            raise ValueError(f"successes must be 0..n per group, got {k} of {n}")
    big_n = sum(totals)
    if big_n == 0:
        return (0.0, 1.0)
    p = sum(successes) / big_n
    sum_ns = sum(n * s for n, s in zip(totals, scores, strict=True))
    var = p * (1.0 - p) * (sum(n * s * s for n, s in zip(totals, scores, strict=True)) - sum_ns**2 / big_n)
    if var <= 0.0:
        return (0.0, 1.0)
    t = sum(s * (k - n * p) for k, n, s in zip(successes, totals, scores, strict=True))
    z = t / math.sqrt(var)
    return (z, math.erfc(abs(z) / math.sqrt(2.0)))


def bootstrap_interval(
    values: Sequence[float],
    statistic: str = "mean",
    confidence: float = 0.95,
    resamples: int = 10_000,
    seed: int = 0,
) -> tuple[float, float]:
    """Percentile bootstrap interval of the mean or the median of ``values``.

    ``resamples`` resamples with replacement (``numpy.random.Generator`` seeded with ``seed``); the
    interval is their statistic's ``(1 − confidence)/2`` and ``(1 + confidence)/2`` quantiles. Empty
    input: ``(nan, nan)``.

    Raises:
        ValueError: unknown statistic, ``resamples < 1`` or a confidence outside (0, 1).
    """
    _check_confidence(confidence)
    if statistic not in ("mean", "median"):
        raise ValueError(f"statistic must be 'mean' or 'median', got {statistic!r}")
    if resamples < 1:
        raise ValueError(f"resamples must be >= 1, got {resamples}")
    x = np.asarray(values, dtype=np.float64)
    if x.size == 0:
        return (math.nan, math.nan)
    rng = np.random.default_rng(seed)
    draws = x[rng.integers(0, x.size, size=(resamples, x.size))]
    stats = draws.mean(axis=1) if statistic == "mean" else np.median(draws, axis=1)
    alpha = (1.0 - confidence) / 2.0
    lo, hi = np.quantile(stats, [alpha, 1.0 - alpha])
    return (float(lo), float(hi))


def _betacf(a: float, b: float, x: float) -> float:
    """Continued fraction of the incomplete beta function (modified Lentz)."""
    tiny = 1e-300
    qab, qap, qam = a + b, a + 1.0, a - 1.0
    c, d = 1.0, 1.0 - qab * x / qap
    d = 1.0 / (d if abs(d) > tiny else tiny)
    h = d
    for m in range(1, 300):
        m2 = 2 * m
        aa = m * (b - m) * x / ((qam + m2) * (a + m2))
        d = 1.0 + aa * d
        d = 1.0 / (d if abs(d) > tiny else tiny)
        c = 1.0 + aa / c
        c = c if abs(c) > tiny else tiny
        h *= d * c
        aa = -(a + m) * (qab + m) * x / ((a + m2) * (qap + m2))
        d = 1.0 + aa * d
        d = 1.0 / (d if abs(d) > tiny else tiny)
        c = 1.0 + aa / c
        c = c if abs(c) > tiny else tiny
        delta = d * c
        h *= delta
        if abs(delta - 1.0) < 1e-15:
            break
    return h


def _betainc(a: float, b: float, x: float) -> float:
    """Regularised incomplete beta function I_x(a, b)."""
    if x <= 0.0:
        return 0.0
    if x >= 1.0:
        return 1.0
    log_front = math.lgamma(a + b) - math.lgamma(a) - math.lgamma(b) + a * math.log(x) + b * math.log1p(-x)
    if x < (a + 1.0) / (a + b + 2.0):
        return math.exp(log_front) * _betacf(a, b, x) / a
    return 1.0 - math.exp(log_front) * _betacf(b, a, 1.0 - x) / b


def _student_t_cdf(t: float, df: float) -> float:
    tail = 0.5 * _betainc(df / 2.0, 0.5, df / (df + t * t))
    return 1.0 - tail if t > 0 else tail


def student_t_quantile(p: float, df: float) -> float:
    """Quantile of Student's t distribution with ``df`` degrees of freedom.

    Raises:
        ValueError: ``p`` outside (0, 1) or ``df <= 0``.
    """
    if not (0.0 < p < 1.0):
        raise ValueError(f"p must be in (0, 1), got {p!r}")
    if not (math.isfinite(df) and df > 0):
        raise ValueError(f"df must be > 0, got {df!r}")
    if p < 0.5:
        return -student_t_quantile(1.0 - p, df)
    lo, hi = 0.0, 1.0
    while _student_t_cdf(hi, df) < p:
        hi *= 2.0
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if _student_t_cdf(mid, df) < p:
            lo = mid
        else:
            hi = mid
        if hi - lo < 1e-12 * max(1.0, hi):
            break
    return 0.5 * (lo + hi)


@dataclass(frozen=True)
class Slope:
    """An ordinary-least-squares line ``y = intercept + slope·x`` with the slope's interval.

    Attributes:
        slope: fitted slope (units of y per unit of x).
        intercept: fitted value at x = 0.
        low: lower end of the slope's interval (t distribution, n − 2 degrees of freedom).
        high: upper end.
        n: number of points.
        confidence: the interval's level.
    """

    slope: float
    intercept: float
    low: float
    high: float
    n: int
    confidence: float

    def as_dict(self) -> dict[str, float]:
        """JSON-ready form."""
        return {
            "slope": self.slope,
            "intercept": self.intercept,
            "low": self.low,
            "high": self.high,
            "n": self.n,
            "confidence": self.confidence,
        }


def ols_slope(x: Sequence[float], y: Sequence[float], confidence: float = 0.95) -> Slope:
    """Least-squares slope of ``y`` on ``x`` with its confidence interval.

    The interval is ``slope ± t_{(1+c)/2, n−2} · s / √Σ(x − x̄)²`` with ``s²`` the residual variance over
    ``n − 2``. Fewer than 2 points or all x equal: every field NaN; exactly 2 points: the slope with a
    NaN interval (no residual degrees of freedom).

    Raises:
        ValueError: ``x`` and ``y`` of different lengths or a confidence outside (0, 1).
    """
    _check_confidence(confidence)
    xa = np.asarray(x, dtype=np.float64)
    ya = np.asarray(y, dtype=np.float64)
    if xa.shape != ya.shape or xa.ndim != 1:
        raise ValueError(f"x and y must be 1-D of one length, got {xa.shape} and {ya.shape}")
    n = int(xa.size)
    nan = math.nan
    sxx = float(((xa - xa.mean()) ** 2).sum()) if n else 0.0
    if n < 2 or sxx == 0.0:
        return Slope(nan, nan, nan, nan, n, confidence)
    slope = float(((xa - xa.mean()) * (ya - ya.mean())).sum()) / sxx
    intercept = float(ya.mean()) - slope * float(xa.mean())
    if n == 2:
        return Slope(slope, intercept, nan, nan, n, confidence)
    residuals = ya - (intercept + slope * xa)
    s = math.sqrt(float((residuals**2).sum()) / (n - 2))
    half = student_t_quantile(0.5 + confidence / 2.0, n - 2) * s / math.sqrt(sxx)
    return Slope(slope, intercept, slope - half, slope + half, n, confidence)
