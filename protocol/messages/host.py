"""The host -> board messages (ids 0x02xx) and the host's heartbeat period."""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass
from typing import ClassVar

from protocol.dbus import FRAME_LEN as DBUS_FRAME_LEN
from protocol.dbus import RcFrame
from protocol.errors import DecodeError
from protocol.messages.enums import CommandCode, Direction
from protocol.messages.fields import (
    NAME_LEN,
    PARAM_LIST_ALL,
    Vec3f,
    _check_len,
    _enum,
    _pack_error,
    _pack_name,
    _unpack_name,
)
from protocol.messages.registry import Message, _register

HEARTBEAT_PERIOD_US = 100_000
"""The host's ``Heartbeat`` period (10 Hz; the board's default host timeout is five of them)."""

HOLD_UNCHANGED = math.nan
"""``HOLD_LENGTHS`` argument: leave this cable as it is."""
HOLD_HERE = math.inf
"""``HOLD_LENGTHS`` argument: hold this cable at its present length (a held cable keeps its set-point)."""
HOLD_RELEASE = -math.inf
"""``HOLD_LENGTHS`` argument: release this cable (its current comes from the tension mapping again)."""


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


HOST_TO_BOARD_LENGTHS: dict[int, int] = {
    Heartbeat.CMD_ID: Heartbeat.FORMAT.size,
    VirtualRc.CMD_ID: DBUS_FRAME_LEN,
    Command.CMD_ID: Command.FORMAT.size,
    ParamRequest.CMD_ID: ParamRequest.FORMAT.size,
    ParamSet.CMD_ID: ParamSet.FORMAT.size,
}
"""``cmd_id -> payload length`` of every host -> board message (all fixed-length): the board's parser
refuses any other id, and any longer announced length, as soon as it has read the id, so no header holds
its input longer than one real frame."""
