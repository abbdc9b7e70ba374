"""The scripted fake board on a real pty or TCP socket: the byte-level shell of ``FakeBoard``.

The toy firmware is ``tests/support/fake_board.py``'s :class:`~tests.support.fake_board.FakeBoard`, the
same one the drone-link tests drive in-process; this shell gives it the board's wire: it decodes the
host's frames (``protocol.link`` + ``protocol.messages``) and hands every message to the fake, writes its
replies, and sends ``Telemetry`` at 100 Hz and ``SimPoses`` at 50 Hz, as a simulated board starting in
GATE (no current until the radio's right lever has been seen DOWN). It can drop and resume the
connection and inject raw bytes.

This is a unit-test fake only; the real virtual board is ``hil.board``.
"""

from __future__ import annotations

import contextlib
import dataclasses
import errno
import os
import socket
import threading
import time
import tty
from typing import Any

from protocol.link import LinkParser
from protocol.messages import Message, Mode, Phase, SimPoses, Telemetry, TelemetryFlags, decode, encode
from tests.support.fake_board import FakeBoard


class LinkPeer:
    """Fake board on a pty (``kind="pty"``) or a TCP listener (``kind="socket"``).

    Attributes:
        url: what the host opens (a /dev/pts path or socket://127.0.0.1:PORT).
        board: the toy firmware behind the wire.
    """

    def __init__(self, kind: str = "socket") -> None:
        self.kind = kind
        self.board = FakeBoard(
            mode=Mode.SAFE,
            phase=Phase.GATE,
            armed=False,
            tension_n=(0.0, 0.0, 0.0),
            current_raw=(0, 0, 0),
            sim=True,
        )
        self._stop = threading.Event()
        self._seq = 0
        self._t0 = time.monotonic()
        self._parser = LinkParser()
        self.paused = threading.Event()  # set: stop sending and drop the connection
        self._conn: socket.socket | None = None
        self._master: int | None = None
        self._slave: int | None = None
        self._listener: socket.socket | None = None
        if kind == "pty":
            master, slave = os.openpty()
            tty.setraw(slave)
            self._master, self._slave = master, slave
            self.url = os.ttyname(slave)
        elif kind == "socket":
            self._listener = self._listen(0)
            self._port = self._listener.getsockname()[1]
            self.url = f"socket://127.0.0.1:{self._port}"
        else:
            raise ValueError(kind)
        self._thread = threading.Thread(target=self._run, name="link-peer", daemon=True)

    @staticmethod
    def _listen(port: int) -> socket.socket:
        s = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        s.bind(("127.0.0.1", port))
        s.listen(1)
        s.settimeout(0.05)
        return s

    def __enter__(self) -> LinkPeer:
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout=2.0)
        for fd in (self._master, self._slave):
            if fd is not None:
                with contextlib.suppress(OSError):
                    os.close(fd)
        self._master = self._slave = None
        if self._conn is not None:
            self._conn.close()
            self._conn = None
        if self._listener is not None:
            self._listener.close()
            self._listener = None

    def drop_connection(self) -> None:
        """Simulate an unplug: close the connection and stop listening until :meth:`resume`."""
        self.paused.set()

    def resume(self) -> None:
        """Plug back in: listen on the same port again."""
        self.paused.clear()

    def inject(self, data: bytes) -> None:
        """Write raw bytes to the host (garbage, partial frames)."""
        try:
            if self._master is not None:
                os.write(self._master, data)
            elif self._conn is not None:
                self._conn.sendall(data)
        except OSError:
            pass

    @property
    def received(self) -> list[Message]:
        """Every decoded host -> board message, in order (read it under :attr:`lock`)."""
        return self.board.received

    @property
    def lock(self) -> threading.Lock:
        """Held while the board handles a message or ticks."""
        return self.board.lock

    @property
    def phase(self) -> Phase:
        """The board's failsafe phase (a test may set it, e.g. ESTOP latched before a run)."""
        return self.board.phase

    @phase.setter
    def phase(self, value: Phase) -> None:
        self.board.set(phase=value)

    @property
    def mode(self) -> Mode:
        """The board's mode."""
        return self.board.mode

    def messages(self, kind: type[Message]) -> list[Message]:
        with self.lock:
            return [m for m in self.received if isinstance(m, kind)]

    def _now_us(self) -> int:
        return int((time.monotonic() - self._t0) * 1e6)

    # ------------------------------------------------------------------ io

    def _write(self, msg: Message) -> None:
        data = encode(msg, self._seq)
        self._seq = (self._seq + 1) & 0xFF
        try:
            if self._master is not None:
                os.write(self._master, data)
            elif self._conn is not None:
                self._conn.sendall(data)
        except OSError:
            pass

    def _read(self) -> bytes:
        if self._master is not None:
            try:
                os.set_blocking(self._master, False)
                return os.read(self._master, 4096)
            except BlockingIOError:
                return b""
            except OSError as exc:
                if exc.errno == errno.EIO:
                    return b""
                raise
        if self._conn is not None:
            try:
                data = self._conn.recv(4096)
            except (BlockingIOError, TimeoutError):
                return b""
            except OSError:
                data = b""
            if not data:
                self._conn.close()
                self._conn = None
            return data
        return b""

    def _run(self) -> None:
        next_tel = next_pose = time.monotonic()
        while not self._stop.is_set():
            if self._listener is not None:
                if self.paused.is_set():
                    if self._conn is not None:
                        self._conn.close()
                        self._conn = None
                    if self._listener.fileno() >= 0:
                        self._listener.close()
                    time.sleep(0.01)
                    continue
                if self._listener.fileno() < 0:
                    self._listener = self._listen(self._port)
                if self._conn is None:
                    try:
                        conn, _ = self._listener.accept()
                    except (TimeoutError, OSError):
                        continue
                    conn.settimeout(0.002)
                    self._conn = conn
                    self._parser.reset()
            data = self._read()
            if data:
                for frame in self._parser.feed(data):
                    with contextlib.suppress(Exception):
                        for reply in self.board.handle(decode(frame), frame.seq, self._now_us()):
                            self._write(reply)
            now = time.monotonic()
            if now >= next_tel:
                next_tel += 0.01
                self._write(self.board.tick(self._now_us()))
            if now >= next_pose:
                next_pose += 0.02
                self._write(self.board.poses())
            time.sleep(0.002)


def _serve(kind: str, urls: Any, stop: Any) -> None:
    with LinkPeer(kind) as peer:
        urls.put(peer.url)
        stop.wait(120.0)


class HardwarePeer(LinkPeer):
    """The scripted fake board made to look like hardware: no SIM flag, no SimPoses."""

    def _write(self, msg: Message) -> None:
        if isinstance(msg, SimPoses):
            return
        if isinstance(msg, Telemetry):
            msg = dataclasses.replace(msg, flags=msg.flags & ~TelemetryFlags.SIM)
        super()._write(msg)


class LinkPeerProcess:
    """:class:`LinkPeer` in its own process (like the real virtual board): only its URL is visible."""

    def __init__(self, kind: str = "socket") -> None:
        import multiprocessing as mp

        ctx = mp.get_context("spawn")
        self._urls = ctx.Queue()
        self._stop = ctx.Event()
        self._proc = ctx.Process(target=_serve, args=(kind, self._urls, self._stop), name="link-peer")
        self.url = ""

    def __enter__(self) -> LinkPeerProcess:
        self._proc.start()
        self.url = self._urls.get(timeout=30.0)
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._proc.join(timeout=5.0)
        if self._proc.is_alive():
            self._proc.kill()
            self._proc.join()
        self._urls.close()
        self._urls.join_thread()
