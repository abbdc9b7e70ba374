"""Firmware loop benchmark: control-tick cost, and 1 kHz real-time lateness with and without SCHED_FIFO.

Usage::

    python bench/loop.py                 # tick cost + two 60 s real-time runs (FIFO, then normal)
    python bench/loop.py --seconds 5     # shorter real-time runs
    python bench/loop.py --ticks-only    # only the tick cost

Part 1 times one control tick (read RC, drain feedback, failsafe, mapping, motor model, one 0x200 frame)
in MANUAL mode with currents flowing, over two buses: ``fake`` (the in-process C610 trio; its motor
simulation is inside the timed region) and ``virtual`` (python-can's virtual bus; the fake trio answers
from a peer bus *outside* the timed region, so only the firmware's side is measured).

Part 2 runs the whole firmware (all tasks, telemetry into an in-memory host link) with
``Firmware.run`` and a ``RealTimeClock`` for N seconds in a fresh subprocess each — once with SCHED_FIFO
and once without — and reports the control task's start lateness (p50/p99/max) and missed deadlines
(runs that started >= 1 ms late). Targets: tick median <= 50 µs; with SCHED_FIFO 0 misses and p99
<= 50 µs; without it, misses <= 1 %.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

# Scripts in bench/ are named after what they measure (bench/protocol.py): do not let the script's own
# directory, which Python puts first on sys.path, shadow the packages of the same name.
_HERE = Path(__file__).resolve().parent
sys.path[:] = [p for p in sys.path if Path(p or ".").resolve() != _HERE]

from controller.clock import RealTimeClock  # noqa: E402
from controller.config import FirmwareConfig  # noqa: E402
from controller.fake_c610 import FakeC610Set  # noqa: E402
from controller.firmware import Firmware  # noqa: E402
from controller.motorbus import CanMotorBus, FakeMotorBus, MotorBus  # noqa: E402
from controller.rc import ScriptedRcSource  # noqa: E402
from controller.transport import MemoryTransport  # noqa: E402
from protocol.dbus import Lever, RcFrame  # noqa: E402

MANUAL = RcFrame((200, -300, 0, 400), Lever.MIDDLE, Lever.DOWN)


def _armed_firmware(bus: MotorBus, pump: Any = None) -> tuple[Firmware, int]:
    rc = ScriptedRcSource(RcFrame.neutral())
    fw = Firmware(FirmwareConfig(), bus, rc)
    t = 0
    for _ in range(50):  # pass the gate, then MANUAL with current flowing
        fw.run_due(t)
        if pump:
            pump()
        t += 1000
    rc.set_frame(MANUAL)
    for _ in range(200):
        fw.run_due(t)
        if pump:
            pump()
        t += 1000
    if fw.commanded_currents == (0, 0, 0):
        raise RuntimeError(f"bench set-up failed: phase {fw.phase.name}, mode {fw.mode.name}")
    return fw, t


def _percentiles(samples_ns: list[int]) -> tuple[float, float]:
    samples_ns.sort()
    n = len(samples_ns)
    return samples_ns[n // 2] / 1000, samples_ns[min(n - 1, (99 * n) // 100)] / 1000


def tick_cost(n: int) -> dict[str, tuple[float, float]]:
    """Median and p99 µs of one control tick, per bus."""
    out: dict[str, tuple[float, float]] = {}

    bus = FakeMotorBus()
    fw, t = _armed_firmware(bus)
    out["fake"] = _time_ticks(fw, t, n, None)

    import can

    channel = f"bench-{os.getpid()}"
    peer = can.Bus(interface="virtual", channel=channel)
    trio = FakeC610Set()

    def pump() -> None:  # the motors answer, outside the timed region
        while (msg := peer.recv(timeout=0)) is not None:
            trio.handle_frame(msg.arbitration_id, bytes(msg.data))
            if msg.arbitration_id == 0x200:
                for can_id, data in trio.step(1000):
                    peer.send(can.Message(arbitration_id=can_id, data=data, is_extended_id=False))

    with CanMotorBus(channel, "virtual") as vbus:
        fw, t = _armed_firmware(vbus, pump)
        out["virtual"] = _time_ticks(fw, t, n, pump)
    peer.shutdown()
    return out


def _time_ticks(fw: Firmware, t: int, n: int, pump: Any) -> tuple[float, float]:
    control = fw.scheduler["control"].run
    samples: list[int] = []
    clock = time.perf_counter_ns
    for _ in range(n):
        t0 = clock()
        control(t)
        samples.append(clock() - t0)
        if pump:
            pump()
        t += 1000
    return _percentiles(samples)


def realtime_child(seconds: float, fifo: bool) -> dict[str, Any]:
    """Run the full firmware in real time; return the control task's lateness figures."""
    host, board = MemoryTransport.pair()
    rc = ScriptedRcSource(RcFrame.neutral())
    fw = Firmware(FirmwareConfig(), FakeMotorBus(), rc, board)
    clock = RealTimeClock(fifo=fifo)
    ticks = 0

    def script() -> bool:  # called every tick: lever to MANUAL after 0.2 s; the host drains its end
        nonlocal ticks
        ticks += 1
        if ticks == 200:
            rc.set_frame(MANUAL)
        if ticks % 100 == 0:
            host.read()
        return False

    r0 = resource.getrusage(resource.RUSAGE_SELF)
    w0 = time.monotonic()
    fw.run(clock, duration_us=int(seconds * 1e6), stop=script)
    wall = time.monotonic() - w0
    r1 = resource.getrusage(resource.RUSAGE_SELF)
    ctl = fw.scheduler["control"]
    return {
        "fifo_active": fw.clock_kind.name == "REALTIME_FIFO",
        "runs": ctl.runs,
        "p50_us": ctl.lateness_percentile_us(0.50),
        "p99_us": ctl.lateness_percentile_us(0.99),
        "max_us": ctl.lateness_max_us,
        "missed": ctl.late,
        "skipped_ticks": ctl.skipped,
        "exec_max_us": ctl.exec_max_us,
        "exec_p99_us": ctl.update_p99(),
        "cpu_percent": 100.0 * ((r1.ru_utime + r1.ru_stime) - (r0.ru_utime + r0.ru_stime)) / wall,
        "mode_at_end": fw.mode.name,
    }


def realtime(seconds: float, fifo: bool) -> dict[str, Any]:
    cmd = [sys.executable, __file__, "--child", "--seconds", str(seconds), "--fifo" if fifo else "--no-fifo"]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=seconds + 120, check=False)
    if proc.returncode != 0:
        raise RuntimeError(f"real-time child failed:\n{proc.stderr}")
    result: dict[str, Any] = json.loads(proc.stdout.strip().splitlines()[-1])
    return result


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--seconds", type=float, default=60.0, help="length of each real-time run (default 60)")
    p.add_argument("--ticks", type=int, default=20_000, help="control ticks timed per bus")
    p.add_argument("--ticks-only", action="store_true", help="skip the real-time runs")
    p.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    p.add_argument("--fifo", dest="fifo", action="store_true", default=True, help=argparse.SUPPRESS)
    p.add_argument("--no-fifo", dest="fifo", action="store_false", help=argparse.SUPPRESS)
    args = p.parse_args(argv)
    if args.child:
        print(json.dumps(realtime_child(args.seconds, args.fifo)))
        return 0

    print(f"control tick cost, MANUAL mode, {args.ticks} ticks per bus:")
    for name, (median, p99) in tick_cost(args.ticks).items():
        print(f"  {name:8s} median {median:6.1f} us   p99 {p99:6.1f} us   (target: median <= 50 us)")
    if args.ticks_only:
        return 0
    print(f"\nreal-time 1 kHz run, full task table, {args.seconds:g} s each (fresh subprocess):")
    for fifo in (True, False):
        r = realtime(args.seconds, fifo)
        label = "SCHED_FIFO" if r["fifo_active"] else "normal" if not fifo else "FIFO DENIED"
        deadlines = r["runs"] + r["skipped_ticks"]
        pct = 100.0 * r["skipped_ticks"] / max(1, deadlines)
        print(
            f"  {label:10s} lateness p50 {r['p50_us']} us, p99 {r['p99_us']} us, max {r['max_us']} us;"
            f" missed deadlines {r['skipped_ticks']} of {deadlines} ({pct:.3f} %)"
            f" in {r['missed']} late starts (>= 1 ms late)"
        )
        print(
            f"             control exec p99 {r['exec_p99_us']} us, max {r['exec_max_us']} us;"
            f" CPU {r['cpu_percent']:.0f} % of one core; mode at end {r['mode_at_end']}"
        )
    print("  targets: SCHED_FIFO 0 missed and p99 <= 50 us; without it misses <= 1 %")
    return 0


if __name__ == "__main__":
    sys.exit(main())
