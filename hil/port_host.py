"""The host's end of a board link on a real port, in real time: an I/O shell around ``HostSession``.

Everything the link protocol needs (the sequence counter, the 10 Hz heartbeat and 14 ms RC grids, command
tokens and their acks, the parameter table, decoding that never raises) is the sans-I/O
:class:`protocol.session.HostSession`. This module only adds what a port needs around it: opening and
reopening the port, a reader thread, the emulated link faults on the bytes each way, a recording of the
bytes, and the board's own messages read off the bytes before the emulated noise (what the run record's
checks judge the board by).
"""

from __future__ import annotations

import contextlib
import queue
import select
import threading
from collections.abc import Callable
from typing import Final

from controller.clock import RealTimeClock
from controller.config import CONTROL_PERIOD_US
from controller.errors import PortError
from controller.transport import SerialTransport
from hil import foxglove_log, recording
from hil.errors import HilError
from hil.faults import FaultSet
from hil.foxglove_log import telemetry_json
from hil.recording import Recorder
from protocol.dbus import RcFrame
from protocol.messages import Event, Message, RawRc, Telemetry
from protocol.session import HostSession
from protocol.stream import MessageStream

__all__ = ["LOOP_PERIOD_US", "PortHost"]

LOOP_PERIOD_US: Final = CONTROL_PERIOD_US
"""The host loop's period, the board's tick: RC, heartbeat and command times are quantised to it."""
_REOPEN_TIMEOUT_US = 2_000_000
_EOF_READS = 200  # readable but empty this many times in a row (>= 1 ms apart): the board closed the link
_READER_POLL_S = 0.01  # the reader thread checks for a stop this often


def _open(port: str) -> SerialTransport:
    try:
        transport = SerialTransport(port)
    except PortError as exc:
        raise HilError(str(exc).splitlines()[0] if str(exc) else f"cannot open {port}") from exc
    with contextlib.suppress(Exception):  # stale bytes a pty kept while nobody listened
        transport.serial.reset_input_buffer()
    return transport


def _fileno(transport: SerialTransport) -> int | None:
    try:
        fd = int(transport.serial.fileno())
    except Exception:  # loop:// and friends: no descriptor, the reader polls every period instead
        return None
    return fd


class _Reader:
    """Reads the port on a thread of its own and queues what arrives with its receive time.

    Why a thread: on a pty, ``read`` and ``poll`` wait for the kernel's tty flush worker, a
    normal-priority kworker; on a shared machine a real-time host loop was measured waiting 20-80 ms in
    them, long enough to miss two RC frames (an RC loss the board rightly latches). Writes never wait for
    it, so the loop that sends RC and heartbeats on time never reads the port itself.
    """

    def __init__(self, transport: SerialTransport, clock: RealTimeClock) -> None:
        self.transport = transport
        self.clock = clock
        self.fd = _fileno(transport)
        self.queue: queue.SimpleQueue[tuple[int, bytes]] = queue.SimpleQueue()
        self.closed = False
        """The port reported end of file (the board closed the link)."""
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="board-link-reader", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        empty = 0
        while not self._stop.is_set():
            if self.fd is not None:
                try:
                    readable, _, _ = select.select([self.fd], [], [], _READER_POLL_S)
                except (OSError, ValueError):  # closed under us
                    return
                if not readable:
                    continue
            data = self.transport.read()
            if data:
                empty = 0
                self.queue.put((self.clock.now_us(), data))
                continue
            if self.fd is not None:  # readable but empty: end of file, or an error
                empty += 1
                if empty >= _EOF_READS:
                    self.closed = True
                    return
            self._stop.wait(LOOP_PERIOD_US / 1e6)

    def drain(self) -> list[tuple[int, bytes]]:
        """Everything received so far, oldest first."""
        out: list[tuple[int, bytes]] = []
        with contextlib.suppress(queue.Empty):
            while True:
                out.append(self.queue.get_nowait())
        return out

    def stop(self) -> None:
        """Stop and join the thread (safe twice)."""
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout=2.0)


class PortHost:
    """A :class:`~protocol.session.HostSession` on a port, ticked by a real-time loop.

    Times are the host's CLOCK_MONOTONIC in µs. While a scenario runs (:meth:`start_scenario`), the
    session's link traffic crosses the emulated link faults both ways; its ``VirtualRc`` frames do not
    (they stand in for the radio, which has its own wire in lockstep). ``offset_us`` (host receive time
    minus board time, the smallest seen) maps host times to board times.

    Args:
        port: a device path, pty path or pyserial URL.
        clock: the loop's clock.
        recorder: records the bytes on the link (board's view: ``link_rx`` what reached it after the
            emulated faults, ``link_tx`` what it sent before them) and the decoded telemetry.

    Raises:
        HilError: the port cannot be opened (one line).
    """

    def __init__(self, port: str, clock: RealTimeClock, recorder: Recorder | None = None) -> None:
        self.port = port
        self.clock = clock
        self.recorder = recorder
        self.session = HostSession()
        self.transport: SerialTransport | None = _open(port)
        self._reader: _Reader | None = _Reader(self.transport, clock)
        self._board = MessageStream()
        self.faults: FaultSet | None = None
        self.t0_us = 0
        self.commands: list[tuple[int, Message]] = []
        self.telemetry: list[Telemetry] = []
        self.board_telemetry_us: list[int] = []
        self.board_rc: list[tuple[int, RcFrame]] = []
        self.board_events: list[Event] = []
        self.rc_sent_us: list[int] = []
        self.reconnects_us: list[int] = []
        self.offset_us: int | None = None
        self.counters: dict[str, int] = {}
        self._down_since: int | None = None

    # --- the loop ---------------------------------------------------------------------------------

    def tick(self, now_us: int) -> None:
        """One host period: connection per faults, receive, what is due, send."""
        self._connection(now_us)
        self._receive(now_us)
        session = self.session
        session.poll(now_us)
        while self.commands and self.commands[0][0] <= now_us:
            session.send(self.commands.pop(0)[1], now_us)
        if self.transport is None:  # unplugged: what was due is lost, as on a real cable
            session.data_to_send()
            session.rc_to_send()
            return
        rc = session.rc_to_send()
        if rc:
            self._write(rc)
            self.rc_sent_us.append(now_us)
        data = session.data_to_send()
        if self.faults is not None:
            data = self.faults.link_bytes(now_us - self.t0_us, data, "rx")
        self._write(data)

    def run_until(self, end_us: int, done: Callable[[], bool] | None = None) -> bool:
        """Tick every :data:`LOOP_PERIOD_US` until ``end_us`` or until ``done()``; True if done."""
        clock = self.clock
        next_tick = clock.now_us()
        for _ in range(2 * max(0, end_us - next_tick) // LOOP_PERIOD_US + 10):
            now = clock.now_us()
            if now >= end_us:
                return False
            self._note_max("loop_late_max_us", now - next_tick)
            self.tick(now)
            self._note_max("tick_exec_max_us", clock.now_us() - now)
            if done is not None and done():
                return True
            next_tick += LOOP_PERIOD_US
            if now - next_tick >= LOOP_PERIOD_US:  # late: skip the missed ticks, never burst
                next_tick = now + LOOP_PERIOD_US
            clock.sleep_until_us(min(next_tick, end_us))
        return False

    def start_scenario(self, t0_us: int, faults: FaultSet) -> None:
        """From ``t0_us`` on, scenario time runs, the link faults apply and the grids restart."""
        self.t0_us = t0_us
        self.faults = faults
        self.session.restart_grids()

    def stop_scenario(self) -> None:
        """No more faults or scripted commands (what the faults held back is dropped)."""
        self.faults = None
        self.commands.clear()

    def close(self) -> None:
        """Stop the reader and release the port (safe twice)."""
        if self._reader is not None:
            self._reader.stop()
            self._reader = None
        if self.transport is not None:
            self.transport.close()
            self.transport = None

    # --- inside -----------------------------------------------------------------------------------

    def _write(self, data: bytes) -> None:
        if self.transport is not None and data:
            self.transport.write(data)
            if self.recorder is not None:
                self.recorder.write_raw(recording.LINK_RX, self.clock.now_us(), data)

    def _receive(self, now_us: int) -> None:
        """Take what the reader thread queued (each chunk with its receive time) and decode it.

        Raises:
            HilError: the board closed the link.
        """
        reader = self._reader
        chunks = reader.drain() if reader is not None else []
        if reader is not None and reader.closed and not chunks:
            raise HilError(f"the board closed the link on {self.port}")
        faults = self.faults
        for t_us, data in chunks:
            if self.recorder is not None:
                self.recorder.write_raw(recording.LINK_TX, t_us, data)
            if faults is not None:
                self._watch_board(data)
                data = faults.link_bytes(t_us - self.t0_us, data, "tx")
            if data:
                self._dispatch(t_us, self.session.receive_data(data, t_us))
        if faults is not None:  # bytes a link-delay fault held back until now
            held = faults.link_bytes(now_us - self.t0_us, b"", "tx")
            if held:
                self._dispatch(now_us, self.session.receive_data(held, now_us))

    def _watch_board(self, data: bytes) -> None:
        """What the board sent, before the emulated noise: its telemetry times, the RC it received (with
        its receive times) and its events."""
        for _, msg in self._board.feed(data):
            if isinstance(msg, Telemetry):
                self.board_telemetry_us.append(msg.time_us)
            elif isinstance(msg, RawRc):
                self.board_rc.append((msg.time_us, msg.frame))
            elif isinstance(msg, Event):
                self.board_events.append(msg)

    def _dispatch(self, now_us: int, messages: list[Message]) -> None:
        for msg in messages:
            if isinstance(msg, Telemetry):
                self.telemetry.append(msg)
                if self.recorder is not None:
                    self.recorder.write_json(foxglove_log.TELEMETRY, now_us, telemetry_json(msg))
                lag = now_us - msg.time_us
                if self.offset_us is None or lag < self.offset_us:
                    self.offset_us = lag

    def _connection(self, now_us: int) -> None:
        down = self.faults is not None and self.faults.link_down(now_us - self.t0_us)
        if down and self.transport is not None:
            self.close()
            self._down_since = now_us
        elif not down and self.transport is None:
            try:
                self.transport = _open(self.port)
            except HilError:
                since = self._down_since if self._down_since is not None else now_us
                if now_us - since > _REOPEN_TIMEOUT_US:
                    raise
                return
            self._reader = _Reader(self.transport, self.clock)
            self._down_since = None
            self.reconnects_us.append(now_us)

    def _note_max(self, key: str, value: int) -> None:
        if self.faults is not None and value > self.counters.get(key, 0):  # only while a scenario runs
            self.counters[key] = value
