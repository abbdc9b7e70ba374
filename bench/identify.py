"""Benchmark of ``spirob-hil identify``: does a fit recover what it claims, does it help where it cannot be
exact, and how long does it take (issue 23's proof without hardware).

1. Hidden truth: ``--draws`` plants (seeded) whose uncertain parameters are drawn within ±50 % of the
   prototype (``hil.identify.synthetic.draw_truth``); each records the excitation twice on the virtual board,
   seen through the real sensors' limits (encoder counts, integer rpm, 1 mA current steps with noise, CAN
   frames late at random, a real-time loop's jitter). The fit sees the first ``--fit-s`` seconds of the first
   recording; the rest of it and all of the second are held out. Goals (fixed before the run): every
   parameter the fit calls identifiable within 10 % of the truth in at least 18 of 20 draws; the 95 %
   intervals cover the truth in at least 90 % of cases; held-out cable lengths within 0.3 mm RMS.
2. Model mismatch (``--mismatch``): truths the fit cannot represent (capsule units, a stretchier cable,
   joint-to-joint stiffness scatter): the fitted model's held-out error against the preset's (goal: halved).
3. Fit time (``--fit-time``): five 60 s recordings of one plant, the default fit (with ``--horizons``'
   stages when given), on the cores there are (goal: at most 10 minutes); ``--fit-time-baseline`` also fits
   them without the force scale's coordinate first and prints the ratio.

Every row is written to ``--out`` (JSON lines) as it finishes; ``--resume`` skips the rows already there.
Prints the figures and their intervals (Wilson for rates, bootstrap for medians) with the sample sizes.

``--no-timing-noise`` records without late feedback frames and tick jitter (the current noise stays).
``--line`` reads the rows of ``--out`` and prints, per draw, the fit's objective along the straight line from
its fitted values to its truth's (``--line-params``: move only these, the others at the fit's values or,
with ``--line-others truth``, the truth's; ``--line-t``: the points), with the
same recording: a wall between them is a local minimum the solver cannot leave (docs/identify.md 6).
``--known-torque`` gives each draw's true torque constant to the fit (as a lab gives the datasheet's, or a
bench test's with a known weight) and fits the other parameters: it removes the common-scale tie. With it
the fits continue over 3, 6 and 10 s as ``spirob-hil identify`` does (``--horizons none`` turns that off).

Usage: ``.venv/bin/python bench/identify.py [--draws 20] [--mismatch] [--fit-time] [--quick]
[--known-torque] [--jacobian dense] [--horizons S,S] [--shard J/K] [--seeds A,B] [--resume] [--summary-only]
[--line [--line-params A,B] [--line-others fit|truth] [--line-t 0,0.5,1]]``
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

# Run as a script, this file's directory comes first on sys.path, where bench/protocol.py would shadow
# the protocol package; benchmarks import the project only.
_HERE = Path(__file__).resolve().parent
sys.path[:] = [p for p in sys.path if Path(p or ".").resolve() != _HERE]

import numpy as np  # noqa: E402

from hil.experiments.stats import bootstrap_interval, wilson_interval  # noqa: E402
from hil.identify.fit import FitOptions, FitResult, fit, objective_at  # noqa: E402
from hil.identify.intervals import IDENTIFIED_WITHIN, fd_floor, si_interval, unexplained  # noqa: E402
from hil.identify.motor_data import length_quantum_m, load_motor_data  # noqa: E402
from hil.identify.starts import default_horizons, parse_horizons, settled_for  # noqa: E402
from hil.identify.synthetic import (  # noqa: E402
    MISMATCHES,
    SensorLimits,
    draw_truth,
    record_truth,
    relative_error,
)
from hil.identify.windows import length_rms_m  # noqa: E402
from hil.sim.config import ModelConfig, SolverConfig  # noqa: E402
from hil.sim.spiral import SpiralDesign  # noqa: E402
from hil.sim.uncertain import ID_PARAMS, apply, by_name, nominal  # noqa: E402

_PRESET = nominal(ModelConfig())
"""The preset's values: the fit's optimizer coordinates are relative to them."""

SETTLED_M = settled_for(length_quantum_m(ModelConfig().motor.spool_radius_m, ModelConfig().motor.gear_ratio))
"""The sensors' own noise on the prototype (``hil.identify.starts.settled_m`` of its recordings): the fit's
default bound on what it may leave unexplained and still call a parameter identified."""

GOAL_WITHIN = 0.10
GOAL_DRAWS = 18 / 20
GOAL_COVERAGE = 0.90
GOAL_HELD_OUT_M = 0.3e-3


def _base(args: argparse.Namespace) -> ModelConfig:
    """The prototype, with ``--jacobian``'s constraint Jacobian for the truths and the fits alike."""
    return ModelConfig(solver=SolverConfig(jacobian=args.jacobian))


def _fit(
    paths: list[Path], args: argparse.Namespace, fit_s: float, known: dict[str, float] | None = None
) -> FitResult:
    """The fit on ``paths``; ``known`` parameters are set to their values and not fitted."""
    data = [load_motor_data(p) for p in paths]
    known = known or {}
    params = tuple(p.name for p in ID_PARAMS if p.name not in known)
    # The fit's rollouts on the truths' own Jacobian (``--jacobian``): these fits resolve 0.01 %, and
    # ``dense`` against ``auto`` moves a parameter by a few of those.
    opts = FitOptions(
        params=params,
        budget_s=fit_s,
        min_span_s=fit_s,
        max_iters=args.max_iters,
        jobs=args.jobs,
        jacobian=None,
        restarts=args.restarts,
        horizons_s=args.horizons,
    )
    return fit(data, apply(_base(args), known), opts, progress=_say)


def _tip_noise_m(args: argparse.Namespace) -> float | None:
    """``--tip-noise-mm`` in metres (None: no tracked tip)."""
    return None if args.tip_noise_mm is None else args.tip_noise_mm * 1e-3


def _horizons(text: str) -> tuple[float, ...]:
    """``--horizons``: :func:`~hil.identify.starts.parse_horizons` for argparse."""
    try:
        return parse_horizons(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def hidden_truth_row(seed: int, args: argparse.Namespace, work: Path) -> dict[str, Any]:
    """One draw: the truth, two recordings, the fit on the first's start, every figure of it."""
    truth = draw_truth(np.random.default_rng(seed))
    paths = [work / f"truth{seed}-{k}.mcap" for k in range(2)]
    t0 = time.monotonic()
    limits = SensorLimits(can_late_rate=0.0, loop_jitter_us=0) if args.no_timing_noise else None
    for k, p in enumerate(paths):
        record_truth(
            p,
            truth,
            seed=1000 * seed + k,
            profile_name=args.profile,
            limits=limits,
            preset=_base(args),
            tip_noise_m=_tip_noise_m(args),
        )
    record_s = time.monotonic() - t0
    # Both recordings go in; the fit's budget (``--fit-s``, at least ``min_span_s`` per recording) is spent
    # on the first one's start, so the second is held out whole and simulated for the traces.
    # --known-torque: the torque constant given as a lab would measure it (datasheet, a known weight),
    # which pins the common scale of the forces (docs/identify.md section 3); the others are fitted.
    known = {"torque_scale": truth["torque_scale"]} if args.known_torque else {}
    result = _fit(paths, args, args.fit_s, known)
    second = _fit_traces_rms(result.traces, paths[1].name)
    params = []
    for e in result.estimates:
        true = truth[e.name]
        row = by_name(e.name)
        scale = 0.0 if row.relative else row.scale  # a relative row's error is always over its truth
        params.append(
            {
                "name": e.name,
                "truth": true,
                "value": e.value,
                "interval": list(e.interval),
                "naive_interval": list(e.naive_interval),
                "hac_interval": list(e.hac_interval),
                "identifiable": e.identifiable,
                "why": e.why,
                "rel_error": relative_error(e.value, true, scale),
                "covered": e.covers(true),
                "naive_covered": e.naive_interval[0] <= true <= e.naive_interval[1],
                "hac_covered": e.hac_interval[0] <= true <= e.hac_interval[1],
            }
        )
    return {
        "kind": "truth",
        "seed": seed,
        "known": known,
        "timing_noise": not args.no_timing_noise,
        "tip_noise_m": _tip_noise_m(args),
        "jacobian": args.jacobian,
        "params": params,
        "held_out_rms_m": result.rms_m(True),
        "held_out_rms_nominal_m": result.rms_m(True, "nominal"),
        "fitted_rms_m": result.rms_m(False),
        "starts": [list(s) for s in result.starts],
        "second_recording_rms_m": second,
        "fit_wall_s": result.wall_s,
        "record_wall_s": record_s,
        "iterations": result.iterations,
        "converged": result.converged,
        "condition_number": result.condition_number,
    }


def _fit_traces_rms(traces: Sequence[Any], name: str) -> float:
    for t in traces:
        if t.recording == name:
            return float(t.rms_m(True))
    return math.nan


def mismatch_row(name: str, args: argparse.Namespace, work: Path) -> dict[str, Any]:
    """One plant the fit cannot represent: its truth is the preset's values with a drawn offset."""
    truth = draw_truth(np.random.default_rng(99))
    paths = [work / f"{name}-{k}.mcap" for k in range(2)]
    for k, p in enumerate(paths):
        record_truth(p, truth, seed=500 + k, profile_name=args.profile, mismatch=name, preset=_base(args))
    result = _fit(paths, args, args.fit_s)  # the second held out whole
    # What the model could do at best with the truth's own values (the shape it lacks aside): the part of
    # the error that is the mismatch itself, against the part a better search would remove.
    second = load_motor_data(paths[1])
    at_truth = length_rms_m(
        second, apply(_base(args), truth), second.design or SpiralDesign.paper_prototype()
    )
    return {
        "kind": "mismatch",
        "name": name,
        "held_out_rms_m": result.rms_m(True),
        "held_out_rms_nominal_m": result.rms_m(True, "nominal"),
        "second_at_truth_values_m": at_truth,
        "second_fitted_m": _fit_traces_rms(result.traces, paths[1].name),
        "fitted_rms_m": result.rms_m(False),
        "fit_wall_s": result.wall_s,
        "identified": [e.name for e in result.estimates if e.identifiable],
    }


def fit_time_row(args: argparse.Namespace, work: Path) -> dict[str, Any]:
    """Five 60 s recordings of one plant, the default fit (with ``--horizons``' stages if given); with
    ``--fit-time-baseline`` the same recordings fitted first in the parameters' own coordinates (the fit
    before the force scale's coordinate, ``FitOptions.scale_coordinates``), the baseline of the same run."""
    truth = draw_truth(np.random.default_rng(2026))
    paths = [work / f"five-{k}.mcap" for k in range(5)]
    for k, p in enumerate(paths):
        record_truth(p, truth, seed=700 + k, profile_name="standard", preset=_base(args))
    row: dict[str, Any] = {"kind": "fit-time", "horizons_s": list(args.horizons), "recordings": len(paths)}
    if args.fit_time_baseline:
        row["baseline"] = _timed_fit(paths, args, scale_coordinates=False)
    row.update(_timed_fit(paths, args, scale_coordinates=True))
    return row


def _timed_fit(paths: list[Path], args: argparse.Namespace, *, scale_coordinates: bool) -> dict[str, Any]:
    t0 = time.monotonic()
    data = [load_motor_data(p) for p in paths]
    options = FitOptions(jobs=args.jobs, horizons_s=args.horizons, scale_coordinates=scale_coordinates)
    result = fit(data, _base(args), options, progress=_say)
    return {
        "scale_coordinates": scale_coordinates,
        "seconds_each": data[0].duration_s,
        "wall_s": time.monotonic() - t0,
        "iterations": result.iterations,
        "rollouts": result.rollouts,
        "simulated_s": result.simulated_s,
        "held_out_rms_m": result.rms_m(True),
        "held_out_rms_nominal_m": result.rms_m(True, "nominal"),
        "fitted_rms_m": result.rms_m(False),
        "identified": [e.name for e in result.estimates if e.identifiable],
    }


_WIDTH_REASON = "95 % interval"


def kept_rms_m(r: dict[str, Any]) -> float:
    """The fitted cable lengths' error of the start a stored row kept (the least objective), as the fit
    judges it; rows without starts say their traces' figure."""
    starts = r.get("starts") or []
    return float(min(starts)[1]) if starts else float(r["fitted_rms_m"])


def settled(r: dict[str, Any]) -> bool:
    """The row's fit explained its recording to the sensors' own noise (:data:`SETTLED_M`)."""
    return kept_rms_m(r) <= SETTLED_M


def rejudged(x: dict[str, Any], rms_m: float = 0.0) -> dict[str, Any]:
    """A stored parameter row judged by today's rules from its stored interval: the width rule
    (:data:`IDENTIFIED_WITHIN` of its value) and the fit's default bound on what it may leave unexplained
    (``rms_m``, the kept start's, against the sensors' noise, which also counts as converged); its other
    reasons (a bound, a correlation, an unconverged fit that did not settle) stay.

    Rows written under the earlier rules (per-parameter thresholds of 8-40 %, or an absolute width; a fit
    that explained its data within 0.3 mm) so count as the fit would call them now: the rules read only the
    interval, the value and the kept start's error, which the rows keep. The interval is first floored at
    the solver's step (:func:`_floored`).
    """
    at_noise = rms_m <= SETTLED_M  # a fit that settled counts as converged (hil.identify.fit)
    kept = [
        part
        for part in x.get("why", "").split("; ")
        if part
        and not part.startswith(_WIDTH_REASON)
        and "unexplained" not in part
        and not (at_noise and part.startswith("the fit had not converged"))
    ]
    x = _floored(x)
    half = 0.5 * (x["interval"][1] - x["interval"][0])
    limit = IDENTIFIED_WITHIN * abs(x["value"])
    reasons = list(kept)
    if not (math.isfinite(half) and half <= limit):
        reasons.insert(0, f"{_WIDTH_REASON} ±{half:.3g} is wider than ±{limit:.3g}")
    why = unexplained(rms_m, None, SETTLED_M)
    if why is not None:
        reasons.append(why)
    return {**x, "identifiable": not reasons, "why": "; ".join(reasons)}


def _floored(x: dict[str, Any]) -> dict[str, Any]:
    """A stored parameter row with its interval at least the solver's finite-difference step wide (the
    default ``fd_step``, :func:`~hil.identify.intervals.fd_floor`), as the fit floors it now; rows written
    before (with a floor of 1e-4 in the optimizer's coordinates) are widened where they were narrower, and
    whether they cover the truth is judged again. Rows the fit floored already are unchanged."""
    row = by_name(x["name"])
    v0 = _PRESET[x["name"]]
    at = row.to_x(x["value"], v0)
    floor = float(fd_floor(np.array([at]), FitOptions().fd_step)[0])
    out = dict(x)
    for key, cov in (("interval", "covered"), ("hac_interval", "hac_covered")):
        if key in x:
            lo, hi = (row.to_x(v, v0) for v in x[key])
            out[key] = list(si_interval(row, v0, at, max(0.5 * (hi - lo), floor)))
            out[cov] = out[key][0] <= x["truth"] <= out[key][1]
    return out


def _declined_for_correlation(x: dict[str, Any]) -> bool:
    """A parameter the fit declined only because it trades against another (|correlation| above 0.95)."""
    if x["identifiable"]:
        return False
    return all(part.startswith("trades against") for part in x["why"].split("; "))


def _correlation_rule(truths: list[dict[str, Any]]) -> None:
    """What the correlation rule declines that the intervals alone would accept, and whether it was right."""
    declined = [(r, x) for r in truths for x in r["params"] if _declined_for_correlation(x)]
    if not declined:
        print("the correlation rule (|corr| > 0.95) declined nothing the intervals alone accept")
        return
    within = sum(x["rel_error"] <= GOAL_WITHIN for _, x in declined)
    covered = sum(bool(x["covered"]) for _, x in declined)
    draws = len({id(r) for r, _ in declined})
    names = sorted({x["name"] for _, x in declined})
    ok = sum(
        all(
            x["rel_error"] <= GOAL_WITHIN
            for x in r["params"]
            if x["identifiable"] or _declined_for_correlation(x)
        )
        for r in truths
    )
    print(
        f"declined only by the correlation rule: {len(declined)} parameters in {draws} draws "
        f"({', '.join(names)}); {within} of them within 10 %, {covered} covered by their interval; "
        f"without the rule, draws whose every identifiable parameter is within 10 %: {ok}/{len(truths)}"
    )


def _seeds(text: str) -> list[int]:
    return [int(v) for v in text.split(",")]


def _say(stage: str, fraction: float) -> None:
    now = time.strftime("%H:%M:%S")
    print(f"    fit: {100 * fraction:3.0f}%  {stage}  ({now})", file=sys.stderr, flush=True)


def summarise(rows: list[dict[str, Any]]) -> None:
    """Print the goals' figures from every row there is."""
    truths = [
        {**r, "params": [rejudged(x, kept_rms_m(r)) for x in r["params"]]}
        for r in rows
        if r["kind"] == "truth"
    ]
    if truths:
        n = len(truths)
        print(f"\nhidden truth: {n} draws, fit on the first {truths[0].get('fit_s', '?')} s of one recording")
        head = ("parameter", "identified", "within 10 %", "covered", "naive covered")
        print(f"{head[0]:20s} {head[1]:>10s} {head[2]:>12s} {head[3]:>14s} {head[4]:>14s}")
        all_cov: list[bool] = []
        ok_draws = 0
        for p in ID_PARAMS:
            rs = [x for r in truths for x in r["params"] if x["name"] == p.name]
            if not rs:
                print(f"{p.name:20s} given (--known-torque), not fitted")
                continue
            ident = [x for x in rs if x["identifiable"]]
            within = sum(x["rel_error"] <= GOAL_WITHIN for x in ident)
            cov = sum(bool(x["covered"]) for x in rs)
            naive = sum(bool(x["naive_covered"]) for x in rs)
            all_cov += [bool(x["covered"]) for x in rs]
            k = len(ident)
            print(
                f"{p.name:20s} {k:>7d}/{n:<2d} {within:>9d}/{k:<2d} {cov:>11d}/{n:<2d} {naive:>11d}/{n:<2d}"
            )
        for r in truths:
            if all(x["rel_error"] <= GOAL_WITHIN for x in r["params"] if x["identifiable"]):
                ok_draws += 1
        lo, hi = wilson_interval(ok_draws, n)
        print(
            f"draws whose every identifiable parameter is within 10 %: {ok_draws}/{n} "
            f"[{lo:.2f}, {hi:.2f}] (goal >= {GOAL_DRAWS:.0%})"
        )
        vacuous = [r["seed"] for r in truths if not any(x["identifiable"] for x in r["params"])]
        if vacuous:
            print(f"draws where the fit called nothing identified (met by refusing): seeds {vacuous}")
        _correlation_rule(truths)
        c = sum(all_cov)
        lo, hi = wilson_interval(c, len(all_cov))
        print(
            f"95 % intervals covering the truth: {c}/{len(all_cov)} = {c / len(all_cov):.0%} "
            f"[{lo:.2f}, {hi:.2f}] (goal >= {GOAL_COVERAGE:.0%})"
        )
        for label, part in (("settled", True), ("did not settle", False)):
            group = [bool(x["covered"]) for r in truths if settled(r) == part for x in r["params"]]
            wrong = [
                r["seed"]
                for r in truths
                if settled(r) == part and any(x["rel_error"] > GOAL_WITHIN for x in r["params"])
            ]
            if group:
                lo, hi = wilson_interval(sum(group), len(group))
                print(
                    f"... in the {len(group) // max(1, len(truths[0]['params']))} draws whose fit {label} "
                    f"(the sensors' noise: {SETTLED_M * 1e6:.2g} um): {sum(group)}/{len(group)} covered "
                    f"[{lo:.2f}, {hi:.2f}]; draws with a fitted value more than 10 % off, identified or "
                    f"not: {wrong or 'none'}"
                )
        # Rows written before the intervals were widened by the remaining step carry no hac_covered.
        widened = [r for r in truths if all("hac_covered" in x for x in r["params"])]
        if widened:
            hac = [bool(x["hac_covered"]) for r in widened for x in r["params"]]
            wid = [bool(x["covered"]) for r in widened for x in r["params"]]
            print(
                f"... of which in the {len(widened)} draws run with the widening for where the fit stopped: "
                f"{sum(wid)}/{len(wid)} covered, {sum(hac)}/{len(hac)} without the widening"
            )
        fitted = np.array([r["second_recording_rms_m"] for r in truths]) * 1e3
        held = np.array([r["held_out_rms_m"] for r in truths]) * 1e3
        nominal_ = np.array([r["held_out_rms_nominal_m"] for r in truths]) * 1e3
        for label, values in (("held out (both recordings)", held), ("the second recording", fitted)):
            med = float(np.median(values))
            lo, hi = bootstrap_interval(list(values), statistic="median", seed=0)
            print(
                f"cable length RMS, {label}: median {med:.3g} mm [{lo:.3g}, {hi:.3g}], max {values.max():.3g}"
            )
        med = float(np.median(nominal_))
        print(f"the preset on the same held-out samples: median {med:.3f} mm (goal for the fit: <= 0.3 mm)")
        walls = np.array([r["fit_wall_s"] for r in truths])
        print(f"fit wall time per draw: median {np.median(walls):.0f} s, max {walls.max():.0f} s")
        for r in truths:
            starts = r.get("starts") or []
            if len(starts) > 1:
                kept = min(range(len(starts)), key=lambda i: starts[i][0])
                each = ", ".join(f"{obj:.4g} ({rms * 1e3:.2g} mm)" for obj, rms in starts)
                print(
                    f"draw {r['seed']}: {len(starts)} starts, objective (fitted length error) {each}; "
                    f"kept {kept + 1}"
                )
    for r in rows:
        if r["kind"] == "mismatch":
            ratio = r["held_out_rms_m"] / r["held_out_rms_nominal_m"]
            print(
                f"mismatch {r['name']}: held out {r['held_out_rms_m'] * 1e3:.3f} mm fitted, "
                f"{r['held_out_rms_nominal_m'] * 1e3:.3f} mm preset: ratio {ratio:.2f} (goal <= 0.5); "
                f"fitted samples {r.get('fitted_rms_m', math.nan) * 1e3:.3f} mm, "
                f"{len(r['identified'])} parameters called identified"
            )
            if "second_at_truth_values_m" in r:
                print(
                    f"  the second recording: fitted {r['second_fitted_m'] * 1e3:.3f} mm; the model with the "
                    f"truth's own values {r['second_at_truth_values_m'] * 1e3:.3f} mm (what the mismatch "
                    "itself costs)"
                )
        elif r["kind"] == "fit-time":
            stages = r.get("horizons_s") or []
            for label, f in (("the parameters' own coordinates (baseline)", r.get("baseline")), ("", r)):
                if f is None:
                    continue
                print(
                    f"fit time{' (horizons ' + ','.join(f'{h:g}' for h in stages) + ' s)' if stages else ''}"
                    f"{', ' + label if label else ''}: {r['recordings']} recordings of "
                    f"{f['seconds_each']:.0f} s: {f['wall_s']:.0f} s wall ({f['iterations']} iterations, "
                    f"{f['rollouts']} rollouts, {f['simulated_s']:.0f} s simulated, "
                    f"{f['simulated_s'] / f['wall_s']:.1f} simulated s per s; goal <= 600 s); held out "
                    f"{f['held_out_rms_m'] * 1e3:.3f} mm (preset {f['held_out_rms_nominal_m'] * 1e3:.3f} mm)"
                )
            if r.get("baseline"):
                print(f"  wall time against the baseline: {r['wall_s'] / r['baseline']['wall_s']:.2f}x")


def line_to_truth(
    row: dict[str, Any], args: argparse.Namespace, work: Path
) -> list[tuple[float, float, float]]:
    """(t, objective, cable-length RMS [m]) along the line from a stored row's fitted values (t = 0) to its
    truth's (t = 1), on the draw's first recording made again (the same seed, profile and Jacobian)."""
    seed = int(row["seed"])
    truth = draw_truth(np.random.default_rng(seed))
    path = work / f"truth{seed}-0.mcap"
    limits = None if row.get("timing_noise", True) else SensorLimits(can_late_rate=0.0, loop_jitter_us=0)
    base = ModelConfig(solver=SolverConfig(jacobian=row.get("jacobian", args.jacobian)))
    record_truth(
        path,
        truth,
        seed=1000 * seed,
        profile_name=args.profile,
        limits=limits,
        preset=base,
        tip_noise_m=row.get("tip_noise_m"),
    )
    known = dict(row.get("known") or {})
    fitted = {x["name"]: float(x["value"]) for x in row["params"]}
    move = set(args.line_params.split(",")) if args.line_params else set(fitted)
    ts = [float(v) for v in args.line_t.split(",")]
    rest = truth if args.line_others == "truth" else fitted  # where the parameters not moved stay
    points = [{n: v + t * (truth[n] - v) if n in move else rest[n] for n, v in fitted.items()} for t in ts]
    fit_s = float(row.get("fit_s", args.fit_s))
    opts = FitOptions(params=tuple(fitted), budget_s=fit_s, min_span_s=fit_s, jobs=args.jobs, jacobian=None)
    values = objective_at([load_motor_data(path)], apply(base, known), opts, points)
    return [(t, obj, rms) for t, (obj, rms) in zip(ts, values, strict=True)]


def _lines(rows: list[dict[str, Any]], args: argparse.Namespace) -> int:
    """``--line``: the objective along the line from each stored fit to its truth."""
    truths = [r for r in rows if r["kind"] == "truth" and (not args.seeds or r["seed"] in _seeds(args.seeds))]
    if not truths:
        print(f"{args.out}: no hidden-truth rows (--line reads them)", file=sys.stderr)
        return 1
    try:
        [float(v) for v in args.line_t.split(",")]
    except ValueError:
        print(f"--line-t {args.line_t!r}: numbers A,B,...", file=sys.stderr)
        return 2
    names = {x["name"] for r in truths for x in r["params"]}
    unknown = sorted(set(args.line_params.split(",")) - names) if args.line_params else []
    if unknown:
        print(f"--line-params: {', '.join(unknown)} not fitted in these rows", file=sys.stderr)
        return 2
    with tempfile.TemporaryDirectory(prefix="bench-identify-line-") as tmp:
        for r in truths:
            moved = (
                f"{args.line_params}, the others at the {args.line_others}'s"
                if args.line_params
                else "every parameter"
            )
            print(f"draw {r['seed']}: from the fit (t = 0) to the truth (t = 1), moving {moved}", flush=True)
            for t, obj, rms in line_to_truth(r, args, Path(tmp)):
                print(f"  t = {t:.3g}: objective {obj:.4g}, cable lengths {rms * 1e6:.3g} um RMS", flush=True)
    return 0


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--draws", type=int, default=20, help="hidden-truth draws (0: none)")
    ap.add_argument("--profile", default="standard", help="excitation profile of the recordings")
    ap.add_argument("--fit-s", type=float, default=30.0, help="seconds of the first recording the fit sees")
    ap.add_argument("--max-iters", type=int, default=FitOptions().max_iters)
    ap.add_argument(
        "--restarts", type=int, default=FitOptions().restarts, help="restarts of a fit that has not settled"
    )
    ap.add_argument(
        "--horizons",
        type=_horizons,
        default=None,
        help="horizon continuation: fit each start to the first S seconds first, S,S,... or none "
        "(default: the command's, 3,6,10 with --known-torque, else none)",
    )
    ap.add_argument("--jobs", type=int, default=None)
    ap.add_argument("--mismatch", action="store_true", help="also the model-mismatch plants")
    ap.add_argument("--fit-time", action="store_true", help="also five 60 s recordings, timed")
    ap.add_argument(
        "--fit-time-baseline",
        action="store_true",
        help="with --fit-time: fit the same recordings first without the force scale's coordinate "
        "(the baseline, in the same run)",
    )
    ap.add_argument("--quick", action="store_true", help="3 draws of the quick profile (a smoke run)")
    ap.add_argument(
        "--no-timing-noise",
        action="store_true",
        help="record without late feedback frames and tick jitter (the current noise stays)",
    )
    ap.add_argument(
        "--known-torque",
        action="store_true",
        help="give the fit each draw's true torque constant (as a datasheet would) and fit the rest",
    )
    ap.add_argument(
        "--tip-noise-mm",
        type=float,
        default=None,
        metavar="MM",
        help="the hidden-truth recordings also carry a tracked tip with this noise per axis (a motion-"
        "capture tracker at 100 Hz; docs/identify.md section 3)",
    )
    ap.add_argument("--out", type=Path, default=Path("runs/bench-identify.jsonl"))
    ap.add_argument("--resume", action="store_true", help="keep the rows already in --out")
    ap.add_argument(
        "--shard",
        default="0/1",
        metavar="J/K",
        help="run only the draws whose seed is J modulo K (K processes, each --jobs 1, share a machine's "
        "cores better than one fit's pool: a fit's line search runs one rollout at a time)",
    )
    ap.add_argument(
        "--jacobian",
        choices=("auto", "dense"),
        default="auto",
        help="the plant's constraint Jacobian, truths and fits alike (dense: the same physics to rounding, "
        "about 1.4x faster here; docs/plant.md)",
    )
    ap.add_argument("--summary-only", action="store_true", help="print the figures of --out; run nothing")
    ap.add_argument("--seeds", help="these draws' seeds (A,B,...) instead of the first --draws")
    ap.add_argument(
        "--line", action="store_true", help="the objective from each row's fit to its truth (rows of --out)"
    )
    ap.add_argument("--line-params", help="with --line: move only these parameters (A,B,...)")
    ap.add_argument("--line-t", default="0,0.25,0.5,0.75,1", help="with --line: the points (0 fit, 1 truth)")
    ap.add_argument(
        "--line-others",
        choices=("fit", "truth"),
        default="fit",
        help="with --line-params: the other parameters at the fit's values or the truth's (a probe of the "
        "objective around the truth)",
    )
    args = ap.parse_args(argv)
    if args.horizons is None:  # the command's default (hil.identify.starts.default_horizons)
        args.horizons = default_horizons(["torque_scale"] if args.known_torque else [])
    try:
        shard, shards = (int(v) for v in args.shard.split("/"))
        if not 0 <= shard < shards:
            raise ValueError
    except ValueError:
        ap.error(f"--shard {args.shard!r}: J/K with 0 <= J < K")
    if args.seeds:
        try:
            _seeds(args.seeds)
        except ValueError:
            ap.error(f"--seeds {args.seeds!r}: whole numbers A,B,...")
    if args.tip_noise_mm is not None and not (math.isfinite(args.tip_noise_mm) and args.tip_noise_mm >= 0):
        ap.error(f"--tip-noise-mm {args.tip_noise_mm}: a finite noise >= 0")
    if args.quick:
        args.draws, args.profile, args.fit_s = 3, "quick", 12.0
    args.out.parent.mkdir(parents=True, exist_ok=True)
    rows: list[dict[str, Any]] = []
    if (args.resume or args.summary_only or args.line) and args.out.exists():
        rows = [json.loads(line) for line in args.out.read_text().splitlines() if line.strip()]
    done = {(r["kind"], r.get("seed"), r.get("name")) for r in rows}
    if args.summary_only:
        if not rows:
            print(f"{args.out}: no rows", file=sys.stderr)
            return 1
        summarise(rows)
        return 0
    if args.line:
        return _lines(rows, args)
    print(
        f"identification benchmark: {args.draws} draws of '{args.profile}', fit on {args.fit_s:g} s",
        flush=True,
    )
    with tempfile.TemporaryDirectory(prefix="bench-identify-") as tmp, open(args.out, "a") as out:
        work = Path(tmp)
        seeds = _seeds(args.seeds) if args.seeds else range(args.draws)
        jobs: list[tuple[str, Any]] = [("truth", s) for s in seeds if s % shards == shard]
        if args.mismatch and shard == 0:
            jobs += [("mismatch", name) for name in MISMATCHES]
        if args.fit_time and shard == 0:
            jobs.append(("fit-time", None))
        for kind, key in jobs:
            tag = (kind, key if kind == "truth" else None, key if kind == "mismatch" else None)
            if tag in done:
                continue
            t0 = time.monotonic()
            if kind == "truth":
                row = hidden_truth_row(int(key), args, work)
                row["fit_s"] = args.fit_s
                row["horizons_s"] = list(args.horizons)
            elif kind == "mismatch":
                row = mismatch_row(str(key), args, work)
            else:
                row = fit_time_row(args, work)
            out.write(json.dumps(row, default=_json_default) + "\n")
            out.flush()
            rows.append(row)
            print(f"  {kind} {key if key is not None else ''}: {time.monotonic() - t0:.0f} s", flush=True)
    summarise(rows)
    return 0


def _json_default(value: object) -> object:
    if isinstance(value, np.bool_ | np.integer | np.floating):
        return value.item()
    raise TypeError(type(value).__name__)


if __name__ == "__main__":
    sys.exit(main())
