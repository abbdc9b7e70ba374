"""Benchmark of the slcan back end: python-can's own ``slcanBus`` against ``CanMotorBus``'s; prints figures.

A 1 kHz loop (absolute deadlines, 2 s per back end) sends one zero-current command per tick and drains
the feedback, as the firmware's tick does, through a USB-CAN adapter speaking slcan on a pty (the fake
C610 trio behind it, in a process of its own). Per back end it prints the ticks run of those due, the
mean and largest tick (the loop's own work, wall-clock) and the feedback frames read, then the ratio of
the mean ticks (python-can's over ours: the baseline measured in the same run).

Usage: ``.venv/bin/python bench/slcan.py [--seconds 2]``
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

# Run as a script, this file's directory comes first on sys.path, where bench/protocol.py would shadow
# the protocol package; benchmarks import the project only.
_HERE = Path(__file__).resolve().parent
sys.path[:] = [p for p in sys.path if Path(p or ".").resolve() != _HERE]
sys.path.insert(0, str(_HERE.parent))

import can  # noqa: E402

from controller.motorbus import CanMotorBus, feedback_filters  # noqa: E402
from tests.support.c610_rigs import SlcanAdapterProcess  # noqa: E402


def _run(seconds: float, baseline: bool) -> tuple[int, int, float, float, int]:
    """(ticks run, ticks due, mean tick us, max tick us, feedback frames) over ``seconds`` at 1 kHz."""
    with SlcanAdapterProcess() as adapter:
        if baseline:
            raw = can.Bus(
                interface="slcan",
                channel=adapter.path,
                bitrate=1_000_000,
                sleep_after_open=0,
                can_filters=feedback_filters(3),
            )
            bus = CanMotorBus(bus=raw)
        else:
            bus = CanMotorBus(adapter.path, "slcan", sleep_after_open=0)
        with bus:
            period = 1_000_000
            start = time.monotonic_ns()
            end = start + int(seconds * 1e9)
            deadline, ticks, total, worst, frames = start, 0, 0, 0, 0
            for _ in range(int(seconds * 1000)):  # bounded in count as well as time
                now = time.monotonic_ns()
                if now >= end:
                    break
                if deadline > now:
                    time.sleep((deadline - now) / 1e9)
                t0 = time.monotonic_ns()
                bus.send_currents([0, 0, 0])
                frames += len(bus.read_feedback())
                took = time.monotonic_ns() - t0
                ticks, total, worst = ticks + 1, total + took, max(worst, took)
                deadline += period
                while deadline < time.monotonic_ns() - period:  # skip, never burst
                    deadline += period
        due = int(seconds * 1000)
    return ticks, due, total / max(ticks, 1) / 1e3, worst / 1e3, frames


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=2.0)
    args = parser.parse_args()
    rows = {}
    for name, baseline in (("python-can slcanBus", True), ("CanMotorBus slcan", False)):
        ticks, due, mean, worst, frames = _run(args.seconds, baseline)
        rows[name] = mean
        print(
            f"{name:20s} ticks {ticks} of {due} due, tick mean {mean:7.1f} us, max {worst:7.1f} us, "
            f"feedback frames {frames} ({frames / max(ticks, 1):.2f} per tick)"
        )
    ratio = rows["python-can slcanBus"] / rows["CanMotorBus slcan"]
    print(f"mean tick, python-can's over ours: {ratio:.1f}x")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
