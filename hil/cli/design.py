"""The options that select a spiral design and a model preset, shared by the ``spirob-hil`` subcommands
(``design``, ``model export``, ``board``, ``run``, ``experiment``)."""

from __future__ import annotations

import argparse
import math

from controller.cli_kit import UsageError, finite_float
from hil.sim.config import ModelConfig
from hil.sim.presets import PRESETS, is_model_file, resolve
from hil.sim.spiral import SpiralDesign

__all__ = [
    "MAX_UNITS_N",
    "add_design_arguments",
    "design_from_args",
    "design_options_given",
    "model_from_args",
    "preset_arg",
]

MAX_UNITS_N = 1000
"""The most units a command line accepts: every unit is a MuJoCo body and a joint of the 1 kHz plant, and
the printed arms have tens (the authors' 24); a thousand is already far past anything buildable."""


def preset_arg(text: str) -> str:
    """``--preset``: a preset's name, or a fitted model file that reads (checked once, here)."""
    if text in PRESETS:
        return text
    if not is_model_file(text):
        raise argparse.ArgumentTypeError(
            f"unknown preset {text!r} (choose from {', '.join(PRESETS)}, or a fitted model FILE.toml)"
        )
    try:
        resolve(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from exc
    return text


def add_design_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the options that select a :class:`SpiralDesign` (used by ``design``, ``model export``, ...).

    A design is one of: a preset (default ``prototype``: a model preset, :mod:`hil.sim.presets`,
    which names its design and its plant model); physical inputs (``--length`` and ``--tip-width`` with
    ``--taper-deg`` or ``--base-width``); spiral parameters (``--a``, ``--b``, ``--theta0-deg`` or
    ``--units``); or a preset with single values of one of the other two forms changed (the rest are the
    preset's). ``--dtheta-deg`` applies to every form but a bare preset; ``--cables`` to every form.
    """
    g = parser.add_argument_group("design (default: --preset prototype)", _COMBINATIONS)
    listing = "; ".join(f"{p.name}: {p.summary}" for p in PRESETS.values())
    g.add_argument(
        "--preset",
        type=preset_arg,
        metavar="NAME|FILE",
        help=f"a named design and plant model ({listing}), or a fitted model file (spirob-hil identify)",
    )
    g.add_argument("--length", type=finite_float, metavar="M", help="length of the straightened arm [m]")
    g.add_argument("--tip-width", type=finite_float, metavar="M", help="width of the tip [m]")
    g.add_argument(
        "--taper-deg", type=finite_float, metavar="DEG", help="taper angle of the straightened arm [degrees]"
    )
    g.add_argument(
        "--base-width", type=finite_float, metavar="M", help="width at the base [m] (instead of the taper)"
    )
    g.add_argument("--a", type=finite_float, metavar="M", help="spiral scaling factor a [m]")
    g.add_argument("--b", type=finite_float, metavar="B", help="spiral growth rate b [1/rad]")
    g.add_argument(
        "--theta0-deg", type=finite_float, metavar="DEG", help="spiral angle of the base [degrees]"
    )
    g.add_argument("--units", type=int, metavar="N", help="number of units (instead of --theta0-deg)")
    g.add_argument(
        "--dtheta-deg", type=finite_float, metavar="DEG", help="discretisation step [degrees] (default 30)"
    )
    g.add_argument("--cables", type=int, choices=(1, 2, 3), help="number of cables (default 3)")


_COMBINATIONS = (
    "Valid combinations: (1) nothing, or --preset NAME: a named design; (2) physical inputs: --length and "
    "--tip-width with exactly one of --taper-deg / --base-width; (3) spiral parameters: --a and --b with "
    "exactly one of --theta0-deg / --units; (4) --preset NAME with any single values of (2) or of (3), not "
    "both: the preset's design with those values changed (e.g. --preset prototype --length 0.3, --preset "
    "authors --units 20). --dtheta-deg goes with (2), (3) and (4); --cables with all of them."
)


_SHAPE_OPTIONS = (
    "length",
    "tip_width",
    "taper_deg",
    "base_width",
    "a",
    "b",
    "theta0_deg",
    "units",
    "dtheta_deg",
    "cables",
)


def design_options_given(args: argparse.Namespace) -> list[str]:
    """The options of :func:`add_design_arguments` that shape the arm (all but ``--preset``, which also
    names the plant model) given on this command line, as flags (``["--length", "--cables"]``)."""
    return ["--" + name.replace("_", "-") for name in _SHAPE_OPTIONS if getattr(args, name) is not None]


def design_from_args(args: argparse.Namespace) -> SpiralDesign:
    """Build the design the options of :func:`add_design_arguments` describe.

    Raises:
        UsageError: options from different forms mixed, or a form incomplete.
        ValueError: the values do not make a design (negative length, taper of 0 or >= 90°, more than
            :data:`MAX_UNITS_N` units, sizes past a float's range, ...).
    """
    try:
        design = _design_from_args(args)
        if design.units > MAX_UNITS_N:
            raise ValueError(f"the design has {design.units} units; at most {MAX_UNITS_N} are modelled")
        design.summary()
    except OverflowError:
        # the spiral grows as exp(b * theta): a large b and many units leave the float range
        raise ValueError(
            "these design inputs give sizes past the range of a float (exp(b * theta0))"
        ) from None
    return design


def _design_from_args(args: argparse.Namespace) -> SpiralDesign:
    physical = [args.length, args.tip_width, args.taper_deg, args.base_width]
    params = [args.a, args.b, args.theta0_deg, args.units]
    has_physical = any(v is not None for v in physical)
    has_params = any(v is not None for v in params)
    if has_physical and has_params:
        raise UsageError(
            "give physical inputs or spiral parameters, not both (--help lists the combinations)"
        )
    if args.preset is not None and (has_physical or has_params or args.dtheta_deg is not None):
        return _preset_overridden(args, physical=has_physical, params=has_params)
    cables = 3 if args.cables is None else args.cables
    dtheta = math.radians(30.0 if args.dtheta_deg is None else args.dtheta_deg)
    if any(v is not None for v in physical):
        if args.length is None or args.tip_width is None:
            raise UsageError("physical inputs need --length and --tip-width")
        if (args.taper_deg is None) == (args.base_width is None):
            raise UsageError("give exactly one of --taper-deg and --base-width")
        taper = None if args.taper_deg is None else math.radians(args.taper_deg)
        return SpiralDesign.from_physical(
            length_m=args.length,
            tip_width_m=args.tip_width,
            taper_rad=taper,
            base_width_m=args.base_width,
            dtheta_rad=dtheta,
            cables=cables,
        )
    if any(v is not None for v in params):
        if args.a is None or args.b is None:
            raise UsageError("spiral parameters need --a and --b")
        if (args.theta0_deg is None) == (args.units is None):
            raise UsageError("give exactly one of --theta0-deg and --units")
        if args.units is not None:
            if not 1 <= args.units <= MAX_UNITS_N:
                raise ValueError(f"--units must be 1..{MAX_UNITS_N}, got {args.units}")
            theta0 = args.units * dtheta
        else:
            theta0 = math.radians(args.theta0_deg)
        return SpiralDesign.from_params(args.a, args.b, theta0, dtheta, cables)
    if args.dtheta_deg is not None:
        raise UsageError("--dtheta-deg needs physical inputs or spiral parameters (a preset fixes it)")
    chosen = resolve(args.preset or "prototype")
    design = chosen.spiral()
    return design.with_cables(cables) if args.cables is not None else design


def _preset_overridden(args: argparse.Namespace, *, physical: bool, params: bool) -> SpiralDesign:
    """The ``--preset``'s design with the single values given on the command line changed.

    Physical overrides start from the preset's physical inputs when it was built from them (the
    prototype: the requested 0.23 m, not the realised length), else from its derived length, tip width and
    taper; spiral-parameter overrides start from its ``a``, ``b``, θ0 and Δθ. ``--dtheta-deg`` alone keeps
    the preset's own form.
    """
    chosen = resolve(args.preset)
    base = chosen.spiral()
    cables = args.cables if args.cables is not None else (chosen.cables or base.cables)
    inputs = dict(base.inputs)
    built_physical = "length_m" in inputs
    dtheta = base.dtheta_rad if args.dtheta_deg is None else math.radians(args.dtheta_deg)
    if params or (not physical and not built_physical):
        if args.theta0_deg is not None and args.units is not None:
            raise UsageError("give at most one of --theta0-deg and --units")
        if args.units is not None:
            if not 1 <= args.units <= MAX_UNITS_N:
                raise ValueError(f"--units must be 1..{MAX_UNITS_N}, got {args.units}")
            theta0 = args.units * dtheta
        elif args.theta0_deg is not None:
            theta0 = math.radians(args.theta0_deg)
        else:
            # Δθ changed alone: keep the unit count (θ0 scales with it).
            theta0 = base.units * dtheta
        a = base.a_m if args.a is None else args.a
        b = base.b if args.b is None else args.b
        return SpiralDesign.from_params(a, b, theta0, dtheta, cables)
    length = inputs.get("length_m", base.length_m) if args.length is None else args.length
    tip = inputs.get("tip_width_m", base.tip_width_m) if args.tip_width is None else args.tip_width
    if args.taper_deg is not None and args.base_width is not None:
        raise UsageError("give at most one of --taper-deg and --base-width")
    taper: float | None
    base_width: float | None = args.base_width
    if args.taper_deg is not None:
        taper = math.radians(args.taper_deg)
    elif base_width is not None:
        taper = None
    elif "base_width_m" in inputs:
        taper, base_width = None, inputs["base_width_m"]
    else:
        taper = inputs.get("taper_rad", base.taper_rad)
    return SpiralDesign.from_physical(
        length_m=length,
        tip_width_m=tip,
        taper_rad=taper,
        base_width_m=base_width,
        dtheta_rad=dtheta,
        cables=cables,
    )


def model_from_args(args: argparse.Namespace) -> ModelConfig:
    """The plant model of ``--preset`` (default ``prototype``: :class:`ModelConfig`'s defaults).

    Raises:
        ValueError: unknown preset name (argparse's choices normally catch it first).
    """
    return resolve(args.preset or "prototype").model
