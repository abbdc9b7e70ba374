"""Manual mapping: pull-only shares, pretension floor, per-cable clamp, slew-rate limit, deadband."""

from __future__ import annotations

import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from controller.cables import CableMapper, TensionSlew, bend_shares
from controller.config import FirmwareConfig

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
