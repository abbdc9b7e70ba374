"""Does the fitted twin grasp like the arm it was fitted to? (issue 23's twin, judged by issue 24's grasps)

Reads the hidden-truth rows of a ``bench/identify.py`` run (``--fits FILE``: each row's seed gives the truth,
its fitted values the twin) and grasps the same ``--placements`` with the same controller (``--params``, by
default the shipped tuned file) on the truth, on the twin (written as a model file and read back as
``--preset arm.toml`` reads it) and on the preset the fit started from, at the experiments' fine physics
(``hil.identify.twin_grasp``); and on the truth with every parameter nudged by 0.1 %, for how often a verdict
survives a change no fit resolves (a grasp on an edge flips with it).

Goal, fixed before the first run: the twin's verdict (the grasp experiments' success criterion) matches the
truth's in at least 90 % of the (draw, placement) pairs, and in more of them than the preset's, exact
McNemar p < 0.05. Prints per draw, then pooled: successes per plant (Wilson), agreement with the truth
(Wilson), McNemar, the mean wrap-angle error (bootstrap) and the largest penetration. Every grasp is written
to ``--out`` (JSON lines) as its draw finishes.

Usage: ``.venv/bin/python bench/twin_grasp.py --fits runs/bench-identify.jsonl [--placements 8]
[--params FILE] [--seed 0] [--jobs 2] [--out runs/twin-grasp.jsonl] [--resume] [--summary-only]``
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

# Run as a script, this file's directory comes first on sys.path, where bench/protocol.py would shadow
# the protocol package; benchmarks import the project only.
_HERE = Path(__file__).resolve().parent
sys.path[:] = [p for p in sys.path if Path(p or ".").resolve() != _HERE]

from controller.errors import ConfigError  # noqa: E402
from controller.param_file import apply_param_file  # noqa: E402
from hil.experiments.parallel import parallel_map  # noqa: E402
from hil.identify.twin_grasp import (  # noqa: E402
    GOAL_AGREEMENT,
    GOAL_P,
    NUDGE_REL,
    PLANTS,
    AgreementSummary,
    Verdict,
    agreement,
    nudged_truth,
    placements,
    rate_errors,
    twin_models,
)
from hil.sim.config import ModelConfig  # noqa: E402
from hil.sim.spiral import SpiralDesign  # noqa: E402
from hil.trial.grasp import GraspSetup, grasp_firmware, grasp_trial_job  # noqa: E402

DEFAULT_PARAMS = _HERE.parent / "examples" / "params_prototype_tuned.toml"


def _line(label: str, s: AgreementSummary) -> str:
    succ = "  ".join(f"{k} {s.success[k]}/{s.n}" for k in PLANTS)
    tw, tlo, thi = s.rate(s.twin_agrees)
    pr, plo, phi = s.rate(s.preset_agrees)
    return (
        f"{label}: success {succ}; agrees with the truth: twin {s.twin_agrees}/{s.n} = {tw:.0%} "
        f"[{tlo:.2f}, {thi:.2f}], preset {s.preset_agrees}/{s.n} = {pr:.0%} [{plo:.2f}, {phi:.2f}]; "
        f"McNemar {s.only_twin} only twin / {s.only_preset} only preset, p = {s.p_value:.3g}; "
        f"the truth nudged by {NUDGE_REL:.1%} agrees {s.nudged_agrees}/{s.n}"
    )


def summarise(records: list[dict[str, Any]], seed: int) -> None:
    """Print the pooled figures and the goal's verdict from stored grasps (one record per placement)."""
    draws: dict[int, list[dict[str, Verdict]]] = {}
    for r in records:
        kinds = [k for k in (*PLANTS, "nudged") if k in r]
        draws.setdefault(int(r["seed"]), []).append({k: Verdict.from_record(r[k]) for k in kinds})
    pooled = [t for d in draws.values() for t in d]
    s = agreement(pooled, seed)
    print(f"\npooled over {len(draws)} draws, " + _line(f"n = {s.n}", s), flush=True)
    for k in ("twin", "preset"):
        mean, lo, hi, n = s.wrap_error_deg[k]
        print(
            f"  {k}: mean |wrap − truth's| {mean:.0f}° [{lo:.0f}, {hi:.0f}] (bootstrap, n = {n} with a HOLD)"
        )
    for k, (mean, lo, hi, n) in rate_errors(list(draws.values()), seed).items():
        print(
            f"  {k}: mean |success rate − truth's| per draw {mean:.1%} [{lo:.1%}, {hi:.1%}] "
            f"(bootstrap, {n} draws)"
        )
    pen = ", ".join(f"{k} {s.penetration_m[k] * 1e3:.2f} mm" for k in PLANTS)
    print(f"  largest penetration: {pen}; physics step 0.25 ms, contacts 0.5 ms", flush=True)
    print(
        f"goal (the twin agrees in >= {GOAL_AGREEMENT:.0%} and beats the preset, p < {GOAL_P}): "
        f"{'met' if s.goal_met else 'NOT met'}"
    )


def _kept(path: Path, placements_per_draw: int) -> list[dict[str, Any]]:
    """The records of ``path``'s whole draws (every placement there once); a draw cut short is run again."""
    try:
        lines = path.read_text(encoding="utf-8").splitlines()
    except FileNotFoundError:
        return []
    records: list[dict[str, Any]] = []
    for line in lines:
        try:
            records.append(json.loads(line))
        except ValueError:
            break  # a line cut by a stop: it and what follows are run again
    whole = {
        seed
        for seed in {r["seed"] for r in records}
        if sorted(r["placement"] for r in records if r["seed"] == seed) == list(range(placements_per_draw))
    }
    return [r for r in records if r["seed"] in whole]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--fits", type=Path, help="a bench/identify.py JSONL with hidden-truth rows")
    ap.add_argument("--placements", type=int, default=8, help="grasps per draw and plant")
    ap.add_argument("--params", type=Path, default=DEFAULT_PARAMS, help="the controller (a parameter file)")
    ap.add_argument("--seed", type=int, default=0, help="the placements' seed")
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--out", type=Path, default=Path("runs/twin-grasp.jsonl"))
    ap.add_argument("--summary-only", action="store_true", help="print the figures of --out; run nothing")
    ap.add_argument(
        "--resume",
        action="store_true",
        help="keep the draws --out holds whole (same --placements, --params and --seed); run the rest",
    )
    args = ap.parse_args(argv)
    if args.summary_only:
        try:
            stored = [json.loads(x) for x in args.out.read_text(encoding="utf-8").splitlines() if x.strip()]
        except (OSError, ValueError) as exc:
            ap.error(f"--out {args.out}: {exc}")
        if not stored:
            ap.error(f"--out {args.out}: no grasps")
        summarise(stored, args.seed)
        return 0
    if args.fits is None:
        ap.error("--fits is required (or --summary-only)")
    if args.placements < 1:
        ap.error("--placements must be >= 1")
    try:
        rows = [json.loads(x) for x in args.fits.read_text(encoding="utf-8").splitlines() if x.strip()]
    except (OSError, ValueError) as exc:
        ap.error(f"--fits {args.fits}: {exc}")
    rows = [r for r in rows if r.get("kind") == "truth"]
    if not rows:
        ap.error(f"--fits {args.fits}: no hidden-truth rows")
    try:
        firmware = apply_param_file(args.params, grasp_firmware())
    except ConfigError as exc:
        ap.error(str(exc))
    design = SpiralDesign.paper_prototype()
    spots = placements(args.placements, args.seed)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    print(
        f"twin grasps: {len(rows)} draws x {len(spots)} placements on the truth, the twin, the preset and "
        f"the nudged truth, controller {args.params.name} "
        f"(strategy {'on' if firmware.grasp.strategy_on else 'off'})"
    )

    def setups(model: ModelConfig) -> list[tuple[GraspSetup, SpiralDesign]]:
        return [
            (
                GraspSetup(
                    p.x_m,
                    p.z_m,
                    p.diameter_m,
                    strategy_on=firmware.grasp.strategy_on,
                    firmware=firmware,
                    model=model,
                    seed=args.seed + j,
                ),
                design,
            )
            for j, p in enumerate(spots)
        ]

    # Every draw's fit started from the same preset: its grasps are the same for all (seeded), so once.
    preset = parallel_map(grasp_trial_job, setups(twin_models(rows[0])[2]), args.jobs, None)
    records = _kept(args.out, len(spots)) if args.resume else []
    done = {int(r["seed"]) for r in records}
    if done:
        print(f"resumed: {len(done)} draws already in {args.out}", flush=True)
    t0 = time.monotonic()
    with args.out.open("w", encoding="utf-8") as out:
        out.writelines(json.dumps(r) + "\n" for r in records)
        out.flush()
        todo = [r for r in rows if int(r["seed"]) not in done]
        for i, row in enumerate(todo):
            truth, twin, _ = twin_models(row)
            jobs = setups(truth) + setups(twin) + setups(nudged_truth(row))
            outs = parallel_map(grasp_trial_job, jobs, args.jobs, None)
            n = len(spots)
            trials = [
                {"truth": outs[j], "twin": outs[n + j], "preset": preset[j], "nudged": outs[2 * n + j]}
                for j in range(n)
            ]
            for j, t in enumerate(trials):
                line = json.dumps(
                    {"seed": row["seed"], "placement": j, **{k: o.as_dict() for k, o in t.items()}},
                    default=str,
                )
                records.append(json.loads(line))  # as --summary-only will read it
                out.write(line + "\n")
            out.flush()
            verdicts = [{k: Verdict.of(o) for k, o in t.items()} for t in trials]
            print(_line(f"draw {row['seed']:2d}", agreement(verdicts)), flush=True)
            elapsed = time.monotonic() - t0
            eta = elapsed / (i + 1) * (len(todo) - i - 1)
            print(
                f"  {len(done) + i + 1}/{len(rows)} draws, {elapsed:.0f} s, about {eta:.0f} s left",
                file=sys.stderr,
                flush=True,
            )
    summarise(records, args.seed)
    return 0


if __name__ == "__main__":
    sys.exit(main())
