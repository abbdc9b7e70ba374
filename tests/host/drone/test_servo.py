"""host.drone.servo: the servo follower's hysteresis, edges-only rule and stale timeout, in simulated time."""

from __future__ import annotations

import argparse

import pytest

from host.drone.servo import ServoFollowConfig, ServoFollower, parse_follow_servo
from protocol import mavlink as mav

GRAB, RELEASE = mav.GripperAction.GRAB, mav.GripperAction.RELEASE
MS = 1000


def report(pwm_us: int, output_n: int = 9) -> mav.ServoOutputRaw:
    """A SERVO_OUTPUT_RAW with ``pwm_us`` on ``output_n`` and 1500 elsewhere."""
    port, slot = divmod(output_n - 1, 16)
    servos = [1500] * 16
    servos[slot] = pwm_us
    return mav.ServoOutputRaw(0, port, tuple(servos))


def feed(f: ServoFollower, pwms: list[int], t0_us: int = 0, step_us: int = 100 * MS) -> list[object]:
    return [f.on_servo_output(report(p), t0_us + i * step_us) for i, p in enumerate(pwms)]


def test_first_reading_is_a_baseline_then_each_change_is_one_request() -> None:
    f = ServoFollower(ServoFollowConfig(9))
    assert feed(f, [1900, 1900, 1100, 1100, 1900]) == [None, None, RELEASE, None, GRAB]
    assert f.requests_n == 2
    assert f.reading == GRAB


def test_hysteresis_band_keeps_the_last_reading() -> None:
    f = ServoFollower(ServoFollowConfig(9, grab_pwm_us=1900, release_pwm_us=1100))
    # band = a quarter of the 800 µs span: grab from 1700 up, release from 1300 down.
    assert [f.classify(p) for p in (1701, 1700, 1699, 1500, 1301, 1300, 0)] == [
        GRAB,
        GRAB,
        None,
        None,
        None,
        RELEASE,
        None,
    ]
    # Noise around the middle and a slow slew never produce a request; crossing into a zone does.
    assert feed(f, [1100, 1450, 1550, 1650, 1699, 1600, 1300, 1710]) == [None] * 7 + [GRAB]


def test_reversed_servo_and_a_second_port() -> None:
    f = ServoFollower(ServoFollowConfig(20, grab_pwm_us=1000, release_pwm_us=2000))
    assert f.on_servo_output(report(2000, output_n=20), 0) is None
    assert f.on_servo_output(report(1000, output_n=4), 1) is None  # port 0: not our output
    assert f.on_servo_output(report(1000, output_n=20), 2) == GRAB


def test_stale_reports_say_so_once_and_the_next_reading_is_a_baseline() -> None:
    f = ServoFollower(ServoFollowConfig(9, stale_us=500 * MS))
    assert feed(f, [1100, 1900]) == [None, GRAB]
    last_us = 100 * MS
    assert not f.check_stale(last_us + 500 * MS)  # not longer than the timeout yet
    assert f.check_stale(last_us + 501 * MS)
    assert f.stale and f.reading is None
    assert not f.check_stale(last_us + 5000 * MS)  # said once per stale period
    # Reports return with the output moved to RELEASE meanwhile: a baseline, no surprise release.
    assert f.on_servo_output(report(1100), last_us + 6000 * MS) is None
    assert f.on_servo_output(report(1900), last_us + 6100 * MS) == GRAB
    assert f.stale_periods_n == 1


def test_a_disabled_output_is_no_report_and_goes_stale() -> None:
    f = ServoFollower(ServoFollowConfig(9, stale_us=500 * MS))
    assert feed(f, [1900, 0, 0, 0, 0, 0, 0, 0]) == [None] * 8
    assert f.check_stale(701 * MS)


def test_never_reported_is_stale_but_silent() -> None:
    f = ServoFollower(ServoFollowConfig(9))
    assert f.stale
    assert not f.check_stale(10_000 * MS)


def test_parse_follow_servo() -> None:
    assert parse_follow_servo("9") == ServoFollowConfig(9)
    cfg = parse_follow_servo("17,grab=1000,release=2000,stale_ms=250")
    assert (cfg.output_n, cfg.grab_pwm_us, cfg.release_pwm_us, cfg.stale_us) == (17, 1000, 2000, 250 * MS)
    assert (cfg.port, cfg.slot) == (1, 0)


@pytest.mark.parametrize(
    ("text", "why"),
    [
        ("0", "1..32"),
        ("33", "1..32"),
        ("x", "output must be an integer"),
        ("9,grab", "key=value"),
        ("9,grab=1500,release=1450", "100 µs apart"),
        ("9,grab=3000", "500..2500"),
        ("9,stale_ms=0", "stale"),
        ("9,neutral=1500", "unknown key"),
    ],
)
def test_parse_follow_servo_refuses_in_one_line(text: str, why: str) -> None:
    with pytest.raises(argparse.ArgumentTypeError, match=why) as info:
        parse_follow_servo(text)
    assert "\n" not in str(info.value)
