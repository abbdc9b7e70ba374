"""Board-link bytes in, typed messages out: a stream that never raises and counts what it rejects.

:class:`MessageStream` is :class:`~protocol.link.LinkParser` (framing, CRCs, resynchronisation) and
:func:`~protocol.messages.decode` (payloads) joined, with the decode failure turned into a counter as
the parser does for bad frames. Every endpoint of the board link reads through one of these, so none
keeps its own decode/try/count loop.

Example:
    >>> from protocol.messages import Heartbeat, encode
    >>> stream = MessageStream()
    >>> stream.feed(b"noise" + encode(Heartbeat(5, 1), seq=7))
    [Received(seq=7, msg=Heartbeat(host_time_us=5, counter=1))]
    >>> stream.bytes_skipped
    5
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import NamedTuple

from protocol.errors import DecodeError
from protocol.link import MAX_PAYLOAD, LinkFrame, LinkParser
from protocol.messages import MESSAGES, Message

__all__ = ["MessageStream", "Received", "UndecodableHook"]

UndecodableHook = Callable[[LinkFrame], None]
"""Called with each intact frame whose payload did not decode (e.g. to answer an unknown command)."""


class Received(NamedTuple):
    """One decoded message and the link ``seq`` of the frame that carried it.

    Attributes:
        seq: the sender's sequence number, 0..255 (a ``CommandAck`` refers to it).
        msg: the decoded message.
    """

    seq: int
    msg: Message


class MessageStream:
    """Incremental decoder of board-link bytes; never raises on any input.

    Feed chunks of any size; each complete, intact frame comes back decoded, in order. Bad bytes are
    skipped and counted by the parser; an intact frame with an unknown ``cmd_id`` or a payload that does
    not decode is counted in ``decode_errors`` (unknown ids also in ``unknown_ids``) and handed to the
    ``undecodable`` hook, if any.

    Counters (monotonic): ``frames_ok`` (intact frames, decoded or not), ``crc_errors`` (header and
    body), ``oversize_errors``, ``id_errors`` (ids refused by ``lengths`` before their payload),
    ``bytes_skipped``, ``decode_errors``, ``unknown_ids``.

    Args:
        max_payload: longest payload accepted (see :class:`~protocol.link.LinkParser`).
        undecodable: called with each intact frame that did not decode.
        lengths: the only ids accepted, each with its longest payload (the board passes
            ``HOST_TO_BOARD_LENGTHS``; see :class:`~protocol.link.LinkParser`).
    """

    __slots__ = ("decode_errors", "parser", "undecodable", "unknown_ids")

    def __init__(
        self,
        max_payload: int = MAX_PAYLOAD,
        *,
        undecodable: UndecodableHook | None = None,
        lengths: Mapping[int, int] | None = None,
    ) -> None:
        self.parser = LinkParser(max_payload, lengths)
        self.undecodable = undecodable
        self.decode_errors = 0
        self.unknown_ids = 0

    @property
    def frames_ok(self) -> int:
        """Intact frames (both CRCs good), whether their payload decoded or not."""
        return self.parser.frames_ok

    @property
    def crc_errors(self) -> int:
        """Frames rejected by their header CRC8 or body CRC16."""
        return self.parser.header_crc_errors + self.parser.body_crc_errors

    @property
    def oversize_errors(self) -> int:
        """Headers declaring a payload longer than ``max_payload``."""
        return self.parser.oversize_errors

    @property
    def id_errors(self) -> int:
        """Headers whose id the ``lengths`` table does not accept (refused before their payload)."""
        return self.parser.id_errors

    @property
    def bytes_skipped(self) -> int:
        """Bytes discarded while hunting for a frame."""
        return self.parser.bytes_skipped

    @property
    def pending(self) -> int:
        """Bytes buffered waiting for the rest of a frame."""
        return self.parser.pending

    def counters(self) -> dict[str, int]:
        """Every counter by name: the parser's (CRC errors split by header and body) and the decoder's."""
        out = self.parser.counters()
        out["decode_errors"] = self.decode_errors
        out["unknown_ids"] = self.unknown_ids
        return out

    def reset(self) -> None:
        """Drop buffered bytes without counting them (e.g. after a reconnect)."""
        self.parser.reset()

    def feed(self, data: bytes | bytearray | memoryview) -> list[Received]:
        """Add received bytes; return every message they complete, in order."""
        frames = self.parser.feed(data)
        if not frames:
            return []
        out: list[Received] = []
        registry = MESSAGES
        for frame in frames:
            cls = registry.get(frame.cmd_id)
            if cls is None:
                # Looked up rather than left to decode(): raising costs more than the whole decode.
                self.unknown_ids += 1
                self._undecodable(frame)
                continue
            try:
                msg = cls.unpack(frame.payload)
            except DecodeError:
                self._undecodable(frame)
                continue
            out.append(Received(frame.seq, msg))
        return out

    def _undecodable(self, frame: LinkFrame) -> None:
        self.decode_errors += 1
        hook = self.undecodable
        if hook is not None:
            hook(frame)
