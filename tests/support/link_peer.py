"""A scripted fake board for host unit tests: the far end of a real pty or TCP socket.

It speaks the board link (``protocol.link`` + ``protocol.messages``): sends ``Telemetry`` at 100 Hz and
``SimPoses`` at 50 Hz, decodes and records every host -> board message, and runs a toy "firmware" so
host tests can see cause and effect: valid RC with the right lever DOWN passes the gate, MIDDLE is MANUAL,
the left stick vertical (ch3) sets the common tension target, ``ESTOP`` latches zero current.

This is a unit-test fake only; the real virtual board is ``hil.board``.
"""

from __future__ import annotations

import contextlib
import errno
import os
import socket
import threading
import time
import tty
from typing import Any

from protocol.dbus import Lever, RcFrame
from protocol.link import LinkParser
from protocol.messages import (
    AckResult,
    Command,
    CommandAck,
    CommandCode,
    Message,
    Mode,
    Phase,
    SimPoses,
    Telemetry,
    TelemetryFlags,
    VirtualRc,
    decode,
    encode,
)

UNITS = 21


class LinkPeer:
    """Fake board on a pty (``kind="pty"``) or a TCP listener (``kind="socket"``).

    Attributes:
        url: what the host opens (a /dev/pts path or socket://127.0.0.1:PORT).
        received: every decoded host -> board message, in order.
    """

    def __init__(self, kind: str = "socket") -> None:
        self.kind = kind
        self.received: list[Message] = []
        self.lock = threading.Lock()
        self._stop = threading.Event()
        self._seq = 0
        self._parser = LinkParser()
        self.phase = Phase.GATE
        self.mode = Mode.SAFE
        self.tension = 0.0
        self.rc: RcFrame | None = None
        self.rc_time = 0.0
        self.rc_last_arrival = 0.0
        self.rc_max_gap_s = 0.0
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

    def messages(self, kind: type[Message]) -> list[Message]:
        with self.lock:
            return [m for m in self.received if isinstance(m, kind)]

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
        t0 = time.monotonic()
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
                        self._on_message(decode(frame), frame.seq)
            now = time.monotonic()
            self._firmware(now)
            if now >= next_tel:
                next_tel += 0.01
                self._write(self._telemetry(now - t0))
            if now >= next_pose:
                next_pose += 0.02
                self._write(self._poses(now - t0))
            time.sleep(0.002)

    # ------------------------------------------------------------------ toy firmware

    def _on_message(self, msg: Message, seq: int) -> None:
        with self.lock:
            self.received.append(msg)
        if isinstance(msg, VirtualRc):
            now = time.monotonic()
            if self.rc_last_arrival:
                self.rc_max_gap_s = max(self.rc_max_gap_s, now - self.rc_last_arrival)
            self.rc_last_arrival = now
            frame = msg.frame
            if frame.is_valid():
                self.rc = frame
                self.rc_time = time.monotonic()
        elif isinstance(msg, Command):
            if msg.code == CommandCode.ESTOP:
                self.phase = Phase.ESTOP
            self._write(CommandAck(msg.code, AckResult.ACCEPTED, seq, "ok"))

    def _firmware(self, now: float) -> None:
        rc = self.rc
        if self.phase == Phase.ESTOP:
            self.mode = Mode.SAFE
        elif rc is None or now - self.rc_time > 0.03:
            if self.phase != Phase.GATE:
                self.phase = Phase.RC_LOST
        elif self.phase in (Phase.GATE, Phase.RC_LOST):
            if rc.right_lever == Lever.DOWN:
                self.phase = Phase.OK
        elif self.phase == Phase.OK:
            self.mode = {Lever.DOWN: Mode.SAFE, Lever.MIDDLE: Mode.MANUAL, Lever.UP: Mode.GRASP}[
                Lever(rc.right_lever)
            ]
        if self.phase == Phase.OK and self.mode == Mode.MANUAL and rc is not None:
            self.tension = 0.5 + max(0, rc.channels[3]) / 660 * 8.0
        else:
            self.tension = 0.0

    def _telemetry(self, t_s: float) -> Telemetry:
        rc = self.rc
        flags = TelemetryFlags.SIM
        if self.phase == Phase.OK:
            flags |= TelemetryFlags.ARMED | TelemetryFlags.RC_OK
        cur = int(self.tension * 0.01 / 0.18 * 1000)
        return Telemetry(
            time_us=int(t_s * 1e6),
            mode=self.mode,
            phase=self.phase,
            flags=flags,
            motors_online=0b111,
            rc_channels=rc.channels if rc else (0, 0, 0, 0),
            right_lever=rc.right_lever if rc else 0,
            left_lever=rc.left_lever if rc else 0,
            commanded_current=(cur, cur, cur),
            motor_current=(cur, cur, cur),
            tension_target_n=(self.tension, self.tension, self.tension),
            tension_est_n=(self.tension, self.tension, self.tension),
            cable_length_m=(0.001 * self.tension,) * 3,
        )

    def _poses(self, t_s: float) -> SimPoses:
        import math

        pos = [(0.0, 0.0, 1.2)]
        quat = [(1.0, 0.0, 0.0, 0.0)]
        bend = 0.02 * self.tension
        x, z = 0.0, 1.17
        for i in range(UNITS):
            ang = bend * i
            pos.append((x, 0.0, z))
            quat.append((math.cos(ang / 2), 0.0, math.sin(ang / 2), 0.0))
            step = 0.015 * 1.075 ** (-i)
            x += step * math.sin(ang)
            z -= step * math.cos(ang)
        return SimPoses(int(t_s * 1e6), tuple(pos), tuple(quat))


def _serve(kind: str, urls: Any, stop: Any) -> None:
    with LinkPeer(kind) as peer:
        urls.put(peer.url)
        stop.wait(120.0)


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
