"""Tests for protocol.c610: C610 command and feedback frames and M2006 unit conversions."""

from __future__ import annotations

import math
import struct

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from protocol.c610 import (
    ANGLE_COUNTS,
    COMMAND_ID_HIGH,
    COMMAND_ID_LOW,
    CURRENT_RAW_MAX,
    FEEDBACK_ID_BASE,
    M2006_GEAR_RATIO,
    MOTORS_MAX,
    MotorFeedback,
    amps_to_raw,
    angle_delta_counts,
    command_frames,
    counts_to_output_rad,
    current_command,
    feedback_id,
    output_rad_s_to_rotor_rpm,
    output_rad_to_counts,
    pack_currents,
    pack_currents3,
    pack_feedback,
    raw_to_amps,
    rotor_rpm_to_output_rad_s,
    unpack_currents,
    unpack_currents3,
)
from protocol.errors import DecodeError

SETTINGS = settings(max_examples=300, deadline=None)


def test_constants() -> None:
    assert (COMMAND_ID_LOW, COMMAND_ID_HIGH, FEEDBACK_ID_BASE) == (0x200, 0x1FF, 0x200)
    assert (CURRENT_RAW_MAX, ANGLE_COUNTS, M2006_GEAR_RATIO) == (10000, 8192, 36)


def test_golden_command_frame() -> None:
    assert current_command([1000, -1000, 10000]) == (0x200, bytes.fromhex("03e8fc1827100000"))
    assert current_command([-10000, 0, 1, -1]) == (0x200, bytes.fromhex("d8f000000001ffff"))


def test_command_pads_to_four_and_accepts_high_id() -> None:
    assert current_command([], COMMAND_ID_HIGH) == (0x1FF, bytes(8))
    assert current_command((5,), 0x1FF) == (0x1FF, bytes.fromhex("0005000000000000"))


def test_golden_high_command_frame_carries_motors_5_to_8() -> None:
    """0x1FF: the same layout as 0x200, motor 5 in bytes 0-1 ... motor 8 in bytes 6-7 (DJI CAN_receive.c)."""
    assert current_command([1000, -1000, 10000, -10000], COMMAND_ID_HIGH) == (
        0x1FF,
        bytes.fromhex("03e8fc182710d8f0"),
    )
    assert current_command([-1, 2], COMMAND_ID_HIGH) == (0x1FF, bytes.fromhex("ffff000200000000"))


def test_golden_command_frames_of_an_eight_motor_board() -> None:
    assert MOTORS_MAX == 8
    assert command_frames([1, -2, 3, -4, 5, -6, 7, -8]) == [
        (0x200, bytes.fromhex("0001fffe0003fffc")),
        (0x1FF, bytes.fromhex("0005fffa0007fff8")),
    ]
    assert command_frames([10000, -10000, 0, 1, -1, 2000, -2000, 9999]) == [
        (0x200, bytes.fromhex("2710d8f000000001")),
        (0x1FF, bytes.fromhex("ffff07d0f830270f")),
    ]


def test_command_frames_send_0x1ff_only_above_four_motors() -> None:
    # three motors: the single 0x200 frame the board has always sent, slot 4 = 0
    assert command_frames([1000, -1000, 10000]) == [(0x200, bytes.fromhex("03e8fc1827100000"))]
    assert command_frames([1, 2, 3, 4]) == [(0x200, bytes.fromhex("0001000200030004"))]
    # five motors: motor 5 alone in the 0x1FF frame, slots 6-8 = 0
    assert command_frames([1, 2, 3, 4, -5]) == [
        (0x200, bytes.fromhex("0001000200030004")),
        (0x1FF, bytes.fromhex("fffb000000000000")),
    ]


@pytest.mark.parametrize("currents", [[], [0] * 9, [0, 0, 0, 0, 10001], [0] * 5 + [1.5]])
def test_command_frames_reject_bad_arguments(currents: list[object]) -> None:
    with pytest.raises(ValueError):
        command_frames(currents)  # type: ignore[arg-type]


@SETTINGS
@given(st.lists(st.integers(-CURRENT_RAW_MAX, CURRENT_RAW_MAX), min_size=1, max_size=8))
def test_command_frames_round_trip(currents: list[int]) -> None:
    frames = command_frames(currents)
    n = len(currents)
    assert [can_id for can_id, _ in frames] == ([0x200] if n <= 4 else [0x200, 0x1FF])
    decoded = [v for _, data in frames for v in unpack_currents(data)]
    assert decoded[:n] == currents and not any(decoded[n:])
    assert len(decoded) == 4 * len(frames)


def test_command_accepts_numpy_integers() -> None:
    arr = np.array([100, -200, 300], dtype=np.int16)
    assert current_command(list(arr))[1] == current_command([100, -200, 300])[1]


@pytest.mark.parametrize(
    ("currents", "can_id"),
    [
        ([10001], 0x200),
        ([-10001], 0x200),
        ([0, 0, 0, 0, 0], 0x200),
        ([1.0], 0x200),
        ([True], 0x200),
        (["1"], 0x200),
        ([0], 0x201),
        ([0], 0x1FE),
    ],
)
def test_command_rejects_bad_arguments(currents: list[object], can_id: int) -> None:
    with pytest.raises(ValueError):
        current_command(currents, can_id)  # type: ignore[arg-type]


@SETTINGS
@given(st.lists(st.integers(-CURRENT_RAW_MAX, CURRENT_RAW_MAX), max_size=4), st.sampled_from([0x200, 0x1FF]))
def test_command_round_trip(currents: list[int], can_id: int) -> None:
    cid, data = current_command(currents, can_id)
    assert cid == can_id
    assert list(struct.unpack(">4h", data)) == currents + [0] * (4 - len(currents))


def test_unchecked_command_entry_points_match_the_checked_frame() -> None:
    assert pack_currents(1000, -1000, 10000, 0) == bytes.fromhex("03e8fc1827100000")
    assert pack_currents3(1000, -1000, 10000) == bytes.fromhex("03e8fc1827100000")
    assert unpack_currents(bytes.fromhex("d8f000000001ffff")) == (-10000, 0, 1, -1)
    assert unpack_currents3(bytes.fromhex("d8f000000001ffff")) == (-10000, 0, 1)  # slot 4 ignored


@SETTINGS
@given(st.lists(st.integers(-CURRENT_RAW_MAX, CURRENT_RAW_MAX), min_size=3, max_size=3))
def test_unchecked_command_round_trip(currents: list[int]) -> None:
    a, b, c = currents
    data = current_command(currents)[1]
    assert pack_currents(a, b, c, 0) == pack_currents3(a, b, c) == data
    assert unpack_currents(data) == (a, b, c, 0) and unpack_currents3(data) == (a, b, c)


GOLDEN_FEEDBACK = bytes.fromhex("1fff03e8ff382400")


def test_unchecked_feedback_packer_matches_the_checked_one() -> None:
    assert pack_feedback(8191, 1000, -200, 36) == GOLDEN_FEEDBACK


def test_golden_feedback_frame() -> None:
    fb = MotorFeedback.unpack(GOLDEN_FEEDBACK)
    assert fb == MotorFeedback(angle=8191, speed_rpm=1000, current=-200, temperature=36)
    assert fb.pack() == GOLDEN_FEEDBACK


def test_feedback_ignores_byte_7_and_packs_it_zero() -> None:
    fb = MotorFeedback.unpack(GOLDEN_FEEDBACK[:7] + b"\xab")
    assert fb.pack() == GOLDEN_FEEDBACK


@pytest.mark.parametrize("data", [bytes(7), bytes(9), b"", bytes.fromhex("2000000000000000")])
def test_feedback_unpack_rejects(data: bytes) -> None:
    with pytest.raises(DecodeError):
        MotorFeedback.unpack(data)


@pytest.mark.parametrize(
    "fb",
    [
        MotorFeedback(8192, 0, 0),
        MotorFeedback(-1, 0, 0),
        MotorFeedback(0, 32768, 0),
        MotorFeedback(0, 0, -32769),
        MotorFeedback(0, 0, 0, 256),
    ],
)
def test_feedback_pack_rejects(fb: MotorFeedback) -> None:
    with pytest.raises(ValueError):
        fb.pack()


@SETTINGS
@given(st.integers(0, ANGLE_COUNTS - 1), st.binary(min_size=6, max_size=6))
def test_feedback_bytes_round_trip(angle: int, rest: bytes) -> None:
    data = angle.to_bytes(2, "big") + rest
    assert MotorFeedback.unpack(data).pack() == data[:7] + b"\x00"


@SETTINGS
@given(
    st.builds(
        MotorFeedback,
        st.integers(0, 8191),
        st.integers(-32768, 32767),
        st.integers(-32768, 32767),
        st.integers(0, 255),
    )
)
def test_feedback_fields_round_trip(fb: MotorFeedback) -> None:
    assert MotorFeedback.unpack(fb.pack()) == fb


def test_feedback_ids_of_eight_motors() -> None:
    assert [feedback_id(m) for m in range(1, MOTORS_MAX + 1)] == list(range(0x201, 0x209))


def test_feedback_id() -> None:
    assert [feedback_id(n) for n in (1, 2, 3, 8)] == [0x201, 0x202, 0x203, 0x208]
    for bad in (0, 9):
        with pytest.raises(ValueError):
            feedback_id(bad)


def test_current_conversions() -> None:
    assert raw_to_amps(1000) == 1.0
    assert raw_to_amps(-10000) == -10.0
    assert amps_to_raw(3.0) == 3000
    assert amps_to_raw(-0.0016) == -2
    assert amps_to_raw(12.0) == CURRENT_RAW_MAX
    assert amps_to_raw(-99.0) == -CURRENT_RAW_MAX


def test_angle_and_speed_conversions() -> None:
    one_output_turn = ANGLE_COUNTS * M2006_GEAR_RATIO
    assert counts_to_output_rad(one_output_turn) == pytest.approx(2 * math.pi)
    assert counts_to_output_rad(-one_output_turn // 4) == pytest.approx(-math.pi / 2)
    assert output_rad_to_counts(2 * math.pi) == one_output_turn
    assert rotor_rpm_to_output_rad_s(36 * 60) == pytest.approx(2 * math.pi)  # 1 output rev/s
    assert output_rad_s_to_rotor_rpm(2 * math.pi) == pytest.approx(2160.0)
    assert counts_to_output_rad(8192, gear_ratio=1) == pytest.approx(2 * math.pi)


@SETTINGS
@given(st.integers(-(10**7), 10**7))
def test_counts_round_trip(counts: int) -> None:
    assert output_rad_to_counts(counts_to_output_rad(counts)) == counts


@pytest.mark.parametrize(
    ("prev", "cur", "delta"),
    [(8190, 2, 4), (2, 8190, -4), (0, 4096, -4096), (0, 4095, 4095), (100, 100, 0)],
)
def test_angle_delta_counts(prev: int, cur: int, delta: int) -> None:
    assert angle_delta_counts(prev, cur) == delta


@SETTINGS
@given(st.integers(0, 8191), st.integers(-4096, 4095))
def test_angle_delta_unwraps(start: int, move: int) -> None:
    assert angle_delta_counts(start, (start + move) % ANGLE_COUNTS) == move
