"""``spirob-hil tune``: the command line of :mod:`hil.tune` (arguments, the search locally or on Ray, progress
with a rate and an ETA, Ctrl-C, the held-out comparison, the parameter file)."""

from __future__ import annotations

import argparse
import importlib.util
import json
import shlex
import sys
import threading
import time
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from rich.console import Console
from rich.table import Table

from controller.cli_kit import (
    EXIT_FAILURE,
    EXIT_INTERRUPTED,
    EXIT_OK,
    UsageError,
    stop_on_signals,
    writable_dir,
)
from hil.campaign.runner import RAY_MISSING, ResultsFile, check_ray_address, execute_ray
from hil.tune.heldout import (
    Rate,
    compare_heldout,
    file_header,
    paired,
    rate_of,
    rate_text,
    write_tuned,
)
from hil.tune.objective import PRUNE_RULES, Evaluation, TuneSpec, placement_sets
from hil.tune.space import baseline_points

__all__ = ["TUNE_HELP", "configure_tune", "run_tune_command"]

PROG = "spirob-hil tune"
TUNE_HELP = "search the grasp controller's parameters for the highest success (Optuna, or Ray Tune)"
"""The one-line help of ``spirob-hil tune``."""

MAX_JOBS_N = 64
MAX_TRIALS_N = 10_000
_PLAIN_PROGRESS_S = 10.0
"""Without a terminal... and with one: a progress line at most this often [s]."""


def _pair(text: str, what: str) -> tuple[float, float]:
    try:
        lo, hi = (float(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"{what} wants LOW,HIGH in mm, got {text!r}") from None
    return lo / 1000, hi / 1000


def _grid(text: str) -> tuple[int, int]:
    try:
        nx, nz = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"--grid wants NXxNZ, e.g. 3x2, got {text!r}") from None
    return nx, nz


def _diameters(text: str) -> tuple[float, ...]:
    try:
        return tuple(float(v) / 1000 for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"--diameters-mm wants D1,D2,..., got {text!r}") from None


def configure_tune(p: argparse.ArgumentParser) -> None:
    """Arguments of ``spirob-hil tune``."""
    d = TuneSpec()
    p.add_argument("--study", default="prototype", metavar="NAME", help="study name (default prototype)")
    p.add_argument(
        "--storage",
        type=Path,
        metavar="PATH",
        help="Optuna journal file (default runs/tune/NAME.journal; --ray: a directory, runs/tune/NAME-ray)",
    )
    p.add_argument("--resume", action="store_true", help="go on with the study in --storage")
    p.add_argument(
        "--trials", type=int, default=40, metavar="N", help="finished trials the study should reach (40)"
    )
    p.add_argument(
        "--budget-min",
        type=float,
        metavar="M",
        help="start no trial after M minutes of search (the held-out comparison still runs)",
    )
    p.add_argument("--jobs", type=int, default=2, metavar="N", help="worker processes or Ray CPUs (2)")
    where = p.add_mutually_exclusive_group()
    where.add_argument("--ray", action="store_true", help="Ray Tune on a local Ray of --jobs CPUs")
    where.add_argument("--ray-address", metavar="ADDR", help="search with Ray Tune on the cluster at ADDR")
    s = p.add_argument_group("the question: placements and pruning (fixed with the study; defaults shown)")
    s.add_argument("--preset", default=d.preset, help=f"plant model preset (default {d.preset})")
    s.add_argument(
        "--diameters-mm",
        type=_diameters,
        default=d.diameters_m,
        metavar="D,...",
        help="object diameters (default 16,24,36)",
    )
    s.add_argument(
        "--x-mm",
        type=lambda t: _pair(t, "--x-mm"),
        default=d.x_range_m,
        metavar="LO,HI",
        help="object centres from the arm's axis (default 20,70)",
    )
    s.add_argument(
        "--z-mm",
        type=lambda t: _pair(t, "--z-mm"),
        default=d.z_range_m,
        metavar="LO,HI",
        help="object centres' height from the base (default -180,-60)",
    )
    s.add_argument("--grid", type=_grid, default=d.grid, metavar="NXxNZ", help="cells per set (default 3x2)")
    s.add_argument("--train-seeds", type=int, default=d.train_seeds, metavar="N", help="training seeds (1)")
    s.add_argument("--test-seeds", type=int, default=d.test_seeds, metavar="N", help="held-out seeds (1)")
    s.add_argument("--seed", type=int, default=d.seed, metavar="N", help="sets' and sampler's seed (0)")
    s.add_argument("--prune", choices=PRUNE_RULES, default=d.prune, help="pruning rule (default bound)")
    p.add_argument(
        "-o", "--output", type=Path, metavar="FILE", help="parameter file (default runs/tune/NAME.toml)"
    )
    p.add_argument(
        "--report",
        type=Path,
        metavar="DIR",
        help="write DIR/tune.md: the search's progress, the held-out comparison, pictures of the tuned "
        "controller's held-out grasps",
    )
    p.add_argument("--json", action="store_true", help="print the result as one JSON object")


def _spec(args: argparse.Namespace) -> TuneSpec:
    try:
        return TuneSpec(
            preset=args.preset,
            diameters_m=args.diameters_mm,
            x_range_m=args.x_mm,
            z_range_m=args.z_mm,
            grid=args.grid,
            train_seeds=args.train_seeds,
            test_seeds=args.test_seeds,
            seed=args.seed,
            prune=args.prune,
        )
    except ValueError as exc:
        raise UsageError(str(exc), PROG) from None


def _check_args(args: argparse.Namespace) -> None:
    if not 1 <= args.jobs <= MAX_JOBS_N:
        raise UsageError(f"--jobs must be 1..{MAX_JOBS_N}, got {args.jobs}", PROG)
    if not 1 <= args.trials <= MAX_TRIALS_N:
        raise UsageError(f"--trials must be 1..{MAX_TRIALS_N}, got {args.trials}", PROG)
    if args.budget_min is not None and not args.budget_min > 0:
        raise UsageError(f"--budget-min must be > 0, got {args.budget_min}", PROG)
    if args.seed < 0:
        raise UsageError(f"--seed must be >= 0, got {args.seed}", PROG)
    if not args.study.replace("-", "").replace("_", "").isalnum():
        raise UsageError(f"--study wants letters, digits, - and _, got {args.study!r}", PROG)
    if (args.ray or args.ray_address) and importlib.util.find_spec("ray") is None:
        raise UsageError(RAY_MISSING, PROG)
    if args.ray_address:
        check_ray_address(args.ray_address)
    if args.report is not None:  # checked before the first grasp, not after the last
        writable_dir(args.report, "write the report into", PROG)


class _Progress:
    """Progress lines on stderr: grasps done, their rate, the ETA of what is left (at most every 10 s)."""

    def __init__(self, err: Console, total_grasps: int, budget_s: float | None, heldout_n: int) -> None:
        self.err = err
        self.total = total_grasps
        self.budget_s = budget_s
        self.heldout_n = heldout_n
        self.t0 = time.monotonic()
        self.last = self.t0
        self.grasps = 0
        self._seen: set[str] = set()

    def row(self, ev: Evaluation) -> None:
        fresh = set(ev.rows) - self._seen - ev.cached
        self._seen |= fresh
        self.grasps += len(fresh)
        now = time.monotonic()
        if now - self.last >= _PLAIN_PROGRESS_S:
            self.last = now
            self.say(f"tune: {self.grasps} grasps, {self.rate_eta()}")

    def rate_eta(self) -> str:
        elapsed = time.monotonic() - self.t0
        if not self.grasps or elapsed <= 0:
            return "ETA -"
        per_s = self.grasps / elapsed
        left_s = max(0.0, self.total - self.grasps) / per_s
        if self.budget_s is not None:
            left_s = min(left_s, max(0.0, self.budget_s - elapsed) + self.heldout_s(per_s))
        minutes, seconds = divmod(round(left_s), 60)
        return f"{per_s * 60:.1f} grasps/min, ETA {minutes}m{seconds:02d}s (at most)"

    def heldout_s(self, per_s: float) -> float:
        return self.heldout_n / per_s

    def say(self, text: str) -> None:
        self.err.print(text, highlight=False, soft_wrap=True)


def run_tune_command(args: argparse.Namespace) -> int:
    """Run ``spirob-hil tune``. Exit status 0, 1 if no trial finished or grasps raised, 130 after Ctrl-C
    (the storage keeps every finished trial)."""
    _check_args(args)
    spec = _spec(args)
    try:
        train, test = placement_sets(spec)
    except ValueError as exc:
        raise UsageError(f"placements: {exc}", PROG) from None
    on_ray = bool(args.ray or args.ray_address)
    root = Path("runs") / "tune"
    storage: Path = args.storage or root / (f"{args.study}-ray" if on_ray else f"{args.study}.journal")
    output: Path = args.output or root / f"{args.study}.toml"
    for path in (storage, output):
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise UsageError(f"cannot write {path}: {exc.strerror or exc}", PROG) from None
    study = None
    if not on_ray:
        from hil.tune.search import TuneError, open_study

        try:
            study = open_study(storage, args.study, spec, resume=args.resume)
        except TuneError as exc:
            raise UsageError(str(exc), PROG) from None
    err = Console(stderr=True)
    rows_path = storage.with_name(storage.name.removesuffix(".journal") + "-rows.jsonl")
    where = f"Ray at {args.ray_address}" if args.ray_address else "a local Ray" if args.ray else "processes"
    err.print(
        f"tune: {len(train)} training and {len(test)} held-out placements; {spec.describe()}; "
        f"up to {args.trials} trials on {where} ({args.jobs} jobs); study {args.study} in {storage}",
        highlight=False,
        soft_wrap=True,
    )
    budget_s = None if args.budget_min is None else args.budget_min * 60
    progress = _Progress(err, args.trials * len(train) + 3 * len(test), budget_s, 3 * len(test))
    with stop_on_signals() as stop, ResultsFile(rows_path, resume=True) as cache:
        if cache.stale:
            progress.say(
                f"{len(cache.stale)} stored grasp(s) in {rows_path} were made by other code or from another "
                "model file: they are run again when needed (the study's finished trials keep their scores)"
            )
        if on_ray:
            from hil.tune.ray_search import search_ray  # Ray is imported only here

            outcome = search_ray(
                spec,
                train,
                name=args.study,
                storage=storage,
                resume=args.resume,
                trials=args.trials,
                budget_s=progress.budget_s,
                jobs=args.jobs,
                address=args.ray_address,
                stop=stop,
                say=progress.say,
            )
        else:
            assert study is not None
            outcome = _search_local(args, study, spec, train, storage, cache, stop, progress)
        best_values, best_k, trials_n, pruned_n = outcome
        if stop.is_set():
            progress.say(
                f"interrupted: {trials_n} trial(s) finished, kept in {storage} (grasps in {rows_path}); "
                + (f"best so far {best_k}/{len(train)}: {best_values}" if best_values else "none finished")
                + "; run again with --resume"
            )
            return EXIT_INTERRUPTED
        if best_values is None:
            progress.say("no trial finished: nothing to write")
            return EXIT_FAILURE
        controllers = {"tuned": _with_timeout(best_values), **_baselines()}
        progress.say(f"tune: best {best_k}/{len(train)} on training; held-out: {len(test)} x 3 grasps")
        executor = None
        if on_ray:

            def executor(runs: Any, jobs: int, stop_: threading.Event) -> Any:
                return execute_ray(runs, jobs, stop_, address=args.ray_address)

        outcomes, ev = compare_heldout(
            spec,
            test,
            controllers,
            jobs=args.jobs,
            stop=stop,
            cache=cache,
            executor=executor,
            on_row=progress.row,
        )
        if ev.interrupted:
            progress.say(f"interrupted in the held-out comparison: grasps kept in {rows_path}; --resume")
            return EXIT_INTERRUPTED
    heldout = {label: rate_of(o) for label, o in outcomes.items()}
    mcnemar = {other: paired(outcomes["tuned"], outcomes[other]) for other in ("default", "ramp")}
    train_rate = Rate(best_k, len(train))
    header = file_header(
        preset=spec.preset,
        made_by=_command_line(args, spec),
        spec=spec,
        trials_n=trials_n,
        pruned_n=pruned_n,
        train=train_rate,
        heldout=heldout,
        mcnemar=mcnemar,
    )
    write_tuned(output, controllers["tuned"], header)
    index = None
    if args.report is not None:
        from hil.tune.objective import runs_for
        from hil.tune.report import write_tune_report

        progress.say(f"report: pictures of the tuned controller's held-out grasps into {args.report}")
        index = write_tune_report(
            args.report,
            describe=spec.describe(),
            points=_trial_points(args, study, storage, len(train)),
            train_n=len(train),
            heldout=heldout,
            mcnemar=mcnemar,
            tuned_rows=[
                ev.rows[r.key] for r in runs_for(controllers["tuned"], test, spec) if r.key in ev.rows
            ],
            values=controllers["tuned"],
            param_file=output,
        )
    return _report(
        args, output, storage, train_rate, heldout, mcnemar, controllers["tuned"], ev.errors, index
    )


def _trial_points(args: argparse.Namespace, study: Any, storage: Path, n: int) -> list[Any] | None:
    """The search's finished trials for the report's progress figure (a Ray search's from its journal)."""
    from hil.tune.report import trial_points

    if study is None:
        from hil.tune.ray_search import load_study

        study = load_study(storage, args.study)
    return None if study is None else trial_points(study, n)


def _command_line(args: argparse.Namespace, spec: TuneSpec) -> str:
    """The command that asks the same question (the options that fix the study, and the search's)."""
    mm = ",".join(f"{d * 1000:g}" for d in spec.diameters_m)
    words = [
        "spirob-hil", "tune", "--study", args.study, "--preset", spec.preset, "--diameters-mm", mm,
        "--x-mm", f"{spec.x_range_m[0] * 1000:g},{spec.x_range_m[1] * 1000:g}",
        f"--z-mm={spec.z_range_m[0] * 1000:g},{spec.z_range_m[1] * 1000:g}",
        "--grid", f"{spec.grid[0]}x{spec.grid[1]}", "--train-seeds", str(spec.train_seeds),
        "--test-seeds", str(spec.test_seeds), "--seed", str(spec.seed), "--prune", spec.prune,
        "--trials", str(args.trials), "--jobs", str(args.jobs),
    ]  # fmt: skip
    if args.budget_min is not None:
        words += ["--budget-min", f"{args.budget_min:g}"]
    if args.ray:
        words.append("--ray")
    return shlex.join(words)


def _with_timeout(values: Mapping[str, Any]) -> dict[str, Any]:
    from hil.tune.space import firmware_values

    return firmware_values({k: v for k, v in values.items() if k != "grasp_reach_timeout_us"})


def _baselines() -> dict[str, dict[str, Any]]:
    from hil.tune.space import firmware_values

    return {label: firmware_values(point) for label, point in baseline_points().items()}


def _search_local(
    args: argparse.Namespace,
    study: Any,
    spec: TuneSpec,
    train: list[Any],
    storage: Path,
    cache: ResultsFile,
    stop: threading.Event,
    progress: _Progress,
) -> tuple[dict[str, Any] | None, int, int, int]:
    from hil.tune.search import best_trial, finished_trials, search_local

    before = len(finished_trials(study))
    if before:
        progress.say(f"tune: {before} trial(s) already in {storage}")
    progress.total = max(0, args.trials - before) * len(train) + progress.heldout_n
    search_local(
        study,
        spec,
        train,
        trials=args.trials,
        budget_s=progress.budget_s,
        jobs=args.jobs,
        stop=stop,
        cache=cache,
        on_row=progress.row,
        on_trial=lambda line: progress.say(f"{line.text()}; {progress.rate_eta()}"),
    )
    done = finished_trials(study)
    pruned = sum(t.state.name == "PRUNED" for t in done)
    best = best_trial(study)
    if best is None:
        return None, 0, len(done), pruned
    return json.loads(best.user_attrs["values"]), int(best.user_attrs["successes"]), len(done), pruned


def _report(
    args: argparse.Namespace,
    output: Path,
    storage: Path,
    train: Rate,
    heldout: Mapping[str, Rate],
    mcnemar: Mapping[str, Mapping[str, Any]],
    values: Mapping[str, Any],
    errors_n: int,
    index: Path | None = None,
) -> int:
    status = EXIT_FAILURE if errors_n else EXIT_OK
    if args.json:
        print(
            json.dumps(
                {
                    "file": str(output),
                    "storage": str(storage),
                    "values": dict(values),
                    "train": train.as_dict(),
                    "heldout": {k: r.as_dict() for k, r in heldout.items()},
                    "mcnemar": {k: dict(m) for k, m in mcnemar.items()},
                    "errors_n": errors_n,
                    "report": None if index is None else str(index),
                },
                allow_nan=False,
            )
        )
        return status
    table = Table(title="held-out placements (never seen by the search)", title_justify="left")
    for name in ("controller", "success (Wilson 95 %)", "vs tuned: only tuned / only it, McNemar p"):
        table.add_column(name)
    for label, r in heldout.items():
        m = mcnemar.get(label)
        vs = "" if m is None else f"{m['only_a']} / {m['only_b']}, p = {m['p_value']:.3g}"
        table.add_row(label, rate_text(r), vs)
    console = Console(file=sys.stdout)
    console.print(table)
    console.print(f"training success of the tuned values: {rate_text(train)}", highlight=False)
    console.print(f"parameter file: {output} (study in {storage})", highlight=False, soft_wrap=True)
    if index is not None:
        console.print(f"report: {index}", highlight=False, soft_wrap=True)
    if errors_n:
        console.print(f"{errors_n} grasp(s) raised: see the rows file", highlight=False)
    return status
