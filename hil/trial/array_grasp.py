"""One grasp by an array of arms (issue 27, item 5): N one-cable arms on a ring under the drone close on an
object under its axis through the firmware's GRASP state machine, which drives the array as one gripper.

The set-up, fixed before the experiment ran:

- the arms: the paper's prototype (23 cm, 21 units) with one cable each, its cable facing the ring's axis
  (:class:`hil.sim.types.RingConfig`), ``ring_radius_m`` from the axis, hanging plumb;
- the firmware: :func:`hil.trial.grasp.grasp_firmware` laid out as N arms of one cable, the plain tension
  ramp (an array closes by curling every arm from its tip; there is no single side to reach towards);
- the object: one of :data:`hil.trial.objects.ARRAY_OBJECTS`, waiting out of reach until the firmware
  starts the grasp, then on its support at its place: on the ring's axis, ``depth_m`` below the arms'
  bases, shifted by the trial's jitter;
- the support goes when the firmware reports HOLD; the trial ends ``hold_s`` (2 s) later, at FAILED, or
  at a 12 s time-out.

Success (the issue's "still held 2 s after the support goes", made measurable): HOLD reached, and
``hold_s`` after the support was removed the object still touches at least one arm, has dropped less than
:data:`~hil.trial.scene.HELD_DROP_MM` below where it was let go, and moves slower than
:data:`~hil.trial.scene.HELD_SPEED_M_S`. A single arm's wrap test (contacts around half the object) is not
asked: several arms hold an object between them without any one wrapping it.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from controller.config import FirmwareConfig
from hil.sim.config import ModelConfig
from hil.sim.objects import contact_units
from hil.sim.spiral import SpiralDesign
from hil.sim.types import PhysicsExtremes, RingConfig
from hil.trial.grasp import grasp_firmware
from hil.trial.objects import ARRAY_OBJECTS, ArrayObject
from hil.trial.rig import Rig, rc_frame
from hil.trial.scene import BASE_Z_M, FAR_M, HELD_DROP_MM, HELD_SPEED_M_S, MS, OBJ, S
from protocol.dbus import Lever
from protocol.messages import GraspState

__all__ = ["ArrayGraspOutcome", "ArrayGraspSetup", "array_design", "array_grasp_trial", "array_object"]

TIMEOUT_S = 12.0
"""A trial that neither holds nor fails by then ends (as not held)."""


def array_design() -> SpiralDesign:
    """Every arm of the arrays: the paper's prototype with one cable."""
    return SpiralDesign.paper_prototype().with_cables(1)


def array_object(key: str) -> ArrayObject:
    """The object of :data:`~hil.trial.objects.ARRAY_OBJECTS` named ``key``.

    Raises:
        KeyError: no such object (the message lists them).
    """
    for o in ARRAY_OBJECTS:
        if o.key == key:
            return o
    raise KeyError(f"no array object {key!r}; objects: {', '.join(o.key for o in ARRAY_OBJECTS)}")


@dataclass(frozen=True)
class ArrayGraspSetup:
    """One array grasp.

    Attributes:
        arms: arms on the ring (1..8).
        object_key: which of the ten objects.
        depth_m: the object's centre below the arms' bases, on the ring's axis.
        offset_m: the trial's jitter of that place (x, y, z) [m].
        ring_radius_m: the arms' bases from the drone's axis.
        tilt_rad: every arm's tilt outwards from plumb.
        hold_s: how long the released object must stay.
        firmware: firmware before the array layout (None = :func:`~hil.trial.grasp.grasp_firmware`).
        model: the plant's model; the object is appended to it.
        seed: the board's seed.
        design: every arm (None = :func:`array_design`); its cable count is set to one.
    """

    arms: int
    object_key: str
    depth_m: float = 0.13
    offset_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    ring_radius_m: float = 0.06
    tilt_rad: float = 0.0
    hold_s: float = 2.0
    firmware: FirmwareConfig | None = None
    model: ModelConfig = field(default_factory=ModelConfig)
    seed: int = 0
    design: SpiralDesign | None = None

    def arm_design(self) -> SpiralDesign:
        """Every arm's design (one cable)."""
        return array_design() if self.design is None else self.design.with_cables(1)

    def target_m(self) -> tuple[float, float, float]:
        """Where the object is put (world frame; the drone's axis is x = y = 0)."""
        dx, dy, dz = self.offset_m
        return (dx, dy, BASE_Z_M - self.depth_m + dz)


@dataclass(frozen=True)
class ArrayGraspOutcome:
    """What one array grasp measured.

    Attributes:
        setup: the trial.
        state: the grasp state at the end.
        t_hold_s: from the start of the grasp (WRAP) to HOLD; NaN if never.
        arms_touching: arms touching the object ``hold_s`` after the support went (0 if no HOLD).
        units_after: arm units touching it then.
        drop_mm: how far below its release height it is at the end (negative: above).
        speed_m_s: its speed over the last 10 ms.
        held: the success criterion of the module's text.
        max_current_raw: the largest |current| sent to an ESC.
        extremes: the worst physics of the trial.
    """

    setup: ArrayGraspSetup
    state: str
    t_hold_s: float
    arms_touching: int
    units_after: int
    drop_mm: float
    speed_m_s: float
    held: bool
    max_current_raw: int
    extremes: PhysicsExtremes

    @property
    def success(self) -> bool:
        """The trial's verdict (``held``)."""
        return self.held

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready form (the setup without its firmware and model configurations)."""
        d = dataclasses.asdict(self)
        d["setup"] = {k: v for k, v in d["setup"].items() if k not in ("firmware", "model", "design")}
        d["success"] = self.success
        return d


def array_rig(setup: ArrayGraspSetup) -> Rig:
    """The rig of one array grasp: GRASP mode (lever UP at 20 ms), the grasp request at 60 ms, the object
    waiting out of reach on its support."""
    fw = setup.firmware or grasp_firmware()
    fw = fw.replaced(grasp_strategy_on=False, grasp_direction_deg=0.0).with_arms(setup.arms, 1)
    obj = array_object(setup.object_key).placed(FAR_M)
    rig = Rig(
        setup.arm_design(),
        fw,
        [(0, rc_frame()), (20 * MS, rc_frame(Lever.UP)), (60 * MS, rc_frame(Lever.UP, Lever.UP))],
        objects=(obj,),
        seed=setup.seed,
        model=setup.model,
        ring=RingConfig(arms=setup.arms, ring_radius_m=setup.ring_radius_m, tilt_rad=setup.tilt_rad),
    )
    rig.plant.hold_object(OBJ)
    return rig


def array_grasp_trial(setup: ArrayGraspSetup) -> ArrayGraspOutcome:
    """Run one array grasp and measure it (pure; picklable in and out)."""
    rig = array_rig(setup)
    plant = rig.plant
    units = plant.units_per_arm
    t_start = t_hold = -1
    released_at = np.full(3, math.nan)
    before_end = np.full(3, math.nan)
    max_current = 0
    end_us = int(TIMEOUT_S * S)
    while rig.now_us < end_us:
        rig.step()
        state = rig.firmware.grasp_state
        max_current = max(max_current, max(abs(c) for c in plant.commanded_currents_raw()))
        now = rig.now_us
        if t_start < 0 and state in (GraspState.REACH, GraspState.WRAP):
            t_start = now
            plant.hold_object(OBJ, setup.target_m())
        if t_hold < 0 and state == GraspState.HOLD:
            t_hold = now
            plant.release_object(OBJ)
            released_at = plant.object_pose(OBJ).pos_m.copy()
            end_us = now + int(setup.hold_s * S)
        if t_hold >= 0 and end_us - now == 10 * MS:
            before_end = plant.object_pose(OBJ).pos_m.copy()
        if state == GraspState.FAILED:
            break
    touching = contact_units(plant, OBJ) if t_hold >= 0 else set()
    names = plant.body_poses().names[1:]
    arm_of = {name: i // units for i, name in enumerate(names)}
    final = plant.object_pose(OBJ).pos_m
    drop_mm = float(released_at[2] - final[2]) * 1000
    speed = float(np.linalg.norm(final - before_end)) / 0.010
    held = t_hold >= 0 and bool(touching) and drop_mm < HELD_DROP_MM and speed < HELD_SPEED_M_S
    out = ArrayGraspOutcome(
        setup,
        GraspState(rig.firmware.grasp_state).name,
        (t_hold - t_start) / S if t_hold >= 0 and t_start >= 0 else math.nan,
        len({arm_of[u] for u in touching}),
        len(touching),
        drop_mm,
        speed,
        held,
        max_current,
        plant.extremes(),
    )
    rig.close()
    return out
