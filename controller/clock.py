"""Clocks behind one interface: integer microseconds, absolute deadlines.

The firmware never reads a clock itself: its tasks receive ``now_us``. A clock is only used by whoever
drives the firmware — :func:`run_periodic`, the one real-time loop (behind
:meth:`controller.firmware.Firmware.run` and ``hil.board.run_realtime``), or a lockstep simulation that
calls :meth:`~controller.firmware.Firmware.run_due` after each plant step. A clock says its own
:attr:`Clock.kind`, so no caller tests which class it has. This is the only module of
``controller`` that calls ``time.*``.

Real-time facts this module rests on (measured on the project's 2-core machine, docs/realtime.md):
plain ``time.sleep(0.001)`` loops miss 3-6 % of 1 kHz deadlines with stalls up to 200 ms; what holds is
SCHED_FIFO + absolute ``clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME)`` deadlines + ``gc.freeze()`` /
``gc.disable()`` during the loop + 1 ns timer slack (``prctl(PR_SET_TIMERSLACK)``): p99 lateness
22-29 µs, 0 misses. Python has no ``time.clock_nanosleep``, so it is called through ``ctypes``.
"""

from __future__ import annotations

import contextlib
import ctypes
import ctypes.util
import errno
import gc
import itertools
import logging
import os
import sys
import threading
import time
from abc import ABC, abstractmethod
from collections.abc import Callable, Iterator

from controller.errors import ClockError
from protocol.messages import ClockKind

__all__ = ["Clock", "LockstepClock", "RealTimeClock", "StopSignal", "monotonic_ns", "run_periodic", "zero_ns"]

_log = logging.getLogger(__name__)

# Linux <time.h> / <linux/prctl.h>.
_CLOCK_MONOTONIC = 1
_TIMER_ABSTIME = 1
_PR_SET_TIMERSLACK = 29
_PR_GET_TIMERSLACK = 30


def monotonic_ns() -> int:
    """CLOCK_MONOTONIC in integer nanoseconds (the scheduler's execution-time timer)."""
    return time.monotonic_ns()


zero_ns: Callable[[], int] = itertools.repeat(0).__next__
"""A timer that always reads 0 (a C callable: no Python frame per call). Lockstep runs time their tasks
with it, so that their telemetry is bit-identical from run to run and their ticks stay small."""


class Clock(ABC):
    """Integer-microsecond time source with absolute sleeps."""

    @abstractmethod
    def now_us(self) -> int:
        """Current time in integer µs (monotonic; the epoch is the clock's own)."""

    @abstractmethod
    def sleep_until_us(self, deadline_us: int) -> None:
        """Return at (or as soon as possible after) the absolute time ``deadline_us``.

        Returns at once if the deadline has passed.
        """

    @property
    @abstractmethod
    def kind(self) -> ClockKind:
        """How a loop on this clock is timed (reported in ``BoardStatus``); final once :meth:`running`."""

    def running(self) -> contextlib.AbstractContextManager[None]:
        """Context held by a real-time loop for its whole run (default: nothing to set up)."""
        return contextlib.nullcontext()

    @property
    def absolute_sleeps(self) -> bool:
        """:meth:`sleep_until_us` sleeps to an absolute deadline (a relative sleep drifts; default True)."""
        return True


StopSignal = threading.Event | Callable[[], bool] | None
"""What ends a periodic loop early: an event that gets set, or a callable that returns True."""


def _is_set(stop: StopSignal) -> bool:
    if stop is None:
        return False
    if isinstance(stop, threading.Event):
        return stop.is_set()
    return bool(stop())


def run_periodic(
    clock: Clock,
    step: Callable[[int], int],
    *,
    begin: Callable[[int], int] | None = None,
    duration_us: int | None = None,
    stop: StopSignal = None,
) -> None:
    """The one real-time loop: sleep to an absolute deadline, run ``step``, repeat.

    Everything runs inside ``clock.running()`` (SCHED_FIFO, GC frozen, ... for a
    :class:`RealTimeClock`). Deadlines are absolute, so a late wake-up never pushes the next one back;
    what to do about a missed deadline (skip, never burst) is the step's business, as it knows its grid.

    Args:
        clock: the time source.
        step: called with the time at each deadline; returns the next absolute deadline (µs).
        begin: called once with the loop's start time, inside ``clock.running()``; returns the first
            deadline (default: the start time, so the first step runs at once).
        duration_us: stop at start + this (no step runs at or after it); None = no limit.
        stop: checked before every step; the loop returns when it is set / returns True.
    """
    with clock.running():
        start = clock.now_us()
        end = None if duration_us is None else start + duration_us
        deadline = start if begin is None else begin(start)
        sleep_until = clock.sleep_until_us
        now_us = clock.now_us
        while True:
            if end is not None and deadline > end:
                deadline = end
            sleep_until(deadline)
            now = now_us()
            if end is not None and now >= end:
                break
            if _is_set(stop):
                break
            deadline = step(now)


class _Timespec(ctypes.Structure):
    _fields_ = [("tv_sec", ctypes.c_long), ("tv_nsec", ctypes.c_long)]


def _load_libc() -> ctypes.CDLL | None:
    if not sys.platform.startswith("linux"):
        return None
    name = ctypes.util.find_library("c") or "libc.so.6"
    try:
        return ctypes.CDLL(name, use_errno=True)
    except OSError:
        return None


class RealTimeClock(Clock):
    """CLOCK_MONOTONIC with absolute-deadline sleeps, and real-time set-up for the loop.

    :meth:`running` (entered by :meth:`Firmware.run <controller.firmware.Firmware.run>`) switches the
    process to SCHED_FIFO when permitted — logging one clear line when it is not — sets the timer slack
    to 1 ns, and freezes and disables the garbage collector; everything is restored on exit.

    Attributes:
        fifo_active: True while SCHED_FIFO is in force (set by :meth:`running`).
    """

    def __init__(
        self, *, fifo: bool = True, fifo_priority: int = 50, timer_slack_ns: int = 1, spin_us: int = 100
    ) -> None:
        """Create the clock.

        Args:
            fifo: ask for SCHED_FIFO while :meth:`running` (falls back to normal priority, with a log
                line, when not permitted).
            fifo_priority: SCHED_FIFO priority, 1..99.
            timer_slack_ns: timer slack while running (1 ns: wake-ups are not batched by the kernel).
            spin_us: wake this long before each deadline and spin the rest. Measured on this VM under
                SCHED_FIFO: a bare absolute sleep wakes 50 µs late at the median and 100 µs at p99;
                waking 100 µs early and spinning gives p99 lateness of 0-20 µs for about 10 % of a core.
                0 disables spinning.

        Raises:
            ValueError: a bad priority, slack or spin.
        """
        if not 1 <= fifo_priority <= 99:
            raise ValueError(f"fifo_priority must be 1..99, got {fifo_priority}")
        if timer_slack_ns < 1:
            raise ValueError(f"timer_slack_ns must be >= 1, got {timer_slack_ns}")
        if not 0 <= spin_us < 1_000_000:
            raise ValueError(f"spin_us must be 0..999999, got {spin_us}")
        self.spin_us = spin_us
        self.fifo = fifo
        self.fifo_priority = fifo_priority
        self.timer_slack_ns = timer_slack_ns
        self.fifo_active = False
        self._libc = _load_libc()
        self._nanosleep = None
        self._prctl = None
        self._ts = _Timespec()
        self._ts_ref = ctypes.byref(self._ts)
        if self._libc is not None:
            fn = getattr(self._libc, "clock_nanosleep", None)
            if fn is not None:
                fn.argtypes = [ctypes.c_int, ctypes.c_int, ctypes.POINTER(_Timespec), ctypes.c_void_p]
                fn.restype = ctypes.c_int
                self._nanosleep = fn
            prctl = getattr(self._libc, "prctl", None)
            if prctl is not None:
                prctl.argtypes = [ctypes.c_int] + [ctypes.c_ulong] * 4
                prctl.restype = ctypes.c_int
                self._prctl = prctl

    @property
    def kind(self) -> ClockKind:
        """``REALTIME_FIFO`` while SCHED_FIFO is in force, else ``REALTIME_NORMAL``."""
        return ClockKind.REALTIME_FIFO if self.fifo_active else ClockKind.REALTIME_NORMAL

    @property
    def absolute_sleeps(self) -> bool:
        """``clock_nanosleep(TIMER_ABSTIME)`` was found (else sleeps fall back to relative ``time.sleep``)."""
        return self._nanosleep is not None

    def now_us(self) -> int:
        """CLOCK_MONOTONIC in integer µs."""
        return time.monotonic_ns() // 1000

    def sleep_until_us(self, deadline_us: int) -> None:
        """Sleep until the absolute CLOCK_MONOTONIC time ``deadline_us`` (``TIMER_ABSTIME``).

        An absolute deadline does not drift: a late wake-up does not push the next one back. Retries on
        EINTR; wakes ``spin_us`` early and spins the rest. Falls back to a relative ``time.sleep`` where
        ``clock_nanosleep`` is unavailable.
        """
        deadline_ns = deadline_us * 1000
        wake_us = deadline_us - self.spin_us
        fn = self._nanosleep
        if fn is None:
            delay_ns = wake_us * 1000 - time.monotonic_ns()
            if delay_ns > 0:
                time.sleep(delay_ns / 1e9)
        elif wake_us * 1000 > time.monotonic_ns():
            sec, usec = divmod(wake_us, 1_000_000)
            ts = self._ts
            ts.tv_sec = sec
            ts.tv_nsec = usec * 1000
            while fn(_CLOCK_MONOTONIC, _TIMER_ABSTIME, self._ts_ref, None) == errno.EINTR:
                pass
        while time.monotonic_ns() < deadline_ns:  # at most spin_us
            pass

    @contextlib.contextmanager
    def running(self) -> Iterator[None]:
        """Real-time set-up for the duration of a loop: SCHED_FIFO, timer slack, GC frozen."""
        old_policy: tuple[int, os.sched_param] | None = None
        old_slack = self._set_timer_slack(self.timer_slack_ns)
        if self.fifo:
            old_policy = self._enter_fifo()
        gc_was_enabled = gc.isenabled()
        gc.collect()
        gc.freeze()  # objects alive now are never scanned again: no long collections mid-loop
        gc.disable()
        try:
            yield
        finally:
            if gc_was_enabled:
                gc.enable()
            gc.unfreeze()
            if old_policy is not None:
                with contextlib.suppress(OSError):
                    os.sched_setscheduler(0, old_policy[0], old_policy[1])
                self.fifo_active = False
            if old_slack is not None:
                self._set_timer_slack(old_slack)

    def _enter_fifo(self) -> tuple[int, os.sched_param] | None:
        if not hasattr(os, "sched_setscheduler"):
            _log.warning("SCHED_FIFO not available on this platform: running at normal priority")
            return None
        try:
            old = (os.sched_getscheduler(0), os.sched_getparam(0))
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(self.fifo_priority))
        except OSError as exc:
            _log.warning(
                "SCHED_FIFO not permitted (%s): running at normal priority, expect missed deadlines "
                "(run as root or grant CAP_SYS_NICE / an rtprio limit)",
                exc.strerror or exc,
            )
            return None
        self.fifo_active = True
        _log.info("SCHED_FIFO priority %d in force", self.fifo_priority)
        return old

    def _set_timer_slack(self, slack_ns: int) -> int | None:
        """Set this thread's timer slack; return the previous value (None if unsupported)."""
        prctl = self._prctl
        if prctl is None:
            return None
        old = int(prctl(_PR_GET_TIMERSLACK, 0, 0, 0, 0))
        if old < 0 or prctl(_PR_SET_TIMERSLACK, slack_ns, 0, 0, 0) != 0:
            return None
        return old


class LockstepClock(Clock):
    """Simulated time, advanced by whoever drives the simulation.

    ``sleep_until_us(t)`` *advances* the clock to ``t`` (the sleeper owns time): a real-time loop such as
    :meth:`Firmware.run <controller.firmware.Firmware.run>` given a lockstep clock therefore runs as fast
    as the CPU allows, tick for tick as it would in real time, and deterministically. A simulation that
    steps a plant between ticks calls :meth:`advance` itself and
    :meth:`Firmware.run_due <controller.firmware.Firmware.run_due>` after each step instead.
    """

    def __init__(self, start_us: int = 0) -> None:
        """Start at ``start_us`` (>= 0).

        Raises:
            ValueError: ``start_us`` is negative.
        """
        if start_us < 0:
            raise ValueError(f"start_us must be >= 0, got {start_us}")
        self._now_us = int(start_us)

    @property
    def kind(self) -> ClockKind:
        """Always ``LOCKSTEP``."""
        return ClockKind.LOCKSTEP

    def now_us(self) -> int:
        """Current simulated time in µs."""
        return self._now_us

    def advance_to(self, t_us: int) -> None:
        """Set the time to ``t_us``.

        Raises:
            ClockError: ``t_us`` is in the past (time never runs backwards).
        """
        if t_us < self._now_us:
            raise ClockError(f"lockstep clock cannot go back from {self._now_us} to {t_us} µs")
        self._now_us = int(t_us)

    def advance(self, dt_us: int) -> None:
        """Move time forward by ``dt_us`` (>= 0).

        Raises:
            ClockError: ``dt_us`` is negative.
        """
        if dt_us < 0:
            raise ClockError(f"lockstep clock cannot advance by a negative {dt_us} µs")
        self._now_us += int(dt_us)

    def sleep_until_us(self, deadline_us: int) -> None:
        """Advance to ``deadline_us`` if it is in the future; return at once otherwise."""
        if deadline_us > self._now_us:
            self._now_us = int(deadline_us)
