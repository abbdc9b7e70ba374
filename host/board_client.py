"""The host's end of the board link: a link process that owns the port, listeners, statistics.

:class:`BoardClient` opens any pyserial URL or device path (``/dev/ttyACM0``, ``/dev/pts/N``,
``socket://127.0.0.1:PORT``, ``loop://``, ``spy://...``) with :func:`serial.serial_for_url` and fans
every decoded board -> host message out to its listeners (the UI model, the recorder, the MAVLink
bridge).

Why a separate process owns the port: the board drops an RC stream after 30 ms without a valid frame
(DJI's figure) and latches the loss until the operator re-arms through SAFE, while virtual RC frames go
out every 14 ms (the DR16's rate). Sent from a thread of the host process, frames were measured 35-58 ms
apart several times in 10 s whenever a browser was attached (viser, numpy and Chromium's software
rendering contend for the GIL and both cores). So a small **link process** (SCHED_FIFO priority 20 when
permitted, below the virtual board's 50) opens the port, writes the ``Heartbeat`` every 100 ms and the
latest ``VirtualRc`` frame every 14 ms on absolute deadlines, forwards received bytes to the host
process, and writes whatever the host sends. The host process parses, decodes and dispatches.

Safety of that split: the host renews a *lease* (shared memory) every few ms; when it stalls longer than
``lease_us`` (1 s) the link process stops both RC and heartbeat, so a hung host still ends in zero
current (RC lost after 30 ms; host lost when the board requires the heartbeat). When the device vanishes
the link process retries until it comes back; after every (re)connect it sends only neutral
right-lever-DOWN frames until the host has seen the reconnect and reset its levers, so the start-up
gate is always passed from SAFE.
"""

from __future__ import annotations

import collections
import contextlib
import enum
import gc
import logging
import multiprocessing as mp
import multiprocessing.connection as mpc
import os
import queue
import select
import signal
import threading
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from types import TracebackType
from typing import Any, Literal

import serial

from controller.config import FailsafeConfig
from controller.transport import set_tcp_nodelay
from protocol.dbus import FRAME_LEN, FRAME_PERIOD_US, RcFrame
from protocol.link import LinkParser
from protocol.messages import (
    HEARTBEAT_PERIOD_US,
    MESSAGES,
    Command,
    CommandAck,
    Message,
    Telemetry,
    VirtualRc,
)
from protocol.session import HostSession
from protocol.stream import MessageStream

__all__ = [
    "RC_TIMEOUT_US",
    "BoardClient",
    "BoardClientConfig",
    "BoardLinkError",
    "ByteTap",
    "LinkState",
    "LinkStats",
    "MessageListener",
    "RcSource",
    "StateListener",
    "open_port",
]

_log = logging.getLogger(__name__)

RC_TIMEOUT_US = FailsafeConfig().rc_timeout_us
"""The board's RC-lost timeout (DJI detect task: 30 ms); a longer gap between virtual RC frames is a loss."""

MessageListener = Callable[[Message], None]
"""Called on the client's thread with every decoded board -> host message (keep it short)."""
StateListener = Callable[["LinkState"], None]
"""Called when the link connects, disconnects or stops."""
ByteTap = Callable[[Literal["rx", "tx"], bytes, int], None]
"""Called with the exact bytes read (``rx``) or written (``tx``) and the monotonic time in µs."""
RcSource = Callable[[], RcFrame | None]
"""Returns the DBUS frame to send now, or None when nobody holds control (then no RC is sent)."""

_SAFE_FRAME = RcFrame.neutral().pack()


class BoardLinkError(Exception):
    """The board link cannot be opened (wrong path, busy device, refused connection)."""


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
        open_timeout_s: how long :meth:`BoardClient.start` waits for the port to open.
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


def _now_us() -> int:
    return time.monotonic_ns() // 1000


def open_port(url: str, *, timeout_s: float, exclusive: bool = True) -> Any:
    """Open a board-link port from a pyserial URL or a device path.

    Args:
        url: ``/dev/ttyACM0``, a pty path, ``socket://host:port``, ``loop://``, ``spy://...``.
        timeout_s: read timeout (0 = non-blocking).
        exclusive: lock a POSIX device against a second opener.

    Returns:
        An open ``serial.SerialBase``.

    Raises:
        BoardLinkError: with a one-line reason (no such device, busy, refused, ...).
    """
    kwargs: dict[str, Any] = {"timeout": timeout_s, "write_timeout": 0.5}
    if "://" not in url:
        if not os.path.exists(url):
            raise BoardLinkError(f"no such device: {url}")
        if exclusive:
            kwargs["exclusive"] = True
    try:
        port = serial.serial_for_url(url, **kwargs)
    except serial.SerialException as exc:
        text = str(exc)
        if "exclusively lock" in text or "Resource temporarily unavailable" in text:
            raise BoardLinkError(f"port busy (another program has it open): {url}") from exc
        raise BoardLinkError(f"cannot open {url}: {text}") from exc
    except (OSError, ValueError) as exc:
        raise BoardLinkError(f"cannot open {url}: {exc}") from exc
    with contextlib.suppress(Exception):  # loop:// has no descriptor
        set_tcp_nodelay(port.fileno())  # socket://: heartbeats must not wait behind RC frames (Nagle)
    return port


# ---------------------------------------------------------------------- the link process


class _Shared:
    """Shared memory between the host and its link process (lock-free single-writer fields)."""

    def __init__(self, ctx: Any) -> None:
        self.rc = ctx.Array("B", FRAME_LEN, lock=False)
        self.rc_on = ctx.Value("b", 0, lock=False)
        """1 while the host wants RC sent."""
        self.rc_gen = ctx.Value("q", -1, lock=False)
        """Connection generation the host has acknowledged (frames are SAFE until it matches)."""
        self.lease_until_us = ctx.Value("q", 0, lock=False)
        self.rc_late = ctx.Value("q", 0, lock=False)
        self.rc_max_gap_us = ctx.Value("q", 0, lock=False)
        self.rc_gaps = ctx.Value("q", 0, lock=False)
        self.lease_expired = ctx.Value("q", 0, lock=False)
        self.realtime = ctx.Value("b", 0, lock=False)


_EVENTS_MAX = 20_000
"""Undelivered events the link process keeps for a stalled host before it drops received bytes."""


def _link_main(
    url: str, cfg: BoardClientConfig, shared: _Shared, conn: mpc.Connection, events: Any, reconnect: bool
) -> None:
    """Body of the link process (module level so the spawn start method can import it)."""
    # A terminal's Ctrl-C reaches the whole process group. The host shuts this process down in order
    # (a last SAFE frame, then the port closed); dying of KeyboardInterrupt here would skip that.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        _LinkWorker(url, cfg, shared, conn, events, reconnect).run()
    except Exception as exc:  # report, never a silent death
        with contextlib.suppress(Exception):
            events.put(("open_failed", f"board link process failed: {type(exc).__name__}: {exc}"))
    finally:
        with contextlib.suppress(Exception):
            conn.close()
        # Let the queue's feeder thread flush what is left, then end.
        with contextlib.suppress(Exception):
            events.close()
            events.join_thread()


class _LinkWorker:
    """Owns the port in the link process: reads, forwards, writes RC and heartbeat on deadlines."""

    def __init__(
        self,
        url: str,
        cfg: BoardClientConfig,
        shared: _Shared,
        conn: mpc.Connection,
        events: Any,
        reconnect: bool,
    ) -> None:
        self.url = url
        self.cfg = cfg
        self.sh = shared
        self.conn = conn
        self.events = events
        self.rx_dropped = 0
        self.reconnect = reconnect
        self.port: Any = None
        self.fd: int | None = None
        self.gen = 0
        self.stop = False
        self.rc_last_us: int | None = None
        self.now_us = 0
        """The time of the current loop pass (the session's callbacks below run inside it)."""
        self.rc_slot_us: int | None = None
        """The slot of the RC frame the session just queued from shared memory (None: none queued)."""
        # The link's protocol state: seq, heartbeat clock, RC slots. It only sends; the host process
        # decodes what is received.
        self.session = HostSession(
            heartbeat_period_us=cfg.heartbeat_period_us,
            rc_period_us=cfg.rc_period_us,
            heartbeat_allowed=self._heartbeat_allowed,
            rc_source=self._rc_payload,
            keep_sent=False,
        )

    # ---------------------------------------------------------------- helpers

    def _post(self, *item: Any) -> None:
        # A queue (with its feeder thread) never blocks this loop, even when the host stalls; what a
        # stalled host cannot take is bounded: received bytes are dropped (and counted) past a limit.
        if item[0] == "rx":
            with contextlib.suppress(NotImplementedError, OSError):
                if self.events.qsize() > _EVENTS_MAX:
                    self.rx_dropped += len(item[1])
                    return
        try:
            self.events.put(item)
        except (OSError, ValueError):
            self.stop = True

    def _flush(self) -> None:
        """Write what the session queued (link traffic, then RC: the order of their seqs in a poll)."""
        session = self.session
        link, rc = session.data_to_send(), session.rc_to_send()
        slot_us, self.rc_slot_us = self.rc_slot_us, None
        if not link and not rc:
            return
        data = link + rc if link and rc else link or rc
        try:
            self.port.write(data)
        except Exception as exc:
            self._lost(f"write failed: {exc}")
            return
        now = _now_us()
        self._post("tx", data, now)
        if slot_us is not None:
            self._rc_written(slot_us)

    def _open(self) -> str | None:
        try:
            self.port = open_port(self.url, timeout_s=0, exclusive=self.cfg.exclusive)
        except BoardLinkError as exc:
            return str(exc)
        fileno = getattr(self.port, "fileno", None)
        try:
            self.fd = int(fileno()) if fileno is not None else None
        except Exception:
            self.fd = None
        self.gen += 1
        now = _now_us()
        for _ in range(self.cfg.safe_frames_on_connect):
            self.session.send(VirtualRc(_SAFE_FRAME), now)
        self._flush()
        return None

    def _close(self) -> None:
        port, self.port, self.fd = self.port, None, None
        if port is not None:
            with contextlib.suppress(Exception):
                port.close()

    def _lost(self, reason: str) -> None:
        self._close()
        self.rc_last_us = None
        self._post("state", "disconnected", reason, self.gen)

    def _realtime(self) -> None:
        prio = self.cfg.rt_priority
        if prio is None:
            return
        try:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(prio))
            self.sh.realtime.value = 1
        except (OSError, AttributeError):
            self.sh.realtime.value = 0

    # ---------------------------------------------------------------- loop

    def run(self) -> None:
        self._realtime()
        gc.collect()
        gc.freeze()
        err = self._open()
        if err is not None:
            self._post("open_failed", err)
            return
        self._post("state", "connected", "", self.gen)
        cfg = self.cfg
        session = self.session
        next_retry = 0
        conn_fd = self.conn.fileno()
        while not self.stop:
            now = self.now_us = _now_us()
            if self.port is None:
                if not self.reconnect:
                    break
                if now >= next_retry:
                    next_retry = now + cfg.reconnect_period_us
                    if self._open() is None:
                        self._post("state", "connected", "", self.gen)
            # Polled while the port is down too: the slots pass (the callbacks send nothing then), so
            # a reconnect resumes on the same grids.
            session.poll(now)
            if self.port is not None:
                self._flush()
            # Sleep until the next deadline or until bytes / a host request arrive.
            deadline = session.next_deadline_us()
            timeout_s = 0.0 if deadline is None else max(0.0, (deadline - _now_us()) / 1e6)
            if self.port is None:
                timeout_s = min(timeout_s, 0.05)
            fds = [conn_fd] + ([self.fd] if self.fd is not None else [])
            try:
                ready, _, _ = select.select(
                    fds, [], [], timeout_s if self.fd is not None else min(timeout_s, 0.002)
                )
            except (OSError, ValueError):
                ready = []
            if self.port is not None and (self.fd is None or self.fd in ready):
                self._read()
            if conn_fd in ready or self.conn.poll(0):
                self._requests()
        if self.port is not None:
            session.send(VirtualRc(_SAFE_FRAME), _now_us())
            with contextlib.suppress(Exception):
                self.port.write(session.data_to_send() + session.rc_to_send())
        self._close()

    def _heartbeat_allowed(self, now: int) -> bool:
        """The session's heartbeat gate: a port, and a host that renewed its lease."""
        return self.port is not None and now <= self.sh.lease_until_us.value

    def _rc_payload(self, slot_us: int) -> bytes | None:
        """The session's RC source: the host's frame from shared memory, if it may be sent now."""
        sh = self.sh
        if self.port is None:
            self.rc_last_us = None
            return None
        if self.now_us > sh.lease_until_us.value:
            if sh.rc_on.value:
                sh.lease_expired.value += 1
                sh.rc_on.value = 0
            self.rc_last_us = None
            return None
        if not sh.rc_on.value:
            self.rc_last_us = None
            return None
        self.rc_slot_us = slot_us
        # Until the host has seen this connection, only SAFE frames (right lever DOWN).
        return bytes(sh.rc) if sh.rc_gen.value == self.gen else _SAFE_FRAME

    def _rc_written(self, slot_us: int) -> None:
        """Timing statistics of a slot's RC frame that reached the port."""
        sh = self.sh
        now = self.now_us
        if now - slot_us > self.cfg.rc_period_us // 2:
            sh.rc_late.value += 1
        if self.rc_last_us is not None:
            gap = now - self.rc_last_us
            if gap > sh.rc_max_gap_us.value:
                sh.rc_max_gap_us.value = gap
            if gap > RC_TIMEOUT_US:
                sh.rc_gaps.value += 1
        self.rc_last_us = now

    def _read(self) -> None:
        try:
            # Non-blocking port (timeout 0): read() takes what is buffered. Not in_waiting: pyserial's
            # socket:// reports only 0 or 1 there. A vanished device raises (pty EIO, socket EOF).
            data = self.port.read(65536)
        except Exception as exc:
            self._lost(f"read failed: {exc}")
            return
        if data:
            self._post("rx", bytes(data), _now_us())

    def _requests(self) -> None:
        try:
            while self.conn.poll(0):
                item = self.conn.recv()
                if item[0] == "send":
                    msg: Message = item[1]
                    if self.port is None:
                        self._post("tx_dropped", msg.CMD_ID)
                    else:
                        self.session.send(msg, _now_us())  # packed once by BoardClient.send already
                        self._flush()
                elif item[0] == "stop":
                    self.stop = True
                    return
        except (OSError, EOFError):
            self.stop = True


# ---------------------------------------------------------------------- the host side


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
        self._shared: _Shared | None = None
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
        self._shared = _Shared(self._ctx)
        self._renew_lease()
        child, parent = self._ctx.Pipe(duplex=False)  # host -> link process requests
        events = self._ctx.Queue()  # link process -> host: bytes, states, sent frames
        proc = self._ctx.Process(
            target=_link_main,
            args=(self.url, self.config, self._shared, child, events, self._reconnect),
            name="board-link",
            daemon=True,
        )
        proc.start()
        child.close()
        self._proc = proc
        self._conn = parent
        self._events = events
        self._set_state(LinkState.CONNECTING)
        # Wait for the first word from the link process: open or not.
        first: Any = None
        deadline = time.monotonic() + self.config.open_timeout_s
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
        sh.lease_until_us.value = _now_us() + self.config.lease_us

    # ------------------------------------------------------------------ dispatching

    def _dispatch_loop(self) -> None:
        poll_s = self.config.rc_poll_period_us / 1e6
        events = self._events
        proc = self._proc
        next_lease = 0.0
        while not self._stop.is_set() and events is not None:
            now = time.monotonic()
            if now >= next_lease:
                next_lease = now + poll_s
                self._renew_lease()
            try:
                item = events.get(timeout=poll_s)
            except queue.Empty:
                if proc is not None and not proc.is_alive() and not self._stop.is_set():
                    _log.error("board link process ended unexpectedly")
                    self._connected.clear()
                    self._set_state(LinkState.DISCONNECTED)
                    break
                continue
            except (EOFError, OSError, ValueError):
                break
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
        now = _now_us() if rx_us is None else rx_us
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
        now = _now_us()
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
                rc_late=int(sh.rc_late.value) if sh else 0,
                rc_max_gap_us=int(sh.rc_max_gap_us.value) if sh else 0,
                rc_gaps_over_timeout=int(sh.rc_gaps.value) if sh else 0,
                lease_expired=int(sh.lease_expired.value) if sh else 0,
                realtime=bool(sh.realtime.value) if sh else False,
                latency_us=latency,
                rtt_us=rtt,
                last_rx_age_us=None if self._last_rx_us is None else now - self._last_rx_us,
            )
