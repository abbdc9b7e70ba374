"""The grasp trial (hil.trial.grasp) outside any experiment."""

from __future__ import annotations

import math
from typing import Any

from hil.sim.objects import contact_units
from hil.trial.grasp import GraspOutcome, GraspSetup, grasp_firmware, grasp_trial
from hil.trial.rig import Rig
from hil.trial.scene import OBJ
from protocol.messages import GraspState


def test_an_object_out_of_reach_is_a_failed_grasp() -> None:
    out = grasp_trial(GraspSetup(0.20, -0.05, 0.02, strategy_on=True))
    assert out.state == "FAILED" and not out.held and math.isnan(out.t_hold_s)


def test_a_ramp_that_curls_in_the_air_is_held_without_the_ceiling_and_failed_with_it() -> None:
    """The firmware's empty-curl rule on the real plant: the ramp closes on nothing (the object is half a
    metre away), its pulling cables pay in as much as they ever do; with ``grasp_hold_max_payin_m`` under
    that pay-in the board says FAILED with the figure, without it HOLD (nothing is held either way)."""
    events: list[str] = []

    def listen(rig: Rig) -> None:
        """Hear the grasp machine's events as it pushes them (the board's link task takes them away)."""
        queue = rig.firmware.grasp._events
        if getattr(queue, "heard", False):
            return
        push = queue.push

        def heard(time_us: int, kind: Any, code: int = 0, value: float = 0.0, text: str = "") -> None:
            events.append(text)
            push(time_us, kind, code, value, text)

        queue.push = heard  # type: ignore[method-assign]
        queue.heard = True  # type: ignore[attr-defined]

    def air(**rules: float) -> tuple[GraspOutcome, float]:
        paid: list[float] = []

        def look(rig: Rig) -> None:
            g = rig.firmware.grasp
            if not paid and g.state in (GraspState.HOLD, GraspState.FAILED):
                paid.append(g.wrap_payin_m)
            listen(rig)

        setup = GraspSetup(0.5, -0.12, 0.02, strategy_on=False, firmware=grasp_firmware(**rules))
        return grasp_trial(setup, on_tick=look), paid[0]

    free, paid = air()
    assert free.state == "HOLD" and not free.held and paid > 0.05  # the prototype's empty curl: about 70 mm
    events.clear()
    ceiling = round(paid * 0.9, 4)
    refused, paid_again = air(grasp_hold_max_payin_m=ceiling)
    assert paid_again == paid  # the same physics up to the verdict
    assert refused.state == "FAILED" and math.isnan(refused.t_hold_s)
    assert f"grasp FAILED: empty curl: {paid * 1e3:.1f} mm paid in > {ceiling * 1e3:.1f}" in events


def test_an_object_put_into_the_arm_is_flagged_and_one_beside_it_is_not() -> None:
    """The trial measures how deep the object overlaps the arm on the tick after it is put in place: the
    straight arm (the ramp's start) is about 16 mm wide 100 mm below its base, so a 20 mm cylinder 14 mm
    off its axis is put a few millimetres into it; the reference placement, 40 mm out, clears it."""
    inside = grasp_trial(GraspSetup(0.014, -0.10, 0.02, strategy_on=False))
    assert inside.placed_overlap_m > 0.001 and inside.placed_inside
    beside = grasp_trial(GraspSetup(0.04, -0.11, 0.02, strategy_on=False))
    assert beside.placed_overlap_m == 0.0 and not beside.placed_inside


def test_a_free_object_is_let_go_at_the_first_touch_and_the_trial_says_where_it_ends() -> None:
    """With ``release_at_touch`` the support gives way the first tick the arm touches the object: the
    trial's object is free from then on (before HOLD). At the reference placement the ramp's tip-first curl
    still hooks it; ``moved_mm`` says how far from its placement it ends."""
    held: list[bool] = []  # on the first tick the arm touches the object, and on the next

    def look(rig: Rig) -> None:
        plant = rig.plant
        if len(held) == 1 or (
            not held and rig.firmware.grasp_state != GraspState.IDLE and contact_units(plant, OBJ)
        ):
            held.append(plant.object_held(OBJ))  # on_tick looks before the trial lets it go

    out = grasp_trial(GraspSetup(0.04, -0.11, 0.02, strategy_on=False, release_at_touch=True), on_tick=look)
    assert held == [True, False]  # on its support until the first touch, free from the tick after
    assert out.state == "HOLD" and out.held and 0.0 < out.moved_mm < 200.0
    never = grasp_trial(GraspSetup(0.20, -0.05, 0.02, strategy_on=True, release_at_touch=True))
    assert never.state == "FAILED" and never.moved_mm < 1.0  # out of reach: untouched, still on its support


def test_the_reach_timeout_follows_the_reach_ramp_it_is_given() -> None:
    """The experiments' firmware fails a reach 0.6 s after its ramp has run down: the default ramp
    (18 N to 0 at 10 N/s) gives 2.4 s; a 4x slower reach the 7.8 s it needs (before, it kept 2.4 s and
    timed out at 12 N, its arm hardly unrolled); a timeout given is kept."""
    assert grasp_firmware().grasp.reach_timeout_us == 2_400_000
    assert grasp_firmware(grasp_reach_rate_n_per_s=2.5).grasp.reach_timeout_us == 7_800_000
    assert grasp_firmware(grasp_pack_n=12.0, grasp_reach_n=4.0).grasp.reach_timeout_us == 1_400_000
    given = grasp_firmware(grasp_reach_rate_n_per_s=2.5, grasp_reach_timeout_us=3_000_000)
    assert given.grasp.reach_timeout_us == 3_000_000
