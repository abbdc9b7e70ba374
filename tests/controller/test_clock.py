"""Clocks: lockstep semantics; the real-time clock's absolute sleeps and set-up (no wall-clock bounds)."""

from __future__ import annotations

import gc
import threading

import pytest

from controller.clock import LockstepClock, RealTimeClock, run_periodic
from controller.errors import ClockError
from protocol.messages import ClockKind


def test_lockstep_advances_only_when_told() -> None:
    c = LockstepClock(1000)
    assert c.now_us() == 1000
    c.advance(500)
    c.advance_to(2000)
    assert c.now_us() == 2000
    with pytest.raises(ClockError):
        c.advance_to(1999)
    with pytest.raises(ClockError):
        c.advance(-1)
    with pytest.raises(ValueError):
        LockstepClock(-1)


def test_lockstep_sleep_advances_to_the_deadline_never_back() -> None:
    c = LockstepClock()
    c.sleep_until_us(5000)
    assert c.now_us() == 5000
    c.sleep_until_us(100)  # in the past: returns at once
    assert c.now_us() == 5000


def test_realtime_sleep_returns_at_or_after_the_deadline() -> None:
    c = RealTimeClock(fifo=False)
    for _ in range(5):
        deadline = c.now_us() + 300
        c.sleep_until_us(deadline)
        assert c.now_us() >= deadline


def test_realtime_sleep_is_one_absolute_sleep_and_none_for_a_past_deadline(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # Which sleep is asked for, not how long it took (no wall-clock bounds): the syscall is recorded.
    c = RealTimeClock(fifo=False, spin_us=0)
    if c._nanosleep is None:
        pytest.skip("no clock_nanosleep in this libc")
    calls: list[tuple[int, int, int, int]] = []

    def fake_nanosleep(clock_id: int, flags: int, ts_ref: object, remain: object) -> int:
        calls.append((clock_id, flags, c._ts.tv_sec, c._ts.tv_nsec))
        return 0

    monkeypatch.setattr(c, "_nanosleep", fake_nanosleep)
    c.sleep_until_us(c.now_us() - 1_000_000)  # past: returns at once, no sleep asked for
    assert calls == []
    deadline = c.now_us() + 2_000
    c.sleep_until_us(deadline)
    # One absolute (TIMER_ABSTIME = 1) CLOCK_MONOTONIC (1) sleep to the deadline itself, then the deadline.
    assert calls == [(1, 1, deadline // 1_000_000, deadline % 1_000_000 * 1000)]
    assert c.now_us() >= deadline
    # Without clock_nanosleep: a relative time.sleep, again none for a past deadline.
    slept: list[float] = []
    monkeypatch.setattr(c, "_nanosleep", None)
    monkeypatch.setattr("controller.clock.time.sleep", slept.append)
    c.sleep_until_us(c.now_us() - 1_000_000)
    assert slept == []
    c.sleep_until_us(c.now_us() + 20_000)
    assert len(slept) == 1 and 0 < slept[0] <= 0.02


def test_realtime_running_restores_gc_and_scheduler() -> None:
    c = RealTimeClock(fifo=True, spin_us=0)
    assert gc.isenabled()
    with c.running():
        assert not gc.isenabled()
    assert gc.isenabled()
    assert not c.fifo_active
    assert c.kind is ClockKind.REALTIME_NORMAL


def test_the_clock_says_its_own_kind() -> None:
    assert LockstepClock().kind is ClockKind.LOCKSTEP
    c = RealTimeClock(fifo=True, spin_us=0)
    with c.running():
        assert c.kind is (ClockKind.REALTIME_FIFO if c.fifo_active else ClockKind.REALTIME_NORMAL)


def test_run_periodic_steps_on_the_deadlines_the_step_returns_until_the_end() -> None:
    c = LockstepClock(1000)
    seen: list[int] = []

    def step(now_us: int) -> int:
        seen.append(now_us)
        return now_us + 300

    run_periodic(c, step, duration_us=1000)
    assert seen == [1000, 1300, 1600, 1900]  # none at or after the end (2000)
    assert c.now_us() == 2000


def test_run_periodic_begin_sets_the_first_deadline_and_stop_ends_the_loop() -> None:
    c = LockstepClock()
    stop = threading.Event()
    seen: list[int] = []

    def step(now_us: int) -> int:
        seen.append(now_us)
        if len(seen) == 3:
            stop.set()
        return now_us + 100

    run_periodic(c, step, begin=lambda start_us: start_us + 50, stop=stop)
    assert seen == [50, 150, 250]
    seen.clear()
    run_periodic(c, step, stop=lambda: True)  # set before the first step: no step runs
    assert seen == []


def test_realtime_clock_validates_arguments() -> None:
    with pytest.raises(ValueError):
        RealTimeClock(fifo_priority=0)
    with pytest.raises(ValueError):
        RealTimeClock(timer_slack_ns=0)
    with pytest.raises(ValueError):
        RealTimeClock(spin_us=-1)
