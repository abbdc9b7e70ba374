"""The 45 cm arm of Fig. S11 and the model it runs on: the prototype's model scaled to it
(:func:`scaled_model`) at a chosen physics step (:func:`with_timestep`) and contact time constant
(:func:`with_contact_timeconst`); the dynamic experiment builds its
rig with :func:`~hil.trial.rig.direct_rig` on that model."""

from __future__ import annotations

import dataclasses
import math

from hil.sim.config import ModelConfig
from hil.sim.spiral import SpiralDesign

PAPER_ARM_LENGTH_M = 0.45
"""Length of the 2-cable arm of Note S5 and Fig. S11 (the supplement: "a 2-cable SpiRob (45cm in length)")."""
PAPER_ARM_TIP_WIDTH_M = 0.010
"""Tip width δ(0) of that arm: not in the supplement; the authors' published design tool's default
(a = 4.95 mm, b = 0.1764: δ(0) = a·(e^{2πb} − 1) = 10.0 mm), whose 24 units are 47 cm long."""
PAPER_ARM_TAPER_DEG = 10.0
"""Taper angle φ of that arm: the same default's (φ(b = 0.1764) = 10.0°, Table S1)."""
PAPER_ARM_DTHETA_DEG = 30.0
"""Discretisation step Δθ: the same default's, and the prototype's."""


def paper_arm_45cm() -> SpiralDesign:
    """The 2-cable 45 cm arm of Fig. S11: 24 units, 0.467 m along its axis, tip 10 mm, base 92 mm."""
    return SpiralDesign.from_physical(
        length_m=PAPER_ARM_LENGTH_M,
        tip_width_m=PAPER_ARM_TIP_WIDTH_M,
        taper_rad=math.radians(PAPER_ARM_TAPER_DEG),
        dtheta_rad=math.radians(PAPER_ARM_DTHETA_DEG),
        cables=2,
    )


def _volume_m3(design: SpiralDesign) -> float:
    """The arm's volume up to a shape factor: Σ chord · mean width² over its units."""
    pairs = zip(design.unit_chords_m(), design.unit_widths_m(), strict=True)
    return sum(c * (0.5 * (wb + wt)) ** 2 for c, (wb, wt) in pairs)


def scaled_model(model: ModelConfig, design: SpiralDesign, reference: SpiralDesign) -> ModelConfig:
    """``model``, whose arm describes ``reference``, scaled to ``design`` in the same material.

    Mass scales with the volume (uniform density); the base joint's stiffness with the cube of the width
    at that joint (an elastic layer scaled in every dimension: k ∝ E·w·t³/l ∝ size³, the law the model
    already applies from joint to joint). Everything else (damping ratio, friction, motor) is kept.
    """
    joint_width = design.unit_widths_m()[0][1] / reference.unit_widths_m()[0][1]
    arm = dataclasses.replace(
        model.arm,
        total_mass_kg=model.arm.total_mass_kg * _volume_m3(design) / _volume_m3(reference),
        base_stiffness_nm_per_rad=model.arm.base_stiffness_nm_per_rad * joint_width**3,
    )
    return dataclasses.replace(model, arm=arm)


def with_timestep(model: ModelConfig, timestep_s: float) -> ModelConfig:
    """``model`` with another physics step (the 1 ms control period must stay a whole number of them)."""
    return dataclasses.replace(model, solver=dataclasses.replace(model.solver, timestep_s=timestep_s))


def with_contact_timeconst(model: ModelConfig, timeconst_s: float) -> ModelConfig:
    """``model`` with another contact ``solref`` time constant (a stiffer or softer arm-object contact)."""
    return dataclasses.replace(model, contact=dataclasses.replace(model.contact, timeconst_s=timeconst_s))
