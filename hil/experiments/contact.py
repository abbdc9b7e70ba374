"""contact (issue 13, item 4): the firmware's contact detector against the simulator's true contact.

The grasp reach of the strategy experiment's placements (:mod:`.strategy`), run through the firmware's
GRASP mode; each trial records the first true arm-object contact during REACH (``plant.contacts()``)
and the moment the firmware's detector ended REACH (WRAP). Per detector (the old stall-only rule: the
new rules' parameters at 0; and the present one):

- true positive: detected at or after the first true contact; false positive: detected before any
  true contact; false negative: a true contact during REACH and no detection before the reach ended;
- precision TP / (TP + FP) and recall TP / (TP + FN), each with a Wilson 95 % interval;
- detection delay after the first true contact (TPs): median with a bootstrap 95 % interval.

The Wilson and bootstrap helpers are private to this module (a shared ``stats`` module is being
written elsewhere; they can move there).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from controller.config import FirmwareConfig
from protocol.dbus import Lever
from protocol.messages import GraspState

from ..model_config import ObjectConfig
from ..spiral import SpiralDesign
from .common import FAR_M, MS, OBJ, Progress, Row, S, pyplot, save_figure, sized
from .grasp import grasp_firmware
from .parallel import parallel_map
from .rig import Rig, contact_units, rc_frame, world_m

OLD_DETECTOR = {"grasp_contact_decel_m_per_s2": 0.0, "grasp_contact_wrap_m_per_s": 0.0}
"""The parameters that turn the new rules off: what is left is the stall-only detector it replaces."""


@dataclass(frozen=True)
class ContactParams:
    """Attributes:
    diameters_m: object diameters.
    xs_m: horizontal distances of the object's centre from the arm's axis (target side, +x).
    zs_m: heights of the object's centre relative to the base (negative = below).
    """

    diameters_m: tuple[float, ...] = (0.016, 0.024, 0.036)
    xs_m: tuple[float, ...] = (0.03, 0.05, 0.07, 0.09)
    zs_m: tuple[float, ...] = (-0.07, -0.10, -0.13, -0.16)


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

    @property
    def kind(self) -> str:
        """``TP``, ``FP``, ``FN`` or ``TN`` (no true contact, no detection)."""
        detected = not math.isnan(self.detected_s)
        touched = not math.isnan(self.true_s)
        if detected:
            return "TP" if touched and self.true_s <= self.detected_s else "FP"
        return "FN" if touched else "TN"


def reach_trial(args: tuple[float, float, float, str, SpiralDesign, int]) -> ReachTrial:
    """Run one reach until the firmware leaves REACH (pure; picklable in and out)."""
    x_m, z_m, diameter_m, detector, design, seed = args
    fw: FirmwareConfig = grasp_firmware(**(OLD_DETECTOR if detector == "old" else {}))
    fw = fw.replaced(grasp_direction_deg=0.0)
    obj = ObjectConfig(OBJ, radius_m=diameter_m / 2, length_m=0.06, pos_m=FAR_M, mass_kg=0.02)
    rig = Rig(
        design,
        fw,
        [(0, rc_frame()), (20 * MS, rc_frame(Lever.UP)), (60 * MS, rc_frame(Lever.UP, Lever.UP))],
        objects=(obj,),
        start_packed=True,
        seed=seed,
    )
    plant = rig.plant
    plant.hold_object(OBJ)
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
    rig.close()

    def rel(t: int) -> float:
        return (t - t_reach) / S if t >= 0 and t_reach >= 0 else math.nan

    return ReachTrial(x_m, z_m, diameter_m, detector, rel(t_true), rel(t_detect), grasp.detector.reason)


def wilson(k: int, n: int, z: float = 1.96) -> tuple[float, float]:
    """Wilson score interval of a proportion ``k / n`` (NaNs for n = 0)."""
    if n == 0:
        return math.nan, math.nan
    p = k / n
    den = 1 + z * z / n
    centre = (p + z * z / (2 * n)) / den
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / den
    return max(0.0, centre - half), min(1.0, centre + half)


def bootstrap_median(values: list[float], seed: int, n_boot: int = 2000) -> tuple[float, float, float]:
    """Median and its percentile-bootstrap 95 % interval (NaNs without values)."""
    if not values:
        return math.nan, math.nan, math.nan
    a = np.asarray(values)
    rng = np.random.default_rng(seed)
    meds = np.median(rng.choice(a, size=(n_boot, len(a)), replace=True), axis=1)
    return float(np.median(a)), float(np.percentile(meds, 2.5)), float(np.percentile(meds, 97.5))


@dataclass(frozen=True)
class ContactResult:
    """Every placement reached with the old and the new detector."""

    params: ContactParams
    seed: int
    trials: tuple[ReachTrial, ...]

    def summary(self, detector: str) -> dict[str, Any]:
        """Counts, precision, recall (Wilson 95 %) and the delay's median (bootstrap 95 %) in ms."""
        sel = [t for t in self.trials if t.detector == detector]
        counts = {k: sum(1 for t in sel if t.kind == k) for k in ("TP", "FP", "FN", "TN")}
        tp, fp, fn = counts["TP"], counts["FP"], counts["FN"]
        delays = [1000 * (t.detected_s - t.true_s) for t in sel if t.kind == "TP"]
        med, lo, hi = bootstrap_median(delays, self.seed)
        return {
            **counts,
            "precision": tp / (tp + fp) if tp + fp else math.nan,
            "precision_ci95": wilson(tp, tp + fp),
            "recall": tp / (tp + fn) if tp + fn else math.nan,
            "recall_ci95": wilson(tp, tp + fn),
            "delay_ms_median": med,
            "delay_ms_ci95": (lo, hi),
            "reasons": {r: sum(1 for t in sel if t.reason == r) for r in sorted({t.reason for t in sel})},
        }

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        return {
            "experiment": "contact",
            "seed": self.seed,
            "old": self.summary("old"),
            "new": self.summary("new"),
            "trials": [{**dataclasses.asdict(t), "kind": t.kind} for t in self.trials],
            "params": dataclasses.asdict(self.params),
        }


def contact(
    design: SpiralDesign | None = None,
    params: ContactParams | None = None,
    seed: int = 0,
    progress: Progress | None = None,
    jobs: int = 1,
) -> ContactResult:
    """Reach every placement with the old and the new detector and compare with the true contact."""
    design = design or SpiralDesign.paper_prototype()
    p = params or ContactParams()
    jobs_in = [
        (x, z, d, det, design, seed)
        for d in p.diameters_m
        for z in p.zs_m
        for x in p.xs_m
        for det in ("old", "new")
    ]
    return ContactResult(p, seed, tuple(parallel_map(reach_trial, jobs_in, jobs, progress)))


def run_at_size(design: SpiralDesign, size: str, seed: int, progress: Progress | None, jobs: int) -> Any:
    """Run the experiment at ``size`` (see :data:`~hil.experiments.common.SIZES`)."""
    p = sized(
        size,
        ContactParams(diameters_m=(0.02,), xs_m=(0.04,), zs_m=(-0.11,)),
        ContactParams(),
        ContactParams(
            xs_m=(0.02, 0.035, 0.05, 0.065, 0.08, 0.095),
            zs_m=(-0.06, -0.08, -0.1, -0.12, -0.14, -0.16, -0.18),
        ),
    )
    return contact(design, p, seed, progress, jobs)


def _fmt(s: dict[str, Any]) -> tuple[str, str, str]:
    def share(v: float, ci: tuple[float, float]) -> str:
        return "n/a" if math.isnan(v) else f"{100 * v:.0f} % [{100 * ci[0]:.0f}, {100 * ci[1]:.0f}]"

    delay = s["delay_ms_median"]
    lo, hi = s["delay_ms_ci95"]
    d = "n/a" if math.isnan(delay) else f"{delay:.0f} ms [{lo:.0f}, {hi:.0f}]"
    return share(s["precision"], s["precision_ci95"]), share(s["recall"], s["recall_ci95"]), d


def table_rows(r: ContactResult) -> list[Row]:
    """Precision, recall and delay of the old and the new detector (the paper states none)."""
    rows: list[Row] = []
    for det in ("old", "new"):
        s = r.summary(det)
        precision, recall, delay = _fmt(s)
        rows += [
            (f"{det} detector: precision (Wilson 95 %)", precision, "-"),
            (f"{det} detector: recall (Wilson 95 %)", recall, "-"),
            (f"{det} detector: delay after true contact, median (bootstrap 95 %)", delay, "-"),
        ]
    return rows


def describe_samples(r: ContactResult) -> str:
    """The sample counts, in words."""
    n = len(r.trials) // 2
    return f"{n} placements, each reached with the old and the new detector"


def plot_figure(r: ContactResult, out: Path) -> Path:
    """Write the figure into the directory ``out``; returns its path (``contact.png``): detection time
    against the first true contact, per detector."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(5, 4))
    for det, marker in (("old", "x"), ("new", "o")):
        sel = [t for t in r.trials if t.detector == det]
        ax.scatter(
            [t.true_s for t in sel],
            [t.detected_s for t in sel],
            marker=marker,
            label=f"{det} detector",
            facecolors="none" if marker == "o" else None,
        )
    lim = max([0.1] + [v for t in r.trials for v in (t.true_s, t.detected_s) if not math.isnan(v)])
    ax.plot([0, lim], [0, lim], "k:", lw=0.8, label="detected = true contact")
    ax.set_xlabel("first true contact after REACH [s]")
    ax.set_ylabel("detected contact after REACH [s]")
    ax.legend()
    return save_figure(fig, out / "contact.png")
