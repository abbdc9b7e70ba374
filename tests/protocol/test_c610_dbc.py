"""protocol/c610.dbc, shipped as package data: cantools decodes the frames our packers build (golden values
and any value), and encodes the same bytes."""

from __future__ import annotations

import functools

import cantools
import pytest
from hypothesis import given
from hypothesis import strategies as st

from protocol.c610 import (
    ANGLE_COUNTS,
    CURRENT_RAW_MAX,
    DBC_PATH,
    MotorFeedback,
    command_frames,
    current_command,
    feedback_id,
    pack_feedback,
)

GOLDEN_COMMAND = bytes.fromhex("03e8fc1827100000")  # motors 1-3 at 1000, -1000, 10000 raw
GOLDEN_COMMAND_HIGH = bytes.fromhex("03e8fc182710d8f0")  # motors 5-8 at 1000, -1000, 10000, -10000 raw
GOLDEN_FEEDBACK = bytes.fromhex("1fff03e8ff382400")  # angle 8191, 1000 rpm, -200 raw, 36 °C

currents = st.integers(-CURRENT_RAW_MAX, CURRENT_RAW_MAX)
int16 = st.integers(-32768, 32767)


@functools.cache
def c610_db() -> cantools.database.can.Database:
    """The shipped DBC, loaded once, from the installed ``protocol`` package's data."""
    # By the module's own path: under pytest's importlib mode the name "protocol" can resolve to
    # tests/protocol (the packaging test checks the installed package data with importlib.resources).
    assert DBC_PATH.is_file(), "c610.dbc must ship inside the protocol package"
    database = cantools.database.load_file(str(DBC_PATH))
    assert isinstance(database, cantools.database.can.Database)
    return database


def test_the_dbc_names_both_commands_and_the_eight_feedback_frames() -> None:
    db = c610_db()
    assert sorted(m.frame_id for m in db.messages) == [0x1FF, *range(0x200, 0x209)]
    assert all(m.length == 8 and not m.is_extended_frame for m in db.messages)


def test_golden_command_frame() -> None:
    db = c610_db()
    can_id, data = current_command([1000, -1000, 10000])
    assert data == GOLDEN_COMMAND
    assert db.decode_message(can_id, data) == pytest.approx(
        {"Motor1_Current": 1.0, "Motor2_Current": -1.0, "Motor3_Current": 10.0, "Motor4_Current": 0.0}
    )


def test_golden_high_command_frame() -> None:
    db = c610_db()
    frames = command_frames([0, 0, 0, 0, 1000, -1000, 10000, -10000])
    assert frames[1] == (0x1FF, GOLDEN_COMMAND_HIGH)
    assert db.decode_message(*frames[1]) == pytest.approx(
        {"Motor5_Current": 1.0, "Motor6_Current": -1.0, "Motor7_Current": 10.0, "Motor8_Current": -10.0}
    )


@given(st.lists(currents, min_size=5, max_size=8))
def test_any_eight_motor_board_decodes_to_its_amps(values: list[int]) -> None:
    db = c610_db()
    decoded: dict[str, int] = {}
    for can_id, data in command_frames(values):
        fields = db.decode_message(can_id, data, scaling=False)
        assert db.encode_message(can_id, fields, scaling=False) == data
        decoded |= fields
    padded = values + [0] * (8 - len(values))
    assert decoded == {f"Motor{i + 1}_Current": v for i, v in enumerate(padded)}


def test_golden_feedback_frame() -> None:
    db = c610_db()
    assert MotorFeedback(8191, 1000, -200, 36).pack() == GOLDEN_FEEDBACK
    for motor in range(1, 9):
        decoded = db.decode_message(feedback_id(motor), GOLDEN_FEEDBACK)
        assert decoded == {"Angle": 8191, "Speed": 1000, "Current": pytest.approx(-0.2), "Temperature": 36}


@given(a=currents, b=currents, c=currents, d=currents)
def test_any_command_decodes_to_its_amps_and_encodes_back(a: int, b: int, c: int, d: int) -> None:
    db = c610_db()
    can_id, data = current_command([a, b, c, d])
    decoded = db.decode_message(can_id, data, scaling=False)
    assert decoded == {"Motor1_Current": a, "Motor2_Current": b, "Motor3_Current": c, "Motor4_Current": d}
    assert db.encode_message(can_id, decoded, scaling=False) == data


@given(angle=st.integers(0, ANGLE_COUNTS - 1), speed=int16, current=int16, temp=st.integers(0, 255))
def test_any_feedback_decodes_to_its_fields_and_encodes_back(
    angle: int, speed: int, current: int, temp: int
) -> None:
    db = c610_db()
    data = pack_feedback(angle, speed, current, temp)
    decoded = db.decode_message(0x202, data)
    assert decoded["Angle"] == angle and decoded["Speed"] == speed and decoded["Temperature"] == temp
    assert decoded["Current"] == pytest.approx(current / 1000)
    assert db.encode_message(0x202, db.decode_message(0x202, data, scaling=False), scaling=False) == data
