"""Protocol benchmark: decode rates and one firmware tick's worth of protocol work.

Run: ``.venv/bin/python bench/protocol.py``. Prints

- DBUS decode rate (``RcFrame.unpack``) and framer rate (``DbusFramer.feed`` + gap flush), frames/s;
- board-link telemetry stream decode rate (``LinkParser.feed`` + ``decode``), frames/s;
- per-tick protocol work (decode one RC frame + pack one 0x200 command + encode one Telemetry frame):
  median and p99 in µs against the 20 µs median target.
"""

from __future__ import annotations

import gc
import statistics
import sys
import time
from pathlib import Path

# Running this file puts bench/ first on sys.path, where this very file would shadow the `protocol`
# package: put the repository root in front.
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from protocol.c610 import current_command
from protocol.dbus import IDLE_GAP_US, DbusFramer, Lever, RcFrame
from protocol.link import LinkParser
from protocol.messages import Mode, Phase, Telemetry, TelemetryFlags, decode, encode

TARGET_TICK_MEDIAN_US = 20.0


def _rate(n: int, elapsed_ns: int) -> float:
    return n / (elapsed_ns / 1e9)


def _telemetry(i: int) -> Telemetry:
    return Telemetry(
        time_us=i * 10_000,
        mode=Mode.MANUAL,
        phase=Phase.OK,
        flags=TelemetryFlags.ARMED | TelemetryFlags.RC_OK | TelemetryFlags.HOST_OK,
        motors_online=0b111,
        rc_channels=(120, -300, 0, 660),
        right_lever=Lever.MIDDLE,
        left_lever=Lever.DOWN,
        motor_angle=(1000 + i % 7000, 2000, 3000),
        motor_speed_rpm=(120, -80, 0),
        motor_current=(1500, 900, 300),
        commanded_current=(1520, 880, 310),
        tension_target_n=(3.0, 2.0, 1.0),
        tension_est_n=(2.9, 2.1, 1.05),
        cable_length_m=(0.012, -0.004, 0.0),
        control_late=3,
        control_exec_p99_us=45,
        control_exec_max_us=310,
        control_lateness_max_us=290,
        rc_frames_ok=i,
        link_frames_ok=i,
    )


def bench_dbus(n: int = 100_000) -> tuple[float, float]:
    """Return (RcFrame.unpack rate, DbusFramer rate) in frames/s."""
    raw = RcFrame((100, -200, 300, -400), Lever.MIDDLE, Lever.UP).pack()
    unpack = RcFrame.unpack
    t0 = time.perf_counter_ns()
    for _ in range(n):
        unpack(raw)
    unpack_rate = _rate(n, time.perf_counter_ns() - t0)

    framer = DbusFramer()
    period_us = 7_000
    frames = 0
    t0 = time.perf_counter_ns()
    for k in range(n // 4):
        now = k * period_us
        frames += len(framer.feed(raw[:9], now))
        frames += len(framer.feed(raw[9:], now + 1_000))
        frames += len(framer.feed(b"", now + 1_000 + IDLE_GAP_US))
    framer_rate = _rate(frames, time.perf_counter_ns() - t0)
    if frames != n // 4:
        raise RuntimeError(f"framer delivered {frames} of {n // 4} frames")
    return unpack_rate, framer_rate


def bench_link_stream(n: int = 20_000, chunk: int = 512) -> float:
    """Telemetry frames/s through LinkParser.feed (in ``chunk``-byte reads) + decode."""
    stream = b"".join(encode(_telemetry(i), i & 0xFF) for i in range(n))
    parser = LinkParser()
    count = 0
    t0 = time.perf_counter_ns()
    for i in range(0, len(stream), chunk):
        for frame in parser.feed(stream[i : i + chunk]):
            decode(frame)
            count += 1
    elapsed = time.perf_counter_ns() - t0
    if count != n:
        raise RuntimeError(f"parser delivered {count} of {n} frames")
    return _rate(n, elapsed)


def bench_tick(n: int = 20_000) -> tuple[float, float]:
    """(median, p99) µs of decode one RC frame + pack one 0x200 command + encode one Telemetry frame."""
    raw = RcFrame((100, -200, 300, -400), Lever.MIDDLE, Lever.UP).pack()
    telemetry = _telemetry(1)
    currents = [1520, 880, 310]
    samples: list[int] = []
    clock = time.perf_counter_ns
    for i in range(n):
        t0 = clock()
        RcFrame.unpack(raw)
        current_command(currents)
        encode(telemetry, i & 0xFF)
        samples.append(clock() - t0)
    samples.sort()
    return statistics.median(samples) / 1000, samples[int(0.99 * (len(samples) - 1))] / 1000


def main() -> int:
    """Run all benchmarks and print their figures; exit 1 if the per-tick median misses the target."""
    gc.collect()
    gc.disable()
    try:
        unpack_rate, framer_rate = bench_dbus()
        link_rate = bench_link_stream()
        median_us, p99_us = bench_tick()
    finally:
        gc.enable()
    telemetry_len = len(encode(_telemetry(0), 0))
    print(f"DBUS RcFrame.unpack:              {unpack_rate:12,.0f} frames/s")
    print(f"DBUS DbusFramer (2 chunks+flush): {framer_rate:12,.0f} frames/s")
    print(f"link telemetry parse+decode:      {link_rate:12,.0f} frames/s  ({telemetry_len}-byte frames)")
    verdict = "OK" if median_us < TARGET_TICK_MEDIAN_US else "MISSED"
    print(
        f"per-tick protocol work:           median {median_us:6.2f} µs, p99 {p99_us:6.2f} µs "
        f"(target median < {TARGET_TICK_MEDIAN_US:.0f} µs: {verdict})"
    )
    return 0 if median_us < TARGET_TICK_MEDIAN_US else 1


if __name__ == "__main__":
    raise SystemExit(main())
