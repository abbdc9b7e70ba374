"""Scheduler: fixed-grid deadlines, late runs skipped (never burst-caught-up), per-task statistics."""

from __future__ import annotations

import pytest

from controller.scheduler import Scheduler, TaskSpec


class FakeTimer:
    """Execution-time timer that each task body advances by a chosen cost."""

    def __init__(self) -> None:
        self.ns = 0

    def __call__(self) -> int:
        return self.ns


def make(costs_us: dict[str, int] | None = None) -> tuple[Scheduler, list[tuple[str, int]], FakeTimer]:
    log: list[tuple[str, int]] = []
    timer = FakeTimer()
    costs = costs_us or {}

    def body(name: str):  # type: ignore[no-untyped-def]
        def run(now_us: int) -> None:
            log.append((name, now_us))
            timer.ns += costs.get(name, 0) * 1000

        return run

    table = [
        TaskSpec("fast", 1000, body("fast")),
        TaskSpec("slow", 10_000, body("slow"), offset_us=3000),
    ]
    return Scheduler(table, timer), log, timer


def test_tasks_run_on_their_grid_in_table_order() -> None:
    s, log, _ = make()
    for t in range(0, 20_000, 1000):
        s.run_due(t)
    assert [t for n, t in log if n == "slow"] == [3000, 13_000]
    assert len([1 for n, _ in log if n == "fast"]) == 20
    assert s.next_deadline_us() == 20_000
    both = [n for n, t in log if t == 3000]
    assert both == ["fast", "slow"]


def test_a_late_tick_is_skipped_not_caught_up() -> None:
    s, log, _ = make()
    s.run_due(0)
    s.run_due(1000)
    # the loop stalls for 3.5 ms: one run at 4500, then back on the grid at 5000
    s.run_due(4500)
    s.run_due(5000)
    fast = [t for n, t in log if n == "fast"]
    assert fast == [0, 1000, 4500, 5000]
    task = s["fast"]
    assert task.late == 1
    assert task.skipped == 2  # deadlines 2000 and 3000 were dropped
    assert task.lateness_max_us == 2500
    assert task.runs == 4


def test_small_lateness_is_not_late() -> None:
    s, _, _ = make()
    s.start(0)
    for k in range(10):
        s.run_due(k * 1000 + 300)
    assert s["fast"].late == 0
    assert s["fast"].lateness_max_us == 300


def test_execution_time_statistics() -> None:
    s, _, _ = make({"fast": 7})
    for t in range(0, 200_000, 1000):
        s.run_due(t)
    stats = {st.name: st for st in s.stats()}
    assert stats["fast"].exec_max_us == 7
    assert stats["fast"].exec_p99_us == 7
    assert stats["fast"].runs == 200
    assert stats["slow"].exec_max_us == 0


def test_table_validation() -> None:
    with pytest.raises(ValueError, match="name"):
        Scheduler([TaskSpec("a_very_long_task_name", 1000, lambda t: None)], FakeTimer())
    with pytest.raises(ValueError, match="period"):
        Scheduler([TaskSpec("a", 0, lambda t: None)], FakeTimer())
    with pytest.raises(ValueError, match="duplicate"):
        Scheduler([TaskSpec("a", 1000, lambda t: None), TaskSpec("a", 1000, lambda t: None)], FakeTimer())
    with pytest.raises(ValueError, match="offset"):
        Scheduler([TaskSpec("a", 1000, lambda t: None, offset_us=1000)], FakeTimer())


def test_lateness_percentiles_from_the_histogram() -> None:
    s, _, _ = make()
    s.start(0)
    for k in range(100):
        s.run_due(k * 1000 + (50 if k == 99 else 5 if k >= 90 else 0))
    fast = s["fast"]
    assert fast.lateness_percentile_us(0.5) == 0
    assert fast.lateness_percentile_us(0.95) == 5
    assert fast.lateness_percentile_us(1.0) == 50 == fast.lateness_max_us


def test_lateness_p99_over_the_recent_window() -> None:
    s, _, _ = make()
    s.start(0)
    fast = s["fast"]
    # 1000 ticks (the 1 kHz task's window): 5 start 80 µs late, 20 start 7 µs late, the rest on time.
    for k in range(1000):
        s.run_due(k * 1000 + (80 if k % 200 == 1 else 7 if k % 50 == 2 else 0))
    assert fast.lateness_p99_us == 0  # cached: only update_p99 / stats() recompute it
    stats = {st.name: st for st in s.stats()}
    assert fast.lateness_p99_us == 7  # 0.5 % above 7 µs, 2.5 % at or above it
    assert stats["fast"].lateness_max_us == 80
    # One on-time second later the window has forgotten the late ticks; the whole-run histogram has not.
    for k in range(1000, 2000):
        s.run_due(k * 1000)
    fast.update_p99()
    assert fast.lateness_p99_us == 0
    assert fast.lateness_percentile_us(0.99) == 7
    fast.reset_stats()
    assert fast.lateness_p99_us == 0 and fast.update_p99() == 0


def test_lateness_p99_saturates_the_ring_not_the_loop() -> None:
    s, _, _ = make()
    s.start(0)
    s.run_due(2**33)  # a huge stall: the ring stores u32, clamped
    assert s["fast"].update_p99() == 0
    assert s["fast"].lateness_p99_us == 0xFFFF_FFFF
