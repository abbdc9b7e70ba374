"""contact (issue 13, item 4): the firmware's contact detector against the simulator's true contact.

The grasp reach at the strategy experiment's placements (:func:`.strategy.placements`: jittered, clear of
the packed coil and the straight arm by :class:`~.geometry.ArmFootprint`), set up as its strategy-on grasp
(:func:`.grasp.grasp_rig`) and run through the firmware's GRASP mode; each trial records the first true
arm-object contact during REACH (``plant.contacts()``) and the moment the firmware's detector ended REACH
(WRAP). Per detector (the old stall-only rule: the new rules' parameters at 0; and the present one):

- true positive: detected at or after the first true contact; false positive: detected before any
  true contact; false negative: a true contact during REACH and no detection before the reach ended;
- precision TP / (TP + FP) and recall TP / (TP + FN), each with a Wilson 95 % interval;
- detection delay after the first true contact (TPs): median with a bootstrap 95 % interval.

The intervals are :mod:`.stats`'s.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from hil.experiments.base import Conditions, Experiment, Sizes
from hil.experiments.common import Row, extremes_rows, pyplot, save_figure, worst_extremes
from hil.experiments.parallel import parallel_map
from hil.experiments.stats import bootstrap_interval, wilson_interval
from hil.experiments.strategy import TINY, StrategyParams, placements
from hil.sim.objects import contact_units
from hil.sim.spiral import SpiralDesign
from hil.sim.types import PhysicsExtremes
from hil.trial.grasp import GraspSetup, grasp_firmware, grasp_rig
from hil.trial.scene import OBJ, S, world_m
from protocol.messages import GraspState

OLD_DETECTOR = {
    "grasp_contact_decel_m_per_s2": 0.0,
    "grasp_contact_wrap_m_per_s": 0.0,
    "grasp_contact_rest_m": 0.0,
}
"""The parameters that turn the new rules off: what is left is the stall-only detector it replaces."""


@dataclass(frozen=True)
class ContactParams:
    """Attributes:
    placements: the strategy experiment's placements and objects (its ``hold_s`` and ``oracle`` are not
        used: a trial ends when REACH does).
    """

    placements: StrategyParams = field(default_factory=StrategyParams)


@dataclass(frozen=True)
class ReachTrial:
    """One reach: where, which detector, and when the true and the detected contact came (s after REACH)."""

    x_m: float
    z_m: float
    diameter_m: float
    detector: str
    true_s: float
    detected_s: float
    reason: str
    extremes: PhysicsExtremes

    @property
    def kind(self) -> str:
        """``TP``, ``FP``, ``FN`` or ``TN`` (no true contact, no detection)."""
        detected = not math.isnan(self.detected_s)
        touched = not math.isnan(self.true_s)
        if detected:
            return "TP" if touched and self.true_s <= self.detected_s else "FP"
        return "FN" if touched else "TN"


def reach_trial(args: tuple[GraspSetup, str, SpiralDesign]) -> ReachTrial:
    """Run one strategy-on reach with ``detector`` (``old`` or ``new``) until the firmware leaves REACH
    (pure; picklable in and out)."""
    setup, detector, design = args
    fw = grasp_firmware(**(OLD_DETECTOR if detector == "old" else {}))
    rig = grasp_rig(dataclasses.replace(setup, strategy_on=True, firmware=fw), design)
    x_m, z_m, diameter_m = setup.x_m, setup.z_m, setup.diameter_m
    plant = rig.plant
    grasp = rig.firmware.grasp
    t_reach = -1
    t_true = -1
    t_detect = -1
    while rig.now_us < 12 * S:
        rig.step()
        state = grasp.state
        if t_reach < 0:
            if state == GraspState.REACH:
                t_reach = rig.now_us
                plant.hold_object(OBJ, world_m(x_m, z_m))
            continue
        if t_true < 0 and contact_units(plant, OBJ):
            t_true = rig.now_us
        if state != GraspState.REACH:
            if state == GraspState.WRAP:
                t_detect = rig.now_us
            break
    extremes = plant.extremes()
    rig.close()

    def rel(t: int) -> float:
        return (t - t_reach) / S if t >= 0 and t_reach >= 0 else math.nan

    return ReachTrial(
        x_m, z_m, diameter_m, detector, rel(t_true), rel(t_detect), grasp.detector.reason, extremes
    )


@dataclass(frozen=True)
class ContactResult:
    """Every placement reached with the old and the new detector (a :class:`~hil.experiments.base.Result`)."""

    params: ContactParams
    seed: int
    trials: tuple[ReachTrial, ...]

    def summary(self, detector: str) -> dict[str, Any]:
        """Counts, precision, recall (Wilson 95 %) and the delay's median (bootstrap 95 %) in ms."""
        sel = [t for t in self.trials if t.detector == detector]
        counts = {k: sum(1 for t in sel if t.kind == k) for k in ("TP", "FP", "FN", "TN")}
        tp, fp, fn = counts["TP"], counts["FP"], counts["FN"]
        delays = [1000 * (t.detected_s - t.true_s) for t in sel if t.kind == "TP"]
        return {
            **counts,
            "precision": tp / (tp + fp) if tp + fp else math.nan,
            "precision_ci95": wilson_interval(tp, tp + fp),
            "recall": tp / (tp + fn) if tp + fn else math.nan,
            "recall_ci95": wilson_interval(tp, tp + fn),
            "delay_ms_median": float(np.median(delays)) if delays else math.nan,
            "delay_ms_ci95": bootstrap_interval(delays, "median", seed=self.seed),
            "reasons": {r: sum(1 for t in sel if t.reason == r) for r in sorted({t.reason for t in sel})},
        }

    @property
    def extremes(self) -> PhysicsExtremes:
        """The worst physics over every reach."""
        return worst_extremes(t.extremes for t in self.trials)

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        trials = []
        for t in self.trials:
            d = {k: v for k, v in dataclasses.asdict(t).items() if k != "extremes"}
            trials.append({**d, **t.extremes.as_dict(), "kind": t.kind})
        return {
            "experiment": "contact",
            "seed": self.seed,
            "old": self.summary("old"),
            "new": self.summary("new"),
            "extremes": self.extremes.as_dict(),
            "trials": trials,
            "params": dataclasses.asdict(self.params),
        }

    def table_rows(self) -> list[Row]:
        """Precision, recall and delay of the old and the new detector (the paper states none)."""
        rows: list[Row] = []
        for det in ("old", "new"):
            s = self.summary(det)
            precision, recall, delay = _fmt(s)
            rows += [
                (f"{det} detector: precision (Wilson 95 %)", precision, "-"),
                (f"{det} detector: recall (Wilson 95 %)", recall, "-"),
                (f"{det} detector: delay after true contact, median (bootstrap 95 %)", delay, "-"),
            ]
        rows.extend(extremes_rows(self.extremes))
        return rows

    def describe_samples(self) -> str:
        """Placements and detectors, in words."""
        n = len(self.trials) // 2
        sp = self.params.placements
        return (
            f"{n} placements (the strategy's: {len(sp.diameters_m)} diameters, {sp.grid[0]} x {sp.grid[1]} "
            f"jittered cells x {sp.seeds} seeds, clear of the packed coil), each reached with the old and "
            "the new detector"
        )

    def figure(self, out: Path) -> Path:
        """Write the figure into the directory ``out``; returns its path (``contact.png``): detection time
        against the first true contact, per detector."""
        plt = pyplot()
        fig, ax = plt.subplots(figsize=(5, 4))
        for det, marker in (("old", "x"), ("new", "o")):
            sel = [t for t in self.trials if t.detector == det]
            ax.scatter(
                [t.true_s for t in sel],
                [t.detected_s for t in sel],
                marker=marker,
                label=f"{det} detector",
                facecolors="none" if marker == "o" else None,
            )
        lim = max([0.1] + [v for t in self.trials for v in (t.true_s, t.detected_s) if not math.isnan(v)])
        ax.plot([0, lim], [0, lim], "k:", lw=0.8, label="detected = true contact")
        ax.set_xlabel("first true contact after REACH [s]")
        ax.set_ylabel("detected contact after REACH [s]")
        ax.legend()
        return save_figure(fig, out / "contact.png")


def contact_jobs(p: ContactParams, on: Conditions) -> list[tuple[GraspSetup, str, SpiralDesign]]:
    """The reaches of :func:`contact`: each of the strategy's placements (:func:`.strategy.placements`,
    in its order), with the old then the new detector."""
    sp = p.placements
    return [
        (GraspSetup(x, z, d, mass_kg=sp.mass_kg, model=on.model, seed=on.seed), det, on.design)
        for x, z, d in placements(on.design, sp, on.seed, on.model)
        for det in ("old", "new")
    ]


def contact(p: ContactParams, on: Conditions) -> ContactResult:
    """Reach every placement of the strategy experiment with the old and the new detector, on the plant
    ``on.model``, and compare with the true contact."""
    trials = parallel_map(reach_trial, contact_jobs(p, on), on.jobs, on.progress)
    return ContactResult(p, on.seed, tuple(trials))


def _fmt(s: dict[str, Any]) -> tuple[str, str, str]:
    def share(v: float, ci: tuple[float, float]) -> str:
        return "n/a" if math.isnan(v) else f"{100 * v:.0f} % [{100 * ci[0]:.0f}, {100 * ci[1]:.0f}]"

    delay = s["delay_ms_median"]
    lo, hi = s["delay_ms_ci95"]
    d = "n/a" if math.isnan(delay) else f"{delay:.0f} ms [{lo:.0f}, {hi:.0f}]"
    return share(s["precision"], s["precision_ci95"]), share(s["recall"], s["recall_ci95"]), d


EXPERIMENT = Experiment(
    "contact",
    "the firmware's contact detector, old and new, vs. the true contact: precision, recall, delay",
    # the strategy experiment's placements at the same size (tiny: its one reference placement)
    Sizes(ContactParams(TINY), ContactParams(), ContactParams(StrategyParams(grid=(6, 6)))),
    contact,
)
"""The contact experiment (:mod:`hil.experiments.catalogue`)."""
