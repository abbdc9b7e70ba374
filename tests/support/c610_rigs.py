"""C610 test rigs that run in a thread: a fake C610 set on a python-can bus, or behind an slcan adapter.

- :class:`C610SetServer` answers every tick's commands on a python-can bus (0x200, and 0x1FF for a set of
  more than four) with the feedback of motors 1..n (0x201..0x200+n); a trio by default;
- :class:`SlcanAdapterEmulator` is a USB-CAN adapter speaking slcan on a pty, a trio behind it, so that
  ``CanMotorBus(interface="slcan", channel=<pty slave>)`` is tested end to end;
- :class:`SlcanAdapterProcess` runs that adapter in a process of its own, for a firmware that runs in
  another: a thread would answer in bursts whenever the test's own threads hold its interpreter.
"""

from __future__ import annotations

import contextlib
import multiprocessing
import os
import select
import threading
import tty
from types import TracebackType
from typing import Any

from controller.fake_c610 import FakeC610Set
from protocol.c610 import COMMAND_ID_HIGH, COMMAND_ID_LOW, MOTORS_PER_COMMAND

__all__ = ["C610SetServer", "SlcanAdapterEmulator", "SlcanAdapterProcess"]


class _Worker:
    """A worker thread with a stop flag, joined by :meth:`stop` (safe twice; daemon, so a failed test
    cannot hang the interpreter)."""

    def __init__(self, name: str) -> None:
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._loop, name=name, daemon=True)
        self.error: BaseException | None = None

    def start(self) -> None:
        """Start serving."""
        self._thread.start()

    def stop(self) -> None:
        """Stop serving and join the thread (safe twice)."""
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout=5.0)

    def _loop(self) -> None:
        try:
            while not self._stop.is_set():
                self._poll()
        except BaseException as exc:
            self.error = exc

    def _poll(self) -> None:
        raise NotImplementedError


class C610SetServer(_Worker):
    """Answers each tick's commands on a python-can bus with the set's feedback (a thread).

    Every 0x200 / 0x1FF frame sets its motors' currents; the set steps and answers on the tick's last
    frame: 0x200 for up to four motors, 0x1FF above (a board sends 0x200 first). Use as a context manager;
    the bus given is shut down on exit.
    """

    def __init__(self, bus: Any, c610s: FakeC610Set | None = None, *, dt_us: int = 1000) -> None:
        """Serve ``c610s`` (default: a fresh trio) on the python-can ``bus``; each tick steps ``dt_us``."""
        super().__init__("c610-set")
        import can

        self._can = can
        self.bus = bus
        self.c610s = c610s if c610s is not None else FakeC610Set()
        self.dt_us = dt_us
        self._step_id = COMMAND_ID_HIGH if len(self.c610s.motors) > MOTORS_PER_COMMAND else COMMAND_ID_LOW

    def __enter__(self) -> C610SetServer:
        self.start()
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.stop()
        self.bus.shutdown()

    def _poll(self) -> None:
        msg = self.bus.recv(timeout=0.01)
        if msg is None or msg.is_extended_id or msg.arbitration_id not in (COMMAND_ID_LOW, COMMAND_ID_HIGH):
            return
        self.c610s.handle_frame(msg.arbitration_id, bytes(msg.data))
        if msg.arbitration_id != self._step_id:
            return
        for can_id, data in self.c610s.step(self.dt_us):
            self.bus.send(self._can.Message(arbitration_id=can_id, data=data, is_extended_id=False))


class SlcanAdapterEmulator(_Worker):
    """A USB-CAN adapter speaking the slcan (Lawicel) ASCII protocol on a pty master, trio behind it.

    Answers ``S<n>``, ``O``, ``C``, ``L``, ``V``, ``v``, ``N`` with ``\\r`` (version queries with a
    version), and each ``t200 8 ...`` command with three ``t20n8...`` feedback lines. Use as a context
    manager; ``fd`` (the pty master) is closed on exit.

    Attributes:
        lines: slcan lines received (for assertions).
        is_open: the host sent ``O`` (and not ``C`` since).
    """

    def __init__(self, fd: int, c610s: FakeC610Set | None = None, *, dt_us: int = 1000) -> None:
        """Serve on the pty master ``fd``."""
        super().__init__("slcan-adapter")
        self.fd = fd
        self.c610s = c610s if c610s is not None else FakeC610Set()
        self.dt_us = dt_us
        self.lines: list[str] = []
        self.is_open = False
        self._buf = bytearray()

    def __enter__(self) -> SlcanAdapterEmulator:
        self.start()
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.stop()
        with contextlib.suppress(OSError):
            os.close(self.fd)

    def _poll(self) -> None:
        ready, _, _ = select.select([self.fd], [], [], 0.01)
        if not ready:
            return
        try:
            data = os.read(self.fd, 4096)
        except OSError:  # the slave side closed: nothing more to serve
            self._stop.wait(0.01)
            return
        self._buf += data
        while True:
            end = self._buf.find(b"\r")
            if end < 0:
                break
            line = self._buf[:end].decode("ascii", errors="replace")
            del self._buf[: end + 1]
            self._handle(line)

    def _handle(self, line: str) -> None:
        self.lines.append(line)
        if not line:
            return
        cmd = line[0]
        reply = b"\r"
        if cmd == "O" or cmd == "L":
            self.is_open = True
        elif cmd == "C":
            self.is_open = False
        elif cmd == "V":
            reply = b"V1013\r"
        elif cmd == "v":
            reply = b"v1013\r"
        elif cmd == "N":
            reply = b"NA123\r"
        elif cmd == "t" and len(line) >= 5:
            can_id = int(line[1:4], 16)
            dlc = int(line[4])
            data = bytes.fromhex(line[5 : 5 + 2 * dlc])
            self.c610s.handle_frame(can_id, data)
            reply = b"\r" if not self.is_open else b""
            if can_id == COMMAND_ID_LOW and self.is_open:
                for fid, fdata in self.c610s.step(self.dt_us):
                    reply += f"t{fid:03X}8{fdata.hex().upper()}\r".encode("ascii")
        self._write(reply)

    def _write(self, data: bytes) -> None:
        view = memoryview(data)
        while view:
            try:
                n = os.write(self.fd, view)
            except BlockingIOError:
                select.select([], [self.fd], [], 0.01)
                continue
            view = view[n:]


def _serve_slcan(fd: int, stop: Any, out: Any) -> None:
    """The body of :class:`SlcanAdapterProcess`: serve until ``stop`` is set, then report on ``out``."""
    with SlcanAdapterEmulator(fd) as adapter:
        stop.wait(120.0)  # bounded: the test's own time-out is far shorter
    trio = adapter.c610s
    out.send(
        {
            "error": repr(adapter.error) if adapter.error is not None else None,
            "lines": [line for line in adapter.lines if not line.startswith("t")],
            "commands": trio.commands,
            "currents_raw": [m.current_raw for m in trio.motors],
        }
    )


class SlcanAdapterProcess:
    """:class:`SlcanAdapterEmulator` in a child process (forked), on a pty it opens; ``path`` is the
    adapter's port. On exit :attr:`summary` holds the adapter's error, its non-frame lines (``S8``,
    ``O``, ...), the commands the trio took and the trio's last currents."""

    def __init__(self) -> None:
        self._master, self._slave = os.openpty()
        tty.setraw(self._slave)
        self.path = os.ttyname(self._slave)
        ctx = multiprocessing.get_context("fork")
        self._stop = ctx.Event()
        self._recv, send = ctx.Pipe(duplex=False)
        self._proc = ctx.Process(target=_serve_slcan, args=(self._master, self._stop, send), daemon=True)
        self.summary: dict[str, Any] = {}

    def __enter__(self) -> SlcanAdapterProcess:
        self._proc.start()
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self._stop.set()
        if self._recv.poll(10.0):
            self.summary = self._recv.recv()
        self._proc.join(timeout=5.0)
        if self._proc.is_alive():
            self._proc.kill()
            self._proc.join(timeout=5.0)
        for fd in (self._master, self._slave):
            with contextlib.suppress(OSError):
                os.close(fd)
