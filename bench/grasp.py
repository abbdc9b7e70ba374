"""Grasp trials per minute at the fine physics (0.25 ms steps): MuJoCo's ``auto`` constraint Jacobian (the
plant's default; sparse for the prototype's 63 degrees of freedom) against ``dense``, in one run (issue 24,
item 5).

Both run the same placements in this process, interleaved trial by trial (so a busy machine slows both
alike), and the figures are trials per minute of this process's CPU time (wall time beside it).

It prints where a physics step's time goes (MuJoCo's stage timers, and the time outside ``mj_step``: the
firmware and the plant's Python), which bounds what any solver option can gain. It also says whether the
physics is the same: the paired outcomes (success rates with Wilson intervals,
the exact McNemar p of the discordant pairs), the largest penetration of each, and the free arm's drift
between the two Jacobians under the same random currents (rounding, or a different plant).

Goal (issue 24): at least 2x the trials per minute, the outcomes unchanged within their intervals.

Usage: ``.venv/bin/python bench/grasp.py [--trials 24] [--seed 0]``
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from collections.abc import Callable
from pathlib import Path

# Run as a script, this file's directory comes first on sys.path, where bench/protocol.py would shadow
# the protocol package; benchmarks import the project only.
_HERE = Path(__file__).resolve().parent
sys.path[:] = [p for p in sys.path if Path(p or ".").resolve() != _HERE]

import mujoco  # noqa: E402
import numpy as np  # noqa: E402

from hil.experiments.stats import mcnemar_exact, wilson_interval  # noqa: E402
from hil.sim.config import PHYSICS_STEPS_S, ModelConfig  # noqa: E402
from hil.sim.plant import Plant  # noqa: E402
from hil.sim.spiral import SpiralDesign  # noqa: E402
from hil.sim.types import PlantConfig  # noqa: E402
from hil.trial.grasp import GraspOutcome, GraspSetup, grasp_trial  # noqa: E402
from hil.trial.rig import Rig  # noqa: E402

CONFIGS = (("auto (the default; sparse here)", "auto"), ("dense", "dense"))
STAGES = (
    ("step", "mjTIMER_STEP"),
    ("position", "mjTIMER_POSITION"),
    ("kinematics+tendons", "mjTIMER_POS_KINEMATICS"),
    ("collision", "mjTIMER_POS_COLLISION"),
    ("constraint", "mjTIMER_CONSTRAINT"),
)
"""MuJoCo's own stage timers (``MjData.timer``, wall time inside ``mj_step``) printed per physics step."""
GOAL_SPEEDUP = 2.0


def placements(n: int, seed: int) -> list[tuple[float, float, float, bool]]:
    """``n`` grasps within the prototype's reach: x 25-65 mm off the axis, 90-170 mm below the base, 15-40 mm
    cylinders, the strategy on for every other one."""
    rng = np.random.default_rng(seed)
    return [
        (
            float(rng.uniform(0.025, 0.065)),
            float(-rng.uniform(0.09, 0.17)),
            float(rng.uniform(0.015, 0.04)),
            k % 2 == 0,
        )
        for k in range(n)
    ]


def model(jacobian: str) -> ModelConfig:
    fine = ModelConfig().with_physics(PHYSICS_STEPS_S["fine"])  # the experiments' step and constraints
    return dataclasses.replace(fine, solver=dataclasses.replace(fine.solver, jacobian=jacobian))


def _keep_first(into: list[Rig]) -> Callable[[Rig], None]:
    """An ``on_tick`` that keeps the trial's rig (its ``MjData`` holds the stage timers)."""

    def keep(rig: Rig) -> None:
        if not into:
            into.append(rig)

    return keep


def drift_m(seconds: float, seed: int) -> float:
    """The largest distance between the two Jacobians' unit positions, the free arm under the same random
    currents (each held 50-300 ms, up to 5 A) at the fine step."""
    design = SpiralDesign.paper_prototype()
    plants = [Plant(design, PlantConfig(model=model(jac))) for _, jac in CONFIGS]
    rng = np.random.default_rng(seed)
    worst = 0.0
    periods = int(seconds * 1000)
    k = 0
    while k < periods:
        raw = tuple(int(v) for v in rng.integers(0, 5001, size=3))
        hold = int(rng.integers(50, 301))
        for _ in range(min(hold, periods - k)):
            poses = []
            for p in plants:
                p.apply_currents(raw)
                p.step()
                poses.append(p.body_poses().positions_m)
            worst = max(worst, float(np.abs(poses[0] - poses[1]).max()))
            k += 1
    return worst


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trials", type=int, default=24, help="placements (each run once per Jacobian)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--drift-seconds", type=float, default=2.0)
    args = ap.parse_args(argv)
    if args.trials < 1:
        ap.error("--trials must be >= 1")
    design = SpiralDesign.paper_prototype()
    spots = placements(args.trials, args.seed)
    cpu = {jac: 0.0 for _, jac in CONFIGS}
    wall = {jac: 0.0 for _, jac in CONFIGS}
    outs: dict[str, list[GraspOutcome]] = {jac: [] for _, jac in CONFIGS}
    stage_s = {jac: dict.fromkeys([k for k, _ in STAGES], 0.0) for _, jac in CONFIGS}
    steps = dict.fromkeys(cpu, 0)
    print(
        f"grasp throughput at the fine step ({PHYSICS_STEPS_S['fine'] * 1e3:g} ms): {args.trials} placements"
    )
    for i, (x, z, dia, on) in enumerate(spots):
        order = CONFIGS if i % 2 == 0 else CONFIGS[::-1]
        for _, jac in order:
            setup = GraspSetup(x, z, dia, strategy_on=on, model=model(jac), seed=args.seed + i)
            rigs: list[Rig] = []
            c0, w0 = time.process_time(), time.perf_counter()
            outs[jac].append(grasp_trial(setup, design, on_tick=_keep_first(rigs)))
            cpu[jac] += time.process_time() - c0
            wall[jac] += time.perf_counter() - w0
            timer = rigs[0].plant.mj_data.timer
            steps[jac] += int(timer[int(mujoco.mjtTimer.mjTIMER_STEP)].number)
            for key, name in STAGES:
                stage_s[jac][key] += float(timer[int(getattr(mujoco.mjtTimer, name))].duration)
        print(f"  {i + 1}/{args.trials}", file=sys.stderr, flush=True)
    rate = {}
    for label, jac in CONFIGS:
        n = len(outs[jac])
        rate[jac] = n / cpu[jac] * 60.0
        wins = sum(o.success for o in outs[jac])
        lo, hi = wilson_interval(wins, n)
        pen = max(o.extremes.penetration_m for o in outs[jac]) * 1e3
        print(
            f"{label:28s} {rate[jac]:6.1f} trials per CPU-minute "
            f"({n / wall[jac] * 60.0:6.1f} per wall-minute); "
            f"success {wins}/{n} = {wins / n:.0%} [{lo:.2f}, {hi:.2f}]; largest penetration {pen:.2f} mm"
        )
    for label, jac in CONFIGS:
        per = {k: v / max(1, steps[jac]) * 1e6 for k, v in stage_s[jac].items()}
        outside = max(0.0, cpu[jac] - stage_s[jac]["step"]) / max(1, steps[jac]) * 1e6
        print(
            f"{label:28s} per physics step (MuJoCo's timers): "
            + ", ".join(f"{k} {v:.0f} us" for k, v in per.items())
            + f"; outside mj_step (firmware, plant in Python) {outside:.0f} us"
        )
    a, b = (outs[jac] for _, jac in CONFIGS)
    only_a = sum(x.success and not y.success for x, y in zip(a, b, strict=True))
    only_b = sum(y.success and not x.success for x, y in zip(a, b, strict=True))
    speedup = rate[CONFIGS[1][1]] / rate[CONFIGS[0][1]]
    print(
        f"speed-up {speedup:.2f}x (goal >= {GOAL_SPEEDUP:g}x); outcomes differ in {only_a + only_b} of "
        f"{len(a)} pairs ({only_a} only with auto, {only_b} only with dense), "
        f"McNemar p = {mcnemar_exact(only_a, only_b):.2f}"
    )
    print(
        f"free arm, same random currents for {args.drift_seconds:g} s: the two Jacobians' units at most "
        f"{drift_m(args.drift_seconds, args.seed):.1e} m apart"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
