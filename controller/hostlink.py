"""The board's end of the host link: a :class:`Transport`, a ``MessageStream`` and a sequence counter.

The board parses with ``HOST_TO_BOARD_LENGTHS``: every id other than the five host -> board messages,
and every length above that id's own, is refused as soon as the id is read, so no header holds the
input longer than one real frame (29 bytes at most). Link work per ``link_rx`` tick has a budget: at
most :data:`RX_BYTES_PER_TICK` bytes are parsed and :data:`RX_FRAMES_PER_TICK` frames handled; the
excess is dropped and counted (``rx_bytes_dropped``, ``rx_frames_dropped``), never carried over, so a
flood costs the control task one bounded slice of every tick and never delays it. The radio and the host's
liveness are not queued behind a flood of other frames: a ``VirtualRc`` or ``Heartbeat`` parsed within the
byte budget is kept even past the frame budget (at most :data:`RX_PRIORITY_PER_TICK` of them, each cheap).
"""

from __future__ import annotations

from collections.abc import Sequence

from controller.transport import Transport
from protocol.link import LinkFrame, LinkParser
from protocol.messages import HOST_TO_BOARD_LENGTHS, Heartbeat, Message, VirtualRc, encode
from protocol.stream import MessageStream, Received, UndecodableHook

__all__ = ["RX_BYTES_PER_TICK", "RX_FRAMES_PER_TICK", "RX_PRIORITY_PER_TICK", "BoardLink"]

RX_BYTES_PER_TICK = 512
"""Link bytes parsed per ``link_rx`` tick (512 kB/s at 1 kHz). A host sends about 3 kB/s (a 27-byte
``VirtualRc`` every 14 ms, a 21-byte ``Heartbeat`` every 100 ms, commands on demand); USB full speed
carries about 1 MB/s, so only a flood reaches the budget."""
RX_FRAMES_PER_TICK = 8
"""Frames handled per ``link_rx`` tick, decoded or not (8000 frames/s; a host sends about 80)."""

RX_PRIORITY_PER_TICK = 2
"""``VirtualRc`` and ``Heartbeat`` frames kept past the frame budget per tick. A host sends one of each per
14 ms and 100 ms, so two per 1 ms tick is already a flood of them; more are dropped like any other frame."""
_PRIORITY = (VirtualRc, Heartbeat)

_NOTHING: tuple[Received, ...] = ()


class BoardLink:
    """Messages in and out over one transport; never blocks and never raises on bad bytes.

    Args:
        transport: the byte pipe (owned by the caller).
        undecodable: told every intact frame whose payload did not decode, within the tick's frame
            budget (the board answers an unknown command code with an UNSUPPORTED ack).
        rx_bytes_per_tick: bytes parsed per :meth:`receive`; the rest of what was read is dropped.
        rx_frames_per_tick: frames handled per :meth:`receive`; later ones are dropped.

    Attributes:
        transport: the byte pipe.
        stream: the decoder (its counters are the link's receive health).
        undecodable: the hook above.
        frames_sent: frames handed to the transport.
        rx_bytes_dropped: bytes read but not parsed (over the byte budget).
        rx_frames_dropped: intact frames not handled (over the frame budget).
        rx_over_budget: :meth:`receive` calls that dropped anything.
        link_changes: host connections made or lost as the transport saw them (``peer_changes``); at
            each the partial frame of the old host is dropped, and the command server resets what a
            host set (DIRECT tensions, length-holds).
    """

    def __init__(
        self,
        transport: Transport,
        undecodable: UndecodableHook | None = None,
        *,
        rx_bytes_per_tick: int = RX_BYTES_PER_TICK,
        rx_frames_per_tick: int = RX_FRAMES_PER_TICK,
    ) -> None:
        """Wrap ``transport``.

        Raises:
            ValueError: a budget below one.
        """
        if rx_bytes_per_tick < 1 or rx_frames_per_tick < 1:
            raise ValueError(f"link budgets must be >= 1: {rx_bytes_per_tick} B, {rx_frames_per_tick} frames")
        self.transport = transport
        self.undecodable = undecodable
        self.stream = MessageStream(undecodable=self._undecodable, lengths=HOST_TO_BOARD_LENGTHS)
        self.rx_bytes_per_tick = rx_bytes_per_tick
        self.rx_frames_per_tick = rx_frames_per_tick
        self.frames_sent = 0
        self.rx_bytes_dropped = 0
        self.rx_frames_dropped = 0
        self.rx_over_budget = 0
        self.link_changes = 0
        self._peer_changes = transport.peer_changes
        self._frames_left = rx_frames_per_tick
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
        """Intact frames that did not decode."""
        return self.stream.decode_errors

    def receive(self) -> Sequence[Received]:
        """``(seq, message)`` of the messages received since the last call, within the tick's budget."""
        transport = self.transport
        data = transport.read()
        if transport.peer_changes != self._peer_changes:
            self._peer_changes = transport.peer_changes
            self.link_changes += 1
            self.stream.reset()  # a new host starts on a frame boundary
        if not data:
            return _NOTHING  # the idle tick (most of them) allocates nothing
        budget = self.rx_bytes_per_tick
        dropped = self.rx_frames_dropped
        over = len(data) > budget
        if over:
            self.rx_bytes_dropped += len(data) - budget
            data = data[:budget]
        self._frames_left = self.rx_frames_per_tick
        out = self.stream.feed(data)  # undecodable frames spend the same budget (_undecodable)
        left = self._frames_left
        if len(out) > left:
            late = out[left:]
            del out[left:]
            # Radio and liveness first: a flood of other frames must not latch RC or host loss.
            kept = [r for r in late if isinstance(r.msg, _PRIORITY)][:RX_PRIORITY_PER_TICK]
            out.extend(kept)
            self.rx_frames_dropped += len(late) - len(kept)
        if over or self.rx_frames_dropped != dropped:
            self.rx_over_budget += 1
        return out

    def _undecodable(self, frame: LinkFrame) -> None:
        if self._frames_left <= 0:
            self.rx_frames_dropped += 1
            return
        self._frames_left -= 1
        hook = self.undecodable
        if hook is not None:
            hook(frame)

    def send(self, msg: Message) -> bool:
        """Encode ``msg`` with the next sequence number and queue it; False if the transport dropped it."""
        frame = encode(msg, self._seq)
        self._seq = (self._seq + 1) & 0xFF
        self.frames_sent += 1
        return self.transport.write(frame)
