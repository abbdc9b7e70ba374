"""An array of arms on a ring under the drone (issue 27, item 3): the model, with each arm's own cables and
drives.

Each arm is the exported, self-contained model of one arm (:func:`hil.sim.mjcf.build_mjcf` with
``standalone=True``: its spools, units, cables and its drives as MuJoCo dc motors, its capstan friction
frozen at a reference; docs/plant.md section 6), attached under the drone with MuJoCo's model editing
(``MjSpec``) at its place on the ring: arm ``i`` at angle ``2πi/N`` from +x, ``ring_radius_m`` from the
drone's axis, its cable 0 facing outwards, tilted ``tilt_rad`` outwards. Every name of arm ``i`` carries the
prefix ``a{i}_`` (``a3_cable_0``, ``a3_unit_12``, the actuator ``a3_motor_0``), so one arm's parts are
found as the single arm's are.

What this is not yet: a :class:`hil.sim.plant.Plant` (the plant's Python drives with their delay and
measured friction, its live capstan friction, its feedback frames and objects) for N arms. A board for the
array needs it; the model here is what it will step.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass

import mujoco
import numpy as np

from hil.sim.config import ModelConfig
from hil.sim.mjcf import build_mjcf
from hil.sim.spiral import SpiralDesign

__all__ = ["MAX_ARMS", "RingConfig", "arm_prefix", "build_array_spec"]

MAX_ARMS = 8
"""Arms an array may have (the C-board drives up to eight C610s; the supplement's arrays have 2-8 arms)."""


@dataclass(frozen=True)
class RingConfig:
    """Where the arms hang.

    Attributes:
        arms: how many (1..:data:`MAX_ARMS`).
        ring_radius_m: their bases' distance from the drone's axis.
        tilt_rad: each arm's tilt outwards from straight down (0 = hanging plumb).
    """

    arms: int = 4
    ring_radius_m: float = 0.06
    tilt_rad: float = 0.0

    def validate(self) -> None:
        """Raise ``ValueError`` for a value out of range."""
        if not 1 <= self.arms <= MAX_ARMS:
            raise ValueError(f"arms must be 1..{MAX_ARMS}, got {self.arms}")
        if not (math.isfinite(self.ring_radius_m) and 0.0 <= self.ring_radius_m <= 1.0):
            raise ValueError(f"ring_radius_m must be 0..1 m, got {self.ring_radius_m!r}")
        if not (math.isfinite(self.tilt_rad) and abs(self.tilt_rad) <= math.pi / 2):
            raise ValueError(f"tilt_rad must be within ±90°, got {self.tilt_rad!r}")


def arm_prefix(i: int) -> str:
    """The prefix of arm ``i``'s names."""
    return f"a{i}_"


def _one_arm_xml(design: SpiralDesign, config: ModelConfig) -> str:
    """The standalone one-arm model with everything the drone carries for it (spools, units, the mount
    and the cable guides: the cables run through them) in one body ``arm``, so that it can be attached
    whole."""
    root = ET.fromstring(build_mjcf(design, config=config, standalone=True))
    drone = root.find("./worldbody/body[@name='drone']")
    if drone is None:  # pragma: no cover - build_mjcf always makes it
        raise ValueError("the one-arm model has no drone body")
    arm = ET.Element("body", {"name": "arm"})
    for child in [c for c in drone if c.tag in ("body", "site")]:  # the mount, the cable guides too
        drone.remove(child)
        arm.append(child)
    drone.append(arm)
    return ET.tostring(root, encoding="unicode")


def build_array_spec(
    design: SpiralDesign | None = None, config: ModelConfig | None = None, ring: RingConfig | None = None
) -> mujoco.MjSpec:
    """The array's model as an ``MjSpec`` (``.compile()`` it; ``.to_xml()`` writes it).

    Args:
        design: every arm's design (default: the paper's prototype).
        config: the model every arm is built with (default: the prototype's); its objects and floor are the
            scene's, once.
        ring: how many arms, where (default :class:`RingConfig`).

    Raises:
        ValueError: a value out of range.
    """
    design = design if design is not None else SpiralDesign.paper_prototype()
    config = config if config is not None else ModelConfig()
    ring = ring if ring is not None else RingConfig()
    ring.validate()
    xml = _one_arm_xml(design, config)
    spec = mujoco.MjSpec.from_string(xml)
    spec.delete(spec.body("arm"))  # the scene keeps its drone, floor and objects; the arms come next
    drone = spec.body("drone")
    for i in range(ring.arms):
        yaw = 2.0 * math.pi * i / ring.arms
        # Yaw the arm so that its cable 0 (+x) faces outwards, then tilt it outwards about the tangent.
        q_yaw = np.array([math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2)])
        q_tilt = np.array([math.cos(-ring.tilt_rad / 2), 0.0, math.sin(-ring.tilt_rad / 2), 0.0])
        quat = np.zeros(4)
        mujoco.mju_mulQuat(quat, q_yaw, q_tilt)
        pos = [ring.ring_radius_m * math.cos(yaw), ring.ring_radius_m * math.sin(yaw), 0.0]
        frame = drone.add_frame(pos=pos, quat=quat.tolist())
        one = mujoco.MjSpec.from_string(xml)  # attaching moves the body out of its spec: one each
        frame.attach_body(one.body("arm"), arm_prefix(i), "")
    return spec
