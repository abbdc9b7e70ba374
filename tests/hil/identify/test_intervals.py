"""The rule that calls a fitted parameter identified (hil.identify.intervals.estimates)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from hil.identify.intervals import IDENTIFIED_WITHIN, estimates
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
