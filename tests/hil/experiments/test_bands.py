"""The bands experiment (issue 24, item 1): its sweep geometry, its set-ups and its verdict rule (the run
itself at tiny size is in test_experiments.py)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from hil.experiments.bands import BandsParams, BandsResult, Sweep, setup_arm
from hil.experiments.common import DEFAULT_MODEL
from hil.sim.presets import PRESETS
from hil.sim.types import PhysicsExtremes
from hil.trial.grasp import GraspOutcome, GraspSetup, grasp_firmware


def test_the_sweep_clearance_is_the_gap_to_the_nearest_swept_unit() -> None:
    # Two snapshots of a 2-unit arm: straight down, then its second unit swung to +x.
    a = np.array([[0j, -0.1j], [0j, -0.1j]])
    b = np.array([[-0.1j, -0.2j], [-0.1j, 0.1 - 0.1j]])
    sweep = Sweep(a, b, np.array([0.01, 0.005]))
    assert sweep.clearance_m(0.05, -0.05, 0.01) == pytest.approx(0.05 - 0.01 - 0.01)  # beside unit 0
    assert sweep.clearance_m(0.05, -0.13, 0.01) == pytest.approx(0.03 - 0.005 - 0.01)  # under the swung unit
    assert sweep.clearance_m(0.0, -0.15, 0.001) < 0  # inside unit 1's first pose


def test_the_papers_set_up_is_the_45_cm_two_cable_arm_on_the_authors_model() -> None:
    arm, model, firmware = setup_arm("paper", DEFAULT_MODEL)
    assert arm.cables == 2 and arm.length_m == pytest.approx(0.467, abs=0.005)
    assert model.mounting == "gravity-off" and model.actuator.kind == "muscle"
    assert model == PRESETS["authors"].model.with_physics(DEFAULT_MODEL.solver.timestep_s)
    # Every force of the firmware scaled by 5 N / 20 N, the rest kept.
    base = grasp_firmware().to_dict()
    scaled = firmware.to_dict()
    assert scaled["tension_max_n"] == pytest.approx(5.0) and scaled["grasp_wrap_n"] == pytest.approx(15.0 / 4)
    assert scaled["grasp_wrap_rate_n_per_s"] == pytest.approx(base["grasp_wrap_rate_n_per_s"] / 4)
    assert scaled["grasp_reach_timeout_us"] == base["grasp_reach_timeout_us"]
    proto, same, fw = setup_arm("prototype", DEFAULT_MODEL)
    assert proto.cables == 3 and same is DEFAULT_MODEL and fw == grasp_firmware()
    with pytest.raises(ValueError, match="unknown set-up"):
        setup_arm("nope", DEFAULT_MODEL)


def _grasp(success: bool) -> GraspOutcome:
    nothing = PhysicsExtremes(0.0, 0.0, 1.0, 0.0)
    return GraspOutcome(
        GraspSetup(0.05, -0.1, 0.02),
        "HOLD",
        1.0,
        math.nan,
        3,
        3,
        200.0,
        0.0,
        0.0,
        success,
        success,
        0,
        nothing,
    )


def _result(pairs: list[tuple[bool, bool]]) -> BandsResult:
    p = BandsParams(setups=("prototype",), bands=("between",), per_band=len(pairs))
    placements = tuple(("prototype", "between", 0.05, -0.1) for _ in pairs)
    outcomes = tuple(g for off, on in pairs for g in (_grasp(off), _grasp(on)))
    return BandsResult(p, 0, placements, outcomes)


def test_the_claim_holds_only_on_a_significant_paired_win_in_the_between_band() -> None:
    win = _result([(False, True)] * 8 + [(True, True)] * 4)  # 8 only-strategy pairs: p = 2 / 2^8
    cell = win.cell("prototype", "between")
    assert (cell["only_on"], cell["only_off"]) == (8, 0) and cell["p_value"] == pytest.approx(2 / 256)
    assert cell["on"]["rate"] == 1.0 and cell["off"]["rate"] == pytest.approx(4 / 12)
    assert win.verdict("prototype") == "holds"
    assert _result([(False, True)] * 4).verdict("prototype") == "not reproduced"  # p = 0.125
    assert _result([(True, False)] * 10).verdict("prototype") == "not reproduced"  # the ramp wins
    assert any("between band" in r[0] for r in win.table_rows())
    label = "objects put inside the arm when placed (not grasps)"
    assert [r[1] for r in win.table_rows() if r[0] == label] == ["0 of 24"]
    inside = dataclasses.replace(_grasp(True), placed_overlap_m=0.004)  # 4 mm into a 10 mm-radius object
    one_in = BandsResult(win.params, 0, win.placements, (inside, *win.outcomes[1:]))
    assert [r[1] for r in one_in.table_rows() if r[0] == label] == ["1 of 24"]


def test_a_diverged_grasp_runs_again_at_half_the_step_then_is_left_out(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    from hil.errors import PlantDivergedError
    from hil.experiments import bands as module

    steps: list[float] = []

    def diverging(setup: GraspSetup, design: object) -> GraspOutcome:
        steps.append(setup.model.solver.timestep_s)
        if len(steps) < limit:
            raise PlantDivergedError("diverged", 1)
        return _grasp(True)

    monkeypatch.setattr(module, "grasp_trial", diverging)
    setup = GraspSetup(0.05, -0.1, 0.02, model=DEFAULT_MODEL)
    limit = 2
    assert module.band_grasp((setup, setup_arm("prototype", DEFAULT_MODEL)[0])) is not None
    assert steps == [DEFAULT_MODEL.solver.timestep_s, DEFAULT_MODEL.solver.timestep_s / 2]
    steps.clear()
    limit = 3
    assert module.band_grasp((setup, setup_arm("prototype", DEFAULT_MODEL)[0])) is None
    result = _result([(True, True), (False, True)])
    result = BandsResult(result.params, 0, result.placements, (None, *result.outcomes[1:]))
    assert result.diverged() == 1 and result.cell("prototype", "between")["n"] == 1


def test_the_reach_measure_counts_placements_per_band() -> None:
    result = _result([(False, True), (False, False), (True, True)])
    touched = BandsResult(result.params, 0, result.placements, result.outcomes, (True, False, False))
    assert touched.reached("prototype", "between") == (1, 3)
    assert touched.as_dict()["reach_touches"] == {"prototype": {"between": [1, 3]}}
    assert any("reach passes through" in r[0] and "between 1/3" in r[1] for r in touched.table_rows())
