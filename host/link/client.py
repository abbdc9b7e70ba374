"""The host's end of the board link: a link process that owns the port, listeners, statistics.

:class:`BoardClient` opens any pyserial URL or device path (``/dev/ttyACM0``, ``/dev/pts/N``,
``socket://127.0.0.1:PORT``, ``loop://``, ``spy://...``) with :func:`serial.serial_for_url` and fans
every decoded board -> host message out to its listeners (:class:`host.link.source.BoardSource`: the
panel's board state, notices and control arbiter, the recorder, the drone link, the run summary).

The port itself is owned by a separate link process (:mod:`host.link.process`: why, and how a hung
host still ends in zero current); this module is the host process's side of it: it starts that process,
hands it what the host sends (messages, and the operator's RC frame once per change: :meth:`set_rc`),
renews its lease (liveness only), decodes what it forwards and keeps the statistics.

Every message sent is told to the sent listeners (with who sent it: the panel's event console lists
them), and a ``Command`` sent with ``on_ack`` gets its own answers: the link process reports the link
``seq`` it went out with, and each ``CommandAck`` for that seq (``IN_PROGRESS``, then the final one)
goes to the sender, or None when the command can no longer be answered (link lost, never written).
"""

from __future__ import annotations

import collections
import contextlib
import logging
import multiprocessing as mp
import multiprocessing.connection as mpc
import os
import queue
import threading
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any, Literal

from host.link.acks import AckHandler, AckRoutes
from host.link.process import BoardLinkError, LinkShared, link_main, now_us
from host.link.source import BoardSource, LinkState
from protocol.dbus import FRAME_PERIOD_US, RcFrame
from protocol.messages import (
    HEARTBEAT_PERIOD_US,
    Command,
    CommandAck,
    Message,
    Telemetry,
)
from protocol.stream import MessageStream

__all__ = [
    "BoardClient",
    "BoardClientConfig",
    "ByteTap",
    "LinkStats",
    "SentListener",
    "load_scaled_s",
]

_log = logging.getLogger(__name__)

ByteTap = Callable[[Literal["rx", "tx"], bytes, int], None]
"""Called with the exact bytes read (``rx``) or written (``tx``) and the monotonic time in µs."""
SentListener = Callable[[Message, str], None]
"""Called with every message handed to the link and who sent it (``Tab 3``, ``host``, ``MAVLink``)."""


def load_scaled_s(base_s: float) -> float:
    """``base_s`` stretched by the machine's load per core (1-minute average), never below ``base_s``.

    A start-up wait that is ample on an idle machine (a fresh interpreter importing and opening a
    port) was measured to run out at a load of 10-15 on two cores; the process was not stuck, only
    starved.
    """
    try:
        load = os.getloadavg()[0]
    except OSError:
        return base_s
    return base_s * max(1.0, load / (os.cpu_count() or 1))


@dataclass(frozen=True, slots=True)
class BoardClientConfig:
    """Timing of the board link.

    Attributes:
        heartbeat_period_us: ``Heartbeat`` period (10 Hz; the board's host timeout is 500 ms).
        rc_period_us: ``VirtualRc`` period while the host has set a frame (DR16: 14 ms).
        reconnect_period_us: pause between attempts to reopen a vanished port.
        rate_window_us: window over which receive rates are computed.
        safe_frames_on_connect: neutral right-lever-DOWN frames sent right after (re)connecting.
        lease_us: the link process stops RC and heartbeat when the host has not renewed its lease for
            this long (a hung host must not keep the arm going). 1 s: on this shared 2-core machine the
            host process was measured stalling 300+ ms under load without being hung.
        lease_renew_period_us: how often the host renews its lease (liveness only: no data rides on it).
        rt_priority: SCHED_FIFO priority of the link process (None: normal priority). Below the
            virtual board's firmware loop (50) so it never delays it.
        exclusive: lock a device port against a second opener (pyserial ``exclusive``; POSIX devices).
        open_timeout_s: how long :meth:`BoardClient.start` waits for the port to open on an idle
            machine; stretched by the load per core (:func:`load_scaled_s`).
    """

    heartbeat_period_us: int = HEARTBEAT_PERIOD_US
    rc_period_us: int = FRAME_PERIOD_US
    reconnect_period_us: int = 500_000
    rate_window_us: int = 1_000_000
    safe_frames_on_connect: int = 3
    lease_us: int = 1_000_000
    lease_renew_period_us: int = 5_000
    rt_priority: int | None = 20
    exclusive: bool = True
    open_timeout_s: float = 20.0

    def __post_init__(self) -> None:
        for name in (
            "heartbeat_period_us",
            "rc_period_us",
            "reconnect_period_us",
            "rate_window_us",
            "lease_us",
            "lease_renew_period_us",
        ):
            if getattr(self, name) <= 0:
                raise ValueError(f"{name} must be > 0")
        if self.safe_frames_on_connect < 0:
            raise ValueError("safe_frames_on_connect must be >= 0")
        if self.rt_priority is not None and not 1 <= self.rt_priority <= 99:
            raise ValueError("rt_priority must be 1..99 or None")
        if self.open_timeout_s <= 0:
            raise ValueError("open_timeout_s must be > 0")


@dataclass(frozen=True, slots=True)
class LinkStats:
    """A snapshot of the link's health.

    Attributes:
        url: the port.
        state: connection state.
        rx_counts: messages received per message type name since start.
        rx_rate_hz: receive rate per message type over the last ``rate_window_us``.
        tx_counts: messages sent per message type name.
        tx_dropped: messages not sent because the link was down or the write failed.
        rx_bytes: bytes read.
        parser: ``LinkParser`` counters (frames_ok, CRC errors, skipped bytes, ...).
        decode_errors: intact frames whose payload did not decode.
        unknown_messages: intact frames with an unknown ``cmd_id``.
        listener_errors: exceptions raised by listeners (logged, never fatal).
        reconnects: successful reconnections after a loss.
        process_restarts: link processes restarted after dying (each one also a loss).
        rc_late: virtual RC frames sent more than half a period late.
        rc_max_gap_us: longest interval between two consecutive virtual RC frames.
        rc_gaps_over_timeout: intervals longer than the board's 30 ms RC timeout (each one is an RC
            loss on the board).
        lease_expired: times the link process stopped RC and heartbeat because the host stalled.
        realtime: the link process runs under SCHED_FIFO.
        latency_us: one-way delay estimate (see :class:`BoardClient`).
        rtt_us: last ``Command`` -> ``CommandAck`` round trip.
        last_rx_age_us: time since the last byte arrived (None before any).
    """

    url: str
    state: LinkState
    rx_counts: Mapping[str, int] = field(default_factory=dict)
    rx_rate_hz: Mapping[str, float] = field(default_factory=dict)
    tx_counts: Mapping[str, int] = field(default_factory=dict)
    tx_dropped: int = 0
    rx_bytes: int = 0
    parser: Mapping[str, int] = field(default_factory=dict)
    decode_errors: int = 0
    unknown_messages: int = 0
    listener_errors: int = 0
    reconnects: int = 0
    process_restarts: int = 0
    rc_late: int = 0
    rc_max_gap_us: int = 0
    rc_gaps_over_timeout: int = 0
    lease_expired: int = 0
    realtime: bool = False
    latency_us: float | None = None
    rtt_us: float | None = None
    last_rx_age_us: int | None = None

    @property
    def errors(self) -> int:
        """All receive-side errors: CRC, oversize, decode and unknown messages."""
        p = self.parser
        return (
            p.get("header_crc_errors", 0)
            + p.get("body_crc_errors", 0)
            + p.get("oversize_errors", 0)
            + self.decode_errors
            + self.unknown_messages
        )


class BoardClient(BoardSource):
    """The board link on the host side: a link process, one dispatcher thread, listeners, statistics.

    Latency estimate: half the round trip of the last ``Command`` -> ``CommandAck`` when one is known,
    otherwise the smoothed excess of (host receive time - board time) of ``Telemetry`` over its running
    minimum, i.e. the delay beyond the fastest frame seen (the two clocks are never synchronised).

    Example:
        >>> with BoardClient("socket://127.0.0.1:5760") as client:  # doctest: +SKIP
        ...     client.add_listener(print)
        ...     client.start()
        ...     client.set_rc(RcFrame.neutral())  # the operator's radio: sent every 14 ms from now on
    """

    def __init__(self, url: str, config: BoardClientConfig | None = None, *, reconnect: bool = True) -> None:
        """Create a client (nothing is opened until :meth:`start`).

        Args:
            url: pyserial URL or device path of the board link.
            config: timing; defaults are the board's rates.
            reconnect: retry a vanished port until :meth:`stop` (otherwise stop on the first loss).
        """
        super().__init__()
        self.url = url
        self.config = config or BoardClientConfig()
        self._reconnect = reconnect
        self._sent_listeners: list[SentListener] = []
        self._taps: list[ByteTap] = []
        self._ctx = mp.get_context("spawn")
        self._shared: LinkShared | None = None
        self._proc: Any = None
        self._conn: mpc.Connection | None = None
        self._events: Any = None
        self._send_lock = threading.Lock()
        """Orders what goes down the pipe, and the pipe's replacement on a restart."""
        self._rc: bytes | None = None
        """The operator's DBUS frame as last set (a restarted link process starts with it)."""
        self._stats_lock = threading.Lock()
        self._stop = threading.Event()
        self._connected = threading.Event()
        self._thread: threading.Thread | None = None
        self._stream = MessageStream()
        self._rx_counts: collections.Counter[str] = collections.Counter()
        self._tx_counts: collections.Counter[str] = collections.Counter()
        self._rx_times: dict[str, collections.deque[int]] = {}
        self._tx_dropped = 0
        self._rx_bytes = 0
        self._reconnects = 0
        self._process_restarts = 0
        self._last_restart = float("-inf")
        self._ever_lost = False
        self._last_rx_us: int | None = None
        self._min_offset_us: int | None = None
        self._offset_excess_us: float | None = None
        self._sent_at: dict[int, int] = {}
        """Command seq -> when it was written (the round trip)."""
        self._rtt_us: float | None = None
        self._acks = AckRoutes()

    # ------------------------------------------------------------------ wiring

    def add_sent_listener(self, listener: SentListener) -> None:
        """Be told of every message handed to the link and who sent it (on the sender's thread)."""
        self._sent_listeners.append(listener)

    def add_tap(self, tap: ByteTap) -> None:
        """See the exact bytes read and written (for recording)."""
        self._taps.append(tap)

    # ------------------------------------------------------------------ lifecycle

    @property
    def connected(self) -> bool:
        """True while the port is open."""
        return self._connected.is_set()

    def start(self) -> None:
        """Start the link process, wait until the port is open, start dispatching.

        Raises:
            BoardLinkError: the port cannot be opened (one-line reason).
        """
        if self._proc is not None:
            return
        self._stop.clear()
        self._shared = LinkShared(self._ctx)
        self._renew_lease()
        proc, events = self._spawn()
        self.set_state(LinkState.CONNECTING)
        # Wait for the first word from the link process: open or not. A fresh interpreter under load
        # can take many seconds to import and open, hence the wait scaled by the load.
        first: Any = None
        deadline = time.monotonic() + load_scaled_s(self.config.open_timeout_s)
        while first is None and time.monotonic() < deadline:
            try:
                item = events.get(timeout=max(0.01, min(0.2, deadline - time.monotonic())))
            except queue.Empty:
                if not proc.is_alive():
                    break
                continue
            except (EOFError, OSError):
                break
            if item[0] in ("state", "open_failed"):
                first = item
            else:
                self._handle(item)  # the SAFE frames written on open
        if first is None or first[0] != "state":
            reason = (
                first[1] if first is not None and first[0] == "open_failed" else "link process did not start"
            )
            self._shutdown_process()
            self._state = LinkState.STOPPED
            raise BoardLinkError(reason)
        self._handle(first)
        self._thread = threading.Thread(target=self._dispatch_loop, name="board-link-rx", daemon=True)
        self._thread.start()

    def _spawn(self) -> tuple[Any, Any]:
        """Start a link process on the shared memory; returns it and its event queue."""
        with self._send_lock:  # a frame set meanwhile goes to the new process or is its first frame
            child, parent = self._ctx.Pipe(duplex=False)  # host -> link process requests
            events = self._ctx.Queue()  # link process -> host: bytes, states, sent frames
            proc = self._ctx.Process(
                target=link_main,
                args=(self.url, self.config, self._shared, child, events, self._reconnect, self._rc),
                name="board-link",
                daemon=True,
            )
            proc.start()
            child.close()
            self._proc = proc
            self._conn = parent
            self._events = events
        return proc, events

    def _restart_process(self) -> None:
        """A link process died: say so, and start a new one that begins with SAFE frames.

        While no process runs the board receives neither RC nor heartbeat, so it is at zero current
        (RC lost after 30 ms); the new process sends only neutral right-lever-DOWN frames until this
        host has seen its connect and its listeners have reset the levers.
        """
        proc = self._proc
        code = proc.exitcode if proc is not None else None
        with self._stats_lock:
            self._process_restarts += 1
        _log.error(
            "board link process died (exit code %s); restarting it, the board holds zero current until "
            "it is back",
            code,
        )
        self._ever_lost = True
        self._connected.clear()
        self.set_state(LinkState.DISCONNECTED)
        self._unroute_all()
        self._shutdown_process()
        # A process that dies at once again is not restarted in a tight loop.
        pause_s = self._last_restart + self.config.reconnect_period_us / 1e6 - time.monotonic()
        if pause_s > 0 and self._stop.wait(pause_s):
            return
        self._last_restart = time.monotonic()
        self._renew_lease()
        self._spawn()

    def stop(self) -> None:
        """Send a last SAFE frame, stop the link process and the thread; safe to call twice."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=3.0)
            self._thread = None
        self._shutdown_process()
        self._connected.clear()
        self._unroute_all()
        if self._state is not LinkState.STOPPED:
            self.set_state(LinkState.STOPPED)

    def _shutdown_process(self) -> None:
        with self._send_lock:
            conn, self._conn = self._conn, None
        proc, self._proc = self._proc, None
        events, self._events = self._events, None
        if conn is not None:
            with contextlib.suppress(Exception):
                conn.send(("stop",))
        if proc is not None:
            # Drain while waiting: the child's feeder thread cannot finish into a full pipe.
            deadline = time.monotonic() + 3.0
            while proc.is_alive() and time.monotonic() < deadline:
                if events is not None:
                    with contextlib.suppress(Exception):
                        while True:
                            events.get_nowait()
                proc.join(timeout=0.05)
            if proc.is_alive():
                proc.kill()
                proc.join(timeout=2.0)
        if conn is not None:
            with contextlib.suppress(Exception):
                conn.close()
        if events is not None:
            with contextlib.suppress(Exception):
                events.close()
                events.join_thread()

    def __enter__(self) -> BoardClient:
        return self

    def wait_connected(self, timeout_s: float) -> bool:
        """Block until connected (True) or ``timeout_s`` passes (False)."""
        return self._connected.wait(timeout_s)

    # ------------------------------------------------------------------ sending

    def set_rc(self, frame: RcFrame | None) -> None:
        """The operator's radio from now on: ``frame`` in every 14 ms slot (None: no RC at all).

        Called once per change (by the control arbiter); the link process's RC slot is the only clock
        that samples it. After a (re)connect the link sends SAFE frames instead until this client's
        state listeners have seen the connection (and reset their levers).

        Raises:
            ValueError: ``frame`` cannot be packed (out-of-range fields).
        """
        data = None if frame is None else frame.pack()
        with self._send_lock:
            self._rc = data
            conn = self._conn
            if conn is not None:
                with contextlib.suppress(OSError, ValueError):  # a dead process: its successor starts with it
                    conn.send(("rc", data))

    def send(self, msg: Message, *, origin: str = "host", on_ack: AckHandler | None = None) -> bool:
        """Send one host -> board message (the link process writes it at once).

        Args:
            msg: the message.
            origin: who sends it, for the sent listeners (``Tab 3``, ``host``, ``MAVLink``).
            on_ack: for a ``Command``: called with each ``CommandAck`` answering it (``IN_PROGRESS``, then
                the final one), or with None once it can have no answer (the link went down first).
                Not called when this returns False.

        Returns:
            True if handed to the link process while connected; False if the link is down or the
            message cannot be encoded (counted in ``tx_dropped``).
        """
        conn = self._conn
        if conn is None or not self._connected.is_set():
            with self._stats_lock:
                self._tx_dropped += 1
            return False
        try:
            # Refused here rather than in the link process, whose session encodes it with the link's seq.
            msg.pack()
        except ValueError:
            _log.exception("cannot encode %r", msg)
            return False
        ticket = 0
        if on_ack is not None and isinstance(msg, Command):
            ticket = self._acks.ticket(int(msg.code), on_ack)
        try:
            with self._send_lock:
                conn.send(("send", msg, ticket))
        except (OSError, ValueError):
            with self._stats_lock:
                self._tx_dropped += 1
            self._acks.drop(ticket)
            return False
        for listener in self._sent_listeners:
            try:
                listener(msg, origin)
            except Exception:
                self.listener_errors += 1
                _log.exception("sent listener failed")
        return True

    def _renew_lease(self) -> None:
        sh = self._shared
        if sh is not None:
            sh.lease_until_us.value = now_us() + self.config.lease_us

    # ------------------------------------------------------------------ answers to commands

    def _written(self, ticket: int, seq: int, t_us: int) -> None:
        """The link process wrote a ``Command`` with ``seq``: time it; route its answers if awaited."""
        with self._stats_lock:
            self._sent_at[seq] = t_us
            if len(self._sent_at) > 64:
                self._sent_at.pop(next(iter(self._sent_at)))
        if ticket:
            for handler in self._acks.written(ticket, seq):
                self._answer(handler, None)

    def _unroute_all(self) -> None:
        """The link went down: every command still awaiting an answer gets None."""
        for handler in self._acks.drop_all():
            self._answer(handler, None)

    def _answer(self, handler: AckHandler, ack: CommandAck | None) -> None:
        try:
            handler(ack)
        except Exception:
            self.listener_errors += 1
            _log.exception("command answer handler failed")

    # ------------------------------------------------------------------ dispatching

    def _dispatch_loop(self) -> None:
        renew_s = self.config.lease_renew_period_us / 1e6
        next_lease = 0.0
        while not self._stop.is_set():
            events, proc = self._events, self._proc
            if events is None:
                break
            now = time.monotonic()
            if now >= next_lease:  # liveness only: a stalled thread lets the lease run out
                next_lease = now + renew_s
                self._renew_lease()
            try:
                item = events.get(timeout=renew_s)
            except queue.Empty:
                if proc is not None and not proc.is_alive() and not self._stop.is_set():
                    self._restart_process()
                continue
            except (EOFError, OSError, ValueError):
                if self._stop.is_set() or proc is None or proc.is_alive():
                    break
                self._restart_process()
                continue
            self._handle(item)

    def _handle(self, item: Any) -> None:
        kind = item[0]
        if kind == "rx":
            self._on_bytes(item[1], item[2])
        elif kind == "tx":
            _, data, t_us, counts = item
            with self._stats_lock:
                self._tx_counts.update(counts)
            if self._taps:
                self._tap("tx", data, t_us)
        elif kind == "sent":
            self._written(item[1], item[2], item[3])
        elif kind == "tx_dropped":
            with self._stats_lock:
                self._tx_dropped += 1
            handler = self._acks.drop(item[2])
            if handler is not None:
                self._answer(handler, None)
        elif kind == "state":
            _, what, reason, gen = item
            if what == "connected":
                self._stream.reset()
                if self._ever_lost:
                    with self._stats_lock:
                        self._reconnects += 1
                    _log.warning("board link back: %s", self.url)
                else:
                    _log.info("board link open: %s", self.url)
                self._connected.set()
                # The state listeners (the control arbiter) reset their levers and set the SAFE frame ...
                self.set_state(LinkState.CONNECTED)
                self._renew_lease()
                # ... and only then may the link send frames that are not SAFE (in order on the pipe).
                with self._send_lock:
                    if self._conn is not None:
                        with contextlib.suppress(OSError, ValueError):
                            self._conn.send(("rc_gen", gen))
            else:
                self._ever_lost = True
                self._connected.clear()
                _log.warning("board link lost (%s): %s; retrying", self.url, reason)
                self.set_state(LinkState.DISCONNECTED)
                self._unroute_all()

    def _tap(self, direction: Literal["rx", "tx"], data: bytes, t_us: int) -> None:
        for tap in self._taps:
            try:
                tap(direction, data, t_us)
            except Exception:
                self.listener_errors += 1
                _log.exception("byte tap failed")

    def _on_bytes(self, data: bytes, t_us: int) -> None:
        self._last_rx_us = t_us
        self._rx_bytes += len(data)
        if self._taps:
            self._tap("rx", data, t_us)
        for _, msg in self._stream.feed(data):
            self.dispatch(msg, t_us)

    def dispatch(self, msg: Message, rx_us: int | None = None) -> None:
        """Count ``msg``, hand it to every listener, and an answer to the command's sender.

        Args:
            msg: a decoded board -> host message.
            rx_us: host receive time (now when None).
        """
        now = now_us() if rx_us is None else rx_us
        name = type(msg).__name__
        with self._stats_lock:
            self._rx_counts[name] += 1
            times = self._rx_times.get(name)
            if times is None:
                times = self._rx_times[name] = collections.deque()
            times.append(now)
            horizon = now - self.config.rate_window_us
            while times and times[0] < horizon:
                times.popleft()
            if isinstance(msg, Telemetry):
                offset = now - msg.time_us
                if self._min_offset_us is None or offset < self._min_offset_us:
                    self._min_offset_us = offset
                excess = float(offset - self._min_offset_us)
                prev = self._offset_excess_us
                self._offset_excess_us = excess if prev is None else 0.9 * prev + 0.1 * excess
            elif isinstance(msg, CommandAck):
                sent = self._sent_at.pop(msg.request_seq, None)
                if sent is not None:
                    self._rtt_us = float(now - sent)
        self.fan_out(msg)
        if isinstance(msg, CommandAck):
            handler = self._acks.answer(msg)
            if handler is not None:
                self._answer(handler, msg)

    # ------------------------------------------------------------------ statistics

    def stats(self) -> LinkStats:
        """A consistent snapshot of the link statistics."""
        now = now_us()
        window_s = self.config.rate_window_us / 1e6
        sh = self._shared
        stream = self._stream
        with self._stats_lock:
            horizon = now - self.config.rate_window_us
            rates = {}
            for name, times in self._rx_times.items():
                while times and times[0] < horizon:
                    times.popleft()
                rates[name] = len(times) / window_s
            rtt = self._rtt_us
            latency = rtt / 2.0 if rtt is not None else self._offset_excess_us
            return LinkStats(
                url=self.url,
                state=self._state,
                rx_counts=dict(self._rx_counts),
                rx_rate_hz=rates,
                tx_counts=dict(self._tx_counts),
                tx_dropped=self._tx_dropped,
                rx_bytes=self._rx_bytes,
                parser=stream.parser.counters(),
                decode_errors=stream.decode_errors - stream.unknown_ids,
                unknown_messages=stream.unknown_ids,
                listener_errors=self.listener_errors,
                reconnects=self._reconnects,
                process_restarts=self._process_restarts,
                rc_late=int(sh.rc_late.value) if sh else 0,
                rc_max_gap_us=int(sh.rc_max_gap_us.value) if sh else 0,
                rc_gaps_over_timeout=int(sh.rc_gaps.value) if sh else 0,
                lease_expired=int(sh.lease_expired.value) if sh else 0,
                realtime=bool(sh.realtime.value) if sh else False,
                latency_us=latency,
                rtt_us=rtt,
                last_rx_age_us=None if self._last_rx_us is None else now - self._last_rx_us,
            )
