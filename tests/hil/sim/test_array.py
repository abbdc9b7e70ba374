"""hil.sim.array: N arms on a ring under the drone, each with its own cables and drives (the standalone
one-arm model attached N times with MuJoCo's model editing)."""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest

from hil.sim.array import arm_prefix, build_array_spec
from hil.sim.mjcf import build_mjcf
from hil.sim.spiral import SpiralDesign
from hil.sim.types import MAX_ARMS, RingConfig


def _site(m: mujoco.MjModel, d: mujoco.MjData, name: str) -> np.ndarray:
    return d.site_xpos[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, name)].copy()


def drone_xy(m: mujoco.MjModel, d: mujoco.MjData) -> np.ndarray:
    """The drone's position with its height zeroed."""
    p = d.xpos[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, "drone")].copy()
    p[2] = 0.0
    return p


def test_eight_arms_each_with_its_cables_and_drives_hang_on_the_ring() -> None:
    m = build_array_spec(ring=RingConfig(arms=8, ring_radius_m=0.06)).compile()
    assert m.ntendon == 24 and m.nu == 24
    names = {mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_ACTUATOR, i) for i in range(m.nu)}
    assert names == {f"{arm_prefix(i)}motor_{k}" for i in range(8) for k in range(3)}
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    drone = d.xpos[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, "drone")]
    for i in range(8):
        tip = _site(m, d, f"a{i}_tip") - drone
        place = math.pi + 2 * math.pi * i / 8
        assert tip[:2] == pytest.approx([0.06 * math.cos(place), 0.06 * math.sin(place)], abs=1e-6)  # plumb


def test_an_arm_moves_only_by_its_own_cable() -> None:
    m = build_array_spec(ring=RingConfig(arms=4)).compile()
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    before = [_site(m, d, f"a{i}_tip") for i in range(4)]
    d.ctrl[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_ACTUATOR, "a2_motor_0")] = 2.0  # 2 A on arm 2's cable 0
    for _ in range(1000):  # 1 s
        mujoco.mj_step(m, d)
    moved = [float(np.linalg.norm(_site(m, d, f"a{i}_tip") - before[i])) for i in range(4)]
    assert moved[2] > 0.05, moved  # it curls
    assert max(moved[:2] + moved[3:]) < 1e-3, moved  # the others hang still
    # It curls inwards: cable 0 of every arm faces the drone's axis.
    tip = _site(m, d, "a2_tip") - drone_xy(m, d)
    start = before[2] - drone_xy(m, d)
    tip[2] = start[2] = 0.0  # horizontally
    inwards = -start / np.linalg.norm(start)
    assert (tip - start) @ inwards > 0.02, (tip, start)


def test_one_arm_at_the_centre_is_the_lone_arm() -> None:
    """The same arm: the same pose at rest, to the bit, and the same curl under the same current. Not to
    the bit in motion: the wrapper body that carries the attached arm makes MuJoCo treat the spools as
    ordinary rather than "simple" bodies, which sums the same dynamics in another order; 0.3 s of a curl
    leaves 0.06 mm between them."""
    design = SpiralDesign.paper_prototype()
    lone = mujoco.MjModel.from_xml_string(build_mjcf(design, standalone=True))
    one = build_array_spec(design, ring=RingConfig(arms=1, ring_radius_m=0.0)).compile()
    rest, runs = [], []
    for m in (lone, one):
        d = mujoco.MjData(m)
        name = "tip" if m is lone else "a0_tip"
        mujoco.mj_forward(m, d)
        rest.append(_site(m, d, name))
        d.ctrl[0] = 1.5
        for _ in range(300):
            mujoco.mj_step(m, d)
        runs.append(_site(m, d, name))
    assert rest[0] == pytest.approx(rest[1], abs=1e-12)
    assert float(np.linalg.norm(runs[0] - rest[0])) > 0.05  # it curled
    assert runs[0] == pytest.approx(runs[1], abs=2e-4)


def test_a_tilted_ring_leans_outwards() -> None:
    m = build_array_spec(ring=RingConfig(arms=2, ring_radius_m=0.05, tilt_rad=0.3)).compile()
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    for i in range(2):
        tip = _site(m, d, f"a{i}_tip")
        assert math.hypot(tip[0], tip[1]) > 0.05 + 0.2 * math.sin(0.3) * 0.9  # about 22 cm of arm, tilted


@pytest.mark.parametrize(
    ("ring", "says"),
    [
        (RingConfig(arms=0), "arms must be"),
        (RingConfig(arms=MAX_ARMS + 1), "arms must be"),
        (RingConfig(ring_radius_m=math.nan), "ring_radius_m"),
        (RingConfig(tilt_rad=2.0), "tilt_rad"),
    ],
)
def test_bad_rings_are_refused(ring: RingConfig, says: str) -> None:
    with pytest.raises(ValueError, match=says):
        build_array_spec(ring=ring)
