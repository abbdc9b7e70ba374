"""The array experiment (Table S2): its trial, its ring sizing, its trend test and its verdict rule."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from hil.experiments.array import (
    PAPER_RATES,
    ArrayParams,
    ArrayResult,
    horizontal_reach_m,
    ring_radius_m,
)
from hil.experiments.stats import cochran_armitage
from hil.sim.plant import Plant
from hil.sim.types import PhysicsExtremes, PlantConfig, RingConfig
from hil.trial.array_grasp import (
    ArrayGraspOutcome,
    ArrayGraspSetup,
    array_design,
    array_grasp_trial,
    array_object,
)
from hil.trial.objects import ARRAY_OBJECTS
from hil.trial.scene import OBJ


def test_the_trend_test_is_the_correlation_of_size_and_success() -> None:
    """Cochran-Armitage's z is sqrt(N) times Pearson's r between score and outcome, trial by trial."""
    k, n, s = [24, 36, 46, 47], [50, 50, 50, 50], [2, 4, 6, 8]  # Table S2's rates, 50 tests per size
    z, p = cochran_armitage(k, n, s)
    x = np.repeat(s, n)
    y = np.concatenate([[1] * ki + [0] * (ni - ki) for ki, ni in zip(k, n, strict=True)])
    assert z == pytest.approx(math.sqrt(len(x)) * np.corrcoef(x, y)[0, 1], rel=1e-12)
    assert z > 0 and p == pytest.approx(math.erfc(z / math.sqrt(2)), rel=1e-12) and p < 1e-6
    assert cochran_armitage([3, 2, 1], [5, 5, 5], [1, 2, 3])[0] < 0  # falling
    assert cochran_armitage([5, 5], [5, 5], [2, 4]) == (0.0, 1.0)  # all succeed: nothing to test
    with pytest.raises(ValueError, match=r"0\.\.n"):
        cochran_armitage([6], [5], [1])


def test_every_object_anywhere_in_its_jitter_clears_the_hanging_arms_of_its_ring() -> None:
    p = ArrayParams()
    assert ring_radius_m("sphere", p) == p.min_ring_radius_m
    assert ring_radius_m("rod", p) > horizontal_reach_m(array_object("rod").config) > 0.1
    worst = p.jitter_m
    for o in ARRAY_OBJECTS:
        setup = ArrayGraspSetup(8, o.key, depth_m=p.depth_m, ring_radius_m=ring_radius_m(o.key, p))
        model = setup.model.with_objects(o.placed((0.0, 0.0, 0.0)))
        plant = Plant(array_design(), PlantConfig(model=model, ring=RingConfig(8, setup.ring_radius_m)))
        for dx, dy in ((worst, worst), (-worst, worst), (worst, -worst), (-worst, -worst)):
            corner = dataclasses.replace(setup, offset_m=(dx, dy, worst))
            plant.hold_object(OBJ, corner.target_m())
            plant.step()
            assert not [c for c in plant.contacts() if c.other == OBJ], (o.key, corner.offset_m)


def test_an_array_holds_a_ball_under_it_and_drops_one_below_its_reach() -> None:
    """The criterion can fail: a ball 30 cm under the bases (the arms are 23 cm) is never caught."""
    held = array_grasp_trial(ArrayGraspSetup(4, "sphere"))
    assert held.state == "HOLD" and held.held and held.success
    assert held.arms_touching >= 2 and held.drop_mm < 60.0 and held.speed_m_s < 0.05
    assert held.extremes.penetration_m < 1e-3
    missed = array_grasp_trial(ArrayGraspSetup(4, "sphere", depth_m=0.30))
    assert not missed.held and missed.arms_touching == 0
    assert missed.as_dict()["success"] is False


def _outcome(arms: int, ok: bool) -> ArrayGraspOutcome:
    nothing = PhysicsExtremes(0.0, 0.0, 1.0, 0.0)
    return ArrayGraspOutcome(ArrayGraspSetup(arms, "sphere"), "HOLD", 1.0, 2, 2, 0.0, 0.0, ok, 0, nothing)


def test_the_verdicts_follow_the_rule_fixed_before_the_run() -> None:
    """Table S2's own counts reproduce its trend and agree at every size; a flat 50 % does neither."""
    p = ArrayParams(objects=("sphere",), trials=50)
    paper = ArrayResult(
        p, 0, tuple(_outcome(a, i < round(PAPER_RATES[a][0] * 50)) for a in p.arms for i in range(50))
    )
    assert paper.verdicts() == {
        "trend": "reproduced",
        "2 arms": "agrees",
        "4 arms": "agrees",
        "6 arms": "agrees",
        "8 arms": "agrees",
    }
    flat = ArrayResult(p, 0, tuple(_outcome(a, i % 2 == 0) for a in p.arms for i in range(50)))
    v = flat.verdicts()
    assert v["trend"] == "not reproduced" and v["2 arms"] == "agrees" and v["8 arms"] == "differs"
    assert any("Cochran-Armitage" in r[0] for r in flat.table_rows())
