"""array (Table S2): arrays of 2, 4, 6 and 8 one-cable arms grasp ten objects, n trials each.

The trial and its success criterion are :mod:`hil.trial.array_grasp`'s, fixed before the run: HOLD
reached, and 2 s after the support went the object still touches an arm, has dropped less than 60 mm
and moves slower than 5 cm/s. Each trial jitters the object's place by up to ``jitter_m`` along each axis.

The ring: ``min_ring_radius_m`` unless an object would touch the hanging arms. The supplement does not
say how its arrays were sized to an object; here the ring grows until the object, anywhere in its jitter,
clears the straight arms by ``clearance_m`` (a 200 mm rod needs 126 mm), so that no trial starts with an
arm inside the object.

Statistics: Wilson 95 % interval per array size (and per size and object), the Cochran-Armitage test of a
trend of success with the array's size, and the paper's rates beside ours (Table S2: five tests per object
and size, i.e. 50 per size). The verdict rule, fixed before the run: the paper's trend is reproduced if
ours is positive with p < 0.05; a size's rate agrees if the paper's rate lies in our 95 % interval.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from hil.experiments.base import Conditions, Experiment, Sizes
from hil.experiments.common import Row, extremes_rows, pct, pyplot, save_figure, worst_extremes
from hil.experiments.parallel import parallel_map
from hil.experiments.stats import cochran_armitage, wilson_interval
from hil.sim.config import ModelConfig, ObjectConfig
from hil.sim.mjcf import unit_geometry
from hil.sim.spiral import SpiralDesign
from hil.sim.types import PhysicsExtremes
from hil.trial.array_grasp import (
    ArrayGraspOutcome,
    ArrayGraspSetup,
    array_design,
    array_grasp_trial,
    array_object,
)
from hil.trial.objects import ARRAY_OBJECTS

PAPER_RATES: dict[int, tuple[float, float]] = {
    2: (0.48, 0.23),
    4: (0.72, 0.37),
    6: (0.92, 0.17),
    8: (0.94, 0.19),
}
"""Table S2's average success per array size, ± the SD over its ten objects (5 tests each)."""
PAPER_TESTS_PER_SIZE = 50


@dataclass(frozen=True)
class ArrayParams:
    """Attributes:
    arms: the array sizes.
    objects: the objects' keys (:data:`hil.trial.objects.ARRAY_OBJECTS`).
    trials: trials per size and object.
    jitter_m: each trial moves the object by up to this along x, y and z (uniform).
    depth_m: the object's centre below the arms' bases, on the ring's axis.
    min_ring_radius_m: the ring's radius unless an object needs more.
    clearance_m: the smallest gap between the hanging arms and an object anywhere in its jitter.
    hold_s: how long a released object must stay.
    """

    arms: tuple[int, ...] = (2, 4, 6, 8)
    objects: tuple[str, ...] = tuple(o.key for o in ARRAY_OBJECTS)
    trials: int = 5
    jitter_m: float = 0.005
    depth_m: float = 0.13
    min_ring_radius_m: float = 0.06
    clearance_m: float = 0.005
    hold_s: float = 2.0


TINY = ArrayParams(arms=(2, 4), objects=("sphere",), trials=1)
"""The smoke-test size: a 60 mm ball in a 2-arm and a 4-arm array."""


def horizontal_reach_m(obj: ObjectConfig) -> float:
    """How far the object reaches from its centre in the horizontal plane (its shape and axis)."""
    if obj.shape == "mesh":
        return max(math.hypot(x, y) for x, y, _ in obj.vertices)
    r, half = obj.radius_m, 0.5 * obj.length_m
    upright = abs(obj.axis[2]) > 0.99
    if obj.shape == "sphere":
        return r
    if obj.shape == "box":
        return math.hypot(r, r) if upright else math.hypot(r, half, r)
    return r if upright else math.hypot(r, half)


def ring_radius_m(key: str, p: ArrayParams, design: SpiralDesign | None = None) -> float:
    """The ring for object ``key``: :attr:`ArrayParams.min_ring_radius_m`, or more so that the object,
    anywhere in its jitter, clears the straight arms (``design``'s widest, base unit; default the
    experiment's arm) by ``clearance_m``."""
    obj = array_object(key).config
    arm = design if design is not None else array_design()
    arm_half_width = 0.5 * unit_geometry(arm, ModelConfig().arm).width_base_side_m[0]
    needed = horizontal_reach_m(obj) + math.sqrt(2.0) * p.jitter_m + arm_half_width + p.clearance_m
    return round(max(p.min_ring_radius_m, needed), 4)


def setups(p: ArrayParams, on: Conditions) -> list[ArrayGraspSetup]:
    """Every trial: per size, object and trial, its jitter drawn from a generator seeded by them."""
    out = []
    for arms in p.arms:
        for key in p.objects:
            radius = ring_radius_m(key, p)
            for t in range(p.trials):
                rng = np.random.default_rng([on.seed, arms, t, sum(map(ord, key))])
                dx, dy, dz = (float(v) for v in rng.uniform(-p.jitter_m, p.jitter_m, 3))
                out.append(
                    ArrayGraspSetup(
                        arms,
                        key,
                        depth_m=p.depth_m,
                        offset_m=(dx, dy, dz),
                        ring_radius_m=radius,
                        hold_s=p.hold_s,
                        model=on.model,
                        seed=on.seed,
                    )
                )
    return out


@dataclass(frozen=True)
class ArrayResult:
    """Every array grasp (a :class:`~hil.experiments.base.Result`)."""

    params: ArrayParams
    seed: int
    outcomes: tuple[ArrayGraspOutcome, ...]

    @property
    def extremes(self) -> PhysicsExtremes:
        """The worst physics over every grasp."""
        return worst_extremes(o.extremes for o in self.outcomes)

    def rate(self, arms: int, key: str | None = None) -> dict[str, Any]:
        """Successes, trials, rate and Wilson 95 % interval of one size (one object or all)."""
        sel = [
            o for o in self.outcomes if o.setup.arms == arms and (key is None or o.setup.object_key == key)
        ]
        k = sum(o.success for o in sel)
        lo, hi = wilson_interval(k, len(sel))
        return {"successes": k, "n": len(sel), "rate": k / len(sel) if sel else math.nan, "ci95": [lo, hi]}

    def trend(self) -> tuple[float, float]:
        """Cochran-Armitage ``(z, p)`` of success against the array's size."""
        rates = [self.rate(a) for a in self.params.arms]
        return cochran_armitage([r["successes"] for r in rates], [r["n"] for r in rates], self.params.arms)

    def verdicts(self) -> dict[str, str]:
        """The fixed rule's verdicts: the trend, and each size with a paper rate."""
        z, p = self.trend()
        out = {"trend": "reproduced" if z > 0 and p < 0.05 else "not reproduced"}
        for a in self.params.arms:
            if a in PAPER_RATES:
                lo, hi = self.rate(a)["ci95"]
                out[f"{a} arms"] = "agrees" if lo <= PAPER_RATES[a][0] <= hi else "differs"
        return out

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        z, p = self.trend()
        return {
            "experiment": "array",
            "seed": self.seed,
            "criterion": f"HOLD, then {self.params.hold_s:g} s after release touching an arm, dropped "
            "< 60 mm, slower than 5 cm/s",
            "sizes": {str(a): self.rate(a) for a in self.params.arms},
            "per_object": {
                key: {str(a): self.rate(a, key) for a in self.params.arms} for key in self.params.objects
            },
            "ring_radius_m": {key: ring_radius_m(key, self.params) for key in self.params.objects},
            "trend_z": z,
            "trend_p": p,
            "verdicts": self.verdicts(),
            "paper": {str(a): {"rate": m, "sd": sd} for a, (m, sd) in PAPER_RATES.items()},
            "extremes": self.extremes.as_dict(),
            "trials": len(self.outcomes),
            "outcomes": [o.as_dict() for o in self.outcomes],
            "params": dataclasses.asdict(self.params),
        }

    def table_rows(self) -> list[Row]:
        """Per size: our rate with its interval, the paper's; the trend; the worst physics."""
        rows: list[Row] = []
        verdicts = self.verdicts()
        for a in self.params.arms:
            r = self.rate(a)
            lo, hi = r["ci95"]
            paper = PAPER_RATES.get(a)
            rows.append(
                (
                    f"{a}-arm array: success",
                    f"{pct(r['rate'])} ({r['successes']}/{r['n']}; 95 % CI {pct(lo)}-{pct(hi)})",
                    f"{paper[0]:.2f} ± {paper[1]:.2f} (n = {PAPER_TESTS_PER_SIZE}): {verdicts[f'{a} arms']}"
                    if paper
                    else "",
                )
            )
        z, p = self.trend()
        rows.append(
            ("trend of success with size (Cochran-Armitage)", f"z = {z:.2f}, p = {p:.3g}", verdicts["trend"])
        )
        rows.extend(extremes_rows(self.extremes))
        return rows

    def describe_samples(self) -> str:
        """Sizes, objects and trials, in words."""
        p = self.params
        return (
            f"{len(p.arms)} array sizes x {len(p.objects)} objects x {p.trials} trials = "
            f"{len(self.outcomes)} grasps (object {p.depth_m * 1000:g} mm under the bases, jitter "
            f"±{p.jitter_m * 1000:g} mm; success = held {p.hold_s:g} s after release)"
        )

    def figure(self, out: Path) -> Path:
        """Write ``array.png`` into ``out``: success against size with its intervals and the paper's, and
        the rate of every size and object."""
        plt = pyplot()
        p = self.params
        fig, (ax, grid) = plt.subplots(1, 2, figsize=(11, 4.4))
        ours = [self.rate(a) for a in p.arms]
        rates = np.array([r["rate"] for r in ours])
        lo = np.array([r["ci95"][0] for r in ours])
        hi = np.array([r["ci95"][1] for r in ours])
        ax.errorbar(
            p.arms, rates, yerr=[rates - lo, hi - rates], fmt="o-", capsize=4, label="simulated (Wilson 95 %)"
        )
        paper = [a for a in p.arms if a in PAPER_RATES]
        ax.errorbar(
            [a + 0.15 for a in paper],
            [PAPER_RATES[a][0] for a in paper],
            yerr=[PAPER_RATES[a][1] for a in paper],
            fmt="s--",
            color="tab:orange",
            capsize=4,
            label="paper, Table S2 (± SD over objects)",
        )
        z, pv = self.trend()
        ax.set_title(f"success vs array size (trend z = {z:.2f}, p = {pv:.2g})", fontsize=9)
        ax.set_xlabel("arms")
        ax.set_ylabel("success rate")
        ax.set_ylim(-0.05, 1.15)
        ax.set_xticks(list(p.arms))
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7, loc="lower right")
        table = np.array([[self.rate(a, key)["rate"] for a in p.arms] for key in p.objects])
        im = grid.imshow(table, vmin=0, vmax=1, cmap="viridis", aspect="auto")
        grid.set_xticks(range(len(p.arms)), [str(a) for a in p.arms])
        grid.set_yticks(range(len(p.objects)), list(p.objects), fontsize=7)
        grid.set_xlabel("arms")
        grid.set_title(f"success per object ({p.trials} trials each)", fontsize=9)
        fig.colorbar(im, ax=grid)
        return save_figure(fig, out / "array.png")


def array(p: ArrayParams, on: Conditions) -> ArrayResult:
    """Every size, object and trial (:func:`setups`) grasped by the firmware's GRASP mode driving the
    array as one gripper, on the plant ``on.model`` (Table S2). The arms are the experiment's own
    (:func:`hil.trial.array_grasp.array_design`), not ``on.design``."""
    runs = setups(p, on)
    return ArrayResult(p, on.seed, tuple(parallel_map(array_grasp_trial, runs, on.jobs, on.progress)))


EXPERIMENT = Experiment(
    "array",
    "arrays of 2-8 one-cable arms grasp ten objects: Wilson intervals, trend test, Table S2 beside",
    # tiny: a ball by 2 and 4 arms; default: 4 sizes x 10 objects x 5 trials (the paper's count); large: 10
    Sizes(TINY, ArrayParams(), ArrayParams(trials=10)),
    array,
    own_arm="arrays of one-cable arms (Table S2)",
)
"""The array experiment (:mod:`hil.experiments.catalogue`)."""
