"""One grasp: the firmware's GRASP state machine against one object, measured (the strategy, contact,
grasp-range and load experiments' trial, and a campaign's grasp run)."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from controller.config import FirmwareConfig
from hil.sim.config import ModelConfig
from hil.sim.objects import contact_units, contact_wrap_deg
from hil.sim.spiral import SpiralDesign
from hil.sim.types import PhysicsExtremes
from hil.trial.rig import Rig, rc_frame
from hil.trial.scene import (
    HELD_DROP_MM,
    HELD_SPEED_M_S,
    MS,
    OBJ,
    SUCCESS_WRAP_DEG,
    S,
    beyond_goal,
    target_object,
    world_m,
)
from protocol.dbus import Lever
from protocol.messages import GraspState


@dataclass(frozen=True)
class GraspSetup:
    """One grasp trial.

    Attributes:
        x_m: object centre, horizontal distance from the arm's base on cable 0's side (+x).
        z_m: object centre, height relative to the base (negative = below).
        diameter_m: cylinder diameter (axis along y).
        strategy_on: the bio-inspired strategy (packed start, reach, contact, wrap) or the plain ramp.
        mass_kg: object mass.
        length_m: cylinder length.
        object_friction: the object's sliding friction coefficient (MuJoCo uses the larger of the
            object's and the arm's).
        hold_s: how long the object must stay after its support is removed.
        release: remove the support at HOLD (False: the object stays fixed, a pole or a branch).
        release_at_touch: the support gives way at the arm's first touch instead (the simulator's true
            contact): a free object that a touch dislodges, which the wrap must catch, not knock away
            (``release`` then changes nothing: the object is already free at HOLD).
        load_rate_n_per_s: if > 0, once the released object has been held for ``hold_s``, a force on it
            along ``load_dir`` grows at this rate until it comes out (the load and grasp-range
            experiments).
        load_cap_n: the load stops growing here.
        load_dir: unit vector (world frame) of that force: ``(0, 0, −1)`` a weight, ``(1, 0, 0)`` a pull
            away from the arm's axis.
        contact_oracle: the simulator's true arm-object contact replaces the firmware's contact detector
            (``GraspMachine.contact_override``): controller and physics told apart.
        firmware: firmware configuration (None = :func:`grasp_firmware`).
        model: the plant's model (a preset or a sensitivity variant); the object is appended to it.
        seed: seed of the board.
    """

    x_m: float
    z_m: float
    diameter_m: float
    strategy_on: bool = True
    mass_kg: float = 0.02
    length_m: float = 0.06
    object_friction: float = 0.8
    hold_s: float = 0.6
    release: bool = True
    release_at_touch: bool = False
    load_rate_n_per_s: float = 0.0
    load_cap_n: float = 20.0
    load_dir: tuple[float, float, float] = (0.0, 0.0, -1.0)
    contact_oracle: bool = False
    firmware: FirmwareConfig | None = None
    model: ModelConfig = field(default_factory=ModelConfig)
    seed: int = 0


@dataclass(frozen=True)
class GraspOutcome:
    """What one grasp trial measured.

    Attributes:
        setup: the trial.
        state: the grasp state at the end (``HOLD`` for a completed grasp).
        t_hold_s: time from the start of the grasp (REACH, or WRAP with the strategy off) to HOLD; NaN if
            never.
        contact_s: time from the start of the grasp to the detected contact (strategy on); NaN if none.
        units_at_hold: arm units touching the object when HOLD was reached.
        units_after: arm units touching it ``hold_s`` after its support was removed.
        wrap_deg: angular extent of the contacts around the object ``hold_s`` after its support was
            removed (0 if HOLD was never reached).
        drop_mm: how far below its release height the object is at the end (negative: above).
        shift_mm: how far the object is from where it was released, at the end.
        held: HOLD reached, and ``hold_s`` after its support was removed the object still touches at
            least 2 units, is less than :data:`HELD_DROP_MM` below its release height and slower than
            :data:`HELD_SPEED_M_S`.
        success: the grasp criterion fixed before the experiments ran: ``held`` and ``wrap_deg`` at
            least :data:`~hil.trial.scene.SUCCESS_WRAP_DEG` (half the circumference).
        max_current_raw: largest |current| sent to an ESC.
        extremes: the worst physics of the whole trial (:meth:`hil.sim.plant.Plant.extremes`).
        load_n: with a load ramp, the force at which the object came out (moved more than
            :data:`HELD_DROP_MM` along the force from where the ramp started, or no contact); the cap if
            it never did; NaN without a ramp or if it was not held.
        moved_mm: how far the object ends from where it was put in place (NaN if it never was): a free
            object knocked away ends far off.
        placed_overlap_m: how deep the arm and the object overlap on the tick after the object was put in
            its place (NaN if it never was). Beyond the penetration goal (:attr:`placed_inside`) the arm
            was already where the object was put (a start that did not keep the shape its placements were
            cleared against), and the trial is not a grasp.
    """

    setup: GraspSetup
    state: str
    t_hold_s: float
    contact_s: float
    units_at_hold: int
    units_after: int
    wrap_deg: float
    drop_mm: float
    shift_mm: float
    held: bool
    success: bool
    max_current_raw: int
    extremes: PhysicsExtremes
    load_n: float = math.nan
    placed_overlap_m: float = math.nan
    moved_mm: float = math.nan

    @property
    def placed_inside(self) -> bool:
        """The object was put in place overlapping the arm beyond the penetration goal."""
        return beyond_goal(self.placed_overlap_m, self.setup.diameter_m / 2)

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready form (the setup without its firmware and model configurations)."""
        d = dataclasses.asdict(self)
        d["setup"] = {k: v for k, v in d["setup"].items() if k not in ("firmware", "model")}
        return d


def grasp_firmware(**changes: Any) -> FirmwareConfig:
    """The firmware of the grasp experiments: defaults, except that IDLE winds the pack up at 60 N/s
    (the trial starts packed and only has to hold it) and a reach that has run its ramp down without
    contact fails 0.6 s later instead of after 4 s.

    The reach's ramp is the one of ``changes`` (its pack and reach tensions and rate), unless they set
    ``grasp_reach_timeout_us`` themselves: a slower reach gets the longer timeout its ramp needs.
    """
    cfg = FirmwareConfig().replaced(grasp_pack_rate_n_per_s=60.0)
    if changes:
        cfg = cfg.replaced(**changes)
    if "grasp_reach_timeout_us" in changes:
        return cfg
    g = cfg.grasp
    ramp_s = (g.pack_n - g.reach_n) / g.reach_rate_n_per_s
    return cfg.replaced(grasp_reach_timeout_us=int((ramp_s + 0.6) * S))


def grasp_rig(setup: GraspSetup, design: SpiralDesign) -> Rig:
    """The rig of one grasp: the firmware in GRASP mode (lever UP at 20 ms, the grasp request at 60 ms),
    packed if the strategy is on, the object waiting out of reach on its support."""
    fw = setup.firmware or grasp_firmware()
    fw = fw.replaced(grasp_strategy_on=setup.strategy_on, grasp_direction_deg=0.0)
    obj = target_object(setup.diameter_m / 2, setup.length_m, setup.mass_kg, setup.object_friction)
    rig = Rig(
        design,
        fw,
        [(0, rc_frame()), (20 * MS, rc_frame(Lever.UP)), (60 * MS, rc_frame(Lever.UP, Lever.UP))],
        objects=(obj,),
        start_packed=setup.strategy_on,
        seed=setup.seed,
        model=setup.model,
    )
    rig.plant.hold_object(OBJ)
    return rig


def grasp_trial(
    setup: GraspSetup, design: SpiralDesign | None = None, on_tick: Callable[[Rig], None] | None = None
) -> GraspOutcome:
    """Run one grasp through the firmware's GRASP mode and measure it (pure; picklable in and out).

    Timeline: lever DOWN, then UP (GRASP mode) at 20 ms, left lever UP (grasp request) at 60 ms. The object
    waits out of reach on its support and is put at its place, still on its support, when the firmware
    starts the grasp (the drone bringing the ready arm next to it); the support is removed when the
    firmware reports HOLD; the trial ends ``hold_s`` later, or when the grasp FAILED.

    ``on_tick(rig)`` is called after every tick (a report films the trial with it); it must only look.
    """
    design = design or SpiralDesign.paper_prototype()
    rig = grasp_rig(setup, design)
    plant = rig.plant
    if setup.contact_oracle:
        rig.firmware.grasp.contact_override = lambda _now_us: bool(contact_units(plant, OBJ))
    target = world_m(setup.x_m, setup.z_m)
    t_start = -1
    t_contact = -1
    t_hold = -1
    units_at_hold = 0
    released_at = np.full(3, math.nan)
    before_end = np.full(3, math.nan)
    max_current = 0
    timeout_us = 12 * S
    end_us = timeout_us
    load_n = math.nan
    placed_overlap = math.nan
    while rig.now_us < end_us:
        rig.step()
        if on_tick is not None:
            on_tick(rig)
        state = rig.firmware.grasp_state
        cur = plant.commanded_currents_raw()
        max_current = max(max_current, max(abs(c) for c in cur))
        now = rig.now_us
        if t_start < 0 and state in (GraspState.REACH, GraspState.WRAP):
            t_start = now
            plant.hold_object(OBJ, target)
        elif t_start >= 0 and math.isnan(placed_overlap):  # the first tick with the object in place
            placed_overlap = max((c.depth_m for c in plant.contacts() if c.other == OBJ), default=0.0)
        if setup.release_at_touch and t_start >= 0 and plant.object_held(OBJ) and contact_units(plant, OBJ):
            plant.release_object(OBJ)
        if t_contact < 0 and state == GraspState.WRAP and setup.strategy_on:
            t_contact = now
        if t_hold < 0 and state == GraspState.HOLD:
            t_hold = now
            units_at_hold = len(contact_units(plant, OBJ))
            if setup.release:
                plant.release_object(OBJ)
            released_at = plant.object_pose(OBJ).pos_m.copy()
            end_us = now + int(setup.hold_s * S)
        if t_hold >= 0 and end_us - now == 10 * MS:
            before_end = plant.object_pose(OBJ).pos_m.copy()
        if state == GraspState.FAILED:
            break
    units_after = len(contact_units(plant, OBJ)) if t_hold >= 0 else 0
    final = plant.object_pose(OBJ).pos_m
    drop_mm = float(released_at[2] - final[2]) * 1000
    shift_mm = float(np.linalg.norm(final - released_at)) * 1000
    speed = float(np.linalg.norm(final - before_end)) / 0.010
    held = t_hold >= 0 and units_after >= 2 and drop_mm < HELD_DROP_MM and speed < HELD_SPEED_M_S
    wrap_deg = contact_wrap_deg(plant, OBJ) if t_hold >= 0 else 0.0
    state_name = GraspState(rig.firmware.grasp_state).name
    if held and setup.release and setup.load_rate_n_per_s > 0:
        load_n = _load_ramp(rig, setup, on_tick)
    out = GraspOutcome(
        setup,
        state_name,
        (t_hold - t_start) / S if t_hold >= 0 else math.nan,
        (t_contact - t_start) / S if t_contact >= 0 else math.nan,
        units_at_hold,
        units_after,
        wrap_deg,
        drop_mm,
        shift_mm,
        held,
        held and wrap_deg >= SUCCESS_WRAP_DEG,
        max_current,
        plant.extremes(),
        load_n,
        placed_overlap,
        float(np.linalg.norm(final - np.asarray(target))) * 1000 if t_start >= 0 else math.nan,
    )
    rig.close()
    return out


def _load_ramp(rig: Rig, setup: GraspSetup, on_tick: Callable[[Rig], None] | None = None) -> float:
    """Grow a force along ``setup.load_dir`` on the held object until it comes out; the force then [N]."""
    plant = rig.plant
    direction = np.asarray(setup.load_dir, dtype=np.float64)
    direction /= np.linalg.norm(direction)
    p0 = plant.object_pose(OBJ).pos_m.copy()
    rate = setup.load_rate_n_per_s / S
    t0 = rig.now_us
    force = 0.0
    while force < setup.load_cap_n:
        force = min(setup.load_cap_n, rate * (rig.now_us - t0))
        plant.apply_object_force(OBJ, tuple(float(v) for v in force * direction))
        rig.step()
        if on_tick is not None:
            on_tick(rig)
        moved_mm = float(np.dot(plant.object_pose(OBJ).pos_m - p0, direction)) * 1000
        if moved_mm > HELD_DROP_MM or not contact_units(plant, OBJ):
            return force
    return setup.load_cap_n


def grasp_trial_job(args: tuple[GraspSetup, SpiralDesign]) -> GraspOutcome:
    """:func:`grasp_trial` of one ``(setup, design)`` pair: the unit of work of a parallel map."""
    return grasp_trial(*args)
