"""The board link's own process: it owns the port and is an I/O shell around ``HostSession``.

Why a separate process owns the port: the board drops an RC stream after 30 ms without a valid frame
(DJI's figure) and latches the loss until the operator re-arms through SAFE, while virtual RC frames go
out every 14 ms (the DR16's rate). Sent from a thread of the host process, frames were measured 35-58 ms
apart several times in 10 s whenever a browser was attached (viser, numpy and Chromium's software
rendering contend for the GIL and both cores). So a small **link process** (SCHED_FIFO priority 20 when
permitted, below the virtual board's 50) opens the port, writes the ``Heartbeat`` every 100 ms and the
host's RC frame every 14 ms on absolute deadlines, forwards received bytes to the host process, and
writes whatever the host sends. The host process (:class:`host.link.client.BoardClient`) parses,
decodes and dispatches.

One clock for the radio: the host pushes its DBUS frame here once, when it changes (``("rc", bytes)``
on the request pipe, in order with everything else it sends); the RC slot of this process is the only
thing that samples it. Nothing else polls.

Safety of that split: the host renews a *lease* (shared memory) every few ms: liveness only, it carries
no data. When the host stalls longer than ``lease_us`` (1 s) this process stops both RC and heartbeat,
so a hung host still ends in zero current (RC lost after 30 ms; host lost when the board requires the
heartbeat); they resume with the lease. When the device vanishes this process retries until it comes
back; after every (re)connect it sends only neutral right-lever-DOWN frames until the host has seen
that connection (``("rc_gen", generation)``, sent after its listeners reset their levers), so the
start-up gate is always passed from SAFE. A restarted process begins with the host's last frame and no
connection seen: SAFE frames again.
"""

from __future__ import annotations

import contextlib
import gc
import multiprocessing.connection as mpc
import os
import select
import signal
import time
from typing import Any, Protocol

import serial

from controller.config import FailsafeConfig
from controller.transport import set_tcp_nodelay
from protocol.dbus import RcFrame
from protocol.messages import Command, Message, VirtualRc
from protocol.session import HostSession

__all__ = [
    "RC_TIMEOUT_US",
    "BoardLinkError",
    "LinkShared",
    "LinkTiming",
    "link_main",
    "now_us",
    "open_port",
]

RC_TIMEOUT_US = FailsafeConfig().rc_timeout_us
"""The board's RC-lost timeout (DJI detect task: 30 ms); a longer gap between virtual RC frames is a loss."""

_SAFE_FRAME = RcFrame.neutral().pack()


class BoardLinkError(Exception):
    """The board link cannot be opened (wrong path, busy device, refused connection)."""


class LinkTiming(Protocol):
    """What the link process reads of the client's configuration (``BoardClientConfig`` has it all)."""

    @property
    def heartbeat_period_us(self) -> int:
        """``Heartbeat`` period."""

    @property
    def rc_period_us(self) -> int:
        """``VirtualRc`` period."""

    @property
    def reconnect_period_us(self) -> int:
        """Pause between attempts to reopen a vanished port."""

    @property
    def safe_frames_on_connect(self) -> int:
        """Neutral right-lever-DOWN frames sent right after (re)connecting."""

    @property
    def rt_priority(self) -> int | None:
        """SCHED_FIFO priority of the link process (None: normal priority)."""

    @property
    def exclusive(self) -> bool:
        """Lock a device port against a second opener."""


def now_us() -> int:
    """The link's clock in µs (monotonic); the host and the link process compare its readings (lease)."""
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


class LinkShared:
    """Shared memory between the host and its link process (lock-free single-writer fields).

    The host writes only its lease; the link process writes its RC statistics. Data (the RC frame, the
    messages to send) travels on the request pipe, in order.
    """

    def __init__(self, ctx: Any) -> None:
        self.lease_until_us = ctx.Value("q", 0, lock=False)
        """Host liveness: the link process sends RC and heartbeats only until then (its clock, µs)."""
        self.rc_late = ctx.Value("q", 0, lock=False)
        self.rc_max_gap_us = ctx.Value("q", 0, lock=False)
        self.rc_gaps = ctx.Value("q", 0, lock=False)
        self.lease_expired = ctx.Value("q", 0, lock=False)
        self.realtime = ctx.Value("b", 0, lock=False)


_EVENTS_MAX = 20_000
"""Undelivered events the link process keeps for a stalled host before it drops received bytes."""


def link_main(
    url: str,
    cfg: LinkTiming,
    shared: LinkShared,
    conn: mpc.Connection,
    events: Any,
    reconnect: bool,
    rc_frame: bytes | None = None,
) -> None:
    """Body of the link process (module level so the spawn start method can import it).

    Args:
        url: pyserial URL or device path of the board link.
        cfg: the link's timing (a :class:`host.link.client.BoardClientConfig`).
        shared: the host's lease and the link's RC statistics.
        conn: requests from the host, handled in order: ``("send", msg, ticket)`` (ticket 0: nobody
            awaits its seq), ``("rc", frame_bytes | None)`` (the RC frame from now on; None: no RC),
            ``("rc_gen", generation)`` (the host has seen that connection), ``("stop",)``.
        events: to the host: ``("rx", bytes, t_us)``, ``("tx", bytes, t_us, counts)`` (counts: frames
            written per message type), ``("sent", ticket, seq, t_us)`` (a ``Command`` written),
            ``("tx_dropped", cmd_id, ticket)``, ``("state", "connected" | "disconnected", reason,
            generation)``, ``("open_failed", reason)``.
        reconnect: retry a vanished port (otherwise end on the first loss).
        rc_frame: the host's RC frame when this process starts (a restarted process keeps sending the
            operator's radio, SAFE until the host has seen its connection).
    """
    # A terminal's Ctrl-C reaches the whole process group. The host shuts this process down in order
    # (a last SAFE frame, then the port closed); dying of KeyboardInterrupt here would skip that.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        _LinkWorker(url, cfg, shared, conn, events, reconnect, rc_frame).run()
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
        cfg: LinkTiming,
        shared: LinkShared,
        conn: mpc.Connection,
        events: Any,
        reconnect: bool,
        rc_frame: bytes | None,
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
        """The slot of the RC frame the session just queued (None: none queued)."""
        self.rc_frame = rc_frame
        """The host's DBUS frame (None: the host sends no RC)."""
        self.rc_gen = -1
        """The connection generation the host has seen (frames are SAFE until it is this one)."""
        self.lapsed = False
        """The lease ran out while RC was on (counted once per lapse)."""
        self.tx_counts: dict[str, int] = {}
        """Frames queued since the last write, per message type (sent to the host with the bytes)."""
        self.tx_tickets: list[tuple[int, int]] = []
        """(ticket, seq) of the ``Command`` frames queued since the last write."""
        self._hb_queued = 0
        self._rc_queued = 0
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
        counts, self.tx_counts = self.tx_counts, {}
        tickets, self.tx_tickets = self.tx_tickets, []
        # The session's own frames (heartbeats, RC slots) counted by what it says it queued.
        for name, now_n, attr in (
            ("Heartbeat", session.heartbeats_sent, "_hb_queued"),
            ("VirtualRc", session.rc_frames_sent, "_rc_queued"),
        ):
            before = getattr(self, attr)
            if now_n != before:
                counts[name] = counts.get(name, 0) + now_n - before
                setattr(self, attr, now_n)
        if not link and not rc:
            return
        data = link + rc if link and rc else link or rc
        try:
            self.port.write(data)
        except Exception as exc:
            self._lost(f"write failed: {exc}")
            return
        now = now_us()
        self._post("tx", data, now, counts)
        for ticket, seq in tickets:
            self._post("sent", ticket, seq, now)
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
        now = now_us()
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
            now = self.now_us = now_us()
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
            timeout_s = 0.0 if deadline is None else max(0.0, (deadline - now_us()) / 1e6)
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
            session.send(VirtualRc(_SAFE_FRAME), now_us())
            with contextlib.suppress(Exception):
                self.port.write(session.data_to_send() + session.rc_to_send())
        self._close()

    def _heartbeat_allowed(self, now: int) -> bool:
        """The session's heartbeat gate: a port, and a host that renewed its lease."""
        return self.port is not None and now <= self.sh.lease_until_us.value

    def _rc_payload(self, slot_us: int) -> bytes | None:
        """The session's RC source: the host's frame, if it may be sent now (the only RC clock)."""
        frame = self.rc_frame
        if self.port is None or frame is None:
            self.rc_last_us = None
            return None
        if self.now_us > self.sh.lease_until_us.value:
            if not self.lapsed:  # the host stalled: no stale sticks, and the board times out to zero
                self.lapsed = True
                self.sh.lease_expired.value += 1
            self.rc_last_us = None
            return None
        self.lapsed = False
        self.rc_slot_us = slot_us
        # Until the host has seen this connection, only SAFE frames (right lever DOWN).
        return frame if self.rc_gen == self.gen else _SAFE_FRAME

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
            self._post("rx", bytes(data), now_us())

    def _requests(self) -> None:
        try:
            while self.conn.poll(0):
                item = self.conn.recv()
                kind = item[0]
                if kind == "send":
                    msg: Message = item[1]
                    ticket: int = item[2]
                    if self.port is None:
                        self._post("tx_dropped", msg.CMD_ID, ticket)
                    else:
                        seq = self.session.send(msg, now_us())  # packed once by BoardClient.send already
                        name = type(msg).__name__
                        self.tx_counts[name] = self.tx_counts.get(name, 0) + 1
                        if isinstance(msg, Command):
                            self.tx_tickets.append((ticket, seq))
                        self._flush()
                elif kind == "rc":
                    self.rc_frame = item[1]
                elif kind == "rc_gen":
                    self.rc_gen = item[1]
                elif kind == "stop":
                    self.stop = True
                    return
        except (OSError, EOFError):
            self.stop = True
