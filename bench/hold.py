"""HOLD on evidence (issue 24, item 4): does a HOLD the firmware declares hold its object, with and without
the wrap-side pay-in rules (``grasp_hold_min_payin_m``, ``grasp_hold_max_payin_m``), on placements the rules
were not chosen on.

Each placement is grasped twice by the same firmware on the same plant (fine step, 0.25 ms): once with the
rules off (the default) and once with them on. Both runs are the same physics up to the moment the pulling
cables come to rest at the wrap tension; there the rule either declares HOLD (and the trial removes the
object's support, as at every HOLD) or FAILED. So every HOLD with the rules is a HOLD without them, and
the runs differ only in which HOLDs are declared.

The rules and the goal were fixed before this benchmark first ran:

- strategy on: ``grasp_hold_min_payin_m`` = 39 mm. From a study of 40 other placements (seed 1; this run's
  placements are drawn with ``--seed``, 2 by default): of the 31 HOLDs, the 14 whose pulling cables had paid
  in less than 39 mm since contact all dropped their object; 9 of the 17 above held.
- the ramp (strategy off): ``grasp_hold_max_payin_m`` = 90 % of the pay-in of a grasp in the air (measured
  first, in this run: the object out of reach). In the same study the ramp's 3 HOLDs on nothing paid in
  71 mm, every held grasp at most 44 mm.
- goal: with the rule, the share of HOLDs that hold their object (held: in contact with 2 units, not
  fallen, at rest 0.6 s after its support went) is higher than without, and the rule refuses at most 1 in
  10 of the HOLDs that held.

Prints, per strategy: HOLDs declared and held (Wilson 95 %), the HOLDs the rule refused and what they did
without it, successes (the experiments' criterion) with the exact McNemar p, and the largest penetration.

``--params FILE`` grasps with a firmware parameter file instead of the experiments' firmware (the shipped
tuned grasp: its ceiling is measured with its own wrap tension); ``--preset`` on another plant (a fitted
twin's model file: the ceiling of the lab's arm); ``--step-ms`` runs at another physics
step (0.125: the convergence check); ``--strategy`` runs one of the two.

Usage: ``.venv/bin/python bench/hold.py [--placements 60] [--seed 2] [--jobs 2] [--params FILE]
[--preset NAME|arm.toml] [--step-ms 0.25] [--strategy both|on|off] [--out hold.jsonl]``
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

# Run as a script, this file's directory comes first on sys.path, where bench/protocol.py would shadow
# the protocol package; benchmarks import the project only.
_HERE = Path(__file__).resolve().parent
sys.path[:] = [p for p in sys.path if Path(p or ".").resolve() != _HERE]

import numpy as np  # noqa: E402

from controller.config import FirmwareConfig  # noqa: E402
from controller.errors import ConfigError  # noqa: E402
from controller.param_file import apply_param_file  # noqa: E402
from hil.experiments.stats import mcnemar_exact, wilson_interval  # noqa: E402
from hil.sim.config import PHYSICS_STEPS_S, ModelConfig  # noqa: E402
from hil.sim.presets import resolve  # noqa: E402
from hil.sim.spiral import SpiralDesign  # noqa: E402
from hil.trial.grasp import GraspSetup, grasp_firmware, grasp_trial  # noqa: E402
from hil.trial.rig import Rig  # noqa: E402
from protocol.messages import GraspState  # noqa: E402

MIN_PAYIN_M = 0.039
"""The strategy's rule, from the study of 40 placements (seed 1)."""
EMPTY_CURL_SHARE = 0.9
"""The ramp's ceiling: this share of the pay-in of a grasp in the air."""
MAX_REFUSED_HELD = 0.10


def placements(n: int, seed: int) -> list[tuple[float, float, float]]:
    """The study's distribution: 20-70 mm off the axis, 80-180 mm below the base, 15-40 mm cylinders."""
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(n):
        x = float(rng.uniform(0.02, 0.07))
        z = float(-rng.uniform(0.08, 0.18))
        out.append((x, z, float(rng.uniform(0.015, 0.04))))
    return out


Job = tuple[float, float, float, bool, dict[str, float], int, FirmwareConfig, ModelConfig, SpiralDesign]
"""x, z, diameter [m], strategy on, the rules' keys, the board's seed, the firmware, the plant, the arm."""


def run(job: Job) -> dict[str, Any]:
    """One grasp; the outcome with the pay-in the firmware had counted when it judged the wrap."""
    x, z, d, on, rules, seed, firmware, model, design = job
    judged: list[float] = []

    def look(rig: Rig) -> None:
        g = rig.firmware.grasp
        if not judged and g.state in (GraspState.HOLD, GraspState.FAILED) and g.wrap_payin_m != 0.0:
            judged.append(g.wrap_payin_m)

    fw = firmware.replaced(**rules) if rules else firmware
    setup = GraspSetup(x, z, d, strategy_on=on, firmware=fw, model=model, seed=seed)
    o = grasp_trial(setup, design, on_tick=look)
    return {
        "x": x,
        "z": z,
        "d": d,
        "on": on,
        "rules": rules,
        "state": o.state,
        "hold": o.state == "HOLD",
        "held": o.held,
        "success": o.success,
        "payin_m": judged[0] if judged else None,
        "penetration_m": o.extremes.penetration_m,
    }


def _rate(k: int, n: int) -> str:
    if n == 0:
        return "0/0"
    lo, hi = wilson_interval(k, n)
    return f"{k}/{n} = {k / n:.0%} [{lo:.2f}, {hi:.2f}]"


def report(rows: list[dict[str, Any]], on: bool, step_s: float) -> bool:
    """Print one strategy's figures; True if its goal is met."""
    base = [r for r in rows if r["on"] == on and not r["rules"]]
    rule = [r for r in rows if r["on"] == on and r["rules"]]
    pairs = list(zip(base, rule, strict=True))
    name = "strategy on" if on else "ramp (strategy off)"
    hb = [b for b in base if b["hold"]]
    hr = [r for r in rule if r["hold"]]
    refused = [b for b, r in pairs if b["hold"] and not r["hold"]]
    extra = sum(r["hold"] and not b["hold"] for b, r in pairs)
    held_b = sum(b["held"] for b in hb)
    held_r = sum(r["held"] for r in hr)
    refused_held = sum(b["held"] for b in refused)
    only_b = sum(b["success"] and not r["success"] for b, r in pairs)
    only_r = sum(r["success"] and not b["success"] for b, r in pairs)
    pen = max(r["penetration_m"] for r in base + rule) * 1e3
    print(f"{name}: {len(pairs)} placements, rule {rule[0]['rules']}")
    print(f"  HOLDs that held, rules off: {_rate(held_b, len(hb))}")
    print(f"  HOLDs that held, rules on:  {_rate(held_r, len(hr))}")
    print(
        f"  refused by the rule: {len(refused)} HOLDs, of which {refused_held} had held without it "
        f"({len(refused) - refused_held} dropped); HOLDs only with the rule: {extra} (must be 0)"
    )
    print(
        f"  success (held, wrap >= 180 deg): off {sum(b['success'] for b in base)}, "
        f"on {sum(r['success'] for r in rule)}; McNemar {only_b}/{only_r}, "
        f"p = {mcnemar_exact(only_b, only_r):.2f}"
    )
    over = {(r["x"], r["z"]) for r in base + rule if r["penetration_m"] > max(1e-3, 0.05 * r["d"])}
    print(
        f"  largest penetration {pen:.2f} mm at a {step_s * 1e3:g} ms step; {len(over)} placements over "
        "the goal (1 mm or 10 % of the radius)"
    )
    better = bool(hr) and bool(hb) and held_r / len(hr) > held_b / len(hb)
    few_lost = refused_held <= MAX_REFUSED_HELD * max(1, held_b)
    print(
        f"  goal (a HOLD holds more often; at most {MAX_REFUSED_HELD:.0%} of the held refused): "
        f"{'met' if better and few_lost and extra == 0 else 'NOT met'}"
    )
    return better and few_lost and extra == 0


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--placements", type=int, default=60)
    ap.add_argument("--seed", type=int, default=2, help="placements' seed (the rule was chosen on seed 1)")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--params", type=Path, default=None, help="a firmware parameter file to grasp with")
    ap.add_argument("--preset", default="prototype", help="the plant: a preset or a fitted model file")
    ap.add_argument("--step-ms", type=float, default=PHYSICS_STEPS_S["fine"] * 1e3, help="physics step")
    ap.add_argument("--strategy", choices=("both", "on", "off"), default="both")
    ap.add_argument("--out", type=Path, default=None, help="write every trial as a JSON line")
    args = ap.parse_args(argv)
    if args.placements < 1 or args.jobs < 1:
        ap.error("--placements and --jobs must be >= 1")
    if not 0.01 <= args.step_ms <= 1.0 or abs(round(1.0 / args.step_ms) * args.step_ms - 1.0) > 1e-9:
        ap.error("--step-ms must divide the 1 ms control period (1, 0.5, 0.25, 0.125, ...)")
    try:
        firmware = apply_param_file(args.params, grasp_firmware()) if args.params else grasp_firmware()
    except ConfigError as e:
        ap.error(str(e))
    try:
        preset = resolve(args.preset)
    except ValueError as e:
        ap.error(str(e))
    step_s = args.step_ms * 1e-3
    model = preset.model.with_physics(step_s)  # contacts and limits as stiff as the step allows
    design = preset.spiral()
    t0 = time.perf_counter()
    print(
        f"controller: {args.params or 'the experiments firmware'}; plant {args.preset}; "
        f"physics step {args.step_ms:g} ms"
    )
    air = run((0.5, -0.12, 0.02, False, {}, 0, firmware, model, design))  # the object half a metre away
    if air["payin_m"] is None or air["state"] != "HOLD":
        print(f"the grasp in the air did not come to rest ({air['state']}): no ceiling", file=sys.stderr)
        return 1
    ceiling = round(EMPTY_CURL_SHARE * air["payin_m"], 4)
    print(
        f"grasp in the air (ramp): {air['payin_m'] * 1e3:.1f} mm paid in at rest; ceiling "
        f"{EMPTY_CURL_SHARE:.0%} of it = {ceiling * 1e3:.1f} mm"
    )
    spots = placements(args.placements, args.seed)
    strategies = {"both": (True, False), "on": (True,), "off": (False,)}[args.strategy]
    jobs: list[Job] = []
    for on in strategies:
        rules = {"grasp_hold_min_payin_m": MIN_PAYIN_M} if on else {"grasp_hold_max_payin_m": ceiling}
        for i, (x, z, d) in enumerate(spots):
            for r in ({}, rules):
                jobs.append((x, z, d, on, r, args.seed * 1000 + i, firmware, model, design))
    rows: list[dict[str, Any]] = []
    out = args.out.open("w", encoding="utf-8") if args.out else None
    with ProcessPoolExecutor(args.jobs) as pool:
        for k, row in enumerate(pool.map(run, jobs)):
            rows.append(row)
            if out:
                out.write(json.dumps(row) + "\n")
                out.flush()
            if (k + 1) % 10 == 0 or k + 1 == len(jobs):
                print(
                    f"  {k + 1}/{len(jobs)} grasps, {time.perf_counter() - t0:.0f} s",
                    file=sys.stderr,
                    flush=True,
                )
    if out:
        out.close()
    met = [report(rows, on, step_s) for on in strategies]
    print(f"{len(jobs) + 1} grasps in {time.perf_counter() - t0:.0f} s ({args.jobs} jobs)")
    names = ["strategy on" if on else "ramp" for on in strategies]
    print("goals: " + ", ".join(f"{n} {'met' if m else 'NOT met'}" for n, m in zip(names, met, strict=True)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
