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
