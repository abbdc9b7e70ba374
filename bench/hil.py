"""Benchmark of the lockstep closed loop (firmware + plant + board link) against the bare plant.

1. Closed loop: the virtual board in lockstep (plant step, DBUS and CAN delivery, the firmware's task
   table, the command to the ESCs) with a scripted host on the board link that sends heartbeats and
   decodes every telemetry frame — while the radio script bends the arm around. The currents the ESCs
   received are kept.
2. Bare plant, same run: a fresh plant with the same seed stepped with exactly those currents, so both
   simulate the same motion and the same contacts. The two are interleaved in chunks (default 0.5 s
   simulated): each closed-loop chunk is followed by the bare plant's same chunk, so the VM's drifting
   speed affects both alike.
3. The whole scenario suite, timed.

Prints the real-time factors, their ratio (target: closed loop >= 80 % of the bare plant's speed) and
the suite's wall time (target <= 2 minutes on the 2-core machine).

Usage: ``.venv/bin/python bench/hil.py [--seconds 10] [--repeats 3] [--chunk 0.5] [--no-suite]``
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Callable
from pathlib import Path

# Run as a script, this file's directory comes first on sys.path, where bench/protocol.py would shadow
# the protocol package; benchmarks import the project only.
_HERE = Path(__file__).resolve().parent
sys.path[:] = [p for p in sys.path if Path(p or ".").resolve() != _HERE]

import numpy as np  # noqa: E402

from hil.board import BoardConfig  # noqa: E402
from hil.environment import Environment  # noqa: E402
from hil.radio import RadioScript  # noqa: E402
from hil.scenarios import SCENARIOS, rc, run_scenario  # noqa: E402
from hil.sim.plant import Plant  # noqa: E402
from protocol.dbus import Lever, RcFrame  # noqa: E402


def stick_script(seconds: float) -> RadioScript:
    """Arm, then sweep the bending direction around while curling and uncurling."""
    steps: list[tuple[int, RcFrame]] = [(0, rc()), (200_000, rc(Lever.MIDDLE))]
    t = 500_000
    k = 0
    while t < seconds * 1e6:
        angle = k * 0.7
        steps.append(
            (
                t,
                rc(
                    Lever.MIDDLE,
                    ch0=int(500 * np.cos(angle)),
                    ch1=int(500 * np.sin(angle)),
                    ch3=(k % 3) * 200,
                ),
            )
        )
        t += 400_000
        k += 1
    return RadioScript(steps)


class ClosedLoop:
    """The virtual board in lockstep with a scripted host, advanced chunk by chunk.

    Args:
        seconds: length of the radio script.
        seed: the board's seed.
        stand_in: diagnostics (``--bounds``): replace the firmware's tick by a stand-in that only drains
            the CAN feedback and sends these currents (one row per tick): what the harness around the
            firmware costs by itself.
        time_firmware: diagnostics: add up the wall time of the firmware's ticks in :attr:`firmware_s`.
    """

    def __init__(
        self, seconds: float, seed: int, *, stand_in: np.ndarray | None = None, time_firmware: bool = False
    ) -> None:
        self.env = Environment(BoardConfig(seed=seed), radio=stick_script(seconds))
        self.board, self.host = self.env.board, self.env.host
        self.ticks = 0
        self.firmware_s = 0.0
        firmware = self.board.firmware
        bus = self.board.bus
        if stand_in is not None:
            rows = iter(stand_in.tolist())

            def stand_in_tick(now_us: int) -> int:
                bus.read_feedback()
                bus.send_currents(next(rows))
                return 1

            firmware.run_due = stand_in_tick  # type: ignore[method-assign]
        elif time_firmware:
            run_due = firmware.run_due

            def timed_tick(now_us: int) -> int:
                t0 = time.perf_counter()
                ran = run_due(now_us)
                self.firmware_s += time.perf_counter() - t0
                return ran

            firmware.run_due = timed_tick  # type: ignore[method-assign]

    def run(self, ticks: int) -> tuple[float, np.ndarray]:
        """Wall time of ``ticks`` ticks and the currents the ESCs received in each."""
        step, host, bus = self.env.step, self.host, self.board.bus
        applied: list[tuple[int, ...]] = []
        keep = applied.append  # the benchmark's own bookkeeping: one append per tick
        t0 = time.perf_counter()
        for _ in range(ticks):
            step()  # the one lockstep loop every scenario and experiment runs
            keep(bus.applied)
        host.drain()  # the scripted host decodes what it received in batches: timed here, with the loop
        wall = time.perf_counter() - t0
        self.ticks += ticks
        return wall, np.array(applied, np.int64)

    def close(self) -> None:
        """Check the loop really ran (telemetry flowed), then release the board."""
        if len(self.host.telemetry) < self.ticks // 10 * 0.9:
            raise SystemExit(
                f"closed loop broken: {len(self.host.telemetry)} telemetry frames in {self.ticks} ticks"
            )
        self.env.close()


class BarePlant:
    """A plant with the closed loop's seed, stepped with the currents the closed loop's ESCs received."""

    def __init__(self, seed: int) -> None:
        rng = np.random.default_rng(seed)
        plant_rng, _ = rng.spawn(2)
        self.plant = Plant(None, None, plant_rng)
        self._previous: tuple[int, int, int] | None = None

    def run(self, applied: np.ndarray, after_step: Callable[[], object] | None = None) -> float:
        """Wall time of one step per row of ``applied`` (and of ``after_step`` after each, if given)."""
        plant = self.plant
        previous = self._previous
        rows = applied.tolist()
        t0 = time.perf_counter()
        for row in rows:
            plant.step()
            currents = (row[0], row[1], row[2])
            if currents != previous:
                plant.apply_currents(currents)
                previous = currents
            if after_step is not None:
                after_step()
        wall = time.perf_counter() - t0
        self._previous = previous
        return wall


def paired_run(
    seconds: float, seed: int, chunk_s: float, loop: ClosedLoop | None = None
) -> tuple[float, float, int]:
    """Closed loop and bare plant interleaved chunk by chunk over the same motion.

    Each ``chunk_s`` of closed loop is followed at once by the bare plant stepping through the same
    chunk, so both halves of a pair see the same state of this shared VM (its speed drifts by +-15 %
    over seconds). Returns the total wall times of both and the tick count.
    """
    loop = loop if loop is not None else ClosedLoop(seconds, seed)
    bare = BarePlant(seed)
    ticks = round(seconds * 1e6 / loop.board.period_us)
    chunk = max(1, round(chunk_s * 1e6 / loop.board.period_us))
    loop_wall = bare_wall = 0.0
    done = 0
    while done < ticks:
        n = min(chunk, ticks - done)
        wall, applied = loop.run(n)
        loop_wall += wall
        bare_wall += bare.run(applied)
        done += n
    loop.close()
    return loop_wall, bare_wall, ticks


def _busy(n: int) -> int:
    x = 0
    for i in range(n):
        x += i
    return x


def busy_loop_cost(seed: int, currents: np.ndarray, target_us: float) -> tuple[float, float]:
    """A tiny-footprint busy loop of about ``target_us`` between plant steps: its own cost and what it adds.

    Returns the loop's warm cost and the time it adds per plant step (bare plant with the loop after
    every step, minus the bare plant alone, interleaved in chunks of 500 steps).
    """
    n = 1000
    t0 = time.perf_counter()
    _busy(n * 100)
    per_iter_us = (time.perf_counter() - t0) / (n * 100) * 1e6
    iters = max(1, round(target_us / per_iter_us))
    t0 = time.perf_counter()
    for _ in range(200):
        _busy(iters)
    warm_us = (time.perf_counter() - t0) / 200 * 1e6
    alone, with_busy = BarePlant(seed), BarePlant(seed)
    plain_s = busy_s = 0.0
    for start in range(0, len(currents), 500):
        chunk = currents[start : start + 500]
        plain_s += alone.run(chunk)
        busy_s += with_busy.run(chunk, after_step=lambda: _busy(iters))
    return warm_us, (busy_s - plain_s) / len(currents) * 1e6


def bounds(seconds: float, seed: int, chunk_s: float, repeats: int) -> None:
    """Where the closed loop's overhead goes (``--bounds``).

    1. The firmware's tick timed inside the loop, where it runs right after each MuJoCo step.
    2. The same loop with the firmware replaced by a stand-in that only drains the feedback and sends the
       currents the firmware sent: the harness alone (plant feedback, radio, link, scripted host). The
       ratio it reaches is the ceiling for any firmware in this loop.
    """
    timed = ClosedLoop(seconds, seed, time_firmware=True)
    loop_wall, bare_wall, ticks = paired_run(seconds, seed, chunk_s, timed)
    firmware_us = timed.firmware_s / ticks * 1e6
    reference = ClosedLoop(seconds, seed)
    _, currents = reference.run(ticks)
    reference.env.close()
    floors = []
    for _ in range(repeats):
        stand_in = ClosedLoop(seconds, seed, stand_in=currents)
        stand_in.ticks = -(10**9)  # its firmware sends no telemetry: skip the loop-health check
        floors.append(paired_run(seconds, seed, chunk_s, stand_in))
    floor_loop, floor_bare, _ = sorted(floors, key=lambda p: p[1] / p[0])[len(floors) // 2]
    burn_warm_us, burn_added_us = busy_loop_cost(seed, currents, firmware_us)
    print("where the overhead goes (--bounds):")
    print(
        f"  firmware's tick inside the loop:                {firmware_us:6.1f} us per tick "
        f"(overhead of that run {(loop_wall - bare_wall) / ticks * 1e6:5.1f} us)"
    )
    print(
        f"  harness alone (firmware stand-in):              {floor_bare / floor_loop:6.1%} of the bare plant,"
        " "
        f"overhead {(floor_loop - floor_bare) / ticks * 1e6:5.1f} us per tick (the ceiling for any firmware)"
    )
    print(
        f"  tiny-footprint busy loop between plant steps:   costs {burn_warm_us:5.1f} us warm, adds "
        f"{burn_added_us:5.1f} us per step (the firmware's cost in the loop is its footprint, not its code)"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=10.0, help="simulated seconds per run (default 10)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument(
        "--repeats", type=int, default=3, help="interleaved runs; the median is reported (default 3)"
    )
    parser.add_argument(
        "--chunk", type=float, default=0.5, help="simulated seconds per closed-loop/bare chunk (default 0.5)"
    )
    parser.add_argument("--no-suite", action="store_true", help="skip timing the scenario suite")
    parser.add_argument(
        "--bounds",
        action="store_true",
        help="also measure where the overhead goes: the harness with a do-nothing firmware stand-in, and "
        "the firmware's own time per tick inside the loop",
    )
    args = parser.parse_args()

    # Interleave the two measurements chunk by chunk and report the median run: on a shared 2-core VM
    # the speed of both drifts by +-15 % with whatever else the host runs.
    pairs: list[tuple[float, float, int]] = []
    for _ in range(args.repeats):
        loop_wall, bare_wall, ticks = paired_run(args.seconds, args.seed, args.chunk)
        pairs.append((loop_wall, bare_wall, ticks))
        loop_x, bare_x = args.seconds / loop_wall, args.seconds / bare_wall
        ratio = bare_wall / loop_wall
        print(f"  run: closed loop {loop_x:5.2f}x, bare plant {bare_x:5.2f}x, ratio {ratio:6.1%}")
    loop_wall, bare_wall, ticks = sorted(pairs, key=lambda p: p[1] / p[0])[len(pairs) // 2]
    loop_rtf = args.seconds / loop_wall
    bare_rtf = args.seconds / bare_wall
    overhead_us = (loop_wall - bare_wall) / ticks * 1e6
    print(
        f"simulated per run: {args.seconds:g} s in {args.chunk:g} s chunks, closed loop and bare plant "
        f"interleaved; median of {args.repeats} runs:"
    )
    print(f"lockstep closed loop (firmware + plant + link): {loop_rtf:6.2f}x real time")
    print(f"bare plant, same currents, same run:            {bare_rtf:6.2f}x real time")
    print(f"closed loop / bare plant speed:                 {loop_rtf / bare_rtf:6.1%} (target >= 80%)")
    print(f"closed-loop overhead per 1 ms tick:             {overhead_us:6.1f} us")

    if args.bounds:
        bounds(args.seconds, args.seed, args.chunk, args.repeats)

    if not args.no_suite:
        t0 = time.perf_counter()
        simulated = 0
        failed = []
        for name, scenario in SCENARIOS.items():
            result = run_scenario(name)
            simulated += scenario.duration_us
            if not result.passed:
                failed.append(name)
        wall = time.perf_counter() - t0
        print(
            f"scenario suite: {len(SCENARIOS)} scenarios, {simulated / 1e6:.1f} s simulated in "
            f"{wall:.1f} s wall ({simulated / 1e6 / wall:.2f}x real time; target <= 120 s)"
        )
        if failed:
            print(f"FAILED scenarios: {', '.join(failed)}")


if __name__ == "__main__":
    main()
