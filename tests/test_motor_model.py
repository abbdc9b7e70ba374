"""Motor model: tension <-> current, unwrapping across 8191/0, cable length, tension estimate."""

from __future__ import annotations

import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from controller.cables import MotorModel
from controller.config import FirmwareConfig
from protocol.c610 import MotorFeedback


def fb(angle: int, speed: int = 0, current: int = 0) -> MotorFeedback:
    return MotorFeedback(angle, speed, current)


def test_tension_to_current_through_spool_and_torque_constant() -> None:
    cfg = FirmwareConfig().replaced(spool_radius_m=0.010, torque_constant_nm_per_a=0.18)
    m = MotorModel(cfg)
    # 9 N * 0.01 m = 0.09 N·m; / 0.18 N·m/A = 0.5 A = 500 raw
    assert m.tension_to_raw(0, 9.0) == 500
    assert m.tension_to_raw(0, 0.0) == 0
    assert m.tension_to_raw(0, -3.0) == 0  # a cable cannot push
    assert m.raw_to_tension(0, 500) == pytest.approx(9.0)


def test_current_clamped_to_limit() -> None:
    m = MotorModel(FirmwareConfig().replaced(current_limit_a=3.0))
    assert m.tension_to_raw(0, 1000.0) == 3000


def test_mirrored_motor_sign() -> None:
    m = MotorModel(FirmwareConfig().replaced(motor_signs=(1, -1, 1)))
    assert m.tension_to_raw(1, 9.0) == -500
    assert m.raw_to_tension(1, -500) == pytest.approx(9.0)


def test_unwrap_forward_across_8191_to_0() -> None:
    m = MotorModel(FirmwareConfig())
    m.update(0, fb(8100), 0)
    m.update(0, fb(50), 1000)  # +142 counts through the wrap
    assert m.counts[0] == 142
    m.update(0, fb(8150), 2000)  # back -92 through the wrap
    assert m.counts[0] == 50


def test_unwrap_multi_turn_and_cable_length() -> None:
    cfg = FirmwareConfig().replaced(spool_radius_m=0.01, gear_ratio=36.0)
    m = MotorModel(cfg)
    angle = 0
    m.update(0, fb(angle), 0)
    # 36 rotor turns = one output turn = 2*pi*r of cable, in steps of 3000 counts
    total = 36 * 8192
    t = 0
    moved = 0
    while moved < total:
        step = min(3000, total - moved)
        moved += step
        angle = (angle + step) % 8192
        t += 1000
        m.update(0, fb(angle), t)
    assert m.counts[0] == total
    assert m.cable_length_m[0] == pytest.approx(2 * math.pi * 0.01)


@given(st.integers(0, 8191), st.lists(st.integers(-4095, 4095), max_size=60))
def test_unwrap_recovers_any_path_of_small_steps(start: int, steps: list[int]) -> None:
    m = MotorModel(FirmwareConfig())
    m.update(2, fb(start), 0)
    pos = start
    for i, s in enumerate(steps, start=1):
        pos += s
        m.update(2, fb(pos % 8192), i * 1000)
    assert m.counts[2] == pos - start


def test_measured_current_estimates_tension_and_speed_is_filtered() -> None:
    cfg = FirmwareConfig().replaced(speed_filter_tau_us=0)
    m = MotorModel(cfg)
    m.update(0, fb(0, speed=3600, current=1000), 0)
    assert m.tension_est_n[0] == pytest.approx(1.0 * 0.18 / 0.01)
    # 3600 rotor rpm = 100 output rpm -> 10.47 rad/s * 0.01 m
    assert m.cable_speed_m_s[0] == pytest.approx(100 * 2 * math.pi / 60 * 0.01)
    m2 = MotorModel(FirmwareConfig().replaced(speed_filter_tau_us=20_000))
    m2.update(0, fb(0, speed=0), 0)
    m2.update(0, fb(0, speed=3600), 1000)
    assert 0 < m2.cable_speed_m_s[0] < m.cable_speed_m_s[0] / 10
