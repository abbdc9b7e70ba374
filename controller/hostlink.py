"""The board's end of the host link: a :class:`Transport`, a ``LinkParser`` and a sequence counter."""

from __future__ import annotations

from controller.transport import Transport
from protocol.link import LinkFrame, LinkParser
from protocol.messages import Message, encode

__all__ = ["BoardLink"]


class BoardLink:
    """Frames in, messages out, over one transport; never blocks and never raises on bad bytes.

    Attributes:
        transport: the byte pipe (owned by the caller).
        parser: the incremental frame parser (its counters are the link's receive health).
        frames_sent: frames handed to the transport.
        decode_errors: intact frames whose payload did not decode (or had an unknown id).
    """

    def __init__(self, transport: Transport) -> None:
        """Wrap ``transport``."""
        self.transport = transport
        self.parser = LinkParser()
        self.frames_sent = 0
        self.decode_errors = 0
        self._seq = 0

    @property
    def crc_errors(self) -> int:
        """Header and body CRC errors seen by the parser."""
        return self.parser.header_crc_errors + self.parser.body_crc_errors

    def receive(self) -> list[LinkFrame]:
        """Verified frames received since the last call."""
        data = self.transport.read()
        if not data:
            return []
        return self.parser.feed(data)

    def send(self, msg: Message) -> bool:
        """Encode ``msg`` with the next sequence number and queue it; False if the transport dropped it."""
        frame = encode(msg, self._seq)
        self._seq = (self._seq + 1) & 0xFF
        self.frames_sent += 1
        return self.transport.write(frame)
