"""The typed board-link message set: one frozen dataclass per ``cmd_id``.

Every message has ``CMD_ID``, ``DIRECTION``, ``pack() -> bytes`` (the payload) and
``unpack(payload)`` (raises :class:`~protocol.errors.DecodeError` on a wrong length or value); framing
is :mod:`protocol.link`. :func:`decode` turns a :class:`~protocol.link.LinkFrame` into its message and
:func:`encode` a message into a complete frame. All fields are little-endian and packed without padding;
the byte layouts are in ``docs/board-link.md`` (``tests/test_messages.py`` checks the two agree).

Values are raw where the wire is raw (rotor counts, C610 current units) and SI with the unit in the name
elsewhere (``tension_est_n``, ``cable_length_m``, ``time_us``). Ids 0x01xx go board -> host, 0x02xx host ->
board.

Callers import everything from here; the modules are ``enums`` (the wire enums and flags,
``Direction``), ``fields`` (field sizes and limits, the shared field codecs, ``truncate_utf8``),
``registry`` (the ``Message`` base, the ``MESSAGES`` registry, ``decode`` and ``encode``), ``board``
(board -> host messages), ``arrays`` (the board -> host messages of an array of arms) and ``host``
(host -> board messages). Importing this package imports every message module, so ``MESSAGES`` is
complete before any ``decode``.
"""

from __future__ import annotations

from protocol.messages.arrays import ARMS_MOTORS_MAX, ArmPoses, ArmsTelemetry
from protocol.messages.board import (
    BoardStatus,
    CommandAck,
    Event,
    MotorFrames,
    ParamValue,
    RawRc,
    SimPoses,
    TaskStats,
    Telemetry,
)
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
    ACK_TEXT_MAX,
    EVENT_TEXT_MAX,
    HOST_TO_BOARD_MAX_PAYLOAD,
    MAX_SIM_BODIES,
    MAX_TASKS,
    NAME_LEN,
    PARAM_INDEX_BY_NAME,
    PARAM_LIST_ALL,
    TASK_NAME_LEN,
    VERSION_LEN,
    Vec3f,
    Vec3i,
    Vec4f,
    Vec4i,
    truncate_utf8,
)
from protocol.messages.host import (
    HEARTBEAT_PERIOD_US,
    HOLD_HERE,
    HOLD_RELEASE,
    HOLD_UNCHANGED,
    HOST_TO_BOARD_LENGTHS,
    Command,
    Heartbeat,
    ParamRequest,
    ParamSet,
    VirtualRc,
)
from protocol.messages.registry import MESSAGES, Message, decode, encode

__all__ = [
    "ACK_TEXT_MAX",
    "ARMS_MOTORS_MAX",
    "EVENT_TEXT_MAX",
    "HEARTBEAT_PERIOD_US",
    "HOLD_HERE",
    "HOLD_RELEASE",
    "HOLD_UNCHANGED",
    "HOST_TO_BOARD_LENGTHS",
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
    "ArmPoses",
    "ArmsTelemetry",
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
    "Vec3f",
    "Vec3i",
    "Vec4f",
    "Vec4i",
    "VirtualRc",
    "decode",
    "encode",
    "truncate_utf8",
]
