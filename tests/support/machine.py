"""How busy the machine is with work that is not this test run's: the evidence behind a ``starved:`` skip.

The load average cannot tell a starved machine from a test that starves itself: a board that spins the
CPU, or a hung Chromium this run started, raises it just as another user's job does. So the monitor
measures, every :data:`SAMPLE_S`, the CPU time every task of the machine ran (the scheduler's run times)
minus the time run by this test run's own process tree (this process and every descendant: the board's
process,
Chromium, MAVProxy), plus the time the hypervisor stole. What is left is the *others'* work: other users,
other jobs, kernel workers. A real-time run may be called void (the machine's fault) only if the others
took at least :data:`BUSY_OTHERS_CORES` of a core in some sample during it; on an idle machine a stalled
board is the board's fault and its test fails.

Linux only (``/proc``); elsewhere :func:`monitor` returns None and every run counts.
"""

from __future__ import annotations

import dataclasses
import os
import threading
import time
from collections import deque
from pathlib import Path

__all__ = [
    "BUSY_OTHERS_CORES",
    "HISTORY_S",
    "SAMPLE_S",
    "MachineMonitor",
    "OthersLoad",
    "monitor",
]

SAMPLE_S = 0.25
"""The monitor's sampling period: short enough to see a burst that starves a 30 ms RC time-out's
neighbourhood, long enough that its own scan of ``/proc`` (about 3 ms) stays near 1 % of a core."""

HISTORY_S = 600.0
"""How far back the monitor remembers (a test's longest wait, with room)."""

BUSY_OTHERS_CORES = 0.5
"""Others' work (and stolen time) of at least half a core in one sample: enough to delay a 1 kHz board and
its host on a 2-core machine, more than an idle machine's background (a few hundredths of a core)."""

_TICK_S = 1.0 / os.sysconf("SC_CLK_TCK") if hasattr(os, "sysconf") else 0.01
_PROC = Path("/proc")


@dataclasses.dataclass(frozen=True)
class OthersLoad:
    """What the machine did for others over a window.

    Attributes:
        window_s: the window's length covered by samples [s].
        mean_cores: others' CPU plus stolen time, averaged over the window [cores].
        peak_cores: the same in the busiest sample of the window [cores].
        samples: how many samples the window holds (0: no evidence, nothing may be called starved).
    """

    window_s: float
    mean_cores: float
    peak_cores: float
    samples: int

    @property
    def busy(self) -> bool:
        """Others took at least :data:`BUSY_OTHERS_CORES` in some sample of the window."""
        return self.samples > 0 and self.peak_cores >= BUSY_OTHERS_CORES

    def text(self) -> str:
        """One line, e.g. ``others' work 0.9 cores at peak, 0.4 on average over 12 s``."""
        if self.samples == 0:
            return "others' work not measured"
        return (
            f"others' work {self.peak_cores:.2f} cores at peak, {self.mean_cores:.2f} on average over "
            f"{self.window_s:.0f} s"
        )


def _machine_busy_s(stat: str) -> tuple[float, float]:
    """Busy and stolen CPU seconds of the whole machine from ``/proc/stat``'s first line."""
    fields = [int(x) for x in stat.split()[1:]]
    user, nice, system, _idle, _iowait, irq, softirq, steal = (fields + [0] * 8)[:8]
    return (user + nice + system + irq + softirq) * _TICK_S, steal * _TICK_S


def _run_times_s(root: int) -> tuple[float, float]:
    """CPU seconds run so far by every live task of the machine, and by those of ``root``'s process tree.

    From each thread's ``/proc/PID/task/TID/schedstat`` (the scheduler's nanosecond run time): the tick
    sampling behind ``/proc/stat`` and ``/proc/PID/stat`` misplaces a 1 kHz loop's short wake-ups (measured
    here: a real-time board's tree at 0.41 cores by ticks while the machine's ticks said 1.0 busy, where the
    run times say 0.51 and 0.52), which would call this run's own board "others".
    """
    parent: dict[int, int] = {}
    run: dict[int, float] = {}
    for entry in os.listdir(_PROC):
        if not entry.isdigit():
            continue
        pid = int(entry)
        try:
            raw = (_PROC / entry / "stat").read_bytes()
            # "pid (comm) state ppid ...": comm may hold spaces and parentheses; split after the last ")".
            parent[pid] = int(raw[raw.rfind(b")") + 2 :].split()[1])
            total = 0
            for task in os.listdir(_PROC / entry / "task"):
                total += int((_PROC / entry / "task" / task / "schedstat").read_text().split()[0])
        except (OSError, ValueError, IndexError):  # gone meanwhile
            continue
        run[pid] = total / 1e9
    children: dict[int, list[int]] = {}
    for pid, ppid in parent.items():
        children.setdefault(ppid, []).append(pid)
    tree, todo, seen = 0.0, [root], set()
    while todo:
        pid = todo.pop()
        if pid in seen:
            continue
        seen.add(pid)
        tree += run.get(pid, 0.0)
        todo.extend(children.get(pid, ()))
    return sum(run.values()), tree


def _tree_cpu_s(root: int) -> float:
    """CPU seconds run so far by ``root`` and its live descendants (:func:`_run_times_s`)."""
    return _run_times_s(root)[1]


class MachineMonitor:
    """Samples others' CPU work in a daemon thread (see the module's docstring).

    Args:
        root: the process whose tree is "this run" (default: this process).
        sample_s: sampling period [s].
    """

    def __init__(self, root: int | None = None, sample_s: float = SAMPLE_S) -> None:
        self.root = os.getpid() if root is None else root
        self.sample_s = sample_s
        self._samples: deque[tuple[float, float, float]] = deque(maxlen=int(HISTORY_S / sample_s) + 1)
        """(end time, seconds covered, others' cores) per sample."""
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="machine-monitor", daemon=True)

    def start(self) -> MachineMonitor:
        """Start sampling (returns self)."""
        self._thread.start()
        return self

    def stop(self) -> None:
        """Stop sampling; safe twice."""
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout=2.0)

    def _read(self) -> tuple[float, float, float, float]:
        _busy, steal = _machine_busy_s((_PROC / "stat").read_text().splitlines()[0])
        everyone, ours = _run_times_s(self.root)
        return time.monotonic(), everyone, steal, ours

    def _run(self) -> None:
        prev = self._read()
        while not self._stop.wait(self.sample_s):
            now = self._read()
            dt = now[0] - prev[0]
            if dt > 0:
                # Others = every task's run time - ours (clamped: a task that exited takes its total with it),
                # plus what the hypervisor stole.
                others = max(0.0, (now[1] - prev[1]) - (now[3] - prev[3])) + max(0.0, now[2] - prev[2])
                with self._lock:
                    self._samples.append((now[0], dt, others / dt))
            prev = now

    def others(self, since: float, until: float | None = None) -> OthersLoad:
        """Others' load in the samples that end after ``since`` and begin before ``until`` (monotonic times;
        ``until`` defaults to now)."""
        end = time.monotonic() if until is None else until
        with self._lock:
            rows = [(dt, cores) for t, dt, cores in self._samples if t > since and t - dt < end]
        if not rows:
            return OthersLoad(0.0, 0.0, 0.0, 0)
        span = sum(dt for dt, _ in rows)
        return OthersLoad(
            window_s=span,
            mean_cores=sum(dt * c for dt, c in rows) / span,
            peak_cores=max(c for _, c in rows),
            samples=len(rows),
        )


_MONITOR: MachineMonitor | None = None
_MONITOR_LOCK = threading.Lock()


def monitor() -> MachineMonitor | None:
    """The run's monitor, started on first use (None where there is no ``/proc/stat``)."""
    global _MONITOR
    with _MONITOR_LOCK:
        if _MONITOR is None and (_PROC / "stat").exists():
            _MONITOR = MachineMonitor().start()
        return _MONITOR
