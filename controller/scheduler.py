"""Cooperative fixed-rate scheduler over a declared task table (Betaflight ``scheduler.c`` style).

Every task receives the time (``now_us``) and never reads a clock. Deadlines are absolute and on a fixed
grid (``offset + k * period``): a task that starts a whole period or more after its deadline has missed
it; it counts as *late*, the missed ticks are *skipped* (never burst-caught-up) and its next deadline is
the next grid point after now. Offsets stagger the slow tasks so they do not all land on one tick.

Statistics per task: runs, late, skipped, max and p99 execution time and p99 start lateness (two fixed
rings of recent samples, about one second's worth, no allocation per run; the p99s are recomputed on
demand by :meth:`Task.update_p99`, never per tick), max lateness, and a lateness histogram over the whole
run (1 µs bins up to 2 ms, then one overflow bin) for percentiles.
"""

from __future__ import annotations

import math
from array import array
from collections.abc import Callable, Sequence
from dataclasses import dataclass

from protocol.messages import TASK_NAME_LEN, TaskStats

__all__ = ["Scheduler", "Task", "TaskSpec"]

_HIST_BINS = 2000


@dataclass(frozen=True, slots=True)
class TaskSpec:
    """One row of the task table.

    Attributes:
        name: ASCII, at most 12 characters (it travels in ``BoardStatus``).
        period_us: period.
        run: the task body, called with ``now_us``.
        offset_us: phase of the task's deadline grid (staggers slow tasks).
    """

    name: str
    period_us: int
    run: Callable[[int], None]
    offset_us: int = 0


class Task:
    """A scheduled task with its statistics (mutable; one per table row)."""

    __slots__ = (
        "_count",
        "_idx",
        "_late_ring",
        "_ring",
        "_window",
        "exec_max_us",
        "exec_p99_us",
        "late",
        "lateness_hist",
        "lateness_max_us",
        "lateness_p99_us",
        "name",
        "next_deadline_us",
        "offset_us",
        "period_us",
        "run",
        "runs",
        "skipped",
    )

    def __init__(self, spec: TaskSpec) -> None:
        """Create the task from its table row.

        Raises:
            ValueError: a bad name, period or offset.
        """
        if not spec.name or len(spec.name) > TASK_NAME_LEN or not spec.name.isascii():
            raise ValueError(f"task name {spec.name!r} must be 1..{TASK_NAME_LEN} ASCII characters")
        if spec.period_us <= 0:
            raise ValueError(f"task {spec.name}: period_us must be > 0, got {spec.period_us}")
        if not 0 <= spec.offset_us < spec.period_us:
            raise ValueError(f"task {spec.name}: offset_us must be 0..period-1, got {spec.offset_us}")
        self.name = spec.name
        self.period_us = spec.period_us
        self.offset_us = spec.offset_us
        self.run = spec.run
        self.next_deadline_us = 0
        self.runs = 0
        self.late = 0
        self.skipped = 0
        self.exec_max_us = 0
        self.exec_p99_us = 0
        self.lateness_max_us = 0
        self.lateness_p99_us = 0
        """Start lateness p99 (µs) over the recent window, as of the last :meth:`update_p99`."""
        window = max(64, min(1024, 1_000_000 // spec.period_us))  # about 1 s of samples
        self._window = window
        self._ring = array("I", bytes(4 * window))
        self._late_ring = array("I", bytes(4 * window))
        self._idx = 0
        self._count = 0
        self.lateness_hist = array("I", bytes(4 * (_HIST_BINS + 1)))
        """Runs per lateness in µs (index), the last bin holding every run >= ``_HIST_BINS`` µs late."""

    def record(self, exec_us: int, lateness_us: int) -> None:
        """Account one run (no allocation)."""
        self.runs += 1
        if exec_us > self.exec_max_us:
            self.exec_max_us = exec_us
        if lateness_us > self.lateness_max_us:
            self.lateness_max_us = lateness_us
        self.lateness_hist[lateness_us if lateness_us < _HIST_BINS else _HIST_BINS] += 1
        idx = self._idx
        self._ring[idx] = exec_us if exec_us < 0xFFFF_FFFF else 0xFFFF_FFFF
        self._late_ring[idx] = lateness_us if lateness_us < 0xFFFF_FFFF else 0xFFFF_FFFF
        idx += 1
        window = self._window
        self._idx = 0 if idx == window else idx
        if self._count < window:
            self._count += 1

    def update_p99(self) -> int:
        """Recompute and cache the p99 execution time and start lateness over the recent window.

        Sorts both rings, so it runs at a status rate, never per tick. Returns the execution p99 (the
        lateness p99 is in :attr:`lateness_p99_us`).
        """
        n = self._count
        if n == 0:
            self.exec_p99_us = self.lateness_p99_us = 0
        else:
            k = min(n - 1, (99 * n) // 100)
            self.exec_p99_us = sorted(self._ring[:n])[k]
            self.lateness_p99_us = sorted(self._late_ring[:n])[k]
        return self.exec_p99_us

    def lateness_percentile_us(self, q: float) -> int:
        """Lateness (µs) at or below which a fraction ``q`` (0..1) of all runs started.

        Values past the histogram's range read as its last bin (2000 µs): use ``lateness_max_us`` there.
        """
        n = self.runs
        if n == 0:
            return 0
        need = max(1, math.ceil(q * n))
        seen = 0
        for lateness, count in enumerate(self.lateness_hist):
            seen += count
            if seen >= need:
                return lateness
        return _HIST_BINS

    def stats(self) -> TaskStats:
        """The task's statistics as a ``BoardStatus`` entry (uses the cached p99)."""
        return TaskStats(
            self.name,
            self.period_us,
            self.runs & 0xFFFF_FFFF,
            self.late & 0xFFFF_FFFF,
            min(self.exec_max_us, 0xFFFF_FFFF),
            min(self.exec_p99_us, 0xFFFF_FFFF),
            min(self.lateness_max_us, 0xFFFF_FFFF),
        )

    def reset_stats(self) -> None:
        """Zero the statistics (not the deadlines)."""
        self.runs = self.late = self.skipped = 0
        self.exec_max_us = self.exec_p99_us = self.lateness_max_us = self.lateness_p99_us = 0
        self._idx = self._count = 0
        for i in range(len(self.lateness_hist)):
            self.lateness_hist[i] = 0


class Scheduler:
    """Runs due tasks in table order.

    Args:
        table: the task table.
        exec_timer_ns: monotonic nanosecond timer used only to measure execution times.
    """

    def __init__(self, table: Sequence[TaskSpec], exec_timer_ns: Callable[[], int]) -> None:
        """Build the tasks from ``table``.

        Raises:
            ValueError: a bad row or duplicate names.
        """
        self.tasks: tuple[Task, ...] = tuple(Task(spec) for spec in table)
        if not self.tasks:
            raise ValueError("the task table is empty")
        names = [t.name for t in self.tasks]
        if len(set(names)) != len(names):
            raise ValueError(f"duplicate task names in {names}")
        self._by_name = {t.name: t for t in self.tasks}
        self._timer_ns = exec_timer_ns
        self._started = False

    def __getitem__(self, name: str) -> Task:
        return self._by_name[name]

    @property
    def started(self) -> bool:
        """:meth:`start` has run (the first :meth:`run_due` starts the scheduler)."""
        return self._started

    def start(self, now_us: int) -> None:
        """Put every task's first deadline at ``now_us + offset``."""
        for t in self.tasks:
            t.next_deadline_us = now_us + t.offset_us
        self._started = True

    def run_due(self, now_us: int) -> int:
        """Run every task whose deadline is at or before ``now_us``; return how many ran."""
        if not self._started:
            self.start(now_us)
        timer = self._timer_ns
        ran = 0
        for t in self.tasks:
            deadline = t.next_deadline_us
            if now_us < deadline:
                continue
            lateness = now_us - deadline
            period = t.period_us
            if lateness >= period:
                missed = lateness // period
                t.late += 1
                t.skipped += missed
                t.next_deadline_us = deadline + (missed + 1) * period
            else:
                t.next_deadline_us = deadline + period
            t0 = timer()
            t.run(now_us)
            t.record((timer() - t0) // 1000, lateness)
            ran += 1
        return ran

    def next_deadline_us(self) -> int:
        """Earliest deadline of any task."""
        tasks = self.tasks
        best = tasks[0].next_deadline_us
        for t in tasks:
            if t.next_deadline_us < best:
                best = t.next_deadline_us
        return best

    def stats(self) -> tuple[TaskStats, ...]:
        """Every task's statistics (recomputes the p99 caches)."""
        for t in self.tasks:
            t.update_p99()
        return tuple(t.stats() for t in self.tasks)
