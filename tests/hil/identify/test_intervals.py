"""The rule that calls a fitted parameter identified (hil.identify.intervals.estimates)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from mujoco import minimize

from hil.identify.intervals import (
    IDENTIFIED_WITHIN,
    TWIN_TARGET_M,
    estimates,
    fd_floor,
    remaining_step,
    unexplained,
)
from hil.sim.config import ModelConfig
from hil.sim.uncertain import by_name, nominal

PRESET = nominal(ModelConfig())


def _judge(name: str, value: float, half_si: float) -> tuple[bool, str]:
    """One parameter fitted to ``value`` with a 95 % interval of ± ``half_si`` (SI), off its bounds."""
    row = by_name(name)
    v0 = PRESET[name] if PRESET[name] > 0 else 1e-3
    x = row.to_x(value, v0)
    # The interval is symmetric in the optimizer's coordinate: the half-width there whose SI interval
    # has the wanted half-width.
    half_x = math.asinh(half_si / value) if row.relative else half_si / row.scale
    (e,) = estimates({name: v0}, [row], np.array([x]), np.array([half_x]), np.array([half_x]), np.eye(1))
    assert e.half_width == pytest.approx(half_si, rel=1e-6)
    return e.identifiable, e.why


@pytest.mark.parametrize("name", ["damping_ratio", "joint_friction", "cable_mu", "delay", "rotor_inertia"])
def test_a_parameter_is_identified_only_when_its_interval_is_within_a_tenth_of_its_value(name: str) -> None:
    """What "identified" promises (within 10 % of the truth, issue 23) decides it, for relative and
    absolute rows alike: a joint friction of 0.3 mN·m known to ±0.6 mN·m is not identified (the earlier
    absolute threshold of 2 mN·m called it so)."""
    value = {"damping_ratio": 0.2, "joint_friction": 3e-4, "cable_mu": 0.3, "delay": 3e-3}.get(name, 9e-8)
    ok, why = _judge(name, value, 0.9 * IDENTIFIED_WITHIN * value)
    assert ok, why
    ok, why = _judge(name, value, 1.1 * IDENTIFIED_WITHIN * value)
    assert not ok and "95 % interval" in why, why
    ok, why = _judge(name, value, 2.0 * value)
    assert not ok


def test_the_remaining_step_is_the_distance_to_a_linear_problems_minimum_and_zero_at_it() -> None:
    """On a linear least-squares problem the Gauss-Newton step lands on the minimum: from a point where a
    solver stopped short, it is exactly the distance left; at the minimum, nothing; kept inside the box."""
    rng = np.random.default_rng(3)
    jac = rng.normal(size=(200, 3))
    best = np.array([0.2, -0.1, 0.05])
    noise = rng.normal(scale=1e-3, size=200)
    target = jac @ best + noise

    def res(x: np.ndarray) -> np.ndarray:
        return jac @ x - target

    minimum = np.linalg.lstsq(jac, target, rcond=None)[0]
    lower, upper = np.full(3, -1.0), np.full(3, 1.0)
    stopped = minimum + np.array([0.03, -0.02, 0.0])
    assert remaining_step(jac, res(stopped), stopped, lower, upper) == pytest.approx(
        [0.03, 0.02, 0.0], abs=1e-12
    )
    assert remaining_step(jac, res(minimum), minimum, lower, upper) == pytest.approx(np.zeros(3), abs=1e-12)
    far = minimum + np.array([0.0, 0.0, 0.5])
    floor = lower.copy()
    floor[2] = minimum[2] + 0.1  # the step would cross the third parameter's lower bound: it stops there
    assert remaining_step(jac, res(far), far, floor, upper)[2] == pytest.approx(0.4)
    assert np.all(remaining_step(np.zeros((0, 3)), np.zeros(0), far, lower, upper) == 0.0)


def test_an_interval_is_widened_by_how_far_the_fit_stopped_from_its_minimum() -> None:
    """The reported interval holds the autocorrelation-consistent one plus the remaining step, so it covers
    a truth at the minimum that the narrow one misses; a parameter narrow only before the widening is not
    called identified, and the reason says the fit stopped short."""
    row = by_name("damping_ratio")
    v0 = PRESET["damping_ratio"]
    x = row.to_x(0.2, v0)
    half, more = 0.01, 0.2  # the minimum lies 0.2 away in ln(value): 22 % off
    (e,) = estimates(
        {row.name: v0},
        [row],
        np.array([x]),
        np.array([half]),
        np.array([half]),
        np.eye(1),
        remaining_x=np.array([more]),
    )
    truth = row.from_x(x + more, v0)
    assert e.covers(truth)
    assert not (e.hac_interval[0] <= truth <= e.hac_interval[1])
    assert e.interval[0] < e.hac_interval[0] and e.hac_interval[1] < e.interval[1]
    assert not e.identifiable and "stopped short of its minimum" in e.why, e.why
    (still,) = estimates({row.name: v0}, [row], np.array([x]), np.array([half]), np.array([half]), np.eye(1))
    assert still.identifiable and still.interval == still.hac_interval


def test_the_interval_floor_is_the_solvers_own_finite_difference_step() -> None:
    """:func:`fd_floor` is the step :func:`mujoco.minimize.jacobian_fd` takes (1 % of ``max(1, |x|)``):
    an interval may not claim the minimum more precisely than the secant the solver steered by."""
    x = np.array([0.3, -2.5, 0.004, 4.0])
    seen: list[np.ndarray] = []

    def residual(xs: np.ndarray) -> np.ndarray:
        seen.append(np.array(xs, dtype=np.float64))
        return np.atleast_2d(xs)

    x_col = x.reshape(-1, 1)
    minimize.jacobian_fd(residual, x_col, residual(x_col), np.float64(0.01), 0)
    steps = np.abs(seen[-1] - x_col).max(axis=0)
    assert fd_floor(x, 0.01) == pytest.approx(steps, rel=1e-9)
    row = by_name("delay")
    (e,) = estimates(
        {"delay": 1e-3},
        [row],
        np.array([0.11]),
        np.array([1e-4]),
        np.array([1e-4]),
        np.eye(1),
        floor_x=fd_floor(np.array([0.11]), 0.01),
    )
    assert e.half_width == pytest.approx(0.01 * row.scale)  # a 0.11 ms delay: ±10 µs, not ±0.1 µs


def test_a_fit_explains_its_data_only_down_to_the_sensors_noise_by_default() -> None:
    """By default the bound is the sensors' own noise: a fit that leaves more stopped in a minimum that is
    not the arm's, or its model cannot follow the arm, and the reason says so with both figures. A bound
    the user sets is the weaker claim and says it in millimetres; an unknown noise falls back to the
    twin's accuracy target."""
    noise = 0.6e-6
    assert unexplained(0.5e-6, None, noise) is None
    why = unexplained(2.1e-6, None, noise)
    assert why is not None and "2.1 um" in why and "sensors' own noise (0.6 um)" in why, why
    assert unexplained(2.1e-6, 3e-4, noise) is None
    why = unexplained(0.4e-3, 3e-4, noise)
    assert why is not None and "0.4 mm" in why and "0.3 mm" in why, why
    assert unexplained(0.2e-3, None, math.nan) is None
    assert unexplained(2 * TWIN_TARGET_M, None, math.nan) is not None
    assert unexplained(math.nan, None, noise) == (
        "the fitted model's cable lengths could not be compared with the recording"
    )
