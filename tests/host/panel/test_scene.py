"""host.panel.scene: the arm's drawing, quaternion helpers, camera presets, MAVLink pose to scene."""

from __future__ import annotations

import math

import numpy as np
import pytest

from hil.sim.spiral import SpiralDesign
from host.panel.scene import (
    ArmGeometry,
    DronePose,
    _cable_colors,
    _unit_colors,
    arm_drawing,
    array_drawing,
    default_hanging_pose,
    quat_mul,
    quat_rotate,
)


def test_arm_drawing_of_a_hanging_arm() -> None:
    geom = ArmGeometry.default()
    pos, quat = default_hanging_pose(geom, DronePose((0.0, 0.0, 1.0)))
    d = arm_drawing(pos, quat, geom)
    n = geom.units
    assert d.unit_positions.shape == (n, 3) and d.unit_scales.shape == (n, 3)
    assert d.cable_segments.shape == (3 * (n + 1), 2, 3)
    # Hanging straight down: every unit below the previous one, the tip lowest, cables 120° apart.
    assert np.all(np.diff(d.unit_positions[:, 2]) < 0)
    assert d.tip_m[2] == pytest.approx(1.0 - 0.03 - sum(geom.unit_lengths_m), abs=1e-9)
    a, b = d.cable_segments[1, 0, :2], d.cable_segments[n + 2, 0, :2]
    angle = math.degrees(math.atan2(a[0] * b[1] - a[1] * b[0], a @ b))
    assert abs(angle) == pytest.approx(120.0, abs=1e-6)
    # Units point along the hang: each instance's +z maps to -z in the world.
    z = quat_rotate(d.unit_wxyzs, np.tile([0.0, 0.0, 1.0], (n, 1)))
    assert np.allclose(z, [0.0, 0.0, -1.0])


def test_arm_drawing_resamples_other_unit_counts() -> None:
    geom = ArmGeometry.default()
    pos, quat = default_hanging_pose(geom.resized(10))
    assert arm_drawing(pos, quat, geom).unit_positions.shape == (10, 3)
    with pytest.raises(ValueError):
        arm_drawing(pos[:1], quat[:1], geom)


def _ring(arms: int, geom: ArmGeometry, radius_m: float = 0.08) -> tuple[np.ndarray, np.ndarray]:
    """Body poses of ``arms`` arms hanging straight down on a ring under a drone at 1 m: the drone, then
    each arm's units, arm after arm (as a ring plant gives them)."""
    pos, quat = default_hanging_pose(geom, DronePose((0.0, 0.0, 1.0)))
    positions, quats = [pos[:1]], [quat[:1]]
    for k in range(arms):
        a = 2 * math.pi * k / arms
        positions.append(pos[1:] + np.array([radius_m * math.cos(a), radius_m * math.sin(a), 0.0]))
        quats.append(quat[1:])
    return np.concatenate(positions), np.concatenate(quats)


@pytest.mark.parametrize("arms", [2, 4, 8])
def test_an_arrays_drawing_has_every_arm_at_its_place_on_the_ring(arms: int) -> None:
    cables = {2: 3, 4: 2, 8: 1}[arms]
    geom = ArmGeometry.from_design(SpiralDesign.paper_prototype().with_cables(cables))
    assert len(geom.cable_angles_deg) == cables
    n = geom.units
    positions, quats = _ring(arms, geom)
    d = array_drawing(positions, quats, geom, arms)
    assert d.unit_positions.shape == (arms * n, 3)
    assert d.cable_segments.shape == (arms * cables * (n + 1), 2, 3)
    for k in range(arms):
        a = 2 * math.pi * k / arms
        centre = np.array([0.08 * math.cos(a), 0.08 * math.sin(a)])
        units = d.unit_positions[k * n : (k + 1) * n, :2]
        assert np.allclose(units, centre, atol=1e-9)  # each arm hangs straight down at its place
        segs = d.cable_segments[k * cables * (n + 1) : (k + 1) * cables * (n + 1)]
        anchors = segs[:: n + 1, 0]  # each cable's first point: on the drone's underside, above its arm
        assert np.all(np.linalg.norm(anchors[:, :2] - centre, axis=1) < 0.03)
        assert np.all(anchors[:, 2] >= positions[1 + k * n, 2] - 1e-9)  # not below its base
    assert np.allclose(d.tip_m, arm_drawing(positions[: 1 + n], quats[: 1 + n], geom).tip_m)  # arm 0's
    assert _unit_colors(n, arms).shape == (arms * n, 3)
    assert _cable_colors(d, geom, arms).shape == (len(d.cable_segments), 2, 3)


def test_one_arm_draws_as_before_and_a_bad_split_is_refused() -> None:
    geom = ArmGeometry.default()
    pos, quat = default_hanging_pose(geom)
    one, before = array_drawing(pos, quat, geom), arm_drawing(pos, quat, geom)
    assert np.array_equal(one.cable_segments, before.cable_segments)
    assert np.array_equal(one.unit_positions, before.unit_positions)
    with pytest.raises(ValueError):
        array_drawing(pos, quat, geom, 4)  # 21 units are not 4 arms
    with pytest.raises(ValueError):
        array_drawing(pos, quat, geom, 0)


def test_quaternion_helpers() -> None:
    q = np.array([math.cos(math.pi / 4), 0.0, 0.0, math.sin(math.pi / 4)])  # 90° about z
    assert np.allclose(quat_rotate(q, np.array([1.0, 0.0, 0.0])), [0.0, 1.0, 0.0])
    assert np.allclose(quat_mul(q, q), [0.0, 0.0, 0.0, 1.0])


def test_camera_presets_follow_the_stick_axes() -> None:
    from host.panel.camera import CAMERA_PRESETS, camera_view
    from host.panel.scene import NOSE_AXIS

    assert NOSE_AXIS == (0.0, 1.0, 0.0)  # stick forward (+y) is the nose; stick right (+x) the pilot's right
    drone = DronePose((0.0, 0.0, 1.0))
    centre, tip = (0.0, 0.0, 0.9), (0.0, 0.0, 0.76)
    views = {p: camera_view(p, centre, drone, tip) for p in CAMERA_PRESETS}
    # Stick view and behind: from -y looking +y, so stick right (+x) is screen right and forward is away.
    for preset in ("sticks", "behind"):
        pos, look = views[preset]
        assert pos[1] < look[1] - 1.0 and abs(pos[0] - look[0]) < 1e-9, preset
    assert views["behind"][0][2] > views["sticks"][0][2]  # behind the drone: from above it
    pos, look = views["side"]  # from the drone's left (-x)
    assert pos[0] < look[0] - 1.0
    pos, look = views["top"]  # above, tilted back: forward is screen up
    assert pos[2] > look[2] + 1.0 and pos[1] < look[1]
    assert views["tip"][1] == tip
    # Every preset follows the yaw: the nose turned to -x (yaw 90°) puts the stick view's camera at +x.
    yawed = DronePose((0.0, 0.0, 1.0), (math.cos(math.pi / 4), 0.0, 0.0, math.sin(math.pi / 4)))
    pos, look = camera_view("sticks", centre, yawed, tip)
    assert pos[0] > look[0] + 1.0 and abs(pos[1]) < 1e-6
    for preset in CAMERA_PRESETS:
        p, a = camera_view(preset, centre, drone, tip)
        assert math.dist(p, a) > 0.3, preset  # never at the point it looks at
    with pytest.raises(ValueError, match="camera preset"):
        camera_view("nowhere", centre, drone, tip)


def test_a_mavlink_drone_pose_keeps_stick_forward_at_its_nose() -> None:
    """A forward-left-up drone pose (MAVLink): the arm's +y (stick forward) turned onto the drone's nose."""
    from host.panel.scene import NOSE_AXIS, arm_frame

    for yaw in (0.0, 0.7, math.pi / 2, -2.0):
        flu = DronePose((1.0, 2.0, 3.0), (math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2)))
        arm = arm_frame(flu)
        nose = quat_rotate(np.array(flu.wxyz), np.array([1.0, 0.0, 0.0]))
        assert np.allclose(quat_rotate(np.array(arm.wxyz), np.array(NOSE_AXIS)), nose)
        assert arm.position_m == flu.position_m


def test_ned_to_scene_turns_the_drones_pose_z_up() -> None:
    from types import SimpleNamespace

    from host.panel.scene import DRONE_HEIGHT_M, ned_to_scene

    assert ned_to_scene(None, None) == DronePose((0.0, 0.0, DRONE_HEIGHT_M))
    pos = SimpleNamespace(x_m=1.0, y_m=2.0, z_m=-3.0)  # north 1, east 2, 3 m up
    level = SimpleNamespace(roll_rad=0.0, pitch_rad=0.0, yaw_rad=0.0)
    pose = ned_to_scene(pos, level)
    assert pose.position_m == (2.0, 1.0, 3.0)  # ENU: east, north, up
    # Nose north (NED yaw 0) is the scene's +y; yawed 90° (east) it points along +x.
    east = ned_to_scene(pos, SimpleNamespace(roll_rad=0.0, pitch_rad=0.0, yaw_rad=math.pi / 2))
    assert np.allclose(quat_rotate(np.array(pose.wxyz), np.array([1.0, 0.0, 0.0])), [0.0, 1.0, 0.0])
    assert np.allclose(quat_rotate(np.array(east.wxyz), np.array([1.0, 0.0, 0.0])), [1.0, 0.0, 0.0])
