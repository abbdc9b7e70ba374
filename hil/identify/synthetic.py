"""Recordings of plants whose parameters are known: how a fit is proven without hardware.

:func:`draw_truth` draws the uncertain parameters within ±50 % of a preset (absolute ranges where the
preset's value is zero); :func:`record_truth` records the ``excitation`` scenario on the virtual board with
that plant, seen through the real sensors' limits:

- the C610's own: 8192-count encoders per rotor turn, integer rpm, 1 mA current steps (the plant's feedback
  frames always have these), plus the current measurement's noise (``current_noise_raw``);
- a real bus's timing: each feedback frame one tick late with some probability (``can-jitter``);
- a real-time loop's lateness: every firmware tick starts up to ``loop_jitter_us`` late (``loop-jitter``;
  the recording's timestamps carry it).

:data:`MISMATCHES` are plants the fit cannot represent exactly (capsule units where the model has wedges,
a cable that stretches three times more, a stiffness law with manufacturing scatter), for the claim that a fit
still helps where it cannot be exact.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Final

import numpy as np

from hil.faults import Fault, FaultKind
from hil.run_record import ScenarioResult
from hil.scenarios import run_scenario
from hil.sim.config import ModelConfig
from hil.sim.spiral import SpiralDesign
from hil.sim.uncertain import ID_PARAMS, apply, nominal

__all__ = ["MISMATCHES", "SensorLimits", "draw_truth", "record_truth"]

_ABSOLUTE_RANGES: Final[dict[str, tuple[float, float]]] = {
    "joint_friction": (0.0, 0.002),
    "delay": (0.0, 0.004),
}
"""Parameters whose preset value is zero: drawn over a plausible range instead of ±50 % of nothing."""


def draw_truth(rng: np.random.Generator, preset: ModelConfig | None = None) -> dict[str, float]:
    """Every uncertain parameter drawn uniformly within ±50 % of the preset's value (``stiffness_exponent``
    clipped to the model's 1..4, absolute ranges for the zero ones), in table order."""
    base = nominal(preset or ModelConfig())
    out: dict[str, float] = {}
    for p in ID_PARAMS:
        if p.name in _ABSOLUTE_RANGES:
            lo, hi = _ABSOLUTE_RANGES[p.name]
            out[p.name] = float(rng.uniform(lo, hi))
        else:
            out[p.name] = float(base[p.name] * rng.uniform(0.5, 1.5))
    out["stiffness_exponent"] = min(4.0, max(1.0, out["stiffness_exponent"]))
    return out


@dataclass(frozen=True, slots=True)
class SensorLimits:
    """How imperfectly the truth is seen.

    Attributes:
        current_noise_raw: standard deviation of the measured current, raw (1 mA) units.
        can_late_rate: probability that a feedback frame is one tick late.
        loop_jitter_us: the firmware's tick starts up to this late (uniform).
    """

    current_noise_raw: float = 20.0
    can_late_rate: float = 0.05
    loop_jitter_us: int = 300

    def faults(self) -> list[Fault]:
        """The faults that play these limits for a whole run."""
        out = []
        if self.can_late_rate > 0:
            out.append(Fault(FaultKind.CAN_JITTER, 0, rate=self.can_late_rate))
        if self.loop_jitter_us > 0:
            out.append(Fault(FaultKind.LOOP_JITTER, 0, delay_us=self.loop_jitter_us))
        return out


def _capsules(m: ModelConfig) -> ModelConfig:
    return dataclasses.replace(m, arm=dataclasses.replace(m.arm, unit_shape="capsule"))


def _stretchy(m: ModelConfig) -> ModelConfig:
    return dataclasses.replace(m, arm=dataclasses.replace(m.arm, cable_modulus_pa=m.arm.cable_modulus_pa / 3))


def _scattered(m: ModelConfig) -> ModelConfig:
    rng = np.random.default_rng(7)
    scatter = tuple(float(x) for x in rng.uniform(0.7, 1.3, 40))
    return dataclasses.replace(m, arm=dataclasses.replace(m.arm, stiffness_scatter=scatter))


MISMATCHES: Final = {
    "capsules": _capsules,
    "stretchy-cable": _stretchy,
    "stiffness-scatter": _scattered,
}
"""Changes to a truth that no parameter of the fit can express: capsule units (the model has wedges), a
cable three times as stretchy (the model's is a 0.5 mm Dyneema braid), ±30 % joint-to-joint scatter of the
stiffness (the model's law is a power of the unit size)."""


def record_truth(
    path: str | Path,
    truth: Mapping[str, float],
    *,
    seed: int = 0,
    profile_name: str = "standard",
    limits: SensorLimits | None = None,
    preset: ModelConfig | None = None,
    design: SpiralDesign | None = None,
    mismatch: str | None = None,
    tip_noise_m: float | None = None,
) -> ScenarioResult:
    """Record the excitation on a virtual board whose plant has ``truth``'s parameters (with
    ``tip_noise_m``, and a tracked tip with that noise per axis: :mod:`hil.identify.tracker`).

    Raises:
        ValueError: a truth the model refuses, or an unknown mismatch.
    """
    lim = limits or SensorLimits()
    model = apply(preset or ModelConfig(), truth)
    model = dataclasses.replace(
        model, motor=dataclasses.replace(model.motor, current_noise_raw=lim.current_noise_raw)
    )
    if mismatch is not None:
        if mismatch not in MISMATCHES:
            raise ValueError(f"unknown mismatch {mismatch!r} (known: {', '.join(MISMATCHES)})")
        model = MISMATCHES[mismatch](model)
    result = run_scenario(
        "excitation",
        seed=seed,
        design=design,
        model=model,
        faults=lim.faults(),
        record=path,
        options={"profile_name": profile_name, "tip_noise_m": tip_noise_m, "tip_seed": seed},
    )
    if not result.passed:
        failed = [c.name for c in result.checks if not c.passed]
        raise ValueError(f"the excitation failed on this truth: {failed}")
    return result


def relative_error(fitted: float, truth: float, scale: float) -> float:
    """|fitted - truth| over |truth| (over ``scale`` when the truth is near zero)."""
    den = abs(truth) if abs(truth) > 0.1 * scale else scale
    return abs(fitted - truth) / den if den > 0 else math.inf
