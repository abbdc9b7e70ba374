"""The options that select a spiral design and a model preset, shared by the ``spirob-hil`` subcommands
(``design``, ``model export``, ``board``, ``run``, ``experiment``)."""

from __future__ import annotations

import argparse
import math

from controller.cli_kit import UsageError, finite_float

from .model_config import ModelConfig
from .model_presets import PRESETS, preset
from .spiral import SpiralDesign

__all__ = ["MAX_UNITS_N", "add_design_arguments", "design_from_args", "model_from_args"]

MAX_UNITS_N = 1000
"""The most units a command line accepts: every unit is a MuJoCo body and a joint of the 1 kHz plant, and
the printed arms have tens (the authors' 24); a thousand is already far past anything buildable."""


def add_design_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the options that select a :class:`SpiralDesign` (used by ``design``, ``model export``, ...).

    A design is one of: a preset (default ``prototype``: a model preset, :mod:`hil.model_presets`,
    which names its design and its plant model); physical inputs (``--length`` and ``--tip-width`` with
    ``--taper-deg`` or ``--base-width``); or spiral parameters (``--a``, ``--b``, ``--theta0-deg`` or
    ``--units``). ``--dtheta-deg`` and ``--cables`` apply to the last two forms.
    """
    g = parser.add_argument_group("design (default: --preset prototype)")
    listing = "; ".join(f"{p.name}: {p.summary}" for p in PRESETS.values())
    g.add_argument(
        "--preset",
        choices=list(PRESETS),
        metavar="NAME",
        help=f"a named design and plant model ({listing})",
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
    forms = sum(
        [args.preset is not None, any(v is not None for v in physical), any(v is not None for v in params)]
    )
    if forms > 1:
        raise UsageError("give a --preset, physical inputs or spiral parameters, not a mix")
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
    chosen = PRESETS[args.preset or "prototype"]
    design = SpiralDesign.preset(chosen.design_preset)
    if args.cables is not None:
        return design.with_cables(cables)
    return design if chosen.cables is None else design.with_cables(chosen.cables)


def model_from_args(args: argparse.Namespace) -> ModelConfig:
    """The plant model of ``--preset`` (default ``prototype``: :class:`ModelConfig`'s defaults).

    Raises:
        ValueError: unknown preset name (argparse's choices normally catch it first).
    """
    return preset(args.preset or "prototype")
