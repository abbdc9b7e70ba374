"""controller.cables: stick mapping and slew limit; the motor model (tension <-> current, feedback)."""

from __future__ import annotations

import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from controller.cables import CableMapper, MotorModel, TensionSlew, bend_shares
from controller.config import FirmwareConfig
from protocol.c610 import MotorFeedback

ANGLES = tuple(math.radians(a) for a in (0.0, 120.0, 240.0))


@given(st.floats(-10.0, 10.0, allow_nan=False))
def test_bend_shares_are_pull_only_and_make_the_requested_moment(direction: float) -> None:
    shares = bend_shares(direction, ANGLES)
    assert all(s >= -1e-12 for s in shares)
    assert min(shares) == pytest.approx(0.0, abs=1e-12)  # the minimal pull-only solution
    mx = sum(s * math.cos(a) for s, a in zip(shares, ANGLES, strict=True))
    my = sum(s * math.sin(a) for s, a in zip(shares, ANGLES, strict=True))
    assert mx == pytest.approx(math.cos(direction), abs=1e-9)
    assert my == pytest.approx(math.sin(direction), abs=1e-9)


def test_bend_toward_a_cable_pulls_that_cable_only() -> None:
    assert bend_shares(0.0, ANGLES) == pytest.approx((1.0, 0.0, 0.0), abs=1e-12)
    assert bend_shares(math.radians(60), ANGLES) == pytest.approx((1.0, 1.0, 0.0), abs=1e-12)


def test_centred_sticks_give_the_pretension_floor() -> None:
    cfg = FirmwareConfig()
    m = CableMapper(cfg)
    assert m.manual((0, 0, 0, 0)) == [cfg.mapping.pretension_n] * 3
    # inside the deadband too, and left stick down never goes below the floor (pull-only)
    assert m.manual((cfg.mapping.stick_deadband, 0, 0, -660)) == [cfg.mapping.pretension_n] * 3


def test_left_stick_up_is_common_tension() -> None:
    cfg = FirmwareConfig()
    t = CableMapper(cfg).manual((0, 0, 0, 660))
    expected = cfg.mapping.pretension_n + cfg.mapping.common_max_n * (660 - cfg.mapping.stick_deadband) / 660
    assert t == pytest.approx([expected] * 3)


def test_right_stick_toward_cable_one_bends_with_cable_one() -> None:
    cfg = FirmwareConfig()
    t = CableMapper(cfg).manual((660, 0, 0, 0))  # stick right = 0 rad = cable 1
    assert t[0] == pytest.approx(cfg.mapping.pretension_n + cfg.mapping.bend_max_n)
    assert t[1] == pytest.approx(cfg.mapping.pretension_n)
    assert t[2] == pytest.approx(cfg.mapping.pretension_n)


def test_clamped_to_tension_max() -> None:
    cfg = FirmwareConfig().replaced(common_max_n=15.0, bend_max_n=15.0, tension_max_n=20.0)
    t = CableMapper(cfg).manual((660, 0, 0, 660))
    assert t[0] == cfg.mapping.tension_max_n
    assert all(cfg.mapping.pretension_n <= x <= cfg.mapping.tension_max_n for x in t)


def test_direct_tensions_clamped_both_ways() -> None:
    cfg = FirmwareConfig()
    assert CableMapper(cfg).direct([-5.0, 3.0, 1e6]) == [
        cfg.mapping.pretension_n,
        3.0,
        cfg.mapping.tension_max_n,
    ]


@given(
    st.lists(st.integers(-660, 660), min_size=4, max_size=4),
)
def test_any_stick_position_is_within_limits(channels: list[int]) -> None:
    cfg = FirmwareConfig()
    t = CableMapper(cfg).manual(channels)
    assert all(cfg.mapping.pretension_n <= x <= cfg.mapping.tension_max_n for x in t)


def test_slew_rate_limit_and_floor() -> None:
    cfg = FirmwareConfig().replaced(slew_n_per_s=10.0)
    slew = TensionSlew(cfg)
    # first active tick starts at the floor
    assert list(slew.step([20.0] * 3, 1000)) == pytest.approx([cfg.mapping.pretension_n + 0.01] * 3)
    for _ in range(99):
        slew.step([20.0] * 3, 1000)
    assert slew.tensions_n == pytest.approx([cfg.mapping.pretension_n + 1.0] * 3)  # 10 N/s for 100 ms
    # going down is limited too, and never below the floor
    for _ in range(1000):
        slew.step([0.0] * 3, 1000)
    assert slew.tensions_n == [cfg.mapping.pretension_n] * 3
    slew.reset()
    assert slew.tensions_n == [0.0] * 3 and not slew.active


def test_stick_direction_needs_deflection() -> None:
    m = CableMapper(FirmwareConfig())
    assert m.stick_direction((100, 0, 0, 0), 0.5) is None
    assert m.stick_direction((0, 660, 0, 0), 0.5) == pytest.approx(math.pi / 2)


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


def _reeling_in(m: MotorModel, index: int, speed_m_s: float) -> None:
    """Feed motor ``index`` a frame with the rotor turning so its cable reels in at ``speed_m_s``."""
    cfg = FirmwareConfig()
    rpm = round(speed_m_s * 60.0 * cfg.motor.gear_ratio / (2.0 * math.pi * cfg.motor.spool_radius_m))
    m.update(index, fb(0, rpm), 1000)


def test_governor_leaves_slow_cables_and_cuts_fast_reeling_ones_toward_the_pretension() -> None:
    cfg = FirmwareConfig().replaced(payin_limit_m_per_s=0.2, pretension_n=0.5)
    m = MotorModel(cfg)
    _reeling_in(m, 0, 0.1)  # below the limit: untouched
    _reeling_in(m, 1, 0.3)  # halfway between the limit and twice it: half the excess over the pretension
    _reeling_in(m, 2, 0.5)  # past twice the limit: the pretension
    out = m.govern([10.0, 10.5, 10.0])
    assert out is m.governed_n
    assert out[0] == 10.0
    assert out[1] == pytest.approx(0.5 + 10.0 * 0.5, rel=1e-3)
    assert out[2] == 0.5
    # paying out fast (the arm pulls the cable) is never cut; nor is a cable already at the pretension
    _reeling_in(m, 0, -1.0)
    _reeling_in(m, 1, 1.0)
    assert m.govern([10.0, 0.5, 0.0]) == [10.0, 0.5, 0.0]


def test_governor_follows_a_mirrored_motor() -> None:
    m = MotorModel(FirmwareConfig().replaced(motor_signs=(1, -1, 1), payin_limit_m_per_s=0.2))
    _reeling_in(m, 1, -1.0)  # rotor turns backwards: on the mirrored motor that reels in
    assert m.govern([10.0, 10.0, 10.0])[1] == 0.5


# --- arms of one and two cables, arrays ---------------------------------------------------------


@given(st.floats(-math.pi, math.pi))
def test_a_one_cable_arm_takes_every_bending_share(direction: float) -> None:
    assert bend_shares(direction, (0.0,)) == (1.0,)


@given(st.floats(-math.pi, math.pi))
def test_a_two_cable_arm_shares_the_bend_in_its_plane(direction: float) -> None:
    s1, s2 = bend_shares(direction, (0.0, math.pi))
    assert min(s1, s2) == pytest.approx(0.0, abs=1e-12)
    assert s1 - s2 == pytest.approx(math.cos(direction))  # the in-plane moment, pull-only


def test_the_mapping_of_one_and_two_cable_arms() -> None:
    one = CableMapper(FirmwareConfig().with_arms(1, 1))
    m = FirmwareConfig().mapping
    assert one.manual([0, 0, 0, 660]) == pytest.approx([m.pretension_n + m.common_max_n * 640 / 660])
    assert one.curl(5.0, 2.0) == pytest.approx([m.pretension_n + 5.0])  # any direction curls it
    two = CableMapper(FirmwareConfig().with_arms(1, 2))
    assert two.manual([660, 0, 0, 0]) == pytest.approx([m.pretension_n + m.bend_max_n, m.pretension_n])
    assert two.manual([-660, 0, 0, 0]) == pytest.approx([m.pretension_n, m.pretension_n + m.bend_max_n])
    assert two.curl(4.0, math.pi / 2) == pytest.approx([m.pretension_n] * 2)  # out of its plane


def test_every_arm_of_an_array_takes_the_arms_targets() -> None:
    lone = CableMapper(FirmwareConfig())
    array = CableMapper(FirmwareConfig().with_arms(2))
    for channels in ([0, 0, 0, 0], [300, -500, 0, 200], [-660, 0, 0, 660]):
        assert array.manual(channels) == lone.manual(channels) * 2
    assert array.curl(6.0, 1.0) == lone.curl(6.0, 1.0) * 2
    assert array.direct([1.0, 2.0, 30.0]) == lone.direct([1.0, 2.0, 30.0]) * 2
    assert array.arm_targets_n == lone.targets_n and lone.arm_targets_n is lone.targets_n
