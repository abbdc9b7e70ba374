"""The host's end of the board link: a link process that owns the port, listeners, statistics.

:class:`BoardClient` opens any pyserial URL or device path (``/dev/ttyACM0``, ``/dev/pts/N``,
``socket://127.0.0.1:PORT``, ``loop://``, ``spy://...``) with :func:`serial.serial_for_url` and fans
every decoded board -> host message out to its listeners (the UI model, the recorder, the MAVLink
bridge).

The port itself is owned by a separate link process (:mod:`host.link.process`: why, and how a hung
host still ends in zero current); this module is the host process's side of it: it starts that process,
renews its lease with the latest RC frame, decodes what it forwards and keeps the statistics.
"""

from __future__ import annotations

import collections
import contextlib
import enum
import logging
import multiprocessing as mp
import multiprocessing.connection as mpc
import os
import queue
import threading
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from types import TracebackType
from typing import Any, Literal

from host.link.process import BoardLinkError, LinkShared, link_main, now_us
from protocol.dbus import FRAME_PERIOD_US, RcFrame
from protocol.link import LinkParser
from protocol.messages import (
    HEARTBEAT_PERIOD_US,
    MESSAGES,
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
    "LinkState",
    "LinkStats",
    "MessageListener",
    "RcSource",
    "StateListener",
    "load_scaled_s",
]

_log = logging.getLogger(__name__)

MessageListener = Callable[[Message], None]
"""Called on the client's thread with every decoded board -> host message (keep it short)."""
StateListener = Callable[["LinkState"], None]
"""Called when the link connects, disconnects or stops."""
ByteTap = Callable[[Literal["rx", "tx"], bytes, int], None]
"""Called with the exact bytes read (``rx``) or written (``tx``) and the monotonic time in µs."""
RcSource = Callable[[], RcFrame | None]
"""Returns the DBUS frame to send now, or None when nobody holds control (then no RC is sent)."""


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


class LinkState(enum.Enum):
    """Connection state of the board link."""

    CONNECTING = "connecting"
    CONNECTED = "connected"
    DISCONNECTED = "disconnected"
    STOPPED = "stopped"


@dataclass(frozen=True, slots=True)
class BoardClientConfig:
    """Timing of the board link.

    Attributes:
        heartbeat_period_us: ``Heartbeat`` period (10 Hz; the board's host timeout is 500 ms).
        rc_period_us: ``VirtualRc`` period while a source gives frames (DR16: 14 ms).
        reconnect_period_us: pause between attempts to reopen a vanished port.
        rate_window_us: window over which receive rates are computed.
        safe_frames_on_connect: neutral right-lever-DOWN frames sent right after (re)connecting.
        lease_us: the link process stops RC and heartbeat when the host has not renewed its lease for
            this long (a hung host must not keep the arm going). 1 s: on this shared 2-core machine the
            host process was measured stalling 300+ ms under load without being hung.
        rc_poll_period_us: how often the host reads the RC source into the shared frame (and renews
            the lease).
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
    rc_poll_period_us: int = 5_000
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
            "rc_poll_period_us",
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


class BoardClient:
    """The board link on the host side: a link process, one dispatcher thread, listeners, statistics.

    Listeners run on the dispatcher thread and must be quick (store the latest value, queue work);
    exceptions they raise are logged and counted, never propagated.

    Latency estimate: half the round trip of the last ``Command`` -> ``CommandAck`` when one is known,
    otherwise the smoothed excess of (host receive time - board time) of ``Telemetry`` over its running
    minimum, i.e. the delay beyond the fastest frame seen (the two clocks are never synchronised).

    Example:
        >>> with BoardClient("socket://127.0.0.1:5760") as client:  # doctest: +SKIP
        ...     client.add_listener(print)
        ...     client.start()
    """

    def __init__(
        self,
        url: str,
        config: BoardClientConfig | None = None,
        *,
        rc_source: RcSource | None = None,
        reconnect: bool = True,
    ) -> None:
        """Create a client (nothing is opened until :meth:`start`).

        Args:
            url: pyserial URL or device path of the board link.
            config: timing; defaults are the board's rates.
            rc_source: read every ``rc_poll_period_us``; a returned frame is sent as ``VirtualRc``
                every ``rc_period_us`` by the link process.
            reconnect: retry a vanished port until :meth:`stop` (otherwise stop on the first loss).
        """
        self.url = url
        self.config = config or BoardClientConfig()
        self._rc_source = rc_source
        self._reconnect = reconnect
        self._listeners: list[MessageListener] = []
        self._state_listeners: list[StateListener] = []
        self._taps: list[ByteTap] = []
        self._ctx = mp.get_context("spawn")
        self._shared: LinkShared | None = None
        self._proc: Any = None
        self._conn: mpc.Connection | None = None
        self._events: Any = None
        self._send_lock = threading.Lock()
        self._stats_lock = threading.Lock()
        self._stop = threading.Event()
        self._connected = threading.Event()
        self._thread: threading.Thread | None = None
        self._state = LinkState.STOPPED
        self._stream = MessageStream()
        self._tx_parser = LinkParser()
        """Splits what the link process wrote back into frames, to count them and time commands."""
        self._rx_counts: collections.Counter[str] = collections.Counter()
        self._tx_counts: collections.Counter[str] = collections.Counter()
        self._rx_times: dict[str, collections.deque[int]] = {}
        self._tx_dropped = 0
        self._rx_bytes = 0
        self._listener_errors = 0
        self._reconnects = 0
        self._process_restarts = 0
        self._last_restart = float("-inf")
        self._ever_lost = False
        self._last_rx_us: int | None = None
        self._min_offset_us: int | None = None
        self._offset_excess_us: float | None = None
        self._pending_cmd: dict[int, int] = {}
        self._rtt_us: float | None = None

    # ------------------------------------------------------------------ wiring

    def add_listener(self, listener: MessageListener) -> None:
        """Receive every decoded board -> host message (on the dispatcher thread)."""
        self._listeners.append(listener)

    def add_state_listener(self, listener: StateListener) -> None:
        """Be told when the link connects, disconnects or stops."""
        self._state_listeners.append(listener)

    def add_tap(self, tap: ByteTap) -> None:
        """See the exact bytes read and written (for recording)."""
        self._taps.append(tap)

    def set_rc_source(self, source: RcSource | None) -> None:
        """Replace the virtual RC source (None: send no RC)."""
        self._rc_source = source

    # ------------------------------------------------------------------ lifecycle

    @property
    def state(self) -> LinkState:
        """Current connection state."""
        return self._state

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
        self._set_state(LinkState.CONNECTING)
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
        child, parent = self._ctx.Pipe(duplex=False)  # host -> link process requests
        events = self._ctx.Queue()  # link process -> host: bytes, states, sent frames
        proc = self._ctx.Process(
            target=link_main,
            args=(self.url, self.config, self._shared, child, events, self._reconnect),
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
        host has seen its connect and reset the levers (``rc_gen`` back to "no connect seen").
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
        self._set_state(LinkState.DISCONNECTED)
        self._shutdown_process()
        if self._shared is not None:
            self._shared.rc_gen.value = -1
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
        if self._state is not LinkState.STOPPED:
            self._set_state(LinkState.STOPPED)

    def _shutdown_process(self) -> None:
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

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.stop()

    def wait_connected(self, timeout_s: float) -> bool:
        """Block until connected (True) or ``timeout_s`` passes (False)."""
        return self._connected.wait(timeout_s)

    # ------------------------------------------------------------------ sending

    def send(self, msg: Message) -> bool:
        """Send one host -> board message (the link process writes it at once).

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
        try:
            with self._send_lock:
                conn.send(("send", msg))
        except (OSError, ValueError):
            with self._stats_lock:
                self._tx_dropped += 1
            return False
        return True

    def _renew_lease(self) -> None:
        sh = self._shared
        if sh is None:
            return
        source = self._rc_source
        frame: RcFrame | None = None
        if source is not None:
            try:
                frame = source()
            except Exception:
                self._listener_errors += 1
                _log.exception("RC source failed")
        if frame is None:
            sh.rc_on.value = 0
        else:
            try:
                data = frame.pack()
            except ValueError:
                _log.exception("RC source produced an unpackable frame: %r", frame)
                sh.rc_on.value = 0
            else:
                # One writer (this thread); a torn read by the link process is impossible to act on:
                # the board rejects a malformed frame, and the next period sends a whole one.
                sh.rc[:] = data  # type: ignore[index]
                sh.rc_on.value = 1
        sh.lease_until_us.value = now_us() + self.config.lease_us

    # ------------------------------------------------------------------ dispatching

    def _dispatch_loop(self) -> None:
        poll_s = self.config.rc_poll_period_us / 1e6
        next_lease = 0.0
        while not self._stop.is_set():
            events, proc = self._events, self._proc
            if events is None:
                break
            now = time.monotonic()
            if now >= next_lease:
                next_lease = now + poll_s
                self._renew_lease()
            try:
                item = events.get(timeout=poll_s)
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
            _, data, t_us = item
            with self._stats_lock:
                for frame in self._tx_parser.feed(data):
                    cls = MESSAGES.get(frame.cmd_id)
                    self._tx_counts[cls.__name__ if cls is not None else f"{frame.cmd_id:#06x}"] += 1
                    if cls is Command:
                        self._pending_cmd[frame.seq] = t_us
                        if len(self._pending_cmd) > 64:
                            self._pending_cmd.pop(next(iter(self._pending_cmd)))
            if self._taps:
                self._tap("tx", data, t_us)
        elif kind == "tx_dropped":
            with self._stats_lock:
                self._tx_dropped += 1
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
                self._set_state(LinkState.CONNECTED)
                # Listeners (the model) have reset their levers: now the link may send their frames.
                self._renew_lease()
                if self._shared is not None:
                    self._shared.rc_gen.value = gen
            else:
                self._ever_lost = True
                self._connected.clear()
                _log.warning("board link lost (%s): %s; retrying", self.url, reason)
                self._set_state(LinkState.DISCONNECTED)

    def _tap(self, direction: Literal["rx", "tx"], data: bytes, t_us: int) -> None:
        for tap in self._taps:
            try:
                tap(direction, data, t_us)
            except Exception:
                self._listener_errors += 1
                _log.exception("byte tap failed")

    def _set_state(self, state: LinkState) -> None:
        self._state = state
        for listener in self._state_listeners:
            try:
                listener(state)
            except Exception:
                self._listener_errors += 1
                _log.exception("state listener failed")

    def _on_bytes(self, data: bytes, t_us: int) -> None:
        self._last_rx_us = t_us
        self._rx_bytes += len(data)
        if self._taps:
            self._tap("rx", data, t_us)
        for _, msg in self._stream.feed(data):
            self.dispatch(msg, t_us)

    def dispatch(self, msg: Message, rx_us: int | None = None) -> None:
        """Count ``msg`` and hand it to every listener (the client calls this; replay may too).

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
                sent = self._pending_cmd.pop(msg.request_seq, None)
                if sent is not None:
                    self._rtt_us = float(now - sent)
        for listener in self._listeners:
            try:
                listener(msg)
            except Exception:
                self._listener_errors += 1
                _log.exception("listener %r failed on %s", listener, name)

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
                listener_errors=self._listener_errors,
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
