"""DJI C610 ESC / M2006 P36 motor frames on CAN (1 Mbit/s, standard 11-bit ids).

Facts (DJI ``RoboMaster/Development-Board-C-Examples``, ``CAN_receive.c``; C610 manual):

- Command: id 0x200 carries motors 1-4, id 0x1FF motors 5-8; 8 bytes = four big-endian int16 current
  setpoints, -10000..10000 = -10 A..+10 A (1000 raw per amp). With three motors slot 4 is 0. One CAN
  bus carries at most eight C610s (ids 1-8, set with each ESC's button); a board with up to four sends
  only 0x200, with five to eight both frames (:func:`command_frames`).
- Feedback: motor n answers on 0x200 + n at about 1 kHz: bytes 0-1 rotor angle 0..8191 (u16 BE, one
  rotor turn), 2-3 rotor speed in rpm (int16 BE, before the gearbox), 4-5 torque current (int16 BE,
  command scale), byte 6 temperature (°C; DJI's ``get_motor_measure`` reads it; a C610 may leave it 0),
  byte 7 unused.
- M2006 P36: 36:1 gearbox. DJI's firmware calls a motor offline after 10 ms without feedback.
"""

from __future__ import annotations

import math
import struct
from collections.abc import Callable, Sequence
from operator import index
from pathlib import Path
from typing import NamedTuple

from protocol.errors import DecodeError

__all__ = [
    "ANGLE_COUNTS",
    "COMMAND3_FORMAT",
    "COMMAND_FORMAT",
    "COMMAND_ID_HIGH",
    "COMMAND_ID_LOW",
    "CURRENT_RAW_MAX",
    "DBC_PATH",
    "FEEDBACK_FORMAT",
    "FEEDBACK_ID_BASE",
    "FRAME_LEN",
    "M2006_GEAR_RATIO",
    "MOTORS_MAX",
    "MOTORS_PER_COMMAND",
    "RAW_PER_AMP",
    "MotorFeedback",
    "amps_to_raw",
    "angle_delta_counts",
    "command_frames",
    "counts_to_output_rad",
    "current_command",
    "feedback_id",
    "output_rad_s_to_rotor_rpm",
    "output_rad_to_counts",
    "pack_currents",
    "pack_currents3",
    "pack_feedback",
    "raw_to_amps",
    "rotor_rpm_to_output_rad_s",
    "unpack_currents",
    "unpack_currents3",
]

DBC_PATH = Path(__file__).with_name("c610.dbc")
"""The C610 frames as a DBC (package data beside this module): the commands on 0x200 and 0x1FF and the
feedback on 0x201-0x208, for cantools, SavvyCAN or a candump log's decoder (``cantools decode``)."""

COMMAND_ID_LOW = 0x200
"""Command frame for motors 1-4."""
COMMAND_ID_HIGH = 0x1FF
"""Command frame for motors 5-8."""
FEEDBACK_ID_BASE = 0x200
"""Motor n (1..8) answers on ``FEEDBACK_ID_BASE + n``."""
FRAME_LEN = 8
"""Data bytes of every C610 frame."""
MOTORS_PER_COMMAND = 4
MOTORS_MAX = 2 * MOTORS_PER_COMMAND
"""C610 ids 1..8: the most motors one bus (and one pair of command frames) carries."""
CURRENT_RAW_MAX = 10_000
"""Largest |current setpoint| in raw units (10 A)."""
RAW_PER_AMP = 1000
ANGLE_COUNTS = 8192
"""Rotor encoder counts per rotor turn (angle is 0..8191)."""
M2006_GEAR_RATIO = 36
"""M2006 P36 gearbox: 36 rotor turns per output turn."""

COMMAND_FORMAT = struct.Struct(">hhhh")
"""Layout of a command frame's 8 data bytes: four int16 setpoints, the frame's first motor first."""
COMMAND3_FORMAT = struct.Struct(">hhhxx")
"""The same frame for motors 1-3 of a 0x200 frame: slot 4 packed as 0 and skipped when unpacking."""
FEEDBACK_FORMAT = struct.Struct(">HhhBx")
"""Layout of a feedback frame's 8 data bytes: angle u16, speed int16, current int16, temperature u8, pad."""

# The 1 kHz entry points: the precompiled structs' own methods, so a control tick or a plant step pays one
# C call and no Python frame for a frame. They check nothing: the caller has clamped every value into its
# wire range (beyond int16/u16 they raise ``struct.error``) and unpacks only 8-byte data (any other length
# raises ``struct.error``). :func:`current_command` and :class:`MotorFeedback` are the checked ones.
pack_currents: Callable[[int, int, int, int], bytes] = COMMAND_FORMAT.pack
"""Four raw setpoints -> the 8 data bytes of a command frame (unchecked)."""
pack_currents3: Callable[[int, int, int], bytes] = COMMAND3_FORMAT.pack
"""Setpoints of motors 1-3 -> the 8 data bytes of a 0x200 frame, slot 4 = 0 (unchecked)."""
unpack_currents: Callable[[bytes], tuple[int, int, int, int]] = COMMAND_FORMAT.unpack
"""The 8 data bytes of a command frame -> its four raw setpoints."""
unpack_currents3: Callable[[bytes], tuple[int, int, int]] = COMMAND3_FORMAT.unpack
"""The 8 data bytes of a 0x200 frame -> the setpoints of motors 1-3 (slot 4 ignored)."""
pack_feedback: Callable[[int, int, int, int], bytes] = FEEDBACK_FORMAT.pack
"""``(angle, speed_rpm, current, temperature)`` -> the 8 data bytes of a feedback frame (unchecked)."""

_ZEROS = (0, 0, 0, 0)
_new_tuple = tuple.__new__  # builds a named tuple from a ready tuple without re-checking its arity


def _as_current(value: object, slot: int) -> int:
    if type(value) is int:  # fast path: the 1 kHz control task passes plain ints
        raw = value
    else:
        if isinstance(value, bool):
            raise ValueError(f"current[{slot}] must be an int, got bool")
        try:
            raw = index(value)  # type: ignore[arg-type]  # also numpy integers; floats refused
        except TypeError:
            raise ValueError(f"current[{slot}] must be an int, got {type(value).__name__}") from None
    if not -CURRENT_RAW_MAX <= raw <= CURRENT_RAW_MAX:
        raise ValueError(f"current[{slot}] = {raw} outside -{CURRENT_RAW_MAX}..{CURRENT_RAW_MAX}")
    return raw


def current_command(currents: Sequence[int], can_id: int = COMMAND_ID_LOW) -> tuple[int, bytes]:
    """Build a C610 current command frame.

    Args:
        currents: up to four raw setpoints (-10000..10000 = -10..10 A) for the motors of this frame in
            order (motor 1..4 for 0x200, 5..8 for 0x1FF); missing slots are sent as 0.
        can_id: ``COMMAND_ID_LOW`` (0x200) or ``COMMAND_ID_HIGH`` (0x1FF).

    Returns:
        ``(can_id, data)`` with the 8 data bytes.

    Raises:
        ValueError: more than four currents, a value that is not an int or is out of range, or a
            ``can_id`` that is neither 0x200 nor 0x1FF.
    """
    if can_id != COMMAND_ID_LOW and can_id != COMMAND_ID_HIGH:
        raise ValueError(f"can_id must be 0x200 or 0x1FF, got {can_id:#x}")
    n = len(currents)
    if n > MOTORS_PER_COMMAND:
        raise ValueError(f"at most {MOTORS_PER_COMMAND} currents per frame, got {n}")
    values = [_as_current(v, i) for i, v in enumerate(currents)]
    if n < MOTORS_PER_COMMAND:
        values.extend(_ZEROS[n:])
    return can_id, COMMAND_FORMAT.pack(*values)


def command_frames(currents: Sequence[int]) -> list[tuple[int, bytes]]:
    """The command frames of a board driving motors 1..n, in the order it sends them.

    Args:
        currents: one raw setpoint per motor, motor 1 first (1 to 8 of them, -10000..10000).

    Returns:
        ``[(0x200, data)]`` for up to four motors (empty slots 0, the frame a three-motor board has
        always sent); ``[(0x200, data), (0x1FF, data)]`` for five to eight.

    Raises:
        ValueError: no currents or more than eight, or a value :func:`current_command` refuses.
    """
    n = len(currents)
    if not 1 <= n <= MOTORS_MAX:
        raise ValueError(f"1..{MOTORS_MAX} currents, got {n}")
    frames = [current_command(currents[:MOTORS_PER_COMMAND], COMMAND_ID_LOW)]
    if n > MOTORS_PER_COMMAND:
        frames.append(current_command(currents[MOTORS_PER_COMMAND:], COMMAND_ID_HIGH))
    return frames


def feedback_id(motor: int) -> int:
    """CAN id of the feedback frame of motor ``motor`` (1..8).

    Raises:
        ValueError: ``motor`` is not in 1..8.
    """
    if not 1 <= motor <= MOTORS_MAX:
        raise ValueError(f"motor must be 1..8, got {motor}")
    return FEEDBACK_ID_BASE + motor


class MotorFeedback(NamedTuple):
    """One C610 feedback frame (CAN id 0x200 + motor number).

    A named tuple, not a dataclass: the firmware decodes three of these every millisecond, and a tuple
    is built about five times faster than a frozen dataclass.

    Attributes:
        angle: rotor angle in encoder counts, 0..8191 (one rotor turn; wraps).
        speed_rpm: rotor speed in rpm before the gearbox, int16.
        current: measured torque current in command units (1000 per amp), int16.
        temperature: motor temperature in °C, 0..255 (byte 6; may be 0 on a C610).
    """

    angle: int
    speed_rpm: int
    current: int
    temperature: int = 0

    @classmethod
    def unpack(cls, data: bytes | bytearray | memoryview) -> MotorFeedback:
        """Decode the 8 data bytes of a feedback frame (byte 7 is ignored).

        Raises:
            DecodeError: ``data`` is not 8 bytes, or the angle is above 8191.
        """
        if len(data) != FRAME_LEN:
            raise DecodeError(f"a C610 feedback frame is {FRAME_LEN} bytes, got {len(data)}")
        fields = FEEDBACK_FORMAT.unpack(data)
        if fields[0] >= ANGLE_COUNTS:
            raise DecodeError(f"rotor angle {fields[0]} outside 0..{ANGLE_COUNTS - 1}")
        return _new_tuple(cls, fields)

    def pack(self) -> bytes:
        """Encode to the 8 data bytes (byte 7 = 0).

        Raises:
            ValueError: a field is outside its wire range.
        """
        if not 0 <= self.angle < ANGLE_COUNTS:
            raise ValueError(f"angle = {self.angle} outside 0..{ANGLE_COUNTS - 1}")
        if not 0 <= self.temperature <= 0xFF:
            raise ValueError(f"temperature = {self.temperature} outside 0..255")
        try:
            return FEEDBACK_FORMAT.pack(self.angle, self.speed_rpm, self.current, self.temperature)
        except struct.error as exc:
            raise ValueError(f"speed_rpm/current must be int16: {exc}") from exc


def raw_to_amps(raw: int) -> float:
    """Raw current (command or feedback units) -> amps."""
    return raw / RAW_PER_AMP


def amps_to_raw(amps: float) -> int:
    """Amps -> raw current command, rounded to nearest and clamped to ±``CURRENT_RAW_MAX``."""
    raw = round(amps * RAW_PER_AMP)
    return max(-CURRENT_RAW_MAX, min(CURRENT_RAW_MAX, raw))


def counts_to_output_rad(counts: int, gear_ratio: float = M2006_GEAR_RATIO) -> float:
    """Rotor encoder counts (wrapped or unwrapped multi-turn) -> output shaft angle in radians."""
    return counts * (2.0 * math.pi) / (ANGLE_COUNTS * gear_ratio)


def output_rad_to_counts(angle_rad: float, gear_ratio: float = M2006_GEAR_RATIO) -> int:
    """Output shaft angle in radians -> unwrapped rotor counts (rounded); ``% ANGLE_COUNTS`` to wrap."""
    return round(angle_rad * ANGLE_COUNTS * gear_ratio / (2.0 * math.pi))


def rotor_rpm_to_output_rad_s(rpm: float, gear_ratio: float = M2006_GEAR_RATIO) -> float:
    """Rotor speed in rpm (as fed back) -> output shaft speed in rad/s."""
    return rpm * (2.0 * math.pi) / (60.0 * gear_ratio)


def output_rad_s_to_rotor_rpm(speed_rad_s: float, gear_ratio: float = M2006_GEAR_RATIO) -> float:
    """Output shaft speed in rad/s -> rotor speed in rpm (round and clamp to int16 before sending)."""
    return speed_rad_s * 60.0 * gear_ratio / (2.0 * math.pi)


def angle_delta_counts(previous: int, current: int) -> int:
    """Shortest signed rotor movement between two wrapped angles, in counts (-4096..4095).

    Summing these deltas unwraps the angle into multi-turn counts, valid while the rotor turns less
    than half a turn between two samples (at 1 kHz: below 30 000 rpm; the M2006 tops out near 18 000).
    """
    half = ANGLE_COUNTS // 2
    return (current - previous + half) % ANGLE_COUNTS - half
