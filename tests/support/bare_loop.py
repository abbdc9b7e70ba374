"""A bare 1 kHz loop: the machine's own timing, measured the way the firmware's loop is run, with no work.

The preflight's lateness check judges the firmware's loop; on a virtual machine the wake-ups themselves
can be late. Run right after a preflight whose lateness failed, this loop is the baseline from the same
machine in the same minute: the same :class:`~controller.clock.RealTimeClock` (SCHED_FIFO when permitted,
1 ns timer slack, absolute sleeps, the same early wake and spin), the same period, missed deadlines
skipped as the firmware skips them, judged by the same :func:`~controller.preflight_checks.judge_lateness`.
If a loop that does nothing fails that judgement too, the machine cannot keep the bound and the preflight's
failure says nothing about the program.

Run as a process of its own (``python tests/support/bare_loop.py [--no-fifo]``), as the firmware is:
prints one JSON object, the :class:`~controller.preflight_checks.LatenessStats` fields and the verdict line.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import subprocess
import sys
from pathlib import Path

PERIOD_US = 1000
"""The firmware's control period."""
TICKS_N = 2000
"""Ticks in the window: the preflight's 2 s."""


def measure(*, fifo: bool, ticks: int = TICKS_N) -> dict[str, object]:
    """Run the bare loop for ``ticks`` periods in this process; its statistics and verdict."""
    from controller.clock import RealTimeClock, run_periodic
    from controller.preflight_checks import LatenessStats, judge_lateness

    clock = RealTimeClock(fifo=fifo)
    lateness: list[int] = []
    skipped = 0
    start: list[int] = []

    def begin(now: int) -> int:
        start.append(now)
        return now + PERIOD_US

    def step(now: int) -> int:
        nonlocal skipped
        deadline = start[0] + PERIOD_US * (len(lateness) + skipped + 1)
        late = now - deadline
        lateness.append(late)
        missed = max(0, late // PERIOD_US)  # the firmware's rule: never burst, skip to the next grid point
        skipped += missed
        return deadline + PERIOD_US * (missed + 1)

    run_periodic(clock, step, begin=begin, duration_us=ticks * PERIOD_US + PERIOD_US // 2)
    ordered = sorted(lateness)
    late_ticks = sum(1 for v in lateness if v >= PERIOD_US)
    stats = LatenessStats(
        runs=len(lateness),
        expected_runs=ticks,
        late=late_ticks,
        skipped=skipped,
        p99_us=max(0, ordered[int(0.99 * (len(ordered) - 1))]) if ordered else 0,
        max_us=max(0, ordered[-1]) if ordered else 0,
        late_wakeups=late_ticks,  # no work at all: every late tick was woken late
        wakeup_overshoot_max_us=max(0, ordered[-1]) if ordered else 0,
    )
    check = judge_lateness(stats)
    return {**dataclasses.asdict(stats), "passed": not check.failed, "line": check.line()}


def measure_in_process_of_its_own(*, fifo: bool, timeout_s: float = 30.0) -> dict[str, object]:
    """:func:`measure` in a fresh interpreter (as the firmware runs: it shares its lock with nothing)."""
    argv = [sys.executable, str(Path(__file__).resolve())] + ([] if fifo else ["--no-fifo"])
    proc = subprocess.run(argv, capture_output=True, text=True, timeout=timeout_s, check=False)
    if proc.returncode != 0:
        raise RuntimeError(f"the bare loop exited {proc.returncode}: {proc.stderr.strip()[-500:]}")
    result: dict[str, object] = json.loads(proc.stdout)
    return result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--no-fifo", action="store_true", help="run at normal priority")
    parser.add_argument("--ticks", type=int, default=TICKS_N)
    args = parser.parse_args()
    print(json.dumps(measure(fifo=not args.no_fifo, ticks=args.ticks)))


if __name__ == "__main__":
    main()
