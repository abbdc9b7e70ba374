"""The board -> host messages (ids 0x01xx) and ``TaskStats``, the task entry of ``BoardStatus``."""

from __future__ import annotations

import struct
from dataclasses import dataclass
from typing import ClassVar

from protocol.dbus import FRAME_LEN as DBUS_FRAME_LEN
from protocol.dbus import RcFrame
from protocol.errors import DecodeError
from protocol.messages.enums import (
    AckResult,
    ArmBlocker,
    ClockKind,
    CommandCode,
    Direction,
    EventKind,
    GraspState,
    Mode,
    Phase,
    TelemetryFlags,
)
from protocol.messages.fields import (
    _POSES,
    ACK_TEXT_MAX,
    EVENT_TEXT_MAX,
    MAX_SIM_BODIES,
    MAX_TASKS,
    NAME_LEN,
    TASK_NAME_LEN,
    VERSION_LEN,
    Vec3f,
    Vec3i,
    Vec4f,
    Vec4i,
    _check_len,
    _enum,
    _flat_poses,
    _pack_error,
    _pack_name,
    _pack_text,
    _unpack_name,
    _unpack_poses,
    _unpack_text,
)
from protocol.messages.registry import Message, _register

_U16_MAX = 0xFFFF


@_register
@dataclass(frozen=True, slots=True)
class Telemetry(Message):
    """Board state at the telemetry rate (100 Hz). 126 bytes.

    Attributes:
        time_us: board time.
        mode: operating mode.
        phase: failsafe phase.
        grasp_state: grasp state machine.
        flags: ``TelemetryFlags``.
        motors_online: bit i set = motor i+1 answered within the offline timeout.
        rc_channels: the last accepted RC frame's channels (offset removed).
        right_lever: its right lever (``Lever`` value, 0 before any frame).
        left_lever: its left lever.
        motor_angle: rotor angles in counts 0..8191, as fed back.
        motor_speed_rpm: rotor speeds in rpm, as fed back.
        motor_current: measured currents, raw C610 units (1000 per amp).
        commanded_current: the currents actually sent in the last 0x200 frame, raw.
        tension_target_n: per-cable tension targets.
        tension_est_n: per-cable tensions estimated from measured current.
        cable_length_m: cable paid in since start (spool radius x unwrapped output angle).
        control_late: control-task ticks that started late, since boot.
        control_exec_p99_us: control-task execution time, 99th percentile (recent window; saturates
            at 65535 on the wire).
        control_exec_max_us: control-task execution time, maximum (saturates at 65535).
        control_lateness_max_us: control-task start lateness, maximum.
        rc_frames_ok: valid RC frames accepted.
        rc_rejected: RC frames rejected as invalid (out of range, lever 0).
        dbus_bytes_dropped: UART bytes dropped by the DBUS framer.
        link_frames_ok: board-link frames received intact.
        link_crc_errors: board-link header + body CRC errors.
        motor_offline_events: times a motor went silent past the offline timeout.
        can_errors: CAN send/receive errors and undecodable feedback frames.
        control_lateness_p99_us: control-task start lateness, 99th percentile (recent window, like
            ``control_exec_p99_us``; saturates at 65535 on the wire). Last on the wire so the earlier
            offsets stay where they were.
        arm_blocker: ``ArmBlocker``: what holds the arming gate shut (``NONE`` while armed). Appended
            after ``control_lateness_p99_us`` for the same reason.
    """

    CMD_ID: ClassVar[int] = 0x0101
    DIRECTION: ClassVar[Direction] = Direction.BOARD_TO_HOST
    FORMAT: ClassVar[struct.Struct] = struct.Struct("<QBBBBB4hBB3H3h3h3h3f3f3fIHHI7IHB")

    time_us: int
    mode: Mode = Mode.SAFE
    phase: Phase = Phase.GATE
    grasp_state: GraspState = GraspState.IDLE
    flags: TelemetryFlags = TelemetryFlags.NONE
    motors_online: int = 0
    rc_channels: Vec4i = (0, 0, 0, 0)
    right_lever: int = 0
    left_lever: int = 0
    motor_angle: Vec3i = (0, 0, 0)
    motor_speed_rpm: Vec3i = (0, 0, 0)
    motor_current: Vec3i = (0, 0, 0)
    commanded_current: Vec3i = (0, 0, 0)
    tension_target_n: Vec3f = (0.0, 0.0, 0.0)
    tension_est_n: Vec3f = (0.0, 0.0, 0.0)
    cable_length_m: Vec3f = (0.0, 0.0, 0.0)
    control_late: int = 0
    control_exec_p99_us: int = 0
    control_exec_max_us: int = 0
    control_lateness_max_us: int = 0
    rc_frames_ok: int = 0
    rc_rejected: int = 0
    dbus_bytes_dropped: int = 0
    link_frames_ok: int = 0
    link_crc_errors: int = 0
    motor_offline_events: int = 0
    can_errors: int = 0
    control_lateness_p99_us: int = 0
    arm_blocker: ArmBlocker = ArmBlocker.NONE

    def pack(self) -> bytes:
        """Encode the payload: one ``struct.pack`` call (this runs on the firmware's telemetry task)."""
        try:
            return self.FORMAT.pack(
                self.time_us,
                self.mode,
                self.phase,
                self.grasp_state,
                self.flags,
                self.motors_online,
                *self.rc_channels,
                self.right_lever,
                self.left_lever,
                *self.motor_angle,
                *self.motor_speed_rpm,
                *self.motor_current,
                *self.commanded_current,
                *self.tension_target_n,
                *self.tension_est_n,
                *self.cable_length_m,
                self.control_late,
                min(self.control_exec_p99_us, _U16_MAX),
                min(self.control_exec_max_us, _U16_MAX),
                self.control_lateness_max_us,
                self.rc_frames_ok,
                self.rc_rejected,
                self.dbus_bytes_dropped,
                self.link_frames_ok,
                self.link_crc_errors,
                self.motor_offline_events,
                self.can_errors,
                min(self.control_lateness_p99_us, _U16_MAX),
                self.arm_blocker,
            )
        except (struct.error, OverflowError) as exc:
            raise _pack_error("Telemetry", exc) from exc

    @classmethod
    def unpack(cls, payload: bytes) -> Telemetry:
        """Decode the payload (see :meth:`Message.unpack`)."""
        _check_len(payload, cls.FORMAT.size, "Telemetry")
        v = cls.FORMAT.unpack(payload)
        return cls(
            v[0],
            _enum(Mode, v[1], "mode"),
            _enum(Phase, v[2], "phase"),
            _enum(GraspState, v[3], "grasp_state"),
            TelemetryFlags(v[4]),
            v[5],
            v[6:10],
            v[10],
            v[11],
            v[12:15],
            v[15:18],
            v[18:21],
            v[21:24],
            v[24:27],
            v[27:30],
            v[30:33],
            v[33],
            v[34],
            v[35],
            v[36],
            v[37],
            v[38],
            v[39],
            v[40],
            v[41],
            v[42],
            v[43],
            v[44],
            _enum(ArmBlocker, v[45], "arm_blocker"),
        )


@_register
@dataclass(frozen=True, slots=True)
class RawRc(Message):
    """One DBUS frame exactly as the board received it (sent per received frame). 26 bytes.

    Attributes:
        time_us: board time the frame was framed.
        data: the 18 raw bytes (valid or not).
    """

    CMD_ID: ClassVar[int] = 0x0102
    DIRECTION: ClassVar[Direction] = Direction.BOARD_TO_HOST
    FORMAT: ClassVar[struct.Struct] = struct.Struct("<Q18s")

    time_us: int
    data: bytes

    @property
    def frame(self) -> RcFrame:
        """The decoded frame."""
        return RcFrame.unpack(self.data)

    def pack(self) -> bytes:
        """Encode the payload (see :meth:`Message.pack`)."""
        if len(self.data) != DBUS_FRAME_LEN:
            raise ValueError(f"RawRc.data must be {DBUS_FRAME_LEN} bytes, got {len(self.data)}")
        try:
            return self.FORMAT.pack(self.time_us, self.data)
        except struct.error as exc:
            raise _pack_error("RawRc", exc) from exc

    @classmethod
    def unpack(cls, payload: bytes) -> RawRc:
        """Decode the payload (see :meth:`Message.unpack`)."""
        _check_len(payload, cls.FORMAT.size, "RawRc")
        time_us, data = cls.FORMAT.unpack(payload)
        return cls(time_us, data)


@_register
@dataclass(frozen=True, slots=True)
class MotorFrames(Message):
    """The latest C610 feedback frame of each motor (at the telemetry rate). 38 bytes.

    Attributes:
        time_us: board time.
        frames: three ``(can_id, data)`` pairs, motor 1..3 in order; ``data`` is the 8 CAN data bytes
            as received (decode with ``MotorFeedback.unpack``). ``can_id`` 0 with zero data = no frame
            received from that motor yet.
    """

    CMD_ID: ClassVar[int] = 0x0103
    DIRECTION: ClassVar[Direction] = Direction.BOARD_TO_HOST
    FORMAT: ClassVar[struct.Struct] = struct.Struct("<QH8sH8sH8s")

    time_us: int
    frames: tuple[tuple[int, bytes], tuple[int, bytes], tuple[int, bytes]]

    def pack(self) -> bytes:
        """Encode the payload (see :meth:`Message.pack`)."""
        if len(self.frames) != 3:
            raise ValueError(f"MotorFrames needs 3 frames, got {len(self.frames)}")
        flat: list[int | bytes] = []
        for can_id, data in self.frames:
            if len(data) != 8:
                raise ValueError(f"CAN data must be 8 bytes, got {len(data)}")
            flat += (can_id, data)
        try:
            return self.FORMAT.pack(self.time_us, *flat)
        except struct.error as exc:
            raise _pack_error("MotorFrames", exc) from exc

    @classmethod
    def unpack(cls, payload: bytes) -> MotorFrames:
        """Decode the payload (see :meth:`Message.unpack`)."""
        _check_len(payload, cls.FORMAT.size, "MotorFrames")
        t, i1, d1, i2, d2, i3, d3 = cls.FORMAT.unpack(payload)
        return cls(t, ((i1, d1), (i2, d2), (i3, d3)))


@_register
@dataclass(frozen=True, slots=True)
class Event(Message):
    """Something happened on the board (mode change, failsafe, fault, ...). 18 + text bytes.

    Attributes:
        time_us: board time of the event.
        kind: ``EventKind``.
        code: kind-specific code (e.g. the new ``Mode`` / ``Phase`` / ``GraspState`` value, a motor
            number for a fault).
        value: kind-specific value (e.g. a parameter's new value).
        text: human-readable text, at most 64 UTF-8 bytes (``truncate_utf8`` to fit).
    """

    CMD_ID: ClassVar[int] = 0x0104
    DIRECTION: ClassVar[Direction] = Direction.BOARD_TO_HOST
    FORMAT: ClassVar[struct.Struct] = struct.Struct("<QBif")
    """Fixed part; then text length u8 and the text."""

    time_us: int
    kind: EventKind
    code: int = 0
    value: float = 0.0
    text: str = ""

    def pack(self) -> bytes:
        """Encode the payload (see :meth:`Message.pack`)."""
        text = _pack_text(self.text, EVENT_TEXT_MAX, "Event.text")
        try:
            return self.FORMAT.pack(self.time_us, self.kind, self.code, self.value) + text
        except (struct.error, OverflowError) as exc:
            raise _pack_error("Event", exc) from exc

    @classmethod
    def unpack(cls, payload: bytes) -> Event:
        """Decode the payload (see :meth:`Message.unpack`)."""
        size = cls.FORMAT.size
        if len(payload) < size + 1:
            raise DecodeError(f"Event payload is at least {size + 1} bytes, got {len(payload)}")
        t, kind, code, value = cls.FORMAT.unpack_from(payload)
        text = _unpack_text(payload, size, EVENT_TEXT_MAX, "Event.text")
        return cls(t, _enum(EventKind, kind, "kind"), code, value, text)


@_register
@dataclass(frozen=True, slots=True)
class ParamValue(Message):
    """One parameter's value (answer to ``ParamRequest`` / ``ParamSet``, or on change). 24 bytes.

    Attributes:
        index: the parameter's index, 0..count-1.
        count: how many parameters the board has.
        name: ASCII, at most 16 characters.
        value: current value.
    """

    CMD_ID: ClassVar[int] = 0x0105
    DIRECTION: ClassVar[Direction] = Direction.BOARD_TO_HOST
    FORMAT: ClassVar[struct.Struct] = struct.Struct("<HH16sf")

    index: int
    count: int
    name: str
    value: float

    def pack(self) -> bytes:
        """Encode the payload (see :meth:`Message.pack`)."""
        name = _pack_name(self.name, NAME_LEN, "ParamValue.name")
        try:
            return self.FORMAT.pack(self.index, self.count, name, self.value)
        except (struct.error, OverflowError) as exc:
            raise _pack_error("ParamValue", exc) from exc

    @classmethod
    def unpack(cls, payload: bytes) -> ParamValue:
        """Decode the payload (see :meth:`Message.unpack`)."""
        _check_len(payload, cls.FORMAT.size, "ParamValue")
        index, count, name, value = cls.FORMAT.unpack(payload)
        return cls(index, count, _unpack_name(name, "ParamValue.name"), value)


_SIM_HEAD = struct.Struct("<QB")


@_register
@dataclass(frozen=True, slots=True)
class SimPoses(Message):
    """World poses of the simulated bodies (simulation only, about 50 Hz). 9 + 28 n bytes.

    Body 0 is the drone, then the arm's units from base to tip; the tip is the last body.

    Attributes:
        time_us: simulation time.
        positions_m: n positions (x, y, z) in the world frame.
        quats_wxyz: n orientations as unit quaternions (w, x, y, z), MuJoCo's order.
    """

    CMD_ID: ClassVar[int] = 0x0106
    DIRECTION: ClassVar[Direction] = Direction.BOARD_TO_HOST

    time_us: int
    positions_m: tuple[Vec3f, ...]
    quats_wxyz: tuple[Vec4f, ...]

    @property
    def tip_position_m(self) -> Vec3f:
        """Position of the last body (the arm's tip unit).

        Raises:
            IndexError: no bodies.
        """
        return self.positions_m[-1]

    def pack(self) -> bytes:
        """Encode the payload (see :meth:`Message.pack`)."""
        n, flat = _flat_poses(self.positions_m, self.quats_wxyz, "bodies")
        try:
            return _SIM_HEAD.pack(self.time_us, n) + _POSES[n].pack(*flat)
        except (struct.error, OverflowError) as exc:
            raise _pack_error("SimPoses", exc) from exc

    @classmethod
    def unpack(cls, payload: bytes) -> SimPoses:
        """Decode the payload (see :meth:`Message.unpack`)."""
        if len(payload) < _SIM_HEAD.size:
            raise DecodeError(f"SimPoses payload is at least {_SIM_HEAD.size} bytes, got {len(payload)}")
        t, n = _SIM_HEAD.unpack_from(payload)
        if n > MAX_SIM_BODIES:
            raise DecodeError(f"SimPoses: {n} bodies, at most {MAX_SIM_BODIES}")
        _check_len(payload, _SIM_HEAD.size + _POSES[n].size, "SimPoses")
        return cls(t, *_unpack_poses(payload, _SIM_HEAD.size, n))


@dataclass(frozen=True, slots=True)
class TaskStats:
    """Scheduler statistics of one firmware task, as carried in ``BoardStatus``. 36 bytes.

    Attributes:
        name: task name, ASCII, at most 12 characters.
        period_us: declared period.
        runs: runs since boot.
        late: runs that started late.
        exec_max_us: longest execution.
        exec_p99_us: execution time, 99th percentile.
        lateness_max_us: latest start.
    """

    FORMAT: ClassVar[struct.Struct] = struct.Struct("<12s6I")

    name: str
    period_us: int
    runs: int = 0
    late: int = 0
    exec_max_us: int = 0
    exec_p99_us: int = 0
    lateness_max_us: int = 0

    def pack(self) -> bytes:
        """Encode the 36-byte entry.

        Raises:
            ValueError: a field does not fit (name > 12 ASCII characters, a value outside u32).
        """
        name = _pack_name(self.name, TASK_NAME_LEN, "TaskStats.name")
        try:
            return self.FORMAT.pack(
                name,
                self.period_us,
                self.runs,
                self.late,
                self.exec_max_us,
                self.exec_p99_us,
                self.lateness_max_us,
            )
        except struct.error as exc:
            raise _pack_error("TaskStats", exc) from exc

    @classmethod
    def unpack_from(cls, payload: bytes, offset: int) -> TaskStats:
        """Decode the entry at ``payload[offset:offset + 36]``.

        Raises:
            DecodeError: too short or a malformed name.
        """
        try:
            name, *values = cls.FORMAT.unpack_from(payload, offset)
        except struct.error as exc:
            raise DecodeError(f"TaskStats: {exc}") from exc
        return cls(_unpack_name(name, "TaskStats.name"), *values)


_STATUS_HEAD = struct.Struct("<Q16sBB")


@_register
@dataclass(frozen=True, slots=True)
class BoardStatus(Message):
    """Firmware identity and scheduler health (2 Hz). 26 + 36 n bytes.

    Attributes:
        time_us: board time.
        firmware_version: ASCII, at most 16 characters.
        clock_kind: ``ClockKind``.
        tasks: one ``TaskStats`` per task (at most ``MAX_TASKS``).
    """

    CMD_ID: ClassVar[int] = 0x0107
    DIRECTION: ClassVar[Direction] = Direction.BOARD_TO_HOST

    time_us: int
    firmware_version: str
    clock_kind: ClockKind
    tasks: tuple[TaskStats, ...] = ()

    def pack(self) -> bytes:
        """Encode the payload (see :meth:`Message.pack`)."""
        if len(self.tasks) > MAX_TASKS:
            raise ValueError(f"at most {MAX_TASKS} tasks, got {len(self.tasks)}")
        version = _pack_name(self.firmware_version, VERSION_LEN, "BoardStatus.firmware_version")
        try:
            head = _STATUS_HEAD.pack(self.time_us, version, self.clock_kind, len(self.tasks))
        except struct.error as exc:
            raise _pack_error("BoardStatus", exc) from exc
        return head + b"".join(t.pack() for t in self.tasks)

    @classmethod
    def unpack(cls, payload: bytes) -> BoardStatus:
        """Decode the payload (see :meth:`Message.unpack`)."""
        hs = _STATUS_HEAD.size
        if len(payload) < hs:
            raise DecodeError(f"BoardStatus payload is at least {hs} bytes, got {len(payload)}")
        t, version, clock_kind, n = _STATUS_HEAD.unpack_from(payload)
        if n > MAX_TASKS:
            raise DecodeError(f"BoardStatus: {n} tasks, at most {MAX_TASKS}")
        ts = TaskStats.FORMAT.size
        _check_len(payload, hs + n * ts, "BoardStatus")
        tasks = tuple(TaskStats.unpack_from(payload, hs + i * ts) for i in range(n))
        return cls(
            t,
            _unpack_name(version, "BoardStatus.firmware_version"),
            _enum(ClockKind, clock_kind, "clock_kind"),
            tasks,
        )


@_register
@dataclass(frozen=True, slots=True)
class CommandAck(Message):
    """The board's answer to a ``Command``. 4 + text bytes.

    Attributes:
        command: the code being answered: a ``CommandCode`` value, or the raw code of an unknown
            command (answered ``UNSUPPORTED``).
        result: ``AckResult``.
        request_seq: link ``seq`` of the ``Command`` frame being answered.
        text: why, at most 48 UTF-8 bytes.
    """

    CMD_ID: ClassVar[int] = 0x0108
    DIRECTION: ClassVar[Direction] = Direction.BOARD_TO_HOST
    FORMAT: ClassVar[struct.Struct] = struct.Struct("<BBB")
    """Fixed part; then text length u8 and the text."""

    command: int
    result: AckResult
    request_seq: int
    text: str = ""

    def pack(self) -> bytes:
        """Encode the payload (see :meth:`Message.pack`)."""
        text = _pack_text(self.text, ACK_TEXT_MAX, "CommandAck.text")
        try:
            return self.FORMAT.pack(self.command, self.result, self.request_seq) + text
        except struct.error as exc:
            raise _pack_error("CommandAck", exc) from exc

    @classmethod
    def unpack(cls, payload: bytes) -> CommandAck:
        """Decode the payload (see :meth:`Message.unpack`)."""
        size = cls.FORMAT.size
        if len(payload) < size + 1:
            raise DecodeError(f"CommandAck payload is at least {size + 1} bytes, got {len(payload)}")
        command, result, request_seq = cls.FORMAT.unpack_from(payload)
        text = _unpack_text(payload, size, ACK_TEXT_MAX, "CommandAck.text")
        if command in CommandCode._value2member_map_:
            command = CommandCode(command)
        return cls(command, _enum(AckResult, result, "result"), request_seq, text)
