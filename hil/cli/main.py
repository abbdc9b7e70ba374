"""`spirob-hil`: design math, model export (and, in later issues, boards, runs, replays, experiments).

Argument parsing lives in :func:`build_parser`, apart from :func:`main`, so tests call
``main(["design", "--json"])``. Each subcommand is one :class:`Command` in ``COMMANDS`` (a name, a
help line, a function that adds its arguments, a function that runs it); a later issue adds its
subcommand by appending one entry. User mistakes (bad options, impossible designs, unwritable paths) are
one line on stderr and exit status 2, never a traceback.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TextIO

from rich.console import Console
from rich.progress import BarColumn, Progress, TaskID, TextColumn, TimeElapsedColumn

from controller.cli_kit import (
    EXIT_FAILURE,
    EXIT_OK,
    Parser,
    UsageError,
    add_version,
    finite_float,
    positive_duration,
    run_command,
    seed,
    stop_on_signals,
    writable_dir,
    writable_file,
)
from hil.cli.campaign import CAMPAIGN_HELP, configure_campaign, run_campaign_command
from hil.cli.design import add_design_arguments, design_from_args, model_from_args
from hil.cli.experiment import EXPERIMENT_HELP, configure_experiment, run_experiment_command
from hil.cli.identify import IDENTIFY_HELP, configure_identify, run_identify_command
from hil.cli.tune import TUNE_HELP, configure_tune, run_tune_command
from hil.identify.excitation import PROFILES
from hil.sim.config import ModelConfig, ObjectConfig, SolverConfig
from hil.sim.mjcf import write_mjcf
from hil.sim.presets import PRESETS

__all__ = ["COMMANDS", "Command", "build_parser", "main"]

PROG = "spirob-hil"


@dataclass(frozen=True)
class Command:
    """One subcommand of ``spirob-hil``.

    Attributes:
        name: the subcommand word.
        help: one-line description for ``--help``.
        configure: adds the subcommand's arguments to its parser.
        run: executes it; returns the exit status. May raise :class:`UsageError` or ``ValueError``.
    """

    name: str
    help: str
    configure: Callable[[argparse.ArgumentParser], None]
    run: Callable[[argparse.Namespace], int]


# ---------------------------------------------------------------------- design


_ROWS: tuple[tuple[str, str, str], ...] = (
    # (label, summary key, SI unit); angles also in degrees, lengths also in mm, for people
    ("a", "a_m", "m"),
    ("b", "b", "1/rad"),
    ("dtheta", "dtheta_rad", "rad"),
    ("theta0", "theta0_rad", "rad"),
    ("units", "units", ""),
    ("beta (unit ratio)", "beta", ""),
    ("taper angle", "taper_rad", "rad"),
    ("tip width", "tip_width_m", "m"),
    ("base width", "base_width_m", "m"),
    ("length", "length_m", "m"),
    ("central spiral at the tip", "rho_c_tip_m", "m"),
    ("central spiral at the base", "rho_c_base_m", "m"),
    ("packed curvature at the tip", "curvature_packed_tip_per_m", "1/m"),
    ("packed curvature at the base", "curvature_packed_base_per_m", "1/m"),
    ("workspace envelope rho_w(theta0)", "rho_w_base_m", "m"),
    ("smallest graspable diameter", "d_min_m", "m"),
    ("largest graspable diameter", "d_max_m", "m"),
    ("length to wrap half of d_min", "grasp_length_d_min_m", "m"),
    ("discretisation efficiency eta", "eta", ""),
    ("max load at d_min (eq. 16)", "max_load_d_min_kg", "kg"),
)


def _human(value: float, unit: str) -> str:
    if unit == "rad":
        return f"  ({math.degrees(value):.4g} deg)"
    if unit == "m":
        return f"  ({value * 1e3:.4g} mm)"
    return ""


def _configure_design(p: argparse.ArgumentParser) -> None:
    add_design_arguments(p)
    p.add_argument("--json", action="store_true", help="print JSON (SI units) instead of a table")
    p.add_argument(
        "--load-force",
        type=finite_float,
        metavar="N",
        default=54.0,
        help="cable force for the load bound M(phi, d, F) of eq. (16) [N] (default 54 = 3 A)",
    )


def _run_design(args: argparse.Namespace) -> int:
    design = design_from_args(args)
    summary = design.summary()
    if not args.load_force > 0:
        raise ValueError(f"--load-force must be > 0, got {args.load_force}")
    summary["load_force_n"] = args.load_force
    summary["max_load_d_min_kg"] = design.max_load_kg(design.d_min_m, args.load_force)
    name = args.preset or "prototype"
    model = model_from_args(args)
    summary["model_preset"] = name
    summary["model"] = _model_summary(model)
    out: TextIO = sys.stdout
    if args.json:
        json.dump(summary, out, indent=2)
        out.write("\n")
        return EXIT_OK
    out.write(f"SpiRob design: {design.cables} cable(s), {design.units} units (SI units)\n")
    for label, key, unit in _ROWS:
        value = summary[key]
        text = str(value) if key == "units" else f"{value:.6g}"
        out.write(f"  {label:<34} {text} {unit}{_human(value, unit)}\n")
    out.write(f"  (load bound for a cable force of {args.load_force:g} N)\n")
    if design.inputs:
        given = ", ".join(f"{k}={v:g}" for k, v in design.inputs)
        out.write(f"  inputs: {given}\n")
    choices = ", ".join(f"{k} {v}" for k, v in summary["model"].items())
    out.write(f"  model preset {name}: {choices} (source: {PRESETS[name].source})\n")
    return EXIT_OK


def _model_summary(model: ModelConfig) -> dict[str, str | float | int]:
    """The choices a model preset makes, for ``design``'s output."""
    return {
        "actuator": model.actuator.kind,
        "stiffness_exponent": model.arm.stiffness_exponent,
        "base_stiffness_nm_per_rad": model.arm.base_stiffness_nm_per_rad,
        "mounting": model.mounting,
    }


# ---------------------------------------------------------------------- model export


def _parse_object(text: str) -> ObjectConfig:
    """``NAME,X,Y,Z,RADIUS[,LENGTH]`` (metres; axis along world y) -> a fixed cylinder."""
    parts = text.split(",")
    if len(parts) not in (5, 6):
        raise UsageError(f"--object wants NAME,X,Y,Z,RADIUS[,LENGTH], got {text!r}")
    try:
        x, y, z, radius = (float(v) for v in parts[1:5])
        length = float(parts[5]) if len(parts) == 6 else 0.2
    except ValueError:
        raise UsageError(f"--object numbers must be floats, got {text!r}") from None
    return ObjectConfig(parts[0], radius, length, (x, y, z))


def _configure_model(p: argparse.ArgumentParser) -> None:
    sub = p.add_subparsers(dest="model_command", metavar="ACTION", required=True, parser_class=Parser)
    e = sub.add_parser("export", help="write a self-contained MJCF model of the arm under a drone")
    add_design_arguments(e)
    e.add_argument("-o", "--output", required=True, type=Path, metavar="PATH", help="MJCF file to write")
    m = e.add_argument_group("model (defaults: the --preset's, docs/plant.md; prototype's shown)")
    m.add_argument(
        "--total-mass", type=finite_float, metavar="KG", help="mass of the arm [kg] (default 0.0384)"
    )
    m.add_argument(
        "--base-stiffness",
        type=finite_float,
        metavar="NM_PER_RAD",
        help="stiffness of the base joint [N m/rad] (default 0.5)",
    )
    m.add_argument(
        "--stiffness-exponent",
        type=int,
        choices=(2, 3),
        help="joint stiffness profile: proportional to unit size^2 or size^3 (default 3)",
    )
    m.add_argument(
        "--damping-ratio", type=finite_float, metavar="ZETA", help="joint damping ratio (default 0.13)"
    )
    m.add_argument(
        "--mu",
        type=finite_float,
        metavar="MU",
        help="capstan friction coefficient of the cables (default 0.3)",
    )
    m.add_argument(
        "--torque-constant",
        type=finite_float,
        metavar="NM_PER_A",
        help="output-shaft torque constant [N m/A] (default 0.18)",
    )
    m.add_argument("--spool-radius", type=finite_float, metavar="M", help="spool radius [m] (default 0.010)")
    m.add_argument("--current-limit", type=finite_float, metavar="A", help="current limit [A] (default 10)")
    m.add_argument("--timestep-ms", type=finite_float, metavar="MS", help="physics step [ms] (default 1)")
    m.add_argument("--floor", action="store_true", help="add a ground plane at z = 0")
    m.add_argument(
        "--object",
        action="append",
        default=[],
        metavar="NAME,X,Y,Z,R[,L]",
        help="add a fixed cylinder along y (repeatable)",
    )


def _run_model(args: argparse.Namespace) -> int:
    design = design_from_args(args)
    base = model_from_args(args)
    arm = base.arm
    arm_changes = {
        "total_mass_kg": args.total_mass,
        "base_stiffness_nm_per_rad": args.base_stiffness,
        "stiffness_exponent": args.stiffness_exponent,
        "damping_ratio": args.damping_ratio,
        "cable_mu": args.mu,
    }
    arm = replace(arm, **{k: v for k, v in arm_changes.items() if v is not None})
    motor_changes = {
        "torque_constant_nm_per_a": args.torque_constant,
        "spool_radius_m": args.spool_radius,
        "current_limit_a": args.current_limit,
    }
    motor = replace(base.motor, **{k: v for k, v in motor_changes.items() if v is not None})
    solver = base.solver if args.timestep_ms is None else SolverConfig(timestep_s=args.timestep_ms * 1e-3)
    cfg = replace(base, arm=arm, motor=motor, solver=solver)
    if args.floor:
        cfg = replace(cfg, drone=replace(cfg.drone, floor=True))
    cfg = cfg.with_objects(*(_parse_object(t) for t in args.object))
    try:
        path = write_mjcf(args.output, design, None, cfg, standalone=True)
    except OSError as exc:
        raise UsageError(f"cannot write {args.output}: {exc.strerror or exc}") from exc
    print(f"wrote {path} ({design.cables} cables, {design.units} units)")
    return EXIT_OK


# ---------------------------------------------------------------------- the virtual board and the harness


def _progress_console() -> Console:
    return Console(stderr=True)


def _configure_board(p: argparse.ArgumentParser) -> None:
    add_design_arguments(p)
    where = p.add_mutually_exclusive_group()
    where.add_argument(
        "--pty", action="store_true", help="serve the board link on a pseudo-terminal (default)"
    )
    where.add_argument(
        "--listen",
        metavar="socket://HOST:PORT",
        help="serve the board link on TCP (e.g. socket://127.0.0.1:5760); one host at a time",
    )
    p.add_argument(
        "--listen-any",
        action="store_true",
        help="allow a --listen address other than loopback: whoever reaches it can drive the arm",
    )
    p.add_argument(
        "--duration", type=positive_duration, metavar="S", help="stop after S seconds (default: until Ctrl-C)"
    )
    p.add_argument(
        "--rc",
        choices=("link", "radio"),
        default="link",
        help="RC source: the host's virtual RC over the link (default), or a virtual radio holding SAFE",
    )
    p.add_argument("--no-fifo", action="store_true", help="do not ask for SCHED_FIFO real-time priority")
    p.add_argument("--seed", type=seed, default=0, help="seed of the plant's random choices (default 0)")
    p.add_argument(
        "--params",
        type=Path,
        metavar="FILE.toml",
        help="the firmware's parameters from a parameter file (flat keys, e.g. from spirob-hil tune)",
    )


def _run_board(args: argparse.Namespace) -> int:
    from controller.clock import RealTimeClock
    from controller.config import FirmwareConfig
    from controller.errors import ConfigError
    from controller.param_file import apply_param_file
    from controller.transport import parse_listen
    from hil.board import BoardConfig, realtime_board, run_realtime
    from hil.sim.types import PlantConfig

    if args.listen is not None:
        try:  # the board's own rule (a loopback address unless --listen-any), before the plant is built
            parse_listen(args.listen, listen_any=args.listen_any)
        except ValueError as exc:
            raise UsageError(str(exc), f"{PROG} board") from None
    firmware = FirmwareConfig()
    if args.params is not None:
        try:
            firmware = apply_param_file(args.params)
        except ConfigError as exc:
            raise UsageError(str(exc), f"{PROG} board") from None
    design = design_from_args(args)
    plant = PlantConfig(model=model_from_args(args))
    try:
        config = BoardConfig(design=design, plant=plant, firmware=firmware, rc=args.rc, seed=args.seed)
        board, url = realtime_board(config, args.listen, listen_any=args.listen_any)
    except OSError as exc:
        raise UsageError(f"cannot listen on {args.listen}: {exc.strerror or exc}", f"{PROG} board") from exc
    print(
        f"virtual board: {design.cables}-cable arm, {design.units} units; board link on {url}",
        flush=True,
    )
    if args.params is not None:
        print(f"firmware parameters from {args.params}", flush=True)
    print("connect with: spirob-host --port " + url, flush=True)
    # Ctrl-C and SIGTERM end the loop between two ticks; the board then sends zero current.
    try:
        with stop_on_signals() as stop:
            run_realtime(
                board,
                RealTimeClock(fifo=not args.no_fifo),
                None if args.duration is None else round(args.duration * 1e6),
                stop,
            )
    finally:
        board.close()
    print("virtual board stopped (zero current sent)", flush=True)
    return EXIT_OK


def _configure_list(p: argparse.ArgumentParser) -> None:
    p.add_argument("--json", action="store_true", help="print JSON")


def _run_list(args: argparse.Namespace) -> int:
    from hil.scenarios import SCENARIOS

    if args.json:
        json.dump(
            [
                {"name": s.name, "summary": s.summary, "duration_s": s.duration_us / 1e6}
                for s in SCENARIOS.values()
            ],
            sys.stdout,
            indent=2,
        )
        sys.stdout.write("\n")
        return EXIT_OK
    width = max(len(n) for n in SCENARIOS)
    for s in SCENARIOS.values():
        print(f"{s.name:<{width}}  {s.summary}")
    return EXIT_OK


def _configure_run(p: argparse.ArgumentParser) -> None:
    p.add_argument("names", nargs="*", metavar="NAME", help="scenarios to run (see 'spirob-hil list')")
    p.add_argument("--all", action="store_true", help="run every scenario")
    p.add_argument("--seed", type=seed, default=0, help="seed of every random choice (default 0)")
    p.add_argument("--json", action="store_true", help="print one JSON object per scenario")
    p.add_argument(
        "--record",
        metavar="PATH",
        help="MCAP recording of every byte in and out of the board; with --port, of the link as the host "
        "sees it (a directory when several scenarios run)",
    )
    p.add_argument(
        "--report",
        metavar="DIR",
        help="write PNG plots of each run there, pictures of its moments rendered by MuJoCo (a GIF where "
        "the arm moves) and NAME.md listing them",
    )
    p.add_argument(
        "--fault",
        action="append",
        default=[],
        metavar="SPEC",
        help="extra fault KIND@START[-END][:key=value,...] (seconds), e.g. link-byte-loss@1-3:rate=0.01",
    )
    p.add_argument(
        "--port",
        metavar="PORT",
        help="run against a board-link endpoint in real time (a real board, or spirob-hil board) instead",
    )
    p.add_argument(
        "--excite",
        choices=list(PROFILES),
        metavar="PROFILE",
        help=f"the excitation scenario's profile ({', '.join(PROFILES)}; default standard)",
    )
    p.add_argument(
        "--tracked-tip",
        type=float,
        metavar="MM",
        help="the excitation's recording also carries the tip as a motion-capture tracker would see it, with "
        "this noise per axis in mm (foxglove.PoseInFrame on /mocap/tip; spirob-hil identify uses it)",
    )
    add_design_arguments(p)


def _check_tracked_tip(args: argparse.Namespace, names: list[str]) -> None:
    """``--tracked-tip``: a simulated tracker, into the excitation's recording, with a sensible noise."""
    where = f"{PROG} run"
    if "excitation" not in names:
        raise UsageError("--tracked-tip is the excitation scenario's option: run excitation", where)
    if args.port:
        raise UsageError("--tracked-tip simulates a tracker: a real arm's comes from its own bridge", where)
    if not args.record:
        raise UsageError("--tracked-tip writes into the recording: give --record FILE.mcap", where)
    if not (math.isfinite(args.tracked_tip) and 0.0 <= args.tracked_tip <= 100.0):
        raise UsageError(f"--tracked-tip {args.tracked_tip}: a noise in mm from 0 to 100", where)


def _run_run(args: argparse.Namespace) -> int:
    from hil.faults import Fault
    from hil.report import print_results
    from hil.run_record import ScenarioResult
    from hil.scenarios import SCENARIOS, run_scenario

    names: list[str] = list(SCENARIOS) if args.all else list(args.names)
    if not names:
        raise UsageError("name at least one scenario, or --all (see 'spirob-hil list')", f"{PROG} run")
    unknown = [n for n in names if n not in SCENARIOS]
    if unknown:
        raise UsageError(f"unknown scenario {unknown[0]!r} (known: {', '.join(SCENARIOS)})", f"{PROG} run")
    faults = [Fault.parse(spec) for spec in args.fault]
    options: dict[str, dict[str, object]] = {}
    if args.excite is not None:
        if "excitation" not in names:
            raise UsageError("--excite is the excitation scenario's option: run excitation", f"{PROG} run")
        if args.port:
            raise UsageError(
                "--excite in real time is spirob-host's: spirob-host --port PORT --excite PROFILE",
                f"{PROG} run",
            )
        options["excitation"] = {"profile_name": args.excite}
    if args.tracked_tip is not None:
        _check_tracked_tip(args, names)
        options.setdefault("excitation", {})["tip_noise_m"] = args.tracked_tip * 1e-3
    design = design_from_args(args)
    if args.report and not args.port:  # checked before the first run, not after it
        writable_dir(Path(args.report), "write plots into", f"{PROG} run")
    record_paths = _record_paths(args.record, names)
    console = _progress_console()
    results: list[ScenarioResult] = []
    if args.port:
        from hil.errors import HilError
        from hil.realtime import check_port_run, port_scenario_names, run_scenario_on_port

        if args.report:
            raise UsageError(
                "--report plots the simulated plant: lockstep runs only, not with --port", f"{PROG} run"
            )
        if args.all:
            names = port_scenario_names()
        try:
            for name in names:  # refuse lockstep-only scenarios before the first run starts
                check_port_run(name, faults)
            for name in names:
                with console.status(f"running {name} on {args.port} in real time ..."):
                    result = run_scenario_on_port(
                        name, args.port, seed=args.seed, faults=faults, record=record_paths.get(name)
                    )
                console.print(f"{name}: {'passed' if result.passed else 'FAILED'}")
                results.append(result)
        except HilError as exc:
            raise UsageError(str(exc), f"{PROG} run") from exc
    else:
        with Progress(
            TextColumn("{task.description}"),
            BarColumn(),
            TextColumn("{task.completed:.0f}/{task.total:.0f} ms simulated"),
            TimeElapsedColumn(),
            console=console,
            transient=True,
            disable=not console.is_terminal,
        ) as progress:
            for name in names:
                ticks = SCENARIOS[name](**options.get(name, {})).duration_us / 1000
                task = progress.add_task(name, total=ticks)

                def advance(done: int, total: int, task: TaskID = task) -> None:
                    progress.update(task, completed=done)  # one tick is one simulated millisecond

                result = run_scenario(
                    name,
                    seed=args.seed,
                    design=design,
                    model=model_from_args(args),
                    faults=faults,
                    record=record_paths.get(name),
                    report_dir=args.report,
                    progress=advance,
                    options=options.get(name),
                )
                progress.remove_task(task)
                if not console.is_terminal:
                    verdict = "passed" if result.passed else "FAILED"
                    console.print(f"{name}: {verdict}")
                results.append(result)
    if args.json:
        for r in results:
            print(json.dumps(r.as_dict()))
    else:
        print_results(results, Console(), "the board's clock, real time" if args.port else "simulated time")
        for name, path in record_paths.items():
            print(f"recorded {name} to {path}")
        if args.report:
            print(f"plots in {args.report}")
            for r in results:
                for line in r.report_lines:
                    print(f"{r.name}: {line}")
                print(f"{r.name}: report {Path(args.report) / (r.name + '.md')}")
    return EXIT_OK if all(r.passed for r in results) else EXIT_FAILURE


def _record_paths(record: str | None, names: list[str]) -> dict[str, Path]:
    if record is None:
        return {}
    path = Path(record)
    if len(names) == 1 and not path.is_dir():
        return {names[0]: writable_file(path, "record to", f"{PROG} run")}
    writable_dir(path, "record into", f"{PROG} run")
    return {n: path / f"{n}.mcap" for n in names}


def _configure_replay(p: argparse.ArgumentParser) -> None:
    p.add_argument("file", metavar="FILE", help="an MCAP recording made by 'spirob-hil run --record'")
    p.add_argument("--json", action="store_true", help="print JSON")


def _run_replay(args: argparse.Namespace) -> int:
    from hil.errors import HilError
    from hil.replay import replay

    path = Path(args.file)
    if not path.is_file():
        raise UsageError(f"no such recording: {path}", f"{PROG} replay")
    try:
        result = replay(path)
    except HilError as exc:
        raise UsageError(f"{path}: {exc}", f"{PROG} replay") from exc
    if result.truncated and not args.json:
        print(f"{path}: truncated (its recorder was killed): replayed up to its last complete tick")
    if args.json:
        print(json.dumps(result.as_dict()))
    elif result.matched:
        print(
            f"{path}: every output byte matched ({result.outputs_compared} outputs over {result.ticks} ticks)"
        )
    else:
        differ = f"{result.mismatches} of {result.outputs_compared} outputs differ"
        print(f"{path}: {differ}; first: {result.first_mismatch}")
    return EXIT_OK if result.matched else EXIT_FAILURE


def _configure_recover(p: argparse.ArgumentParser) -> None:
    p.add_argument("file", metavar="FILE", help="an MCAP recording whose writer was killed")
    p.add_argument(
        "-o", "--output", metavar="OUT", help="the complete file to write (default: FILE.recovered.mcap)"
    )


def _run_recover(args: argparse.Namespace) -> int:
    from hil.mcap_bounded import RecordingError
    from hil.recording import is_mcap, is_truncated, recover

    path = Path(args.file)
    if not path.is_file():
        raise UsageError(f"no such recording: {path}", f"{PROG} recover")
    if not is_mcap(path):
        raise UsageError(f"{path} is not an MCAP file", f"{PROG} recover")
    try:
        truncated = is_truncated(path)
    except RecordingError as exc:
        raise UsageError(f"{path}: {exc}", f"{PROG} recover") from exc
    if not truncated:
        raise UsageError(f"{path} is complete: nothing to recover", f"{PROG} recover")
    out = Path(args.output) if args.output else path.with_name(path.name + ".recovered.mcap")
    if out.resolve() == path.resolve():
        raise UsageError("--output must differ from FILE", f"{PROG} recover")
    try:
        got = recover(path, out)
    except RecordingError as exc:
        raise UsageError(f"{path}: {exc} (nothing recovered)", f"{PROG} recover") from exc
    except OSError as exc:
        raise UsageError(f"cannot write {out}: {exc.strerror or exc}", f"{PROG} recover") from exc
    until = "" if got.last_time_us is None else f" up to {got.last_time_us / 1e6:.3f} s"
    print(f"{path}: {got.messages_n} messages{until} recovered into {out}")
    return EXIT_OK


COMMANDS: list[Command] = [
    Command(
        "design", "print a spiral design's quantities (Table S1, Note S2)", _configure_design, _run_design
    ),
    Command("model", "MuJoCo model of the arm: 'model export'", _configure_model, _run_model),
    Command(
        "board", "run the virtual board in real time on a pty or a TCP port", _configure_board, _run_board
    ),
    Command("list", "list the scenarios, one line each", _configure_list, _run_list),
    Command("run", "run scenarios in lockstep (or on a board link with --port)", _configure_run, _run_run),
    Command(
        "replay",
        "replay a recording through the firmware and compare every output byte",
        _configure_replay,
        _run_replay,
    ),
    Command(
        "recover",
        "make a killed recording open in the standard MCAP readers (copies its complete records)",
        _configure_recover,
        _run_recover,
    ),
    Command(
        "experiment",
        EXPERIMENT_HELP,
        configure_experiment,
        run_experiment_command,
    ),
    Command("campaign", CAMPAIGN_HELP, configure_campaign, run_campaign_command),
    Command("identify", IDENTIFY_HELP, configure_identify, run_identify_command),
    Command("tune", TUNE_HELP, configure_tune, run_tune_command),
]
"""The subcommands, in ``--help`` order. Later issues append theirs."""


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``spirob-hil`` with every subcommand in :data:`COMMANDS`."""
    parser = Parser(prog=PROG, description="SpiRob hardware-in-the-loop: design math, plant model, harness.")
    add_version(parser)
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True, parser_class=Parser)
    for cmd in COMMANDS:
        p = sub.add_parser(cmd.name, help=cmd.help, description=cmd.help)
        cmd.configure(p)
        p.set_defaults(_run=cmd.run)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``spirob-hil``; returns the exit status (2: a user mistake, 130: Ctrl-C)."""
    parser = build_parser()

    def body() -> int:
        args = parser.parse_args(argv)
        status: int = args._run(args)
        return status

    # Ctrl-C: recordings in progress are closed on the way out (their ``with`` blocks)
    return run_command(PROG, body)


if __name__ == "__main__":
    sys.exit(main())
