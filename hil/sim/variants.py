"""Variants of a plant model: one of its uncertain parameters scaled by a factor.

The parameters (:data:`PARAMETERS`) are the ones with no datasheet behind them: the base joint's stiffness,
the joints' damping ratio, the spool's (rotor) inertia, the drive's output friction and the contact friction
(arm and objects together: MuJoCo takes the larger of a pair's two coefficients). The sensitivity
experiment runs its measures on them; a campaign names one per run (``design.variant``, docs/campaigns.md).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass

from hil.sim.config import ModelConfig

__all__ = ["BASELINE", "PARAMETERS", "Variant"]


def _base_stiffness(m: ModelConfig, f: float) -> ModelConfig:
    k = m.arm.base_stiffness_nm_per_rad * f
    return dataclasses.replace(m, arm=dataclasses.replace(m.arm, base_stiffness_nm_per_rad=k))


def _damping_ratio(m: ModelConfig, f: float) -> ModelConfig:
    return dataclasses.replace(m, arm=dataclasses.replace(m.arm, damping_ratio=m.arm.damping_ratio * f))


def _spool_inertia(m: ModelConfig, f: float) -> ModelConfig:
    j = m.motor.rotor_inertia_kg_m2 * f
    return dataclasses.replace(m, motor=dataclasses.replace(m.motor, rotor_inertia_kg_m2=j))


def _drive_friction(m: ModelConfig, f: float) -> ModelConfig:
    t = m.motor.output_friction_nm * f
    return dataclasses.replace(m, motor=dataclasses.replace(m.motor, output_friction_nm=t))


def _contact_friction(m: ModelConfig, f: float) -> ModelConfig:
    return dataclasses.replace(m, arm=dataclasses.replace(m.arm, geom_friction=m.arm.geom_friction * f))


PARAMETERS: dict[str, Callable[[ModelConfig, float], ModelConfig]] = {
    "base stiffness": _base_stiffness,
    "damping ratio": _damping_ratio,
    "spool inertia": _spool_inertia,
    "drive friction": _drive_friction,
    "contact friction": _contact_friction,
}
"""The varied parameters: name -> ``(model, factor) -> model``. The contact friction's objects follow the
arm's (see :func:`hil.experiments.dynamic.dynamic`)."""

BASELINE = "baseline"
"""The label of the model as given."""


@dataclass(frozen=True)
class Variant:
    """One model: the baseline, or one parameter scaled by ``factor``."""

    parameter: str
    factor: float

    @property
    def label(self) -> str:
        """``baseline`` or e.g. ``base stiffness x0.5``."""
        return BASELINE if self.parameter == BASELINE else f"{self.parameter} x{self.factor:g}"

    def apply(self, model: ModelConfig) -> ModelConfig:
        """The variant of ``model``."""
        return model if self.parameter == BASELINE else PARAMETERS[self.parameter](model, self.factor)

    @classmethod
    def parse(cls, text: str) -> Variant:
        """The variant a :attr:`label` names: ``"baseline"`` or ``"PARAMETER xFACTOR"``.

        Raises:
            ValueError: not a label of a known parameter with a finite factor > 0.
        """
        name, _, factor = text.strip().rpartition(" x")
        if text.strip() == BASELINE:
            return cls(BASELINE, 1.0)
        try:
            value = float(factor)
        except ValueError:
            value = math.nan
        if name not in PARAMETERS or not (math.isfinite(value) and value > 0):
            raise ValueError(
                f"{text!r} is not 'baseline' or 'PARAMETER xFACTOR' with PARAMETER one of "
                f"{', '.join(PARAMETERS)} and FACTOR > 0"
            )
        return cls(name, value)
