"""``spirob-hil campaign FILE``: the command line of :mod:`hil.campaign.spec` (arguments, the executor, the
streamed results file, progress with a rate and an ETA, the summary as a table or JSON, the maps)."""

from __future__ import annotations

import argparse
import importlib.util
import json
import math
import sys
import threading
import time
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

from rich.console import Console
from rich.progress import BarColumn, Progress, TextColumn
from rich.table import Table

from controller.cli_kit import (
    EXIT_FAILURE,
    EXIT_INTERRUPTED,
    EXIT_OK,
    UsageError,
    stop_on_signals,
    writable_dir,
)
from hil.campaign.runner import (
    MAX_RETRIES_N,
    RAY_MISSING,
    ResultsFile,
    check_ray_address,
    execute_local,
    execute_ray,
)
from hil.campaign.spec import Campaign, CampaignError, Run, load_campaign

__all__ = ["CAMPAIGN_HELP", "configure_campaign", "run_campaign_command"]

PROG = "spirob-hil campaign"
CAMPAIGN_HELP = (
    "run a grid or random sample of grasp trials, array grasps or scenarios, resumable, locally or on Ray"
)
"""The one-line help of ``spirob-hil campaign``."""

MAX_JOBS_N = 64
"""The most local worker processes (or local Ray CPUs) ``--jobs`` starts: more is a typo."""
MAX_RETRIES_LIMIT = 10
"""The most ``--max-retries``: a run that kills its worker ten times will kill it an eleventh."""
_PLAIN_PROGRESS_S = 10.0
"""Without a terminal, a progress line at most this often [s]."""


def configure_campaign(p: argparse.ArgumentParser) -> None:
    """Arguments of ``spirob-hil campaign``."""
    p.add_argument(
        "file", nargs="?", type=Path, metavar="FILE", help="campaign file, .toml or .json (docs/campaigns.md)"
    )
    p.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="change or add a key of the file (repeatable): seeds=3, design.cable_mu=[0.2,0.4], "
        "scenario.name=overcurrent (VALUE: a TOML value, or a bare word)",
    )
    p.add_argument(
        "-o",
        "--out",
        type=Path,
        metavar="PATH",
        help="JSON-lines results file (default: FILE's stem + .jsonl in the current directory)",
    )
    p.add_argument(
        "--params",
        type=Path,
        metavar="FILE.toml",
        help="a firmware parameter file (e.g. from spirob-hil tune): the grasp runs' firmware under the "
        "campaign's own controller keys",
    )
    p.add_argument("--resume", action="store_true", help="go on with --out: skip the runs already in it")
    p.add_argument(
        "--rerun-stale",
        action="store_true",
        help="with --resume: run again the runs whose rows were made by other code or another model file "
        "(without it such a file is refused)",
    )
    p.add_argument(
        "--jobs", type=int, default=2, metavar="N", help="local worker processes, or --ray's CPUs (default 2)"
    )
    where = p.add_mutually_exclusive_group()
    where.add_argument("--ray", action="store_true", help="run on a local Ray of --jobs CPUs (needs Ray)")
    where.add_argument(
        "--ray-address", metavar="ADDR", help="run on the Ray cluster at ADDR, e.g. 10.0.0.5:6379 (needs Ray)"
    )
    p.add_argument(
        "--max-retries",
        type=int,
        default=MAX_RETRIES_N,
        metavar="N",
        help=f"start a run whose worker died again, up to N times (default {MAX_RETRIES_N})",
    )
    p.add_argument(
        "--report",
        type=Path,
        metavar="DIR",
        help="write a success map per design (PNG) into DIR, pictures of a success and a failure "
        "(rendered by MuJoCo) and campaign.md listing them",
    )
    p.add_argument(
        "--paired",
        metavar="KEY",
        help="a two-valued axis (e.g. controller.strategy_on): pair each run with the one that differs only "
        "in KEY and say, per plant and controller, where KEY's larger value wins (exact McNemar; with "
        "--report, claim_map.png)",
    )
    p.add_argument("--top", type=int, default=10, metavar="N", help="designs in the table (default 10)")
    p.add_argument("--json", action="store_true", help="print the summary as one JSON object")


def _check_args(args: argparse.Namespace) -> None:
    if not 1 <= args.jobs <= MAX_JOBS_N:
        raise UsageError(f"--jobs must be 1..{MAX_JOBS_N}, got {args.jobs}", PROG)
    if not 0 <= args.max_retries <= MAX_RETRIES_LIMIT:
        raise UsageError(f"--max-retries must be 0..{MAX_RETRIES_LIMIT}, got {args.max_retries}", PROG)
    if args.top < 1:
        raise UsageError(f"--top must be >= 1, got {args.top}", PROG)
    if args.rerun_stale and not args.resume:
        raise UsageError("--rerun-stale goes with --resume", PROG)
    if args.file is None and not args.set:
        raise UsageError("give a campaign FILE, or describe one with --set KEY=VALUE", PROG)
    if args.file is None and args.out is None:
        raise UsageError("without a campaign FILE, name the results file with --out", PROG)
    if args.file is not None and not args.file.is_file():
        raise UsageError(f"no such campaign file: {args.file}", PROG)
    if (args.ray or args.ray_address) and importlib.util.find_spec("ray") is None:
        raise UsageError(RAY_MISSING, PROG)
    if args.ray_address:
        check_ray_address(args.ray_address)


def run_campaign_command(args: argparse.Namespace) -> int:
    """Run ``spirob-hil campaign``: rows stream into the results file, progress goes to stderr, the
    summary to stdout. Exit status 1 if a run raised, 130 after Ctrl-C (the file keeps every finished run).
    """
    _check_args(args)
    params = None
    if args.params is not None:
        from controller.param_file import load_param_file

        params = load_param_file(args.params)  # a ConfigError is one line, exit 2
    campaign = load_campaign(args.file, args.set, params)
    out: Path = args.out if args.out is not None else Path(args.file.stem + ".jsonl")
    if args.report is not None:  # checked before the first run, not after the last
        writable_dir(args.report, "write the maps into", PROG)
    runs = campaign.runs()
    if args.paired is not None:
        from hil.campaign.claims import arm_values

        try:
            arm_values([{"inputs": r.inputs} for r in runs], args.paired)
        except ValueError as exc:
            raise UsageError(f"--paired: {exc}", PROG) from None
    err = Console(stderr=True)
    executor = (
        f"Ray at {args.ray_address}"
        if args.ray_address
        else f"a local Ray of {args.jobs} CPUs"
        if args.ray
        else f"{args.jobs} local process(es)"
    )
    with ResultsFile(out, resume=args.resume) as results:
        stale_n = sum(r.key in results.stale for r in runs)
        if stale_n and not args.rerun_stale:
            raise CampaignError(
                f"{out}: {stale_n} of this campaign's rows were made by other code or from another model "
                "file than this run would use (the plant, firmware or MuJoCo changed since), so their "
                "outcomes may not be this code's: --rerun-stale runs them again, or write to a new --out"
            )
        todo = [r for r in runs if r.key not in results.done]
        skipped_n = len(runs) - len(todo)
        note = f", {results.unreadable_n} unreadable line(s) skipped" if results.unreadable_n else ""
        if stale_n:
            note += f", {stale_n} made by other code to run again"
        err.print(
            f"campaign: {len(runs)} runs, {skipped_n} already in {out}{note}; "
            f"{len(todo)} to run on {executor}",
            highlight=False,
            soft_wrap=True,
        )
        t0 = time.perf_counter()
        with stop_on_signals() as stop:
            ran_n = _stream(args, todo, results, stop, err)
        elapsed_s = time.perf_counter() - t0
        if stop.is_set():
            err.print(
                f"interrupted: {ran_n} run(s) finished this time, {len(todo) - ran_n} left; "
                f"{out} keeps them: run again with --resume",
                highlight=False,
                soft_wrap=True,
            )
            return EXIT_INTERRUPTED
        rows = [results.done[r.key] for r in runs if r.key in results.done]
    return _summarise(args, campaign, rows, out, ran_n, skipped_n, elapsed_s)


def _executor(
    args: argparse.Namespace, todo: Sequence[Run], stop: threading.Event
) -> Iterator[dict[str, Any]]:
    if args.ray or args.ray_address:
        return execute_ray(todo, args.jobs, stop, address=args.ray_address, max_retries=args.max_retries)
    return execute_local(todo, args.jobs, stop, max_retries=args.max_retries)


def _stream(
    args: argparse.Namespace, todo: Sequence[Run], results: ResultsFile, stop: threading.Event, err: Console
) -> int:
    """Append each row to the file as it comes; show the rate and the ETA. Returns the rows written."""
    total = len(todo)
    if not total:
        return 0
    done = 0
    t0 = time.perf_counter()
    last_line = t0
    with Progress(
        TextColumn("campaign"),
        BarColumn(),
        TextColumn("{task.completed:.0f}/{task.total:.0f} runs  {task.fields[rate]}  ETA {task.fields[eta]}"),
        console=err,
        transient=True,
        disable=not err.is_terminal,
    ) as bar:
        task = bar.add_task("campaign", total=total, rate="-", eta="-")
        rows = _executor(args, todo, stop)
        try:
            for row in rows:
                results.append(row)
                done += 1
                now = time.perf_counter()
                rate, eta = _rate_eta(done, total, now - t0)
                bar.update(task, completed=done, rate=rate, eta=eta)
                if not err.is_terminal and (now - last_line >= _PLAIN_PROGRESS_S or done == total):
                    line = f"campaign: {done}/{total} runs, {rate}, ETA {eta}"
                    err.print(line, highlight=False, soft_wrap=True)
                    last_line = now
        finally:
            close = getattr(rows, "close", None)
            if close is not None:
                close()  # the executor stops its workers (Ctrl-C) or shuts its Ray down
    return done


def _rate_eta(done: int, total: int, elapsed_s: float) -> tuple[str, str]:
    if done == 0 or elapsed_s <= 0:
        return "-", "-"
    per_s = done / elapsed_s
    left_s = (total - done) / per_s
    minutes, seconds = divmod(round(left_s), 60)
    hours, minutes = divmod(minutes, 60)
    eta = f"{hours}h{minutes:02d}m" if hours else f"{minutes}m{seconds:02d}s"
    return f"{per_s * 60:.1f} runs/min", eta


def _summarise(
    args: argparse.Namespace,
    campaign: Campaign,
    rows: list[dict[str, Any]],
    out: Path,
    ran_n: int,
    skipped_n: int,
    elapsed_s: float,
) -> int:
    from hil.campaign.summary import (  # matplotlib only for the summary
        campaign_pictures,
        design_rates,
        success_maps,
    )
    from hil.report import write_index

    designs = design_rates(rows)
    errors_n = sum(r["outcome"] == "error" for r in rows)
    maps = success_maps(rows, args.report) if args.report is not None else []
    pictures: list[tuple[str, Any]] = []
    index = None
    if args.report is not None:
        pictures, notes = campaign_pictures(rows, args.report)
        index = write_index(args.report, "campaign", f"{campaign.kind} campaign", maps, pictures, notes)
    paired = _paired(args, rows) if args.paired is not None else None
    if args.json:
        summary = {
            "file": str(out),
            "kind": campaign.kind,
            "runs_n": len(rows),
            "ran_n": ran_n,
            "skipped_n": skipped_n,
            "errors_n": errors_n,
            "elapsed_s": round(elapsed_s, 1),
            "runs_per_min": round(ran_n / elapsed_s * 60, 2) if ran_n and elapsed_s > 0 else None,
            "designs": [d.as_dict() for d in designs[: args.top]],
            "maps": [str(p) for p in maps],
            "pictures": [str(p) for _, pics in pictures for p in pics.paths],
            "report": None if index is None else str(index),
        }
        if paired is not None:
            summary["paired"] = paired
        print(json.dumps(summary, allow_nan=False))
        return EXIT_FAILURE if errors_n else EXIT_OK
    table = Table(
        title=f"best designs of {len(designs)} ({campaign.kind} campaign, {len(rows)} runs)",
        title_justify="left",
    )
    for name, justify in (("#", "right"), ("design", "left"), ("success", "right"), ("rate", "right")):
        table.add_column(name, justify=justify)  # type: ignore[arg-type]
    table.add_column("95 % interval (Wilson)", justify="right")
    for i, d in enumerate(designs[: args.top], start=1):
        lo, hi = d.ci95
        errs = f" ({d.errors} errors)" if d.errors else ""
        rate, ci = ("n/a", "n/a") if not d.n else (f"{d.rate:.0%}", f"{lo:.2f} - {hi:.2f}")
        table.add_row(str(i), d.label, f"{d.successes}/{d.n}{errs}", rate, ci)
    console = Console(file=sys.stdout)
    console.print(table)
    console.print(
        f"results: {out} ({ran_n} run now, {skipped_n} from before, {errors_n} errors)",
        highlight=False,
        soft_wrap=True,
    )
    for path in maps:
        console.print(f"map: {path}", highlight=False, soft_wrap=True)
    for _, pics in pictures:
        for line in [pics.note] if pics.note else [str(p) for p in pics.paths]:
            console.print(f"pictures: {line}", highlight=False, soft_wrap=True)
    if index is not None:
        console.print(f"report: {index}", highlight=False, soft_wrap=True)
    if paired is not None:
        _print_paired(console, paired)
    return EXIT_FAILURE if errors_n else EXIT_OK


def _paired(args: argparse.Namespace, rows: list[dict[str, Any]]) -> dict[str, Any]:
    """The claim's cells, its verdict and its map (with ``--report``), JSON-ready."""
    from hil.campaign.claims import ALPHA, arm_values, claim_map, paired_cells, verdict

    a, b = arm_values(rows, args.paired)
    cells = paired_cells(rows, args.paired)
    title = f"{args.paired}={a} minus {b}: success rate per cell (* p < {ALPHA:g})"
    drawn = claim_map(cells, args.report / "claim_map.png", title) if args.report is not None else None
    return {
        "arm": args.paired,
        "a": a,
        "b": b,
        "cells": [
            {
                "inputs": c.inputs,
                "pairs": c.pairs,
                "a_successes": c.a_successes,
                "b_successes": c.b_successes,
                "only_a": c.only_a,
                "only_b": c.only_b,
                "p": c.p,
                "holds": c.holds,
                "penetration_m": None if math.isnan(c.penetration_m) else c.penetration_m,
                "placed_inside": c.placed_inside,
            }
            for c in cells
        ],
        "verdict": verdict(cells, args.paired, a),
        "map": None if drawn is None else str(drawn),
    }


def _print_paired(console: Console, paired: dict[str, Any]) -> None:
    table = Table(
        title=f"{paired['arm']} = {paired['a']} against {paired['b']}, paired per plant and controller",
        title_justify="left",
    )
    for name in (
        "cell",
        "pairs",
        str(paired["a"]),
        str(paired["b"]),
        "only a / only b",
        "McNemar p",
        "holds",
        "deepest",
        "placed inside",
    ):
        table.add_column(name)
    for c in paired["cells"]:
        label = ", ".join(f"{k.partition('.')[2]}={v}" for k, v in sorted(c["inputs"].items())) or "all"
        table.add_row(
            label,
            str(c["pairs"]),
            str(c["a_successes"]),
            str(c["b_successes"]),
            f"{c['only_a']} / {c['only_b']}",
            f"{c['p']:.2g}",
            "yes" if c["holds"] else "no",
            "n/a" if c["penetration_m"] is None else f"{c['penetration_m'] * 1000:.2f} mm",
            str(c["placed_inside"]),
        )
    console.print(table)
    console.print(f"verdict: {paired['verdict']}", highlight=False, soft_wrap=True)
    if paired["map"]:
        console.print(f"claim map: {paired['map']}", highlight=False, soft_wrap=True)
