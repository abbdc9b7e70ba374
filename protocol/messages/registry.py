"""The base of every board-link message, the ``cmd_id`` registry and :func:`decode` / :func:`encode`.

The message modules fill :data:`MESSAGES` with ``@_register`` as they are imported; importing
``protocol.messages`` imports them all.
"""

from __future__ import annotations

from typing import ClassVar, Self, TypeVar

from protocol.errors import UnknownMessageError
from protocol.link import LinkFrame, encode_frame
from protocol.messages.enums import Direction


class Message:
    """Base of every board-link message (the frozen dataclasses of ``board`` and ``host``)."""

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
