"""The board's end of the host link: a :class:`Transport`, a ``MessageStream`` and a sequence counter."""

from __future__ import annotations

from collections.abc import Sequence

from controller.transport import Transport
from protocol.link import LinkParser
from protocol.messages import Message, encode
from protocol.stream import MessageStream, Received, UndecodableHook

__all__ = ["BoardLink"]

_NOTHING: tuple[Received, ...] = ()


class BoardLink:
    """Messages in and out over one transport; never blocks and never raises on bad bytes.

    Args:
        transport: the byte pipe (owned by the caller).
        undecodable: told every intact frame whose payload did not decode (the board answers an unknown
            command code with an UNSUPPORTED ack).

    Attributes:
        transport: the byte pipe.
        stream: the decoder (its counters are the link's receive health).
        frames_sent: frames handed to the transport.
        misdirected: board -> host messages a host sent to the board (decoded, never acted on).
    """

    def __init__(self, transport: Transport, undecodable: UndecodableHook | None = None) -> None:
        """Wrap ``transport``."""
        self.transport = transport
        self.stream = MessageStream(undecodable=undecodable)
        self.frames_sent = 0
        self.misdirected = 0
        self._seq = 0

    @property
    def parser(self) -> LinkParser:
        """The incremental frame parser (frames received, bytes skipped)."""
        return self.stream.parser

    @property
    def crc_errors(self) -> int:
        """Header and body CRC errors."""
        return self.stream.crc_errors

    @property
    def decode_errors(self) -> int:
        """Intact frames that did not decode or had an unknown id, and misdirected messages."""
        return self.stream.decode_errors + self.misdirected

    def receive(self) -> Sequence[Received]:
        """``(seq, message)`` of every message received since the last call."""
        data = self.transport.read()
        if not data:
            return _NOTHING  # the idle tick (most of them) allocates nothing
        return self.stream.feed(data)

    def send(self, msg: Message) -> bool:
        """Encode ``msg`` with the next sequence number and queue it; False if the transport dropped it."""
        frame = encode(msg, self._seq)
        self._seq = (self._seq + 1) & 0xFF
        self.frames_sent += 1
        return self.transport.write(frame)
