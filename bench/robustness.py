"""Robustness benchmark: hostile link input against a real-time virtual board on TCP loopback.

Run: ``.venv/bin/python bench/robustness.py [--seconds S]``. Starts a real-time virtual board
(``hil.board.VirtualBoardProcess``, its own process) and connects as its one host: virtual RC (lever
DOWN) every 14 ms and a heartbeat every 100 ms throughout. Then, S seconds each, a quiet baseline and four
floods on the same connection, as fast as the socket takes them: random garbage, long headers
(``A5 F4 01 <seq> <crc8>``, a valid header announcing 500 bytes), list-all ``ParamRequest`` frames, and
valid ``VirtualRc`` frames. Prints per phase the control task's worst start lateness (the board's own
``control_lateness_max_us`` rise, else its worst 1 s p99), late ticks, telemetry received per second,
and whether RC_LOST latched. Targets (printed, not asserted): no control tick
more than 1 ms late from link input, telemetry >= 90 Hz. A flood on the host's own connection queues
its RC frames behind it (in the sockets, then past the board's per-tick budget), so RC_LOST latching under
a flood is the failsafe doing its work: zero current, re-armed through SAFE.
"""

from __future__ import annotations

import argparse
import math
import os
import socket
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path

# Running this file puts bench/ first on sys.path, where bench/protocol.py would shadow the `protocol`
# package: put the repository root in front.
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from hil.board import VirtualBoardProcess
from protocol.dbus import RcFrame
from protocol.link import SOF, crc8
from protocol.messages import (
    Event,
    EventKind,
    Heartbeat,
    ParamRequest,
    Phase,
    Telemetry,
    VirtualRc,
    encode,
)
from protocol.stream import MessageStream

TARGET_LATENESS_US = 1000
TARGET_TELEMETRY_HZ = 90.0
_RC_PERIOD_S = 0.014
_HEARTBEAT_PERIOD_S = 0.1


def _long_headers(n: int) -> bytes:
    out = bytearray()
    for seq in range(n):
        head = bytes([SOF, 0xF4, 0x01, seq & 0xFF])
        out += head + bytes([crc8(head)])
    return bytes(out)


FLOODS: dict[str, Callable[[], bytes]] = {
    "garbage": lambda: os.urandom(4096),
    "long headers": lambda: _long_headers(800),
    "ParamRequest": lambda: b"".join(encode(ParamRequest(), k & 0xFF) for k in range(150)),
    "valid RC": lambda: b"".join(encode(VirtualRc(RcFrame.neutral().pack()), k & 0xFF) for k in range(150)),
}


class Host:
    """The board's one host: steady RC and heartbeats, a reader thread, an optional flood thread."""

    def __init__(self, url: str) -> None:
        address, port = url.removeprefix("socket://").rsplit(":", 1)
        self.sock = socket.create_connection((address, int(port)), timeout=5)
        self.sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self.lock = threading.Lock()  # one writer at a time: frames never interleave
        self.stream = MessageStream()
        self.telemetry: list[tuple[float, Telemetry]] = []
        self.phases: list[tuple[float, int]] = []
        self.stop = threading.Event()
        self.flood: bytes | None = None
        self._seq = 0
        self._threads = [
            threading.Thread(target=self._read, name="reader", daemon=True),
            threading.Thread(target=self._steady, name="steady", daemon=True),
            threading.Thread(target=self._flood, name="flood", daemon=True),
        ]
        for t in self._threads:
            t.start()

    def _send(self, data: bytes) -> None:
        with self.lock:
            self.sock.sendall(data)

    def _read(self) -> None:
        while not self.stop.is_set():
            try:
                data = self.sock.recv(65536)
            except TimeoutError:
                continue
            except OSError:
                return
            now = time.monotonic()
            for _, msg in self.stream.feed(data):
                if isinstance(msg, Telemetry):
                    self.telemetry.append((now, msg))
                elif isinstance(msg, Event) and msg.kind == EventKind.PHASE:
                    self.phases.append((now, msg.code))

    def _steady(self) -> None:
        rc = RcFrame.neutral().pack()
        next_hb = time.monotonic()
        while not self.stop.is_set():
            now = time.monotonic()
            frames = [VirtualRc(rc)]
            if now >= next_hb:
                frames.append(Heartbeat(int(now * 1e6), self._seq))
                next_hb += _HEARTBEAT_PERIOD_S
            data = b"".join(encode(m, (self._seq + k) & 0xFF) for k, m in enumerate(frames))
            self._seq = (self._seq + len(frames)) & 0xFF
            self._send(data)
            time.sleep(_RC_PERIOD_S)

    def _flood(self) -> None:
        while not self.stop.is_set():
            chunk = self.flood
            if chunk is None:
                time.sleep(0.005)
                continue
            self._send(chunk)

    def close(self) -> None:
        self.stop.set()
        self.flood = None
        for t in self._threads:
            t.join(timeout=2.0)
        self.sock.close()


def _phase(host: Host, name: str, flood: bytes | None, seconds: float) -> dict[str, float | str]:
    start = time.monotonic()
    before = host.telemetry[-1][1] if host.telemetry else None
    host.flood = flood
    time.sleep(seconds)
    host.flood = None
    end = time.monotonic()
    window = [m for t, m in host.telemetry if start <= t <= end]
    latched = any(code == Phase.RC_LOST for t, code in host.phases if start <= t <= end + 0.1)
    if not window:
        return {"phase": name, "telemetry_hz": 0.0, "worst_late_us": math.nan, "late": "-", "rc_lost": "?"}
    last = window[-1]
    max_before = before.control_lateness_max_us if before else 0
    rise = last.control_lateness_max_us if last.control_lateness_max_us > max_before else 0
    worst = max(rise, max(m.control_lateness_p99_us for m in window))
    late = last.control_late - (before.control_late if before else 0)
    return {
        "phase": name,
        "telemetry_hz": len(window) / (end - start),
        "worst_late_us": float(worst),
        "late": str(late),
        "rc_lost": "yes" if latched else "no",
    }


def main(argv: list[str] | None = None) -> int:
    """Run the baseline and the floods; print one row each."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=5.0, help="length of each phase (default 5)")
    parser.add_argument("--no-fifo", action="store_true", help="do not ask for SCHED_FIFO in the board")
    args = parser.parse_args(argv)
    with VirtualBoardProcess(listen="socket://127.0.0.1:0", fifo=not args.no_fifo) as board:
        url = board.start(timeout_s=60)
        host = Host(url)
        try:
            time.sleep(1.0)  # through the gate
            rows = [_phase(host, "baseline", None, args.seconds)]
            for name, make in FLOODS.items():
                rows.append(_phase(host, name, make(), args.seconds))
                time.sleep(0.5)  # the queued flood drains before the next phase
        finally:
            host.close()
    print(f"robustness: real-time virtual board on TCP loopback, {args.seconds:g} s per phase")
    print(f"targets: control lateness <= {TARGET_LATENESS_US} µs, telemetry >= {TARGET_TELEMETRY_HZ:g} Hz")
    head = f"{'phase':<14} {'worst late µs':>14} {'late ticks':>11} {'telemetry Hz':>13} {'RC_LOST':>8}"
    print(head + "  verdict")
    for r in rows:
        worst, hz = float(r["worst_late_us"]), float(r["telemetry_hz"])
        ok = worst <= TARGET_LATENESS_US and hz >= TARGET_TELEMETRY_HZ
        print(
            f"{r['phase']!s:<14} {worst:>14.0f} {r['late']!s:>11} {hz:>13.1f} {r['rc_lost']!s:>8}  "
            f"{'meets' if ok else 'misses'} the targets"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
