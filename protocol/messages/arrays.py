"""The board -> host messages of an array of arms (issue 27): ``ArmsTelemetry`` and ``ArmPoses``.

A board laid out as one arm of up to three cables never sends them (its bytes are unchanged); one laid out
as several arms sends ``ArmsTelemetry`` with each ``Telemetry`` and, in simulation, an ``ArmPoses`` for
each arm after arm 0 with each ``SimPoses`` (docs/board-link.md).
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from typing import ClassVar

from protocol.errors import DecodeError
from protocol.messages.enums import Direction
from protocol.messages.fields import (
    _POSES,
    MAX_SIM_BODIES,
    Vec3f,
    Vec4f,
    _check_len,
    _flat_poses,
    _pack_error,
    _unpack_poses,
)
from protocol.messages.registry import Message, _register

_ARMS_HEAD = struct.Struct("<QBBB")
_ARMS_MOTOR = struct.Struct("<Hhhhfff?")
_ARMS_FIELDS = 8
"""Fields of one motor's entry (angle, speed, current, commanded, target, estimate, length, hold)."""
ARMS_MOTORS_MAX = 8
"""Motors an ``ArmsTelemetry`` carries at most (the C-board's eight C610 ids)."""
_ARMS_MOTOR_STRUCTS = {n: struct.Struct("<" + _ARMS_MOTOR.format[1:] * n) for n in range(ARMS_MOTORS_MAX + 1)}


@_register
@dataclass(frozen=True, slots=True)
class ArmsTelemetry(Message):
    """Every motor of a board laid out as an array (with each ``Telemetry``). 11 + 21 n bytes, n <= 8.

    Sent only by a board whose layout is not the one 3-cable arm (``Telemetry`` carries motors 1-3): what
    a 3-motor board sends is unchanged. Motor ``m`` (1-based) drives cable ``(m-1) % cables_per_arm`` of
    arm ``(m-1) // cables_per_arm``.

    Attributes:
        time_us: board time.
        arms: arms of the layout.
        cables_per_arm: cables of each arm (1-3).
        motor_angle: per motor, rotor angle in counts 0..8191, as fed back.
        motor_speed_rpm: per motor, rotor speed in rpm.
        motor_current: per motor, measured current, raw (1000 per amp).
        commanded_current: per motor, the current last sent, raw.
        tension_target_n: per motor, its cable's tension target.
        tension_est_n: per motor, its cable's tension estimated from the measured current.
        cable_length_m: per motor, cable paid in since start.
        hold: per motor, its cable is in length-hold.
    """

    CMD_ID: ClassVar[int] = 0x0109
    DIRECTION: ClassVar[Direction] = Direction.BOARD_TO_HOST

    time_us: int
    arms: int
    cables_per_arm: int
    motor_angle: tuple[int, ...]
    motor_speed_rpm: tuple[int, ...]
    motor_current: tuple[int, ...]
    commanded_current: tuple[int, ...]
    tension_target_n: tuple[float, ...]
    tension_est_n: tuple[float, ...]
    cable_length_m: tuple[float, ...]
    hold: tuple[bool, ...]

    def pack(self) -> bytes:
        """Encode the payload (see :meth:`Message.pack`)."""
        columns = (
            self.motor_angle,
            self.motor_speed_rpm,
            self.motor_current,
            self.commanded_current,
            self.tension_target_n,
            self.tension_est_n,
            self.cable_length_m,
            self.hold,
        )
        n = len(self.motor_angle)
        if any(len(c) != n for c in columns):
            raise ValueError("ArmsTelemetry: every per-motor field needs one value per motor")
        _check_layout(self.arms, self.cables_per_arm, n, ValueError)
        flat = [v for row in zip(*columns, strict=True) for v in row]
        try:
            return _ARMS_HEAD.pack(self.time_us, self.arms, self.cables_per_arm, n) + _ARMS_MOTOR_STRUCTS[
                n
            ].pack(*flat)
        except (struct.error, OverflowError) as exc:
            raise _pack_error("ArmsTelemetry", exc) from exc

    @classmethod
    def unpack(cls, payload: bytes) -> ArmsTelemetry:
        """Decode the payload (see :meth:`Message.unpack`)."""
        head = _ARMS_HEAD.size
        if len(payload) < head:
            raise DecodeError(f"ArmsTelemetry payload is at least {head} bytes, got {len(payload)}")
        t, arms, cables, n = _ARMS_HEAD.unpack_from(payload)
        _check_layout(arms, cables, n, DecodeError)
        _check_len(payload, head + _ARMS_MOTOR_STRUCTS[n].size, "ArmsTelemetry")
        if any(b > 1 for b in payload[head + _ARMS_MOTOR.size - 1 :: _ARMS_MOTOR.size]):
            raise DecodeError("ArmsTelemetry: hold is 0 or 1")
        v = _ARMS_MOTOR_STRUCTS[n].unpack_from(payload, head)
        k = _ARMS_FIELDS
        cols = [tuple(v[j::k]) for j in range(k)]
        return cls(t, arms, cables, *cols)  # type: ignore[arg-type]


def _check_layout(arms: int, cables: int, n: int, error: type[Exception]) -> None:
    if not (1 <= n <= ARMS_MOTORS_MAX and 1 <= cables <= 3 and arms * cables == n):
        raise error(
            f"ArmsTelemetry: {arms} arm(s) of {cables} cable(s) for {n} motors (1-{ARMS_MOTORS_MAX} motors, "
            "1-3 cables per arm, arms x cables = motors)"
        )


_ARM_POSES_HEAD = struct.Struct("<QBBB")


@_register
@dataclass(frozen=True, slots=True)
class ArmPoses(Message):
    """World poses of one arm's units of an array (simulation only, with each ``SimPoses``). 11 + 28 n bytes.

    ``SimPoses`` keeps the drone and arm 0 (a host that predates arrays draws that arm); a board whose
    plant has more than one arm sends one ``ArmPoses`` for each of arms 1 .. arms-1 right after it, at
    the same time. Units go from base to tip, in the same world frame and with the same 28-byte pose as
    ``SimPoses``.

    Attributes:
        time_us: simulation time (the ``SimPoses`` it goes with has the same).
        arm: the arm, 0 .. arms-1.
        arms: arms of the plant, 1 .. 8.
        positions_m: n positions (x, y, z) in the world frame.
        quats_wxyz: n orientations as unit quaternions (w, x, y, z).
    """

    CMD_ID: ClassVar[int] = 0x010A
    DIRECTION: ClassVar[Direction] = Direction.BOARD_TO_HOST

    time_us: int
    arm: int
    arms: int
    positions_m: tuple[Vec3f, ...]
    quats_wxyz: tuple[Vec4f, ...]

    @property
    def tip_position_m(self) -> Vec3f:
        """Position of the arm's tip unit (the last).

        Raises:
            IndexError: no units.
        """
        return self.positions_m[-1]

    def pack(self) -> bytes:
        """Encode the payload (see :meth:`Message.pack`)."""
        _check_arm(self.arm, self.arms, ValueError)
        n, flat = _flat_poses(self.positions_m, self.quats_wxyz, "units")
        try:
            return _ARM_POSES_HEAD.pack(self.time_us, self.arm, self.arms, n) + _POSES[n].pack(*flat)
        except (struct.error, OverflowError) as exc:
            raise _pack_error("ArmPoses", exc) from exc

    @classmethod
    def unpack(cls, payload: bytes) -> ArmPoses:
        """Decode the payload (see :meth:`Message.unpack`)."""
        head = _ARM_POSES_HEAD.size
        if len(payload) < head:
            raise DecodeError(f"ArmPoses payload is at least {head} bytes, got {len(payload)}")
        t, arm, arms, n = _ARM_POSES_HEAD.unpack_from(payload)
        _check_arm(arm, arms, DecodeError)
        if n > MAX_SIM_BODIES:
            raise DecodeError(f"ArmPoses: {n} units, at most {MAX_SIM_BODIES}")
        _check_len(payload, head + _POSES[n].size, "ArmPoses")
        return cls(t, arm, arms, *_unpack_poses(payload, head, n))


def _check_arm(arm: int, arms: int, error: type[Exception]) -> None:
    if not (1 <= arms <= ARMS_MOTORS_MAX and 0 <= arm < arms):
        raise error(f"ArmPoses: arm {arm} of {arms} (1-{ARMS_MOTORS_MAX} arms, numbered from 0)")
