"""The grasp trial (hil.trial.grasp) outside any experiment."""

from __future__ import annotations

import math

from hil.trial.grasp import GraspSetup, grasp_trial


def test_an_object_out_of_reach_is_a_failed_grasp() -> None:
    out = grasp_trial(GraspSetup(0.20, -0.05, 0.02, strategy_on=True))
    assert out.state == "FAILED" and not out.held and math.isnan(out.t_hold_s)
