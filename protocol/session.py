"""The host's end of the board link as a sans-I/O state machine.

:class:`HostSession` does everything a host does on the link except touching a port or a clock, in the
manner of h11's ``Connection``: the shell feeds it received bytes (:meth:`~HostSession.receive_data`),
calls :meth:`~HostSession.poll` with the time, sends messages through it, and writes out what it
queued (:meth:`~HostSession.data_to_send`, :meth:`~HostSession.rc_to_send`). Time comes in as integer
microseconds on whatever clock the shell uses (board time in lockstep, ``CLOCK_MONOTONIC`` on a port).

What it owns, once for every host:

- the single u8 link ``seq`` counter (every frame sent takes the next one);
- the heartbeat clock (10 Hz) and the ``VirtualRc`` slots (14 ms, the DR16's rate), both on a grid
  from the first :meth:`~HostSession.poll`: a late poll sends once and skips the missed slots, never a
  burst;
- commands and their acks: :meth:`~HostSession.command` returns a :data:`CommandToken` (not the u8
  ``seq``, which wraps every 256 frames) and :meth:`~HostSession.ack` gives the latest ``CommandAck``
  for it;
- the parameter table (``ParamValue`` answers) and the last ``Telemetry``;
- decoding, through a :class:`~protocol.stream.MessageStream` (never raises; counts).

Outgoing bytes are kept in two queues: ``VirtualRc`` frames in :meth:`~HostSession.rc_to_send`,
everything else (heartbeats, commands, parameters) in :meth:`~HostSession.data_to_send`. A shell with
one port writes both after each call (data first: a poll queues its heartbeat before its RC frame, so
the wire order follows ``seq``); the port runner keeps the radio's stand-in outside its emulated link
faults by writing the RC queue around them.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import NewType

from protocol.dbus import FRAME_PERIOD_US
from protocol.messages import (
    HEARTBEAT_PERIOD_US,
    PARAM_INDEX_BY_NAME,
    PARAM_LIST_ALL,
    AckResult,
    Command,
    CommandAck,
    CommandCode,
    Heartbeat,
    Message,
    ParamRequest,
    ParamSet,
    ParamValue,
    Telemetry,
    VirtualRc,
    encode,
)
from protocol.stream import MessageStream

__all__ = ["ACKS_KEPT", "CommandToken", "HeartbeatAllowed", "HostSession", "RcSlotSource", "next_slot"]

ACKS_KEPT = 1024
"""Commands whose acks are remembered; older tokens are forgotten (``ack`` then returns None)."""

CommandToken = NewType("CommandToken", int)
"""Names one sent command for :meth:`HostSession.ack`; increases by one per command, never wraps."""
RcSlotSource = Callable[[int], bytes | None]
"""Called with a due RC slot's time; returns the 18 DBUS bytes to send in it, or None to send none."""
HeartbeatAllowed = Callable[[int], bool]
"""Called with the time of a due heartbeat; False blocks it (the slot still passes)."""

_ARGS_N = 3


def next_slot(slot_us: int, now_us: int, period_us: int) -> int:
    """The first slot of the grid ``slot_us + k * period_us`` after ``now_us`` (missed slots skipped).

    Args:
        slot_us: a slot of the grid (the one just served).
        now_us: the current time, at or after ``slot_us``.
        period_us: the grid's period, > 0.

    Returns:
        The next slot strictly after ``now_us``.
    """
    return slot_us + ((now_us - slot_us) // period_us + 1) * period_us


class HostSession:
    """The host's end of the board link: seq, heartbeats, RC slots, commands and acks, parameters.

    No I/O and no clock: see the module docstring for the calling pattern.

    Args:
        heartbeat_period_us: period of the ``Heartbeat`` (10 Hz).
        rc_period_us: period of the ``VirtualRc`` slots (the DR16's 14 ms).
        heartbeats: send heartbeats at all.
        heartbeat_allowed: asked at each due heartbeat; False blocks it (a host-loss fault, an expired
            lease). None: always allowed.
        rc_source: asked at each RC slot for the frame to send (see :data:`RcSlotSource`); None: the
            frame set with :meth:`set_rc` is sent.
        keep_sent: keep every link message sent in :attr:`sent` (long-running hosts pass False).

    Attributes:
        stream: the decoder (its counters are the receive-side health).
        sent: ``(now_us, msg)`` of every message queued for :meth:`data_to_send`, in order (empty when
            ``keep_sent`` is False).
        params: last value received for each parameter name.
        param_count: the board's parameter count (from the last ``ParamValue``; 0 before any).
        last_telemetry: the last ``Telemetry`` received.
        last_heartbeat_us: when the last heartbeat was queued (None before any).
        heartbeats_sent: heartbeats queued so far (the next one's ``counter``, before wrapping).
        rc_frames_sent: ``VirtualRc`` frames queued so far.
        last_rc_us: when the last ``VirtualRc`` frame was queued (None before any).
        unmatched_acks: acks that answer no pending command of this session.
        rtt_us: ``Command`` -> final ``CommandAck`` time of the last command answered.
    """

    def __init__(
        self,
        *,
        heartbeat_period_us: int = HEARTBEAT_PERIOD_US,
        rc_period_us: int = FRAME_PERIOD_US,
        heartbeats: bool = True,
        heartbeat_allowed: HeartbeatAllowed | None = None,
        rc_source: RcSlotSource | None = None,
        keep_sent: bool = True,
    ) -> None:
        if heartbeat_period_us <= 0 or rc_period_us <= 0:
            raise ValueError("heartbeat_period_us and rc_period_us must be > 0")
        self.heartbeat_period_us = heartbeat_period_us
        self.rc_period_us = rc_period_us
        self.heartbeats = heartbeats
        self.heartbeat_allowed = heartbeat_allowed
        self.rc_source = rc_source
        self.keep_sent = keep_sent
        self.stream = MessageStream()
        self.sent: list[tuple[int, Message]] = []
        self.params: dict[str, float] = {}
        self.param_count = 0
        self.last_telemetry: Telemetry | None = None
        self.last_heartbeat_us: int | None = None
        self.heartbeats_sent = 0
        self.rc_frames_sent = 0
        self.last_rc_us: int | None = None
        self.unmatched_acks = 0
        self.rtt_us: int | None = None
        self._seq = 0
        self._data = bytearray()
        self._rc = bytearray()
        self._rc_fixed: bytes | None = None
        self._polled = False
        self._next_hb_us = 0
        self._next_rc_us = 0
        self._tokens = 0
        self._pending: dict[int, tuple[CommandToken, int, int]] = {}
        """Command ``seq`` -> (token, code, sent at): awaiting their final ack."""
        self._acks: dict[CommandToken, CommandAck] = {}
        self._answers = 0
        self._answered: dict[str, int] = {}
        """Parameter name -> the serial number of its last answer (see :meth:`param_mark`)."""

    # --- sending ----------------------------------------------------------------------------------

    @property
    def next_seq(self) -> int:
        """The ``seq`` the next frame sent will carry."""
        return self._seq

    def send(self, msg: Message, now_us: int) -> int:
        """Queue ``msg`` with the next ``seq``.

        ``VirtualRc`` frames go to :meth:`rc_to_send` (counted, not kept in :attr:`sent`); everything
        else to :meth:`data_to_send`.

        Args:
            msg: a host -> board message.
            now_us: the time it is sent.

        Returns:
            The ``seq`` it carries.

        Raises:
            ValueError: the message cannot be packed (nothing is queued, the seq is not used).
        """
        seq = self._seq
        frame = encode(msg, seq)
        self._seq = (seq + 1) & 0xFF
        if type(msg) is VirtualRc:
            self._rc += frame
            self.rc_frames_sent += 1
            self.last_rc_us = now_us
        else:
            self._data += frame
            if self.keep_sent:
                self.sent.append((now_us, msg))
        return seq

    def command(self, code: CommandCode, *args: float, now_us: int) -> CommandToken:
        """Send a ``Command`` and start waiting for its ack.

        Args:
            code: the command.
            *args: up to three arguments (see ``CommandCode``); missing ones are 0.
            now_us: the time it is sent.

        Returns:
            The token to ask :meth:`ack` with.

        Raises:
            ValueError: more than three arguments, or they cannot be packed.
        """
        if len(args) > _ARGS_N:
            raise ValueError(f"a Command takes at most {_ARGS_N} arguments, got {len(args)}")
        padded = (*args, 0.0, 0.0, 0.0)
        seq = self.send(Command(code, (padded[0], padded[1], padded[2])), now_us)
        token = CommandToken(self._tokens)
        self._tokens += 1
        # A seq reused after 256 frames replaces a command that was never answered: its ack is lost.
        self._pending[seq] = (token, int(code), now_us)
        return token

    def hold_lengths(self, lengths_m: Sequence[float], now_us: int) -> CommandToken:
        """Select length-hold per cable (``HOLD_LENGTHS``), acked like every command.

        Args:
            lengths_m: one value per cable: ``HOLD_UNCHANGED`` (NaN), ``HOLD_RELEASE`` (-inf),
                ``HOLD_HERE`` (+inf: hold at the present length) or a length in m to hold at (the
                board's ``cable_length_m`` frame).
            now_us: the time it is sent.

        Returns:
            The token to ask :meth:`ack` with.

        Raises:
            ValueError: not exactly three values.
        """
        if len(lengths_m) != _ARGS_N:
            raise ValueError(f"HOLD_LENGTHS takes one value per cable ({_ARGS_N}), got {len(lengths_m)}")
        return self.command(CommandCode.HOLD_LENGTHS, *lengths_m, now_us=now_us)

    def ack(self, token: CommandToken) -> CommandAck | None:
        """The latest ack for the command ``token`` (``IN_PROGRESS`` may be followed by the final one).

        Returns None while unanswered, and for tokens older than the last :data:`ACKS_KEPT` commands.
        """
        return self._acks.get(token)

    def request_params(self, now_us: int, index: int = PARAM_LIST_ALL, name: str = "") -> int:
        """Ask for parameter values (``ParamRequest``): all by default, one by index, or one by name.

        Args:
            now_us: the time it is sent.
            index: ``PARAM_LIST_ALL``, an index >= 0, or ``PARAM_INDEX_BY_NAME`` with ``name``.
            name: the parameter's name (with ``PARAM_INDEX_BY_NAME``).

        Returns:
            The request's ``seq``.

        Raises:
            ValueError: the request cannot be packed.
        """
        if name and index != PARAM_INDEX_BY_NAME:
            raise ValueError(f"a name is looked up with index PARAM_INDEX_BY_NAME, not {index}")
        return self.send(ParamRequest(index, name), now_us)

    def set_param(self, name: str, value: float, now_us: int) -> int:
        """Set a parameter (``ParamSet``); the board answers with the value now in force.

        Returns:
            The request's ``seq``.

        Raises:
            ValueError: the name is not at most 16 ASCII characters.
        """
        return self.send(ParamSet(name, value), now_us)

    def set_rc(self, payload: bytes | None) -> None:
        """The DBUS frame sent in every RC slot (None: none), when no ``rc_source`` is given.

        Raises:
            ValueError: ``payload`` is not a whole DBUS frame.
        """
        if payload is not None:
            VirtualRc(payload).pack()  # checks the length now rather than at the next slot
        self._rc_fixed = payload

    # --- periodic ---------------------------------------------------------------------------------

    def poll(self, now_us: int) -> None:
        """Queue what is due by ``now_us``: the heartbeat, then the RC frame of the current slot.

        Both grids start at the first poll. A late poll serves the first slot it missed (the RC source
        is asked with that slot's time) and skips the rest. A blocked heartbeat still passes its slot;
        so does an RC slot whose source gives None.
        """
        if not self._polled:
            self._polled = True
            self._next_hb_us = now_us
            self._next_rc_us = now_us
        if self.heartbeats and now_us >= self._next_hb_us:
            allowed = self.heartbeat_allowed
            if allowed is None or allowed(now_us):
                self.send(Heartbeat(now_us, self.heartbeats_sent & 0xFFFF_FFFF), now_us)
                self.heartbeats_sent += 1
                self.last_heartbeat_us = now_us
            self._next_hb_us = next_slot(self._next_hb_us, now_us, self.heartbeat_period_us)
        slot_us = self._next_rc_us
        if now_us >= slot_us and (self.rc_source is not None or self._rc_fixed is not None):
            source = self.rc_source
            payload = self._rc_fixed if source is None else source(slot_us)
            if payload is not None:
                self.send(VirtualRc(payload), now_us)
            self._next_rc_us = next_slot(slot_us, now_us, self.rc_period_us)

    def restart_grids(self) -> None:
        """Start the heartbeat and RC grids anew at the next :meth:`poll` (a scenario's time zero)."""
        self._polled = False

    def next_rc_slot_us(self) -> int | None:
        """The time of the next RC slot (None before the first poll)."""
        return self._next_rc_us if self._polled else None

    def next_deadline_us(self) -> int | None:
        """When :meth:`poll` next has work: 0 before the first poll, None when nothing is periodic."""
        rc = self._next_rc_us if self._rc_wanted() else None
        if not self.heartbeats:
            return rc if rc is None or self._polled else 0
        hb = self._next_hb_us if self._polled else 0
        return hb if rc is None else min(hb, rc)

    def _rc_wanted(self) -> bool:
        return self.rc_source is not None or self._rc_fixed is not None

    # --- outgoing bytes ---------------------------------------------------------------------------

    def data_to_send(self) -> bytes:
        """Take the queued link traffic (heartbeats, commands, parameter requests), in ``seq`` order."""
        if not self._data:
            return b""
        out = bytes(self._data)
        self._data.clear()
        return out

    def rc_to_send(self) -> bytes:
        """Take the queued ``VirtualRc`` frames, in ``seq`` order."""
        if not self._rc:
            return b""
        out = bytes(self._rc)
        self._rc.clear()
        return out

    # --- incoming ---------------------------------------------------------------------------------

    def receive_data(self, data: bytes | bytearray | memoryview, now_us: int) -> list[Message]:
        """Take received bytes; track acks, parameters and telemetry; return the messages decoded.

        Never raises: bad bytes are counted by :attr:`stream`.

        Args:
            data: any chunk of what the board sent.
            now_us: when it arrived (times the command round trip).
        """
        received = self.stream.feed(data)
        if not received:
            return []
        out: list[Message] = []
        for _, msg in received:
            out.append(msg)
            kind = type(msg)
            if kind is Telemetry:
                self.last_telemetry = msg  # type: ignore[assignment]  # checked by type() above
            elif kind is CommandAck:
                self._on_ack(msg, now_us)  # type: ignore[arg-type]  # checked by type() above
            elif kind is ParamValue:
                self._on_param(msg)  # type: ignore[arg-type]  # checked by type() above
        return out

    def _on_ack(self, ack: CommandAck, now_us: int) -> None:
        pending = self._pending.get(ack.request_seq)
        if pending is None or pending[1] != int(ack.command):
            self.unmatched_acks += 1
            return
        token, _, sent_us = pending
        acks = self._acks
        acks.pop(token, None)  # re-inserted last: the dict stays in answer order for the eviction below
        acks[token] = ack
        if len(acks) > ACKS_KEPT:
            del acks[next(iter(acks))]
        if ack.result is not AckResult.IN_PROGRESS:
            del self._pending[ack.request_seq]
            self.rtt_us = now_us - sent_us

    def _on_param(self, value: ParamValue) -> None:
        self.params[value.name] = value.value
        self.param_count = value.count
        self._answers += 1
        self._answered[value.name] = self._answers

    def param_mark(self) -> int:
        """A mark to pass to :meth:`answered_since` (the number of ``ParamValue`` answers so far)."""
        return self._answers

    def answered_since(self, mark: int) -> set[str]:
        """Names of the parameters answered after :meth:`param_mark` returned ``mark``."""
        return {name for name, n in self._answered.items() if n > mark}

    def counters(self) -> dict[str, int]:
        """The receive side's counters (see :class:`~protocol.stream.MessageStream`) and unmatched acks."""
        out = self.stream.counters()
        out["unmatched_acks"] = self.unmatched_acks
        return out
