"""An array of arms on a ring under the drone (issue 27, item 3): the model, with each arm's own cables and
drives.

Each arm is the model of one arm (:func:`hil.sim.mjcf.build_mjcf`), attached under the drone with MuJoCo's
model editing (``MjSpec``) at its place on the ring: arm ``i`` at angle ``π + 2πi/N`` from +x,
``ring_radius_m`` from the drone's axis, its cable 0 facing the axis (a one-cable arm curls inwards, around
what hangs under the drone), tilted ``tilt_rad`` outwards. Every name of arm ``i`` carries the prefix
``a{i}_`` (``a3_cable_0``, ``a3_unit_12``, the actuator ``a3_motor_0``), so one arm's parts are found as the
single arm's are.

``standalone=True`` attaches the exported, self-contained arm (its drives as MuJoCo dc motors, its capstan
friction frozen at a reference; docs/plant.md section 6): the array in plain MuJoCo. ``False`` attaches the
plant's arm: :class:`hil.sim.plant.Plant` with ``PlantConfig.ring`` steps it with its Python drives, their
delay and measured friction, and its live capstan friction, arm by arm.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET

import mujoco
import numpy as np

from hil.sim.config import ModelConfig
from hil.sim.mjcf import build_mjcf
from hil.sim.spiral import SpiralDesign
from hil.sim.types import RingConfig

__all__ = ["arm_prefix", "build_array_spec"]


def arm_prefix(i: int) -> str:
    """The prefix of arm ``i``'s names."""
    return f"a{i}_"


def _one_arm_xml(design: SpiralDesign, config: ModelConfig, standalone: bool) -> str:
    """The one-arm model with everything the drone carries for it (spools, units, the mount
    and the cable guides: the cables run through them) in one body ``arm``, so that it can be attached
    whole."""
    root = ET.fromstring(build_mjcf(design, config=config, standalone=standalone))
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
    design: SpiralDesign | None = None,
    config: ModelConfig | None = None,
    ring: RingConfig | None = None,
    *,
    standalone: bool = True,
) -> mujoco.MjSpec:
    """The array's model as an ``MjSpec`` (``.compile()`` it; ``.to_xml()`` writes it).

    Args:
        design: every arm's design (default: the paper's prototype).
        config: the model every arm is built with (default: the prototype's); its objects and floor are the
            scene's, once.
        ring: how many arms, where (default :class:`RingConfig`).
        standalone: attach the exported arm (plain MuJoCo) or the plant's (see the module's text).

    Raises:
        ValueError: a value out of range.
    """
    design = design if design is not None else SpiralDesign.paper_prototype()
    config = config if config is not None else ModelConfig()
    ring = ring if ring is not None else RingConfig()
    ring.validate()
    xml = _one_arm_xml(design, config, standalone)
    spec = mujoco.MjSpec.from_string(xml)
    spec.delete(spec.body("arm"))  # the scene keeps its drone, floor and objects; the arms come next
    drone = spec.body("drone")
    for i in range(ring.arms):
        yaw = 2.0 * math.pi * i / ring.arms  # cable 0 (the arm's +x) turned to face the axis ...
        place = yaw + math.pi  # ... from the opposite side of the ring
        # Yaw the arm, then tilt it outwards (towards its own -x) about the tangent.
        q_yaw = np.array([math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2)])
        q_tilt = np.array([math.cos(ring.tilt_rad / 2), 0.0, math.sin(ring.tilt_rad / 2), 0.0])
        quat = np.zeros(4)
        mujoco.mju_mulQuat(quat, q_yaw, q_tilt)
        pos = [ring.ring_radius_m * math.cos(place), ring.ring_radius_m * math.sin(place), 0.0]
        frame = drone.add_frame(pos=pos, quat=quat.tolist())
        one = mujoco.MjSpec.from_string(xml)  # attaching moves the body out of its spec: one each
        frame.attach_body(one.body("arm"), arm_prefix(i), "")
    return spec
