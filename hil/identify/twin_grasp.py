"""Does a fitted twin grasp like the arm it was fitted to? The hidden-truth check through grasps.

The identification benchmark judges a twin by its cable lengths on a held-out recording. A lab fits one to
know what its arm will *do*, and the arm's reason to exist is to grasp. So for a hidden-truth draw (its
parameters known, a fit of its recordings done), the same placements are grasped by the same controller
on three plants:

- **truth**: the draw's own parameters (the arm);
- **twin**: the fitted values, written as a model file and read back as ``--preset arm.toml`` reads it;
- **preset**: the preset the fit started from (what a lab would simulate without a fit);

and once more on the truth with every parameter nudged by :data:`NUDGE_REL` (**nudged**: random signs,
seeded by the draw), which says how often a verdict survives a change far below anything a fit could
promise. A grasp on an edge flips with such a nudge, so no twin can be expected to agree with the truth
more often than the nudged truth does. (Another board seed is no such reference: the grasp trials run
without current noise, so the seed only moves the encoders' zero, which the firmware takes out.)

Each plant runs at the experiments' fine physics (0.25 ms steps, :data:`hil.experiments.common.
DEFAULT_MODEL`), although the fit ran at the board's 1 ms: the fitted values are physical quantities and
must carry over. A twin is judged by how often its verdict (the grasp experiments' success criterion)
matches the truth's on the same placement, against how often the preset's does (exact McNemar on the
placements where exactly one of them matches), and by its wrap angle's distance from the truth's.
"""

from __future__ import annotations

import math
import tempfile
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from hil.experiments.common import EXPERIMENT_STEP_S
from hil.experiments.stats import bootstrap_interval, mcnemar_exact, wilson_interval
from hil.identify.synthetic import draw_truth
from hil.sim.config import ModelConfig
from hil.sim.model_file import FittedParameter, ModelFile, write_model_file
from hil.sim.presets import PRESETS, resolve
from hil.sim.spiral import SpiralDesign
from hil.sim.uncertain import apply, by_name
from hil.trial.grasp import GraspOutcome

__all__ = [
    "PLANTS",
    "AgreementSummary",
    "Placement",
    "Verdict",
    "agreement",
    "nudged_truth",
    "placements",
    "rate_errors",
    "twin_models",
]

PLANTS = ("truth", "twin", "preset")
"""The three plants of a draw, in the order :func:`twin_models` returns them."""
NUDGE_REL = 1e-3
"""The ``nudged`` truth's parameters are its own times 1 ± this (0.1 %, a hundredth of the 10 % goal)."""

GOAL_AGREEMENT = 0.90
"""Goal, fixed before the first run: the twin's verdict matches the truth's in at least this share of the
(draw, placement) pairs, and in more of them than the preset's (McNemar p < :data:`GOAL_P`)."""
GOAL_P = 0.05


@dataclass(frozen=True, slots=True)
class Placement:
    """One grasp's object: centre ``x_m`` off the axis, ``z_m`` below the base, a ``diameter_m`` cylinder."""

    x_m: float
    z_m: float
    diameter_m: float


def placements(n: int, seed: int) -> list[Placement]:
    """``n`` placements in the prototype's reach (x 20-70 mm, z 80-180 mm below the base, 15-40 mm
    cylinders), the box the tuning's placements and the grasp benchmark's come from."""
    rng = np.random.default_rng(seed)
    return [
        Placement(
            float(rng.uniform(0.020, 0.070)),
            float(-rng.uniform(0.080, 0.180)),
            float(rng.uniform(0.015, 0.040)),
        )
        for _ in range(n)
    ]


def twin_models(
    row: Mapping[str, Any], work: Path | None = None, preset: str = "prototype"
) -> tuple[ModelConfig, ModelConfig, ModelConfig]:
    """The truth, the twin and the preset of one identification benchmark row, at the experiments' step.

    ``row`` is a ``kind = "truth"`` row of ``bench/identify.py``: its ``seed`` gives the truth (the same
    draw), its ``params`` the fitted values (``value``, ``interval``, ``identifiable``) and ``known`` the
    values that were given, not fitted. The twin goes through a model file in ``work`` (a temporary
    folder if None), so it is exactly what ``--preset arm.toml`` would simulate.

    Raises:
        ValueError: not a hidden-truth row, or a value the model refuses.
    """
    if row.get("kind") != "truth" or "seed" not in row or "params" not in row:
        raise ValueError("not a hidden-truth row of bench/identify.py (kind, seed and params needed)")
    base = PRESETS[preset].model
    truth = apply(base, draw_truth(np.random.default_rng(int(row["seed"])), base))
    fitted: dict[str, FittedParameter] = {}
    for p in row["params"]:
        lo, hi = p.get("interval", (math.nan, math.nan))
        fitted[p["name"]] = FittedParameter(
            p["name"],
            float(p["value"]),
            by_name(p["name"]).unit,
            (float(lo), float(hi)),
            bool(p["identifiable"]),
        )
    for name, value in dict(row.get("known", {})).items():
        fitted[name] = FittedParameter(name, float(value), by_name(name).unit, note="given, not fitted")
    model_file = ModelFile(preset, SpiralDesign.paper_prototype(), fitted, tool="bench/twin_grasp.py")
    with tempfile.TemporaryDirectory() as tmp:
        path = (work or Path(tmp)) / f"twin-{int(row['seed'])}.toml"
        write_model_file(path, model_file)
        twin = resolve(str(path)).model
    step = EXPERIMENT_STEP_S
    return truth.with_physics(step), twin.with_physics(step), base.with_physics(step)


def nudged_truth(row: Mapping[str, Any], rel: float = NUDGE_REL, preset: str = "prototype") -> ModelConfig:
    """The truth of a hidden-truth row with every parameter times ``1 ± rel`` (signs drawn from the row's
    seed), at the experiments' step: how a verdict moves under a change no fit resolves."""
    base = PRESETS[preset].model
    seed = int(row["seed"])
    truth = draw_truth(np.random.default_rng(seed), base)
    signs = np.random.default_rng([seed, 1]).choice((-1.0, 1.0), size=len(truth))
    nudged = {k: v * (1.0 + rel * s) for (k, v), s in zip(truth.items(), signs, strict=True)}
    # A truth the draw clipped to the model's bound (stiffness_exponent at 1 or 4) is nudged inward.
    p = nudged["stiffness_exponent"]
    if not 1.0 <= p <= 4.0:
        nudged["stiffness_exponent"] = truth["stiffness_exponent"] * (1.0 - rel * math.copysign(1.0, p - 2.5))
    return apply(base, nudged).with_physics(EXPERIMENT_STEP_S)


@dataclass(frozen=True, slots=True)
class Verdict:
    """What the agreement figures need of one grasp (:class:`~hil.trial.grasp.GraspOutcome`, or its stored
    JSON form)."""

    success: bool
    state: str
    wrap_deg: float
    penetration_m: float

    @classmethod
    def of(cls, outcome: GraspOutcome) -> Verdict:
        return cls(outcome.success, outcome.state, outcome.wrap_deg, outcome.extremes.penetration_m)

    @classmethod
    def from_record(cls, record: Mapping[str, Any]) -> Verdict:
        """From :meth:`GraspOutcome.as_dict`'s form."""
        pen = record["extremes"]["penetration_m"]
        return cls(bool(record["success"]), str(record["state"]), float(record["wrap_deg"]), float(pen))


@dataclass(frozen=True)
class AgreementSummary:
    """How a twin and a preset agree with the truth over paired grasps.

    Attributes:
        n: paired placements (each grasped on all three plants).
        success: successes per plant (:data:`PLANTS`).
        twin_agrees: placements where the twin's verdict is the truth's.
        preset_agrees: the same for the preset.
        only_twin: placements where the twin agrees and the preset does not.
        only_preset: the reverse.
        p_value: exact McNemar of ``only_twin`` against ``only_preset``.
        wrap_error_deg: mean |wrap angle − the truth's| per plant (twin, preset), and its bootstrap
            95 % interval, over the placements where the truth or that plant reached HOLD.
        penetration_m: the largest penetration of any grasp, per plant.
        nudged_agrees: placements where the nudged truth (``nudged``, :func:`nudged_truth`) gives the
            truth's verdict; None without those grasps.
    """

    n: int
    success: Mapping[str, int]
    twin_agrees: int
    preset_agrees: int
    only_twin: int
    only_preset: int
    p_value: float
    wrap_error_deg: Mapping[str, tuple[float, float, float, int]]
    penetration_m: Mapping[str, float]
    nudged_agrees: int | None = None

    def rate(self, count: int) -> tuple[float, float, float]:
        """``count / n`` and its Wilson 95 % interval."""
        lo, hi = wilson_interval(count, self.n)
        return count / self.n if self.n else math.nan, lo, hi

    @property
    def goal_met(self) -> bool:
        """The twin matches the truth in ≥ :data:`GOAL_AGREEMENT` of the pairs and beats the preset."""
        return (
            self.n > 0
            and self.twin_agrees >= GOAL_AGREEMENT * self.n
            and self.only_twin > self.only_preset
            and self.p_value < GOAL_P
        )


def agreement(trials: Sequence[Mapping[str, Verdict]], seed: int = 0) -> AgreementSummary:
    """Summarise paired grasps: one mapping per placement from each of :data:`PLANTS` (and ``nudged``, if
    run) to its verdict."""
    success = {k: sum(t[k].success for t in trials) for k in PLANTS}
    twin = [t["twin"].success == t["truth"].success for t in trials]
    pre = [t["preset"].success == t["truth"].success for t in trials]
    only_twin = sum(a and not b for a, b in zip(twin, pre, strict=True))
    only_preset = sum(b and not a for a, b in zip(twin, pre, strict=True))
    wrap: dict[str, tuple[float, float, float, int]] = {}
    for k in ("twin", "preset"):
        errs = [
            abs(t[k].wrap_deg - t["truth"].wrap_deg)
            for t in trials
            if t[k].state == "HOLD" or t["truth"].state == "HOLD"
        ]
        if errs:
            lo, hi = bootstrap_interval(errs, seed=seed)
            wrap[k] = (float(np.mean(errs)), lo, hi, len(errs))
        else:
            wrap[k] = (math.nan, math.nan, math.nan, 0)
    pen = {k: max((t[k].penetration_m for t in trials), default=math.nan) for k in PLANTS}
    return AgreementSummary(
        len(trials),
        success,
        sum(twin),
        sum(pre),
        only_twin,
        only_preset,
        mcnemar_exact(only_twin, only_preset),
        wrap,
        pen,
        sum(t["nudged"].success == t["truth"].success for t in trials)
        if all("nudged" in t for t in trials)
        else None,
    )


def rate_errors(
    draws: Sequence[Sequence[Mapping[str, Verdict]]], seed: int = 0
) -> dict[str, tuple[float, float, float, int]]:
    """Per plant (twin, preset, and nudged if run): the mean over draws of |its success rate − the
    truth's| on the draw's placements, with its bootstrap 95 % interval and the number of draws. A
    verdict on an edge may flip, and a rate is what a lab reads off a campaign."""
    out: dict[str, tuple[float, float, float, int]] = {}
    kinds = [k for k in ("twin", "preset", "nudged") if draws and all(k in t for d in draws for t in d)]
    for k in kinds:
        errs = [
            abs(sum(t[k].success for t in d) - sum(t["truth"].success for t in d)) / len(d)
            for d in draws
            if d
        ]
        lo, hi = bootstrap_interval(errs, seed=seed)
        out[k] = (float(np.mean(errs)), lo, hi, len(errs))
    return out
