"""hil.experiments.stats against values computed by hand or tabulated."""

from __future__ import annotations

import math

import numpy as np
import pytest

from hil.experiments.stats import (
    bootstrap_interval,
    mcnemar_exact,
    ols_slope,
    student_t_quantile,
    wilson_interval,
)


def test_wilson_matches_the_textbook_values() -> None:
    assert wilson_interval(5, 10) == pytest.approx((0.2366, 0.7634), abs=1e-4)
    assert wilson_interval(0, 10) == pytest.approx((0.0, 0.2775), abs=1e-4)
    assert wilson_interval(10, 10) == pytest.approx((0.7225, 1.0), abs=1e-4)
    assert all(math.isnan(v) for v in wilson_interval(0, 0))
    with pytest.raises(ValueError):
        wilson_interval(11, 10)
    with pytest.raises(ValueError):
        wilson_interval(1, 10, confidence=1.0)


def test_mcnemar_is_the_doubled_binomial_tail() -> None:
    assert mcnemar_exact(1, 8) == pytest.approx(2 * (1 + 9) / 2**9)
    assert mcnemar_exact(8, 1) == mcnemar_exact(1, 8)
    assert mcnemar_exact(0, 5) == pytest.approx(2 / 32)
    assert mcnemar_exact(4, 4) == 1.0  # capped
    assert mcnemar_exact(0, 0) == 1.0
    with pytest.raises(ValueError):
        mcnemar_exact(-1, 2)


def test_student_t_quantiles_match_the_tables() -> None:
    assert student_t_quantile(0.975, 1) == pytest.approx(12.706205, rel=1e-6)
    assert student_t_quantile(0.975, 3) == pytest.approx(3.182446, rel=1e-6)
    assert student_t_quantile(0.975, 10) == pytest.approx(2.228139, rel=1e-6)
    assert student_t_quantile(0.025, 10) == pytest.approx(-2.228139, rel=1e-6)
    assert student_t_quantile(0.975, 1e6) == pytest.approx(1.959966, rel=1e-5)


def test_ols_slope_and_its_interval() -> None:
    s = ols_slope([1, 2, 3, 4, 5], [2, 4, 5, 4, 5])
    assert (s.slope, s.intercept) == pytest.approx((0.6, 2.2))
    half = 3.182446305 * math.sqrt(0.8 / 10)  # s² = 2.4/3, Σ(x − x̄)² = 10
    assert (s.low, s.high) == pytest.approx((0.6 - half, 0.6 + half), rel=1e-6)
    exact = ols_slope([0.0, 1.0, 2.0], [1.0, 3.0, 5.0])
    assert (exact.low, exact.slope, exact.high) == pytest.approx((2.0, 2.0, 2.0))
    assert math.isnan(ols_slope([1.0, 1.0], [1.0, 2.0]).slope)
    two = ols_slope([0.0, 1.0], [0.0, 3.0])
    assert two.slope == pytest.approx(3.0) and math.isnan(two.low)


def test_bootstrap_is_seeded_and_covers_the_mean() -> None:
    rng = np.random.default_rng(1)
    x = rng.normal(10.0, 2.0, size=200)
    lo, hi = bootstrap_interval(list(x), seed=4)
    assert (lo, hi) == bootstrap_interval(list(x), seed=4)
    assert lo < float(x.mean()) < hi
    # close to the normal-theory interval mean ± 1.96 σ/√n
    assert hi - lo == pytest.approx(2 * 1.96 * float(x.std(ddof=1)) / math.sqrt(200), rel=0.15)
    outlier = [float(v) for v in range(1, 20)] + [1000.0]  # the median ignores it, the mean does not
    med = bootstrap_interval(outlier, statistic="median", seed=0)
    assert 5.0 <= med[0] <= 10.5 <= med[1] <= 15.0
    assert bootstrap_interval(outlier, seed=0)[1] > 50.0
    assert bootstrap_interval([7.0, 7.0, 7.0]) == (7.0, 7.0)
    assert all(math.isnan(v) for v in bootstrap_interval([]))
    with pytest.raises(ValueError):
        bootstrap_interval([1.0], statistic="mode")


# ---------------------------------------------------------------------- against SciPy
# The module has its own implementations (no SciPy import at run time); SciPy (which mujoco[sysid] installs)
# is the reference they must agree with.

scipy_stats = pytest.importorskip("scipy.stats")


@pytest.mark.parametrize("confidence", [0.8, 0.95, 0.99])
def test_wilson_agrees_with_scipy(confidence: float) -> None:
    for n in (1, 2, 7, 20, 113):
        for k in range(n + 1):
            ci = scipy_stats.binomtest(k, n).proportion_ci(confidence_level=confidence, method="wilson")
            assert wilson_interval(k, n, confidence) == pytest.approx((ci.low, ci.high), abs=1e-12), (k, n)


def test_mcnemar_agrees_with_scipys_exact_binomial_test() -> None:
    for only_a in range(0, 26):
        for only_b in range(0, 26):
            n = only_a + only_b
            want = 1.0 if n == 0 else scipy_stats.binomtest(only_a, n, 0.5, alternative="two-sided").pvalue
            assert mcnemar_exact(only_a, only_b) == pytest.approx(want, rel=1e-12, abs=1e-300), (
                only_a,
                only_b,
            )


@pytest.mark.parametrize("df", [1, 2, 3, 5, 8, 13, 30, 120])
def test_student_t_quantile_agrees_with_scipy(df: int) -> None:
    for p in (0.5, 0.6, 0.9, 0.95, 0.975, 0.995, 0.9995, 0.025, 0.001):
        assert student_t_quantile(p, df) == pytest.approx(scipy_stats.t.ppf(p, df), rel=1e-9, abs=1e-12)


def test_ols_slope_agrees_with_scipy_linregress() -> None:
    rng = np.random.default_rng(7)
    x = np.linspace(0.0, 3.0, 17)
    y = 0.4 - 1.3 * x + rng.normal(0.0, 0.2, x.size)
    fit = scipy_stats.linregress(x, y)
    half = scipy_stats.t.ppf(0.975, x.size - 2) * fit.stderr
    got = ols_slope(x.tolist(), y.tolist(), 0.95)
    assert (got.slope, got.intercept) == pytest.approx((fit.slope, fit.intercept), rel=1e-12)
    assert (got.low, got.high) == pytest.approx((fit.slope - half, fit.slope + half), rel=1e-9)


@pytest.mark.parametrize("statistic", ["mean", "median"])
def test_bootstrap_agrees_with_scipys_percentile_bootstrap(statistic: str) -> None:
    # Both resample with their own random streams: the ends agree within the resampling noise (under 1 %
    # of the width at 10,000 resamples), not to the bit. Seeds fixed, so the comparison is repeatable.
    values = np.random.default_rng(3).gamma(2.0, 1.5, 60)
    func = np.mean if statistic == "mean" else np.median
    for confidence in (0.9, 0.95):
        ref = scipy_stats.bootstrap(
            (values,),
            func,
            confidence_level=confidence,
            n_resamples=10_000,
            method="percentile",
            vectorized=True,
            rng=np.random.default_rng(11),
        ).confidence_interval
        low, high = bootstrap_interval(values.tolist(), statistic, confidence, resamples=10_000, seed=5)
        width = ref.high - ref.low
        assert abs(low - ref.low) < 0.02 * width and abs(high - ref.high) < 0.02 * width, (
            (low, high),
            (ref.low, ref.high),
        )
