"""``spirob-hil identify REC.mcap ... -o arm.toml``: the command line of :mod:`hil.identify` (arguments,
progress, the table, the model file, the report). The fit itself knows nothing of argparse or printing."""

from __future__ import annotations

import argparse
import json
import math
from collections.abc import Collection, Sequence
from pathlib import Path
from typing import Any

from absl import logging as absl_logging
from rich.console import Console
from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn, TimeRemainingColumn
from rich.table import Table

from controller.cli_kit import EXIT_OK, UsageError, finite_float, writable_dir, writable_file
from hil.cli.design import preset_arg
from hil.identify.fit import FitError, FitOptions, FitResult, fit
from hil.identify.motor_data import IdentifyDataError, load_motor_data
from hil.identify.report import write_report
from hil.identify.starts import (
    DELAY_CELLS_S,
    KNOWN_TORQUE_HORIZONS_S,
    default_horizons,
    parse_horizons,
    settled_m,
)
from hil.recording import package_version
from hil.sim.model_file import FittedParameter, ModelFile, read_model_file, write_model_file
from hil.sim.presets import is_model_file, resolve
from hil.sim.uncertain import ID_PARAMS, apply, by_name

__all__ = ["IDENTIFY_HELP", "configure_identify", "run_identify_command"]

IDENTIFY_HELP = (
    "fit the plant's uncertain parameters to recordings of an arm; write a model file --preset takes"
)
MAX_JOBS_N = 64
MAX_RESTARTS_N = 16
"""Restarts at most (each costs about one fit)."""


def _param_list(text: str) -> tuple[str, ...]:
    names = tuple(n.strip() for n in text.split(",") if n.strip())
    known = {p.name for p in ID_PARAMS}
    unknown = [n for n in names if n not in known]
    if unknown or not names:
        raise argparse.ArgumentTypeError(
            f"unknown parameter(s) {', '.join(unknown) or '(none given)'}; known: {', '.join(sorted(known))}"
        )
    return names


def _known(text: str) -> tuple[str, float]:
    name, eq, value = text.partition("=")
    names = {p.name for p in ID_PARAMS}
    if not eq or name.strip() not in names:
        raise argparse.ArgumentTypeError(
            f"--known wants NAME=VALUE with NAME one of {', '.join(sorted(names))}, got {text!r}"
        )
    try:
        v = float(value)
    except ValueError:
        raise argparse.ArgumentTypeError(f"--known {name.strip()}: not a number: {value!r}") from None
    if not math.isfinite(v):
        raise argparse.ArgumentTypeError(f"--known {name.strip()}: not a finite number: {value!r}")
    return name.strip(), v


KNOWN_NOTE = "known: given with --known (a datasheet, a bench test), not fitted"
"""The model file's note on a parameter the lab gave rather than the fit found."""


def configure_identify(p: argparse.ArgumentParser) -> None:
    """Arguments of ``spirob-hil identify``."""
    p.add_argument("recordings", nargs="+", type=Path, metavar="REC.mcap", help="recordings of an excitation")
    p.add_argument(
        "-o", "--output", required=True, type=Path, metavar="FILE.toml", help="the model file to write"
    )
    p.add_argument(
        "--preset",
        type=preset_arg,
        default="prototype",
        metavar="NAME|FILE",
        help="the model the fit starts from and keeps where it does not fit (default prototype)",
    )
    p.add_argument(
        "--report", type=Path, metavar="DIR", help="write an HTML report (figures, intervals) into DIR"
    )
    p.add_argument(
        "--params",
        type=_param_list,
        metavar="A,B,...",
        help=f"the parameters to fit (default all: {', '.join(q.name for q in ID_PARAMS)})",
    )
    p.add_argument(
        "--known",
        type=_known,
        action="append",
        default=[],
        metavar="NAME=VALUE",
        help="a parameter the lab knows (e.g. torque_scale from the datasheet): set, not fitted; "
        "repeatable. Giving torque_scale removes the fit's common-scale tie (docs/identify.md)",
    )
    p.add_argument(
        "--budget-s",
        type=finite_float,
        default=FitOptions().budget_s,
        metavar="S",
        help="simulated seconds per evaluation, shared among the recordings; the rest is held out "
        f"(default {FitOptions().budget_s:g})",
    )
    p.add_argument(
        "--max-iters",
        type=int,
        default=FitOptions().max_iters,
        metavar="N",
        help=f"solver iterations at most (default {FitOptions().max_iters}; unconverged: nothing identified)",
    )
    p.add_argument(
        "--explained-within-mm",
        type=finite_float,
        default=None,
        metavar="MM",
        help="the fitted cable lengths' RMS error above which the fit does not explain the arm and no "
        "parameter is called identified (default: the encoders' own noise, 10x their quantization RMS, "
        "0.0006 mm on the prototype; 0.3, the twin's accuracy target, is the weaker claim)",
    )
    p.add_argument(
        "--restarts",
        type=int,
        default=FitOptions().restarts,
        metavar="N",
        help="start the fit again from up to N more points while it leaves more of the cable lengths "
        "unexplained than the encoders' own noise (the delay at "
        + " and ".join(f"{1e3 * v:g}" for v in DELAY_CELLS_S)
        + " ms first, then points around the first start); the best start is kept, each costs about "
        f"one fit (default {FitOptions().restarts})",
    )
    p.add_argument(
        "--horizons",
        metavar="S,S",
        help="horizon continuation: fit every start to the recordings' first S seconds first, each horizon "
        "in turn, then to all the fit sees (e.g. 3,6,10: a long simulation's objective is a field of pits "
        "from stick-slip, a few seconds' is smooth); 'none' turns it off (default "
        + ",".join(f"{v:g}" for v in KNOWN_TORQUE_HORIZONS_S)
        + " when --known gives torque_scale, where it was shown to help; else none)",
    )
    p.add_argument(
        "--jobs", type=int, metavar="N", help="worker processes for the rollouts (default: one per core)"
    )
    p.add_argument("--json", action="store_true", help="print the result as one JSON object")


def _horizons(text: str | None, known: Collection[str]) -> tuple[float, ...]:
    """``--horizons``: None takes :func:`~hil.identify.starts.default_horizons` of the parameters given
    (``known``), ``none`` turns continuation off, else seconds S,S,..."""
    if text is None:
        return default_horizons(known)
    try:
        return parse_horizons(text)
    except ValueError as exc:
        raise UsageError(f"--horizons: {exc}") from None


def run_identify_command(args: argparse.Namespace) -> int:
    """``spirob-hil identify``: check everything a user can get wrong first, then fit, then write."""
    if not 1 <= args.max_iters <= 1000:
        raise UsageError(f"--max-iters must be 1..1000, got {args.max_iters}")
    if not 0 <= args.restarts <= MAX_RESTARTS_N:
        raise UsageError(f"--restarts must be 0..{MAX_RESTARTS_N}, got {args.restarts}")
    if args.jobs is not None and not 1 <= args.jobs <= MAX_JOBS_N:
        raise UsageError(f"--jobs must be 1..{MAX_JOBS_N}, got {args.jobs}")
    if not 1.0 <= args.budget_s <= 3600.0:
        raise UsageError(f"--budget-s must be 1..3600 s, got {args.budget_s:g}")
    if args.explained_within_mm is not None and not 0.0 < args.explained_within_mm <= 1000.0:
        raise UsageError(
            f"--explained-within-mm must be above 0 and at most 1000, got {args.explained_within_mm:g}"
        )
    horizons = _horizons(args.horizons, [name for name, _ in args.known])
    writable_file(args.output, "the model file")
    if args.report is not None:
        writable_dir(args.report, "the report")
    try:
        data = [load_motor_data(path) for path in args.recordings]
    except IdentifyDataError as exc:
        raise UsageError(str(exc)) from exc
    chosen = resolve(args.preset)
    base_preset = read_model_file(args.preset).preset if is_model_file(args.preset) else args.preset
    known = dict(args.known)
    if len(known) != len(args.known):
        raise UsageError("--known gives a parameter twice")
    both = sorted(set(known) & set(args.params or ()))
    if both:
        raise UsageError(f"--known and --params both name {', '.join(both)}: a parameter is given or fitted")
    try:
        start = apply(chosen.model, known)
    except ValueError as exc:
        raise UsageError(f"--known: {exc}") from exc
    fitted = tuple(n for n in (args.params or tuple(p.name for p in ID_PARAMS)) if n not in known)
    if not fitted:
        raise UsageError("--known gives every parameter: nothing left to fit")
    options = FitOptions(
        params=fitted,
        budget_s=args.budget_s,
        max_iters=args.max_iters,
        jobs=args.jobs,
        explained_within_m=None if args.explained_within_mm is None else args.explained_within_mm * 1e-3,
        restarts=args.restarts,
        horizons_s=horizons,
    )
    designs = {d.design for d in data if d.design is not None}
    design = next(iter(designs)) if len(designs) == 1 else chosen.spiral()
    err = Console(stderr=True)
    absl_logging.set_verbosity(absl_logging.ERROR)  # the toolbox's advice lines; the report says what matters
    try:
        result = _fit_with_progress(data, start, options, design, args, err)
    except FitError as exc:
        raise UsageError(str(exc)) from exc
    model = _model_file(result, base_preset, design, known, chosen.model)
    write_model_file(args.output, model)
    page = None
    if args.report is not None:
        page = write_report(
            result, args.report, f"Identification: {', '.join(p.name for p in args.recordings)}"
        )
    if args.json:
        extra = {"known": known, "horizons_s": list(horizons)}
        print(json.dumps(_finite(_as_dict(result, args.output, page) | extra), allow_nan=False))
    else:
        _print(result, args.output, page, known)
        delay_fitted = any(e.name == "delay" for e in result.estimates)
        hint = local_minimum_hint(
            result.starts,
            settled_m(data),
            args.restarts,
            delay_fitted,
            args.explained_within_mm is None,
            bool(horizons),
            "torque_scale" in fitted,
        )
        if hint:
            Console().print(f"[yellow]{hint}", highlight=False)
    return EXIT_OK


def _fit_with_progress(
    data: list[Any], model: Any, options: FitOptions, design: Any, args: argparse.Namespace, err: Console
) -> FitResult:
    columns = (
        TextColumn("[bold]identify"),
        BarColumn(),
        TextColumn("{task.percentage:>3.0f}%"),
        TimeElapsedColumn(),
        TimeRemainingColumn(),
        TextColumn("{task.description}"),
    )
    with Progress(*columns, console=err, transient=False, disable=args.json and not err.is_terminal) as bar:
        task = bar.add_task("reading", total=1.0)

        def progress(stage: str, fraction: float) -> None:
            bar.update(task, completed=min(1.0, fraction), description=stage)

        result = fit(
            data,
            model,
            options,
            design=design,
            progress=progress,
            sysid_report=None if args.report is None else args.report / "sysid",
        )
        bar.update(task, completed=1.0, description="done")
    return result


def _model_file(
    result: FitResult, preset: str, design: Any, known: dict[str, float], preset_model: Any
) -> ModelFile:
    params = {
        e.name: FittedParameter(e.name, e.value, e.unit, e.interval, e.identifiable, e.preset, e.why)
        for e in result.estimates
    }
    for name, value in known.items():  # the model file carries them: a reader gets the arm the fit saw
        row = by_name(name)
        params[name] = FittedParameter(name, value, row.unit, preset=row.read(preset_model), note=KNOWN_NOTE)
    fit_summary: dict[str, float | int | str] = {
        "fitted_rms_mm": _mm(result.rms_m(False)),
        "held_out_rms_mm": _mm(result.rms_m(True)),
        "preset_fitted_rms_mm": _mm(result.rms_m(False, "nominal")),
        "preset_held_out_rms_mm": _mm(result.rms_m(True, "nominal")),
        "condition_number": result.condition_number,
        "iterations": result.iterations,
        "converged": str(result.converged).lower(),
        "rollouts": result.rollouts,
        "simulated_s": round(result.simulated_s, 1),
        "wall_s": round(result.wall_s, 1),
    }
    return ModelFile(
        preset, design, params, fit_summary, result.recordings, tool=f"spirob-teleop {package_version()}"
    )


def _mm(m: float) -> float:
    return round(m * 1e3, 4) if math.isfinite(m) else math.nan


def _print(result: FitResult, output: Path, page: Path | None, known: dict[str, float]) -> None:
    console = Console()
    table = Table(title="fitted parameters (95 % intervals, autocorrelation-consistent)")
    for col in ("parameter", "preset", "fitted", "95 % interval", "identified"):
        table.add_column(col)
    for e in result.estimates:
        lo, hi = e.interval
        table.add_row(
            e.name,
            f"{e.preset:.4g}",
            f"{e.value:.4g} {e.unit}",
            f"{lo:.4g} .. {hi:.4g}",
            "yes" if e.identifiable else f"no: {e.why}",
        )
    console.print(table)
    if known:
        given = ", ".join(f"{k} = {v:.4g} {by_name(k).unit}".rstrip() for k, v in known.items())
        console.print(f"known (--known, not fitted): {given}", highlight=False)
    console.print(
        f"cable length error: fitted {_mm(result.rms_m(False))} mm, held out {_mm(result.rms_m(True))} mm "
        f"(the preset: {_mm(result.rms_m(False, 'nominal'))} mm, {_mm(result.rms_m(True, 'nominal'))} mm); "
        f"{result.iterations} iterations, {result.rollouts} rollouts, {result.wall_s:.0f} s"
    )
    if len(result.starts) > 1:
        each = "; ".join(f"{obj:.4g} ({_mm(rms)} mm)" for obj, rms in result.starts)
        console.print(f"{len(result.starts)} starts, objective (fitted length error): {each}; the least kept")
    if not result.converged:
        console.print(
            f"[yellow]the fit had not converged: its last iteration still lowered the error by "
            f"{100 * result.last_reduction:.1f} %; the intervals are local "
            "(more --max-iters, or fewer --params)"
        )
    console.print(f"wrote {output}" + (f"; report {page}" if page is not None else ""))


def _as_dict(result: FitResult, output: Path, page: Path | None) -> dict[str, Any]:
    return {
        "model_file": str(output),
        "report": None if page is None else str(page),
        "parameters": [
            {
                "name": e.name,
                "unit": e.unit,
                "preset": e.preset,
                "value": e.value,
                "interval": list(e.interval),
                "naive_interval": list(e.naive_interval),
                "hac_interval": list(e.hac_interval),
                "identifiable": e.identifiable,
                "why": e.why,
                "at_bound": e.at_bound,
            }
            for e in result.estimates
        ],
        "fitted_rms_m": result.rms_m(False),
        "held_out_rms_m": result.rms_m(True),
        "preset_fitted_rms_m": result.rms_m(False, "nominal"),
        "preset_held_out_rms_m": result.rms_m(True, "nominal"),
        "condition_number": result.condition_number,
        "iterations": result.iterations,
        "converged": result.converged,
        "starts": [{"objective": obj, "fitted_length_rms_m": rms} for obj, rms in result.starts],
        "rollouts": result.rollouts,
        "simulated_s": result.simulated_s,
        "wall_s": result.wall_s,
        "recordings": [list(r) for r in result.recordings],
    }


def _finite(value: Any) -> Any:
    """JSON has no NaN: a number that is not finite becomes null."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: _finite(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_finite(v) for v in value]
    return value


def local_minimum_hint(
    starts: Sequence[tuple[float, float]],
    settled: float,
    restarts: int,
    delay_fitted: bool = True,
    bound_is_noise: bool = True,
    horizons: bool = False,
    scale_tied: bool = False,
) -> str | None:
    """What to do when the best start left more than the encoders' noise (``settled``, m), or None.

    ``starts`` are the fit's ``(objective, fitted length RMS in m)``, one per start. In the hidden-truth
    draws every wrong fit left more than that, and no fit that left less was wrong (docs/identify.md section
    6); a real arm's fit always leaves more, so the hint says what it can and cannot mean. With
    ``bound_is_noise`` (no ``--explained-within-mm``) it also says why nothing is called identified; without
    ``horizons`` (no ``--horizons``) it offers horizon continuation. With ``scale_tied`` (the torque constant
    fitted) it offers ``--known torque_scale`` too: on twenty hidden truths with continuation, 13 of 20 first
    starts settled with the constant given, 9 of 17 with it fitted (docs/identify.md section 6;
    a tracked tip of 0.3 mm adds little to the motors' data, section 3).
    """
    if not starts or not math.isfinite(settled):
        return None
    rms = min(starts)[1]
    if not rms > settled:
        return None
    left = (
        f"the fit left {_mm(rms)} mm on its samples, more than the sensors' noise ({_mm(settled)} mm, ten "
        "times the encoders' quantization RMS)"
    )
    why = (
        " Below that no parameter is called identified (--explained-within-mm sets a weaker bound)."
        if bound_is_noise
        else ""
    )
    if scale_tied:
        span = (
            " The torque constant was fitted: it moves with the arm's force scale, the hardest direction for"
            " the search; --known torque_scale=VALUE (the datasheet's, or a weighing: docs/identify.md"
            " section 3) takes it out of the search"
            + ("." if horizons else ", and --horizons 3,6,10 fits the first seconds first.")
        )
    elif horizons:
        span = ""
    else:
        span = " --horizons 3,6,10 fits the first seconds first, where stick-slip leaves fewer such minima."

    if restarts == 0:
        cells = " and ".join(f"{1e3 * v:g}" for v in DELAY_CELLS_S)
        where = f"with the delay at {cells} ms" if delay_fitted else "from points around the first start"
        return (
            f"{left}: a model that follows its arm gets there, so it may have stopped in a local minimum; "
            f"--restarts 2 starts again {where} (about one fit's time each). "
            "No model follows a real arm to its encoders' noise: there this only says the model misses."
            + span
            + why
        )
    return (
        f"{left} after {len(starts)} starts: either the model cannot follow this arm (compare the report's "
        "traces) or every start stopped in a local minimum." + span + why
    )
