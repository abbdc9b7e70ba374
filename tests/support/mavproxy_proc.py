"""A headless MAVProxy process for tests: commands on stdin, console lines collected from stdout."""

from __future__ import annotations

import contextlib
import os
import re
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path

from tests.support.realtime_guard import scaled_s, timed_out

MAVPROXY = Path(sys.executable).with_name("mavproxy.py")
_ROOT = Path(__file__).resolve().parents[2]
"""The repository: where ``python -m host.cli`` runs."""
WAIT_S = 15.0
"""A wait on a quiet machine; every wait here grows with the load (``realtime_guard.scaled_s``) and, if it
still times out on a starved machine, skips the test as ``starved:`` instead of failing it."""
RUN_LIMIT_S = 120.0
"""MAVProxy's own lifetime on a quiet machine (``timeout`` kills a process the test lost), also scaled."""
# MAVProxy is a test dependency (the "test" extra): a missing one fails the tests that need it, loudly.


def free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def wait_for(cond: Callable[[], bool], what: str, timeout: float = WAIT_S) -> None:
    """Poll ``cond`` for ``timeout`` s scaled with the load; on time-out fail, or skip as starved."""
    deadline = time.monotonic() + scaled_s(timeout)
    while time.monotonic() < deadline:
        if cond():
            return
        time.sleep(0.02)
    timed_out(what)


class MavProxy:
    """A headless MAVProxy subprocess: commands on stdin, console lines collected from stdout."""

    def __init__(self, port: int, state_dir: Path, cmds: list[str]) -> None:
        argv = [
            "timeout",
            "-k",
            "5",
            f"{scaled_s(RUN_LIMIT_S):.0f}",
            sys.executable,
            str(MAVPROXY),
            f"--master=udpin:127.0.0.1:{port}",
            "--target-system=1",
            "--target-component=25",
            "--default-modules=log,signing,param,cmdlong,misc",
            f"--state-basedir={state_dir}",
            "--mav20",
        ]
        argv += [f"--cmd={c}" for c in cmds]
        env = dict(os.environ, PYTHONUNBUFFERED="1", HOME=str(state_dir))  # keep ~/.mavproxy out of it
        self.proc = subprocess.Popen(
            argv,
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            cwd=state_dir,
            env=env,
        )
        self._lines: list[str] = []
        self._lock = threading.Lock()
        self._reader = threading.Thread(target=self._read, name="mavproxy-stdout", daemon=True)
        self._reader.start()

    def _read(self) -> None:
        assert self.proc.stdout is not None
        for raw in self.proc.stdout:  # ends at EOF, when the process exits
            with self._lock:
                self._lines.append(raw.decode("utf-8", errors="replace").rstrip())

    def lines(self) -> list[str]:
        with self._lock:
            return list(self._lines)

    def send(self, line: str) -> None:
        assert self.proc.stdin is not None
        self.proc.stdin.write(line.encode() + b"\n")
        self.proc.stdin.flush()

    def expect(self, pattern: str, start: int = 0, timeout: float = WAIT_S) -> int:
        """Index of the first console line at or after ``start`` matching ``pattern``.

        Waits ``timeout`` s scaled with the load. A MAVProxy that exited fails the test; one that only
        ran out of time skips it as starved on a starved machine (``realtime_guard.timed_out``).
        """
        rx = re.compile(pattern)
        deadline = time.monotonic() + scaled_s(timeout)
        while time.monotonic() < deadline:
            for i, line in enumerate(self.lines()[start:], start):
                if rx.search(line):
                    return i
            if self.proc.poll() is not None:
                break
            time.sleep(0.02)
        tail = "\n".join(self.lines()[-30:])
        if self.proc.poll() is not None:
            raise AssertionError(f"MAVProxy exited without printing /{pattern}/; last lines:\n{tail}")
        timed_out(f"MAVProxy to print /{pattern}/", f"; last lines:\n{tail}")

    def close(self) -> None:
        if self.proc.poll() is None and self.proc.stdin is not None:
            with contextlib.suppress(OSError):
                self.proc.stdin.close()  # EOF on its console makes MAVProxy exit
            try:
                self.proc.wait(timeout=5)
            except subprocess.TimeoutExpired:
                self.proc.terminate()
                try:
                    self.proc.wait(timeout=5)
                except subprocess.TimeoutExpired:
                    self.proc.kill()
                    self.proc.wait(timeout=5)
        self._reader.join(timeout=5)
        if self.proc.stdout is not None:
            self.proc.stdout.close()


def stop_host(host: subprocess.Popen[str]) -> None:
    """Ctrl-C, the normal end of a run: the host closes its recording and exits (safe twice)."""
    if host.poll() is None:
        host.send_signal(signal.SIGINT)
        try:
            host.wait(timeout=20)
        except subprocess.TimeoutExpired:
            host.kill()
            host.wait(timeout=10)


@contextlib.contextmanager
def host_under_mavproxy(
    tmp_path: Path, extra_args: Sequence[str] = ()
) -> Iterator[tuple[MavProxy, Path, subprocess.Popen[str]]]:
    """A MAVProxy waiting on a free loopback port and a headless ``spirob-host --virtual-rc grasp`` sending
    to it for up to 90 s, recording its board link: ``(proxy, recording, host)``; both stopped on exit."""
    port = free_udp_port()
    state = tmp_path / "mavproxy"
    state.mkdir()
    proxy = MavProxy(port, state, [])
    host: subprocess.Popen[str] | None = None
    try:
        proxy.expect(r"Waiting for heartbeat|Connect udpin")
        record = tmp_path / "run.mcap"
        argv = [sys.executable, "-m", "host.cli", "--headless", *extra_args, "--virtual-rc", "grasp"]
        argv += ["--mavlink", f"udpout:127.0.0.1:{port}", "--record", str(record), "--duration", "90"]
        host = subprocess.Popen(argv, cwd=_ROOT, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        yield proxy, record, host
    finally:
        if host is not None:
            stop_host(host)
            if host.stdout is not None:
                host.stdout.close()
        proxy.close()
