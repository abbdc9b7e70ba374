"""The plant's uncertain parameters: one row each, with where it lives in the model and what bounds it.

Each row names one physical quantity nobody has measured on the lab's arm, the field of
:class:`hil.sim.config.ModelConfig` that holds it, its unit, its search bounds (relative to the preset the
fit starts from, or absolute where the preset's value can be zero), the scale the optimizer works in, and
what in the data shows it. :func:`apply` writes values into a model configuration; :func:`nominal` reads
them out. Everything else (the fit, the model file, the report, the docs' table) reads these rows.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Final

from hil.sim.config import ModelConfig

__all__ = ["ID_PARAMS", "IdParam", "apply", "by_name", "nominal"]


@dataclass(frozen=True, slots=True)
class IdParam:
    """One identified parameter.

    Attributes:
        name: short name (the model file's key).
        field: ``section.field`` of :class:`~hil.sim.config.ModelConfig` (``arm.damping_ratio``).
        unit: SI unit ('' for a ratio).
        relative: bounds are factors of the preset's value (``lo * v .. hi * v``); else absolute.
        lo: lower bound (a factor, or an absolute value).
        hi: upper bound.
        scale: the optimizer's unit for an absolute row (one optimizer unit is this much). A relative
            row is optimized as the logarithm of its factor on the preset's value: a stiffness, an
            inertia or a friction that can only be positive, and whose effects scale together (all forces
            times a factor is a straight line in these coordinates, which the solver follows at once).
        shown_by: what in a recording shows it (the docs and the report say so).
        description: one line.
    """

    name: str
    field: str
    unit: str
    relative: bool
    lo: float
    hi: float
    scale: float
    shown_by: str
    description: str

    def bounds(self, preset_value: float) -> tuple[float, float]:
        """Search bounds around a preset's value."""
        if self.relative:
            return self.lo * preset_value, self.hi * preset_value
        return self.lo, self.hi

    def to_x(self, value: float, preset_value: float) -> float:
        """The optimizer's coordinate: ln(value / preset) for a relative row, value / scale for others."""
        return math.log(value / preset_value) if self.relative else value / self.scale

    def from_x(self, x: float, preset_value: float) -> float:
        """The inverse of :meth:`to_x`."""
        return preset_value * math.exp(x) if self.relative else x * self.scale

    def value_at(self, x: float, preset_value: float) -> float:
        """:meth:`from_x` kept within :meth:`bounds`.

        The optimizer keeps ``x`` in :meth:`x_bounds`, but its steps and finite differences can land a
        rounding error past a bound (a delay of -7e-21 s, seen in a fit), which the model rightly refuses.
        """
        lo, hi = self.bounds(preset_value)
        return min(hi, max(lo, self.from_x(x, preset_value)))

    def x_bounds(self, preset_value: float) -> tuple[float, float]:
        """The search bounds in the optimizer's coordinate."""
        lo, hi = self.bounds(preset_value)
        return self.to_x(lo, preset_value), self.to_x(hi, preset_value)

    def read(self, model: ModelConfig) -> float:
        """This parameter's value in ``model``."""
        section, attr = self.field.split(".")
        return float(getattr(getattr(model, section), attr))


ID_PARAMS: Final[tuple[IdParam, ...]] = (
    IdParam(
        "base_stiffness",
        "arm.base_stiffness_nm_per_rad",
        "N·m/rad",
        True,
        1 / 3,
        3.0,
        1.0,
        "the slow ramps: cable length against tension, and gravity's sag",
        "bending stiffness of the joint next to the base",
    ),
    IdParam(
        "stiffness_exponent",
        "arm.stiffness_exponent",
        "",
        False,
        1.5,
        4.0,
        1.0,
        "the ramps' knees: the order and tension at which the joints close",
        "p in stiffness ∝ (unit size)^p along the arm",
    ),
    IdParam(
        "damping_ratio",
        "arm.damping_ratio",
        "",
        True,
        0.25,
        4.0,
        1.0,
        "the rings after each step and the multisine's resonances",
        "damping ratio of every arm joint",
    ),
    IdParam(
        "joint_friction",
        "arm.joint_friction_nm",
        "N·m",
        False,
        0.0,
        0.01,
        0.001,
        "hysteresis that does not grow with the tension",
        "dry friction of the base joint (scaling with the joints' stiffness)",
    ),
    IdParam(
        "cable_mu",
        "arm.cable_mu",
        "",
        False,
        0.0,
        1.0,
        1.0,
        "hysteresis that grows with the tension; the base-first uncurling",
        "capstan friction coefficient of the cables in the unit holes",
    ),
    IdParam(
        "rotor_inertia",
        "motor.rotor_inertia_kg_m2",
        "kg·m²",
        True,
        1 / 3,
        3.0,
        1.0,
        "how fast the spools answer a current step",
        "rotor inertia of each M2006 (reflected to the cable through 36:1 and the spool)",
    ),
    IdParam(
        "drive_friction",
        "motor.output_friction_nm",
        "N·m",
        True,
        0.05,
        5.0,
        1.0,
        "the current needed before a spool moves; hysteresis at the spool",
        "dry friction of gearbox and bearings at the output shaft",
    ),
    IdParam(
        "torque_scale",
        "motor.torque_scale",
        "",
        True,
        0.5,
        1.6,
        1.0,
        "tension per amp against gravity's known weight and the arm's known mass",
        "the motors' true torque constant over the configured one",
    ),
    IdParam(
        "delay",
        "motor.command_delay_s",
        "s",
        False,
        0.0,
        0.01,
        0.001,
        "the phase of the response to the multisine and the start of each step",
        "from a current command leaving the firmware to the motor acting on it (loop and CAN)",
    ),
)
"""The parameters a fit identifies, in the model file's order."""

_BY_NAME: Final = {p.name: p for p in ID_PARAMS}


def by_name(name: str) -> IdParam:
    """The row of ``name``.

    Raises:
        ValueError: no such parameter.
    """
    try:
        return _BY_NAME[name]
    except KeyError:
        raise ValueError(f"unknown identified parameter {name!r} (known: {', '.join(_BY_NAME)})") from None


def nominal(model: ModelConfig) -> dict[str, float]:
    """Every identified parameter's value in ``model``."""
    return {p.name: p.read(model) for p in ID_PARAMS}


def apply(model: ModelConfig, values: Mapping[str, float]) -> ModelConfig:
    """``model`` with the given identified parameters replaced (validated).

    Raises:
        ValueError: an unknown name, a non-finite value, or a value the model refuses.
    """
    changes: dict[str, dict[str, float]] = {}
    for name, value in values.items():
        p = by_name(name)
        if not math.isfinite(value):
            raise ValueError(f"{name}: not a finite value ({value})")
        section, attr = p.field.split(".")
        changes.setdefault(section, {})[attr] = float(value)
    replaced = {s: dataclasses.replace(getattr(model, s), **fields) for s, fields in changes.items()}
    out = dataclasses.replace(model, **replaced)
    out.validate()
    return out
