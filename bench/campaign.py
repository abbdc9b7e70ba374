"""Campaign throughput: runs per minute of one small campaign on 1 and 2 local worker processes and on a
local Ray of 2 CPUs, so the cost of running on Ray is a measured number.

Run: ``.venv/bin/python bench/campaign.py [--runs N] [--scenario NAME] [--no-ray]``. The campaign is
``NAME`` (default ``startup-gate``, 1.5 simulated seconds) over seeds 0..N-1, through the executors of
``spirob-hil campaign`` (:mod:`hil.campaign.runner`). Per executor it prints the wall time (with start-up:
worker processes, or Ray's node) and the steady rate (from the first finished run to the last, runs per
minute); then Ray's steady rate over the local pool's at 2 workers. Target (printed, not asserted): Ray
within 15 % of the local pool at 2 workers on a 2-core machine.
"""

from __future__ import annotations

import argparse
import importlib.util
import sys
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

# Running this file puts bench/ first on sys.path, where bench/protocol.py would shadow the `protocol`
# package: put the repository root in front.
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from hil.campaign.runner import execute_local, execute_ray
from hil.campaign.spec import Run, parse_campaign

TARGET_RATIO = 0.85
"""Ray's steady rate at 2 CPUs should be at least this share of the local pool's at 2 workers."""


def _measure(name: str, rows: Iterator[dict[str, Any]], n: int) -> float:
    """Drain ``rows``; print wall time and steady rate; return the steady rate [runs/min]."""
    t0 = time.perf_counter()
    stamps = []
    for row in rows:
        if row["outcome"] == "error":
            raise SystemExit(f"{name}: run {row['key']} failed: {row.get('error')}")
        stamps.append(time.perf_counter())
    if len(stamps) != n:
        raise SystemExit(f"{name}: {len(stamps)} of {n} runs finished")
    wall_s = stamps[-1] - t0
    steady = (n - 1) / (stamps[-1] - stamps[0]) * 60 if n > 1 and stamps[-1] > stamps[0] else float("nan")
    print(f"  {name:<22} {n} runs in {wall_s:6.1f} s ({n / wall_s * 60:6.1f} runs/min with start-up); "
          f"steady {steady:6.1f} runs/min")  # fmt: skip
    return steady


def main() -> int:
    """Run the benchmark; exit status 0 (the target is reported, not enforced)."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    ap.add_argument("--runs", type=int, default=24, help="runs (seeds) per executor (default 24)")
    ap.add_argument(
        "--scenario", default="startup-gate", help="the scenario each run is (default startup-gate)"
    )
    ap.add_argument("--no-ray", action="store_true", help="local processes only")
    args = ap.parse_args()
    if args.runs < 2:
        ap.error("--runs must be at least 2 (a steady rate needs two finished runs)")
    runs: list[Run] = parse_campaign(
        {"kind": "scenario", "seeds": args.runs, "scenario": {"name": args.scenario}}
    ).runs()
    stop = threading.Event()
    print(f"campaign: {args.scenario} x {args.runs} seeds")
    executors: list[tuple[str, Callable[[], Iterator[dict[str, Any]]]]] = [
        ("local, 1 worker", lambda: execute_local(runs, 1, stop)),
        ("local, 2 workers", lambda: execute_local(runs, 2, stop)),
    ]
    if args.no_ray:
        print("  (Ray skipped: --no-ray)")
    elif importlib.util.find_spec("ray") is None:
        print("  (Ray skipped: not installed; pip install 'spirob-teleop[ray]')")
    else:
        executors.append(("Ray, 2 CPUs", lambda: execute_ray(runs, 2, stop)))
    rates = {name: _measure(name, make(), len(runs)) for name, make in executors}
    if "Ray, 2 CPUs" in rates:
        ratio = rates["Ray, 2 CPUs"] / rates["local, 2 workers"]
        verdict = "within" if ratio >= TARGET_RATIO else "OUTSIDE"
        print(f"Ray / local at 2 workers: {ratio:.2f} ({verdict} the 15 % target)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
