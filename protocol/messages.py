"""The typed board-link message set: one frozen dataclass per ``cmd_id``.

Every message has ``CMD_ID``, ``DIRECTION``, ``pack() -> bytes`` (the payload) and
``unpack(payload)`` (raises :class:`~protocol.errors.DecodeError` on a wrong length or value); framing
is :mod:`protocol.link`. :func:`decode` turns a :class:`~protocol.link.LinkFrame` into its message and
:func:`encode` a message into a complete frame. All fields are little-endian and packed without padding;
the byte layouts are in ``docs/board-link.md`` (``tests/test_messages.py`` checks the two agree).

Values are raw where the wire is raw (rotor counts, C610 current units) and SI with the unit in the name
elsewhere (``tension_est_n``, ``cable_length_m``, ``time_us``). Ids 0x01xx go board -> host, 0x02xx host ->
board.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from enum import IntEnum, IntFlag, StrEnum
from typing import ClassVar, Self, TypeVar

from protocol.dbus import FRAME_LEN as DBUS_FRAME_LEN
from protocol.dbus import RcFrame
from protocol.errors import DecodeError, UnknownMessageError
from protocol.link import LinkFrame, encode_frame

__all__ = [
    "ACK_TEXT_MAX",
    "EVENT_TEXT_MAX",
    "HEARTBEAT_PERIOD_US",
    "HOST_TO_BOARD_MAX_PAYLOAD",
    "MAX_SIM_BODIES",
    "MAX_TASKS",
    "MESSAGES",
    "NAME_LEN",
    "PARAM_INDEX_BY_NAME",
    "PARAM_LIST_ALL",
    "TASK_NAME_LEN",
    "VERSION_LEN",
    "AckResult",
    "ArmBlocker",
    "BoardStatus",
    "ClockKind",
    "Command",
    "CommandAck",
    "CommandCode",
    "Direction",
    "Event",
    "EventKind",
    "GraspState",
    "Heartbeat",
    "Message",
    "Mode",
    "MotorFrames",
    "ParamRequest",
    "ParamSet",
    "ParamValue",
    "Phase",
    "RawRc",
    "SimPoses",
    "TaskStats",
    "Telemetry",
    "TelemetryFlags",
    "VirtualRc",
    "decode",
    "encode",
    "truncate_utf8",
]

Vec3i = tuple[int, int, int]
Vec4i = tuple[int, int, int, int]
Vec3f = tuple[float, float, float]
Vec4f = tuple[float, float, float, float]

NAME_LEN = 16
"""Parameter names: ASCII, at most 16 bytes, NUL-padded on the wire (like MAVLink param ids)."""
EVENT_TEXT_MAX = 64
"""UTF-8 bytes of an ``Event`` text."""
ACK_TEXT_MAX = 48
"""UTF-8 bytes of a ``CommandAck`` text."""
VERSION_LEN = 16
"""ASCII bytes of the firmware version in ``BoardStatus``."""
TASK_NAME_LEN = 12
"""ASCII bytes of a task name in ``BoardStatus``."""
MAX_TASKS = 32
"""Most task entries in one ``BoardStatus``."""
MAX_SIM_BODIES = 64
"""Most bodies in one ``SimPoses`` (drone + 63 units: 1801 bytes of payload)."""
HOST_TO_BOARD_MAX_PAYLOAD = 20
"""Largest host -> board payload (``ParamSet``). The board's parser uses it as ``max_payload``: then a
corrupted length field stalls the board's input by at most 29 bytes instead of a whole ``MAX_PAYLOAD``."""
PARAM_INDEX_BY_NAME = -1
"""``ParamRequest.index``: look the parameter up by ``name``."""
PARAM_LIST_ALL = -2
"""``ParamRequest.index``: send every parameter (one ``ParamValue`` each)."""

_U16_MAX = 0xFFFF


# --- wire enums -----------------------------------------------------------------------------------


class Mode(IntEnum):
    """Operating mode (right lever: DOWN = SAFE, MIDDLE = MANUAL, UP = GRASP)."""

    SAFE = 0
    """Zero current."""
    MANUAL = 1
    """Stick teleop."""
    GRASP = 2
    """Grasp strategy."""
    DIRECT = 3
    """Host sets the per-cable tensions."""


class Phase(IntEnum):
    """Failsafe phase."""

    GATE = 0
    """Start-up gate: waiting for valid RC and the right lever DOWN."""
    OK = 1
    RC_LOST = 2
    MOTOR_FAULT = 3
    """Latched until re-armed through SAFE."""
    HOST_LOST = 4
    ESTOP = 5
    """Latched until cleared and re-armed through SAFE."""


class ArmBlocker(IntEnum):
    """``Telemetry.arm_blocker``: what holds the arming gate shut (``NONE`` while armed)."""

    NONE = 0
    RC_INVALID = 1
    """No valid RC frame within the RC timeout."""
    LEVER_NOT_DOWN = 2
    """The right lever has not been seen DOWN (SAFE) since the gate closed."""
    ESTOP_LATCHED = 3
    """An E-stop is latched until CLEAR_ESTOP."""
    MOTOR_FAULT = 4
    """A motor is silent."""
    HOST_MISSING = 5
    """The host heartbeat is required and missing."""
    DISARMED = 6
    """The host sent DISARM (until ARM)."""


class GraspState(IntEnum):
    """State of the grasp state machine."""

    IDLE = 0
    REACH = 1
    WRAP = 2
    HOLD = 3
    RELEASE = 4
    FAILED = 5


class TelemetryFlags(IntFlag):
    """Bits of ``Telemetry.flags``."""

    NONE = 0
    ARMED = 1 << 0
    """Current may flow (start-up gate passed, no latched fault)."""
    HOST_REQUIRED = 1 << 1
    """The board drops to zero current when the host heartbeat stops."""
    HOST_OK = 1 << 2
    """Host heartbeat fresh."""
    RC_OK = 1 << 3
    """A valid RC frame within the RC-lost timeout."""
    SIM = 1 << 4
    """Running against the simulated plant."""


class CommandCode(IntEnum):
    """``Command.code`` (0 is never sent, so an all-zero payload is rejected)."""

    ARM = 1
    DISARM = 2
    ESTOP = 3
    CLEAR_ESTOP = 4
    GRASP = 5
    RELEASE = 6
    HOLD = 7
    SET_MODE = 8
    """args[0] = ``Mode`` value."""
    SET_TENSIONS = 9
    """args = per-cable tension targets in N (DIRECT mode)."""
    REQUIRE_HOST = 10
    """args[0] = 1.0 to require the host heartbeat, 0.0 to stop requiring it."""


class EventKind(IntEnum):
    """``Event.kind``."""

    BOOT = 0
    MODE = 1
    PHASE = 2
    FAULT = 3
    GRASP = 4
    PARAM = 5
    INFO = 6


class AckResult(IntEnum):
    """``CommandAck.result``; the values equal MAVLink's ``MAV_RESULT`` so bridges map them 1:1."""

    ACCEPTED = 0
    REJECTED = 1
    """Temporarily rejected (busy / wrong state): ``MAV_RESULT_TEMPORARILY_REJECTED``."""
    DENIED = 2
    """Bad arguments."""
    UNSUPPORTED = 3
    FAILED = 4
    IN_PROGRESS = 5


class ClockKind(IntEnum):
    """``BoardStatus.clock_kind``: how the firmware's loop is timed."""

    REALTIME_FIFO = 0
    """Real-time clock with SCHED_FIFO priority."""
    REALTIME_NORMAL = 1
    """Real-time clock without real-time priority (expect late ticks)."""
    LOCKSTEP = 2
    """Advanced by the simulation."""


class Direction(StrEnum):
    """Which way a message travels."""

    BOARD_TO_HOST = "board->host"
    HOST_TO_BOARD = "host->board"


# --- helpers --------------------------------------------------------------------------------------

_E = TypeVar("_E", bound=IntEnum)


def _enum(enum_cls: type[_E], value: int, field: str) -> _E:
    # The value-to-member map directly: a dict lookup instead of EnumType.__call__, about ten times
    # cheaper (every Telemetry frame decodes three of these). Our enums are plain IntEnums, no flags.
    member = enum_cls._value2member_map_.get(value)
    if member is None:
        raise DecodeError(f"{field}: {value} is not a {enum_cls.__name__}")
    return member  # type: ignore[return-value]  # the map holds enum_cls's members


def _check_len(payload: bytes, size: int, name: str) -> None:
    if len(payload) != size:
        raise DecodeError(f"{name} payload is {size} bytes, got {len(payload)}")


def _pack_error(name: str, exc: Exception) -> ValueError:
    return ValueError(f"cannot pack {name}: {exc}")


def truncate_utf8(text: str, max_bytes: int) -> str:
    """Longest prefix of ``text`` whose UTF-8 encoding fits in ``max_bytes`` (never splits a character)."""
    raw = text.encode("utf-8")
    if len(raw) <= max_bytes:
        return text
    return raw[:max_bytes].decode("utf-8", errors="ignore")


def _pack_text(text: str, max_bytes: int, field: str) -> bytes:
    raw = text.encode("utf-8")
    if len(raw) > max_bytes:
        raise ValueError(f"{field} is {len(raw)} UTF-8 bytes, at most {max_bytes} (see truncate_utf8)")
    return bytes((len(raw),)) + raw


def _unpack_text(payload: bytes, at: int, max_bytes: int, field: str) -> str:
    """Decode the length-prefixed text at ``payload[at]``, which must end the payload exactly."""
    n = payload[at]
    if n > max_bytes:
        raise DecodeError(f"{field} length {n} exceeds {max_bytes}")
    if len(payload) != at + 1 + n:
        raise DecodeError(f"{field}: payload is {len(payload)} bytes, text length says {at + 1 + n}")
    try:
        return payload[at + 1 :].decode("utf-8")
    except UnicodeDecodeError as exc:
        raise DecodeError(f"{field} is not UTF-8") from exc


def _pack_name(name: str, size: int, field: str) -> bytes:
    """ASCII, no NUL, at most ``size`` bytes; ``struct``'s ``s`` format NUL-pads it."""
    try:
        raw = name.encode("ascii")
    except UnicodeEncodeError:
        raise ValueError(f"{field} {name!r} is not ASCII") from None
    if len(raw) > size or b"\0" in raw:
        raise ValueError(f"{field} {name!r}: at most {size} ASCII characters, no NUL")
    return raw


def _unpack_name(raw: bytes, field: str) -> str:
    """Inverse of :func:`_pack_name`; only the canonical form (NULs only after the name) decodes."""
    name, _, pad = raw.partition(b"\0")
    if pad.strip(b"\0"):
        raise DecodeError(f"{field}: bytes after the terminating NUL")
    try:
        return name.decode("ascii")
    except UnicodeDecodeError:
        raise DecodeError(f"{field} is not ASCII") from None


# --- base and registry ----------------------------------------------------------------------------


class Message:
    """Base of every board-link message (frozen dataclasses below)."""

    __slots__ = ()

    CMD_ID: ClassVar[int]
    DIRECTION: ClassVar[Direction]

    def pack(self) -> bytes:
        """Encode the payload.

        Raises:
            ValueError: a field cannot be represented on the wire.
        """
        raise NotImplementedError

    @classmethod
    def unpack(cls, payload: bytes) -> Self:
        """Decode a payload.

        Raises:
            DecodeError: wrong length or a value outside its wire range.
        """
        raise NotImplementedError


MESSAGES: dict[int, type[Message]] = {}
"""Registry ``cmd_id -> message class``."""

_M = TypeVar("_M", bound=type[Message])


def _register(cls: _M) -> _M:
    if cls.CMD_ID in MESSAGES:
        raise RuntimeError(f"duplicate cmd_id {cls.CMD_ID:#06x}")
    MESSAGES[cls.CMD_ID] = cls
    return cls


def decode(frame: LinkFrame) -> Message:
    """Decode a verified link frame into its typed message.

    Raises:
        UnknownMessageError: no message has this ``cmd_id``.
        DecodeError: the payload does not decode.
    """
    cls = MESSAGES.get(frame.cmd_id)
    if cls is None:
        raise UnknownMessageError(f"unknown cmd_id {frame.cmd_id:#06x}")
    return cls.unpack(frame.payload)


def encode(msg: Message, seq: int) -> bytes:
    """A complete link frame carrying ``msg`` with sequence number ``seq`` (0..255).

    Raises:
        ValueError: the message cannot be packed or ``seq`` is out of range.
    """
    return encode_frame(msg.CMD_ID, msg.pack(), seq)


# --- board -> host --------------------------------------------------------------------------------


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
_POSE_FLOATS = 7
_POSES = tuple(struct.Struct(f"<{_POSE_FLOATS * n}f") for n in range(MAX_SIM_BODIES + 1))


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
        n = len(self.positions_m)
        if n != len(self.quats_wxyz):
            raise ValueError(f"{n} positions but {len(self.quats_wxyz)} quaternions")
        if n > MAX_SIM_BODIES:
            raise ValueError(f"at most {MAX_SIM_BODIES} bodies, got {n}")
        flat: list[float] = []
        for p, q in zip(self.positions_m, self.quats_wxyz, strict=True):
            if len(p) != 3 or len(q) != 4:
                raise ValueError("positions are (x, y, z), quaternions (w, x, y, z)")
            flat += p
            flat += q
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
        v = _POSES[n].unpack_from(payload, _SIM_HEAD.size)
        positions = tuple(v[i : i + 3] for i in range(0, len(v), _POSE_FLOATS))
        quats = tuple(v[i + 3 : i + 7] for i in range(0, len(v), _POSE_FLOATS))
        return cls(t, positions, quats)


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


# --- host -> board --------------------------------------------------------------------------------


HEARTBEAT_PERIOD_US = 100_000
"""The host's ``Heartbeat`` period (10 Hz; the board's default host timeout is five of them)."""


@_register
@dataclass(frozen=True, slots=True)
class Heartbeat(Message):
    """Host liveness (10 Hz); when the host is required the board zeroes current without it. 12 bytes.

    Attributes:
        host_time_us: host clock (for latency estimates; the board does not sync to it).
        counter: increments by one per heartbeat (wraps at 2**32).
    """

    CMD_ID: ClassVar[int] = 0x0201
    DIRECTION: ClassVar[Direction] = Direction.HOST_TO_BOARD
    FORMAT: ClassVar[struct.Struct] = struct.Struct("<QI")

    host_time_us: int
    counter: int

    def pack(self) -> bytes:
        """Encode the payload (see :meth:`Message.pack`)."""
        try:
            return self.FORMAT.pack(self.host_time_us, self.counter)
        except struct.error as exc:
            raise _pack_error("Heartbeat", exc) from exc

    @classmethod
    def unpack(cls, payload: bytes) -> Heartbeat:
        """Decode the payload (see :meth:`Message.unpack`)."""
        _check_len(payload, cls.FORMAT.size, "Heartbeat")
        return cls(*cls.FORMAT.unpack(payload))


@_register
@dataclass(frozen=True, slots=True)
class VirtualRc(Message):
    """A DBUS frame from the host's virtual sticks; the board runs it through its RC parser. 18 bytes.

    Attributes:
        data: the 18 raw DBUS bytes.
    """

    CMD_ID: ClassVar[int] = 0x0202
    DIRECTION: ClassVar[Direction] = Direction.HOST_TO_BOARD

    data: bytes

    @classmethod
    def from_frame(cls, frame: RcFrame) -> VirtualRc:
        """Wrap a frame (``frame.pack()``; raises ``ValueError`` if it does not pack)."""
        return cls(frame.pack())

    @property
    def frame(self) -> RcFrame:
        """The decoded frame."""
        return RcFrame.unpack(self.data)

    def pack(self) -> bytes:
        """Encode the payload (see :meth:`Message.pack`)."""
        if len(self.data) != DBUS_FRAME_LEN:
            raise ValueError(f"VirtualRc.data must be {DBUS_FRAME_LEN} bytes, got {len(self.data)}")
        return bytes(self.data)

    @classmethod
    def unpack(cls, payload: bytes) -> VirtualRc:
        """Decode the payload (see :meth:`Message.unpack`)."""
        _check_len(payload, DBUS_FRAME_LEN, "VirtualRc")
        return cls(bytes(payload))


@_register
@dataclass(frozen=True, slots=True)
class Command(Message):
    """A command to the board, answered by ``CommandAck``. 13 bytes.

    Attributes:
        code: ``CommandCode``.
        args: three arguments, meaning per code (see ``CommandCode``); unused ones 0.
    """

    CMD_ID: ClassVar[int] = 0x0203
    DIRECTION: ClassVar[Direction] = Direction.HOST_TO_BOARD
    FORMAT: ClassVar[struct.Struct] = struct.Struct("<B3f")

    code: CommandCode
    args: Vec3f = (0.0, 0.0, 0.0)

    def pack(self) -> bytes:
        """Encode the payload (see :meth:`Message.pack`)."""
        try:
            return self.FORMAT.pack(self.code, *self.args)
        except (struct.error, OverflowError) as exc:
            raise _pack_error("Command", exc) from exc

    @classmethod
    def unpack(cls, payload: bytes) -> Command:
        """Decode the payload (see :meth:`Message.unpack`)."""
        _check_len(payload, cls.FORMAT.size, "Command")
        code, *args = cls.FORMAT.unpack(payload)
        return cls(_enum(CommandCode, code, "code"), (args[0], args[1], args[2]))


@_register
@dataclass(frozen=True, slots=True)
class ParamRequest(Message):
    """Ask for parameter values (answered with ``ParamValue``). 18 bytes.

    Attributes:
        index: >= 0 by index; ``PARAM_INDEX_BY_NAME`` (-1) by ``name``; ``PARAM_LIST_ALL`` (-2) all.
        name: ASCII, at most 16 characters (used with index -1).
    """

    CMD_ID: ClassVar[int] = 0x0204
    DIRECTION: ClassVar[Direction] = Direction.HOST_TO_BOARD
    FORMAT: ClassVar[struct.Struct] = struct.Struct("<h16s")

    index: int = PARAM_LIST_ALL
    name: str = ""

    def pack(self) -> bytes:
        """Encode the payload (see :meth:`Message.pack`)."""
        if self.index < PARAM_LIST_ALL:
            raise ValueError(f"ParamRequest.index must be >= {PARAM_LIST_ALL}, got {self.index}")
        name = _pack_name(self.name, NAME_LEN, "ParamRequest.name")
        try:
            return self.FORMAT.pack(self.index, name)
        except struct.error as exc:
            raise _pack_error("ParamRequest", exc) from exc

    @classmethod
    def unpack(cls, payload: bytes) -> ParamRequest:
        """Decode the payload (see :meth:`Message.unpack`)."""
        _check_len(payload, cls.FORMAT.size, "ParamRequest")
        index, name = cls.FORMAT.unpack(payload)
        if index < PARAM_LIST_ALL:
            raise DecodeError(f"ParamRequest.index {index} < {PARAM_LIST_ALL}")
        return cls(index, _unpack_name(name, "ParamRequest.name"))


@_register
@dataclass(frozen=True, slots=True)
class ParamSet(Message):
    """Set a parameter (answered with ``ParamValue`` carrying the value now in force). 20 bytes.

    Attributes:
        name: ASCII, at most 16 characters.
        value: requested value.
    """

    CMD_ID: ClassVar[int] = 0x0205
    DIRECTION: ClassVar[Direction] = Direction.HOST_TO_BOARD
    FORMAT: ClassVar[struct.Struct] = struct.Struct("<16sf")

    name: str
    value: float

    def pack(self) -> bytes:
        """Encode the payload (see :meth:`Message.pack`)."""
        name = _pack_name(self.name, NAME_LEN, "ParamSet.name")
        try:
            return self.FORMAT.pack(name, self.value)
        except (struct.error, OverflowError) as exc:
            raise _pack_error("ParamSet", exc) from exc

    @classmethod
    def unpack(cls, payload: bytes) -> ParamSet:
        """Decode the payload (see :meth:`Message.unpack`)."""
        _check_len(payload, cls.FORMAT.size, "ParamSet")
        name, value = cls.FORMAT.unpack(payload)
        return cls(_unpack_name(name, "ParamSet.name"), value)
