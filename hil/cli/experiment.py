"""``spirob-hil experiment NAME``: the command line of :mod:`hil.experiments` (arguments, progress bar,
table or JSON, figure). The experiments themselves know nothing of argparse, rich or printing."""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from rich.console import Console
from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn
from rich.table import Table

from controller.cli_kit import EXIT_OK, UsageError, finite_float, seed, writable_dir
from controller.config import CONTROL_PERIOD_US
from hil.cli.design import add_design_arguments, design_from_args, design_options_given, model_from_args
from hil.experiments.catalogue import EXPERIMENTS, run_experiment
from hil.experiments.common import PHYSICS, SIZES, grasp_pictures
from hil.experiments.outcomes import GraspOutcomes
from hil.report import write_index

if TYPE_CHECKING:
    from hil.render import Pictures

__all__ = ["EXPERIMENT_HELP", "MAX_JOBS_N", "NO_GRASP", "configure_experiment", "run_experiment_command"]

NO_GRASP = "this experiment runs no grasp trial: no pictures (its figure is above)"
"""The report's line for an experiment with no grasp to picture."""

MAX_JOBS_N = 64
"""The most worker processes ``--jobs`` starts: each holds a MuJoCo plant; more than this is a typo."""

EXPERIMENT_HELP = "reproduce a result of the paper: " + ", ".join(EXPERIMENTS)
"""The one-line help of ``spirob-hil experiment``: every experiment of the catalogue, by name."""


def configure_experiment(p: argparse.ArgumentParser) -> None:
    """Arguments of ``spirob-hil experiment``."""
    p.add_argument("name", choices=list(EXPERIMENTS), metavar="NAME", help=", ".join(EXPERIMENTS))
    p.add_argument("--json", action="store_true", help="print one JSON object instead of a table")
    p.add_argument(
        "--report",
        type=Path,
        metavar="DIR",
        help="write the experiment's PNG figure into DIR, pictures of a grasp that succeeded and one that "
        "did not (rendered by MuJoCo), and NAME.md listing them",
    )
    p.add_argument("--seed", type=seed, default=0, help="seed of every random choice (default 0)")
    p.add_argument(
        "--size",
        choices=SIZES,
        default="default",
        help="tiny: seconds (a smoke test); default: the documented run (< 5 min); large: denser",
    )
    p.add_argument(
        "--jobs", type=int, default=2, metavar="N", help="worker processes for independent runs (default 2)"
    )
    p.add_argument(
        "--physics",
        choices=list(PHYSICS),
        help="fine: a 0.25 ms step with 0.5 ms contacts and joint limits (every experiment's default but "
        "convergence's); board: the real-time board's 1 ms step with 2 ms constraints",
    )
    p.add_argument(
        "--timestep-ms",
        type=finite_float,
        metavar="MS",
        help="physics step [ms] (default: --physics's); the constraints keep --physics's time constants; "
        "the 1 ms control period must be a whole number "
        "of steps: 1, 0.5, 0.25 ... (to show a result converges)",
    )
    add_design_arguments(p)


def run_experiment_command(args: argparse.Namespace) -> int:
    """Run ``spirob-hil experiment``: progress on stderr, the table (or JSON) on stdout, a PNG with
    ``--report``."""
    if not 1 <= args.jobs <= MAX_JOBS_N:
        raise ValueError(f"--jobs must be 1..{MAX_JOBS_N}, got {args.jobs}")
    if args.report is not None:  # checked before the experiment runs, not after
        writable_dir(args.report, "write the figure into", "spirob-hil experiment")
    exp = EXPERIMENTS[args.name]
    shaped = design_options_given(args)
    if exp.own_arm and shaped:
        raise UsageError(
            f"experiment {exp.name} drives {exp.own_arm} whatever the design options say: drop "
            f"{' '.join(shaped)} (--preset still picks the plant model)"
        )
    step_s = PHYSICS[args.physics] if args.physics else exp.model.solver.timestep_s
    model = model_from_args(args).with_physics(step_s)
    if args.timestep_ms is not None:
        step_s = args.timestep_ms / 1000.0
        ratio = CONTROL_PERIOD_US * 1e-6 / step_s if step_s > 0 else 0.0
        if not (step_s > 0 and abs(ratio - round(ratio)) < 1e-9 and round(ratio) >= 1):
            raise ValueError(
                f"--timestep-ms must divide the 1 ms control period (1, 0.5, 0.25 ...): {args.timestep_ms:g}"
            )
        model = dataclasses.replace(model, solver=dataclasses.replace(model.solver, timestep_s=step_s))
        try:
            model.validate()
        except ValueError as exc:
            raise ValueError(f"--timestep-ms {args.timestep_ms:g}: {exc} (--physics board has 2 ms)") from exc
    design = design_from_args(args)
    err = Console(stderr=True)
    t0 = time.perf_counter()
    with Progress(
        TextColumn("{task.description}"),
        BarColumn(),
        TextColumn("{task.completed:.0f}/{task.total:.0f}"),
        TimeElapsedColumn(),
        console=err,
        transient=True,
        disable=not err.is_terminal,
    ) as bar:
        task = bar.add_task(f"experiment {exp.name}", total=None)

        def progress(done: int, total: int) -> None:
            bar.update(task, completed=done, total=total)

        result = run_experiment(
            args.name,
            design=design,
            size=args.size,
            seed=args.seed,
            progress=progress,
            jobs=args.jobs,
            model=model,
        )
    elapsed = time.perf_counter() - t0
    figure = index = None
    pictures: list[tuple[str, Pictures]] = []
    if args.report is not None:
        try:
            figure = result.figure(args.report)
            if isinstance(result, GraspOutcomes):
                pictures = grasp_pictures(result.outcomes, design, args.report, exp.name)
            notes = [] if pictures else [NO_GRASP]
            index = write_index(args.report, exp.name, f"experiment {exp.name}", [figure], pictures, notes)
        except OSError as exc:
            raise ValueError(f"cannot write into {args.report}: {exc.strerror or exc}") from exc
    if args.json:
        out = result.as_dict()
        out["samples"] = result.describe_samples()
        out["size"] = args.size
        out["preset"] = args.preset
        out["timestep_s"] = model.solver.timestep_s
        out["contact_timeconst_s"] = model.contact.timeconst_s
        out["limit_timeconst_s"] = model.arm.limit_timeconst_s
        out["elapsed_s"] = round(elapsed, 1)
        if figure is not None:
            out["figure"] = str(figure)
            out["report"] = str(index)
            out["pictures"] = [str(p) for _, pics in pictures for p in pics.paths]
        print(json.dumps(_clean(out), allow_nan=False, default=_json_default))
        return EXIT_OK
    table = Table(title=f"{exp.name}: {exp.summary}", title_justify="left")
    table.add_column("quantity")
    table.add_column("this model", justify="right")
    table.add_column("paper")
    for quantity, ours, paper in result.table_rows():
        table.add_row(quantity, ours, paper)
    console = Console()
    console.print(table)
    console.print(
        f"samples: {result.describe_samples()}; preset {args.preset or 'prototype'}; "
        f"step {model.solver.timestep_s * 1000:g} ms (contacts {model.contact.timeconst_s * 1000:g} ms, "
        f"limits {model.arm.limit_timeconst_s * 1000:g} ms); seed {args.seed}; "
        f"size {args.size}; {elapsed:.0f} s"
    )
    if figure is not None:
        console.print(f"figure: {figure}", highlight=False, soft_wrap=True)
        for _, pics in pictures:
            for line in [pics.note] if pics.note else [str(p) for p in pics.paths]:
                console.print(f"pictures: {line}", highlight=False, soft_wrap=True)
        console.print(f"report: {index}", highlight=False, soft_wrap=True)
    return EXIT_OK


def _clean(value: Any) -> Any:
    """JSON has no NaN or infinity: they become null."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: _clean(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_clean(v) for v in value]
    return value


def _json_default(value: object) -> object:
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, np.generic):
        return value.item()
    raise TypeError(f"not JSON serialisable: {type(value).__name__}")
