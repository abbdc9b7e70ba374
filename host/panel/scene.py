"""The 3D scene of the teleop panel: a quadrotor with the SpiRob arm hanging under it.

Geometry is computed with numpy from body poses (``SimPoses``: body 0 the drone, then the units base to
tip) and pushed to viser as few nodes as possible, because viser's cost is per node and per message:

- all units are ONE batched mesh (a unit cylinder scaled per instance to the unit's width and length);
- the three cables are ONE line-segment node (attachment points 120° apart on every unit);
- the tip path is ONE line-segment node whose colours fade with age;
- the drone is one mesh posed by its frame.

Each update happens inside ``server.atomic()`` followed by ``server.flush()`` so a browser applies the
whole arm at once; viser keeps only the newest state per node, so a slow browser never builds a backlog.

The unit meshes are oriented without assuming how the MJCF places a unit in its body frame: a unit's
axis is the direction to the next body, expressed in the unit's own frame (the tip reuses its
neighbour's), so the drawing follows the plant whatever its convention.

**Directions** (the arm's frame = the plant's drone body, body 0): the right stick bends the arm toward
``atan2(ch1, ch0)`` from cable 1 (``controller.cables``), cable 1 at +x, so stick right = +x and stick
forward = +y. The drone is drawn with its nose along **+y** (:data:`NOSE_AXIS`): stick forward bends the
arm toward the nose and stick right toward the right of a pilot behind the drone, as on a DT7 flying the
drone itself. On the real drone that is how the arm is mounted: cable 1 on the drone's right, cables 2
and 3 at 120° steps counter-clockwise seen from above. A MAVLink pose (forward-left-up body) is turned
into the arm's frame by :func:`arm_frame`.
"""

from __future__ import annotations

import collections
import math
import threading
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import mujoco
import numpy as np
import numpy.typing as npt
import trimesh
import viser
import viser.transforms as vtf

__all__ = [
    "NOSE_AXIS",
    "ArmGeometry",
    "DronePose",
    "SceneHandles",
    "SceneObject",
    "arm_drawing",
    "arm_frame",
    "array_drawing",
    "build_scene",
    "default_hanging_pose",
    "ned_to_scene",
    "quat_mul",
    "quat_rotate",
    "scene_objects",
]

FloatArray = npt.NDArray[np.float64]

DRONE_HEIGHT_M = 1.2
"""Where the drone hovers when no pose source says otherwise."""
NOSE_AXIS = (0.0, 1.0, 0.0)
"""The drone's nose in the arm's frame: +y, where the right stick's forward bends the arm (the pilot's
right, stick right, is +x)."""
_FLU_TO_ARM = (math.sqrt(0.5), 0.0, 0.0, -math.sqrt(0.5))
"""The arm's frame in a forward-left-up drone body: yawed -90°, so the arm's +y is the body's +x (nose)."""
_TRAIL_LEN = 150
_CABLE_RADIUS = 0.55
"""Cable attachment radius as a fraction of the unit width (the unit mesh's surface is at 0.5)."""
_UNIT_COLOR_BASE = np.array([40, 110, 200], dtype=np.float64)
_UNIT_COLOR_TIP = np.array([120, 210, 255], dtype=np.float64)
_CABLE_COLORS = ((220, 60, 60), (60, 170, 60), (230, 160, 30))
_TRAIL_NEW = np.array([255, 110, 0], dtype=np.float64)
_TRAIL_OLD = np.array([245, 245, 245], dtype=np.float64)


@dataclass(frozen=True, slots=True)
class DronePose:
    """A drone pose in the scene's world frame (z up).

    Attributes:
        position_m: x, y, z.
        wxyz: orientation quaternion (w, x, y, z).
    """

    position_m: tuple[float, float, float]
    wxyz: tuple[float, float, float, float] = (1.0, 0.0, 0.0, 0.0)


@dataclass(frozen=True, slots=True)
class SceneObject:
    """A static object drawn in the scene (e.g. the cylinder to grasp).

    Attributes:
        name: unique name.
        kind: ``cylinder``, ``capsule``, ``box`` or ``sphere``.
        position_m: centre.
        size_m: cylinder (radius, radius, height); capsule (radius, radius, length between the centres
            of its end caps); box (x, y, z); sphere (radius, radius, radius). Cylinders and capsules lie
            along their local z.
        wxyz: orientation.
        color: RGB 0..255.
    """

    name: str
    kind: str
    position_m: tuple[float, float, float]
    size_m: tuple[float, float, float]
    wxyz: tuple[float, float, float, float] = (1.0, 0.0, 0.0, 0.0)
    color: tuple[int, int, int] = (160, 120, 80)


@dataclass(frozen=True, slots=True)
class ArmGeometry:
    """Per-unit sizes used to draw the arm, base first.

    Attributes:
        unit_widths_m: mean width of each unit.
        unit_lengths_m: joint-to-joint length of each unit.
        cable_angles_deg: angular position of the three cables around the arm.
    """

    unit_widths_m: tuple[float, ...]
    unit_lengths_m: tuple[float, ...]
    cable_angles_deg: tuple[float, ...] = (0.0, 120.0, 240.0)

    def __post_init__(self) -> None:
        if len(self.unit_widths_m) != len(self.unit_lengths_m) or not self.unit_widths_m:
            raise ValueError("unit_widths_m and unit_lengths_m must be non-empty and equally long")

    @property
    def units(self) -> int:
        """Number of units."""
        return len(self.unit_widths_m)

    @classmethod
    def from_design(cls, design: Any) -> ArmGeometry:
        """The units of a ``hil.sim.spiral.SpiralDesign`` (mean width, chord), base first."""
        widths = tuple((a + b) / 2.0 for a, b in design.unit_widths_m())
        cables = int(getattr(design, "cables", 3))
        return cls(widths, tuple(design.unit_chords_m()), tuple(360.0 * k / cables for k in range(cables)))

    @classmethod
    def default(cls) -> ArmGeometry:
        """The paper's 3-cable prototype (``hil.sim.spiral``), or a 21-unit geometric stand-in."""
        try:
            from hil.sim.spiral import SpiralDesign

            return cls.from_design(SpiralDesign.paper_prototype())
        except Exception:  # hil not installed / changed: draw a plausible arm anyway
            beta = 1.075
            n = 21
            widths = tuple(0.032 * beta ** (-i) for i in range(n))
            return cls(widths, tuple(w * 0.75 for w in widths))

    def resized(self, units: int) -> ArmGeometry:
        """The same taper resampled to ``units`` units (when the plant reports another count)."""
        if units == self.units:
            return self
        if units <= 0:
            raise ValueError("units must be > 0")
        src = np.linspace(0.0, 1.0, self.units)
        dst = np.linspace(0.0, 1.0, units)
        total = sum(self.unit_lengths_m)
        lengths = np.interp(dst, src, np.asarray(self.unit_lengths_m))
        lengths *= total / float(lengths.sum())
        widths = np.interp(dst, src, np.asarray(self.unit_widths_m))
        return ArmGeometry(
            tuple(float(w) for w in widths), tuple(float(x) for x in lengths), self.cable_angles_deg
        )


# ---------------------------------------------------------------------- quaternions (w, x, y, z)
# viser.transforms does the quaternion algebra on batches; MuJoCo's mju_quatZ2Vec the z-to-axis alignment.


def ned_to_scene(position: Any, attitude: Any) -> DronePose:
    """MAVLink ``LOCAL_POSITION_NED`` / ``ATTITUDE`` (NED world, FRD body) -> the scene's z-up pose (ENU
    world, FLU body); either may be None (no position: hovering at ``DRONE_HEIGHT_M``)."""
    if position is not None:
        pos = (float(position.y_m), float(position.x_m), -float(position.z_m))
    else:
        pos = (0.0, 0.0, DRONE_HEIGHT_M)
    if attitude is None:
        return DronePose(pos)
    # Aerospace Z-Y-X (yaw, pitch, roll): body FRD -> world NED.
    r_ned_frd = vtf.SO3.from_rpy_radians(attitude.roll_rad, attitude.pitch_rad, attitude.yaw_rad).as_matrix()
    t_enu_ned = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
    t_frd_flu = np.diag([1.0, -1.0, -1.0])
    wxyz = vtf.SO3.from_matrix(t_enu_ned @ r_ned_frd @ t_frd_flu).wxyz
    return DronePose(pos, (float(wxyz[0]), float(wxyz[1]), float(wxyz[2]), float(wxyz[3])))


def arm_frame(drone: DronePose) -> DronePose:
    """The pose of the arm's frame (the scene's body 0) for a drone pose in forward-left-up axes
    (:func:`ned_to_scene`): same position, yawed so that :data:`NOSE_AXIS` points along the drone's nose."""
    q = quat_mul(np.asarray(drone.wxyz, dtype=np.float64), np.asarray(_FLU_TO_ARM, dtype=np.float64))
    return DronePose(drone.position_m, _wxyz(q))


def quat_mul(a: FloatArray, b: FloatArray) -> FloatArray:
    """Hamilton product of (..., 4) quaternion arrays (``viser.transforms.SO3`` composition)."""
    return np.asarray((vtf.SO3(wxyz=a) @ vtf.SO3(wxyz=b)).wxyz, dtype=np.float64)


def quat_rotate(q: FloatArray, v: FloatArray) -> FloatArray:
    """Rotate (..., 3) vectors by (..., 4) unit quaternions (``viser.transforms.SO3.apply``)."""
    return np.asarray(vtf.SO3(wxyz=q).apply(v), dtype=np.float64)


def _normalize(v: FloatArray, fallback: Sequence[float]) -> FloatArray:
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    fb = np.broadcast_to(np.asarray(fallback, dtype=np.float64), v.shape)
    out: FloatArray = np.where(n > 1e-12, v / np.maximum(n, 1e-12), fb)
    return out


def _align_z_to(axis: FloatArray) -> FloatArray:
    """Quaternions rotating +z onto each vector of ``axis`` (N, 3): MuJoCo's ``mju_quatZ2Vec`` (identity
    for a zero vector, 180° about x for -z)."""
    out = np.empty((len(axis), 4))
    for i, vec in enumerate(np.ascontiguousarray(axis, dtype=np.float64)):
        mujoco.mju_quatZ2Vec(out[i], vec)
    return out


# ---------------------------------------------------------------------- geometry


def default_hanging_pose(geom: ArmGeometry, drone: DronePose | None = None) -> tuple[FloatArray, FloatArray]:
    """Body poses of an arm hanging straight down under the drone (when no pose source exists).

    Returns:
        positions (units + 1, 3) and quaternions (units + 1, 4), drone first.
    """
    d = drone or DronePose((0.0, 0.0, DRONE_HEIGHT_M))
    top = np.asarray(d.position_m, dtype=np.float64) - np.array([0.0, 0.0, 0.03])
    offsets = np.concatenate(([0.0], np.cumsum(geom.unit_lengths_m)[:-1]))
    units = top[None, :] - np.outer(offsets, [0.0, 0.0, 1.0])
    pos = np.vstack((np.asarray(d.position_m, dtype=np.float64)[None, :], units))
    quat = np.tile(np.array([1.0, 0.0, 0.0, 0.0]), (geom.units + 1, 1))
    quat[0] = d.wxyz
    return pos, quat


@dataclass(frozen=True, slots=True)
class ArmDrawing:
    """Everything needed to draw the arm for one pose.

    Attributes:
        unit_positions: (n, 3) centres of the unit meshes.
        unit_wxyzs: (n, 4) orientations of the unit meshes (their +z along the unit).
        unit_scales: (n, 3) per-instance scales (width, width, length).
        cable_segments: (c * (n + 1), 2, 3) segments of the c cables, cable after cable.
        tip_m: (3,) the tip end point.
    """

    unit_positions: FloatArray
    unit_wxyzs: FloatArray
    unit_scales: FloatArray
    cable_segments: FloatArray
    tip_m: FloatArray


def arm_drawing(positions: FloatArray, quats: FloatArray, geom: ArmGeometry) -> ArmDrawing:
    """Unit instances and cable segments for body poses (drone first, then units base to tip).

    Args:
        positions: (1 + n, 3) body positions.
        quats: (1 + n, 4) body orientations (w, x, y, z).
        geom: unit sizes; resampled if ``n`` differs.

    Raises:
        ValueError: fewer than two bodies or mismatched shapes.
    """
    positions = np.asarray(positions, dtype=np.float64)
    quats = _normalize(np.asarray(quats, dtype=np.float64), (1.0, 0.0, 0.0, 0.0))
    if positions.ndim != 2 or positions.shape[1] != 3 or quats.shape != (len(positions), 4):
        raise ValueError("positions must be (N, 3) and quats (N, 4)")
    if len(positions) < 2:
        raise ValueError("need the drone and at least one unit")
    p = positions[1:]
    q = quats[1:]
    n = len(p)
    geom = geom.resized(n)
    widths = np.asarray(geom.unit_widths_m)
    lengths = np.asarray(geom.unit_lengths_m, dtype=np.float64).copy()

    # Unit axis in each unit's own frame: towards the next body; the tip copies its neighbour.
    axis_local = np.tile(np.array([0.0, 0.0, -1.0]), (n, 1))
    if n > 1:
        delta = p[1:] - p[:-1]
        dist = np.linalg.norm(delta, axis=1)
        local = np.asarray(vtf.SO3(wxyz=q[:-1]).inverse().apply(delta), dtype=np.float64)
        axis_local[:-1] = _normalize(local, (0.0, 0.0, -1.0))
        axis_local[-1] = axis_local[-2]
        good = dist > 1e-6
        lengths[:-1] = np.where(good, dist, lengths[:-1])
    align = _align_z_to(axis_local)
    inst_q = quat_mul(q, align)
    axis_world = quat_rotate(q, axis_local)
    centres = p + axis_world * (lengths[:, None] / 2.0)
    scales = np.stack((widths, widths, lengths), axis=1)

    # Cable attachment points: on each unit's base side, just outside its surface (55 % of its width off
    # the axis, so the cables stay visible); plus the tip side of the last unit; plus an anchor on the
    # drone's underside.
    angles = np.radians(np.asarray(geom.cable_angles_deg, dtype=np.float64))
    drone_p = positions[0]
    drone_q = quats[0]
    tip = p[-1] + axis_world[-1] * lengths[-1]
    segments = []
    for a in angles:
        radial_local = np.array([math.cos(a), math.sin(a), 0.0])
        radial = quat_rotate(inst_q, np.broadcast_to(radial_local, (n, 3)))
        r = (_CABLE_RADIUS * widths)[:, None]
        base_side = p + radial * r
        tip_side = tip + radial[-1] * (_CABLE_RADIUS * widths[-1] / 1.075)
        anchor = drone_p + quat_rotate(
            drone_q, radial_local * _CABLE_RADIUS * widths[0] + np.array([0.0, 0.0, -0.02])
        )
        chain = np.vstack((anchor[None, :], base_side, tip_side[None, :]))
        segments.append(np.stack((chain[:-1], chain[1:]), axis=1))
    return ArmDrawing(centres, inst_q, scales, np.concatenate(segments, axis=0), tip)


def array_drawing(positions: FloatArray, quats: FloatArray, geom: ArmGeometry, arms: int = 1) -> ArmDrawing:
    """:func:`arm_drawing` of every arm of an array, joined: unit instances and cable segments arm after arm.

    Args:
        positions: (1 + arms n, 3) body positions: the drone, then each arm's units base to tip, arm after
            arm (a ring plant's ``body_poses``, :meth:`host.panel.board_state.BoardState.bodies`).
        quats: (1 + arms n, 4) body orientations.
        geom: one arm's unit sizes.
        arms: how many arms the units split into.

    Returns:
        The drawing, whose ``tip_m`` is arm 0's tip. One arm: exactly :func:`arm_drawing`'s.

    Raises:
        ValueError: the units do not split into ``arms`` arms of at least one unit.
    """
    positions = np.asarray(positions, dtype=np.float64)
    quats = np.asarray(quats, dtype=np.float64)
    if arms == 1:
        return arm_drawing(positions, quats, geom)
    units, rest = divmod(len(positions) - 1, max(arms, 1))
    if arms < 1 or rest or units < 1:
        raise ValueError(f"{len(positions)} bodies are not a drone and {arms} arms of as many units")
    drone_q = quats[0]
    # Each arm hangs from its own mount on the ring: the drone's orientation, just above the arm's base,
    # so its cables run up into the drone's underside there and not to the drone's centre.
    lift = quat_rotate(drone_q, np.array([0.0, 0.0, 0.02]))
    parts = []
    for arm in range(arms):
        lo = 1 + arm * units
        p = positions[lo : lo + units]
        q = quats[lo : lo + units]
        parts.append(arm_drawing(np.vstack((p[0] + lift, p)), np.vstack((drone_q, q)), geom))
    return ArmDrawing(
        np.concatenate([d.unit_positions for d in parts]),
        np.concatenate([d.unit_wxyzs for d in parts]),
        np.concatenate([d.unit_scales for d in parts]),
        np.concatenate([d.cable_segments for d in parts]),
        parts[0].tip_m,
    )


def _drone_mesh() -> trimesh.Trimesh:
    parts = [trimesh.creation.box(extents=(0.12, 0.12, 0.04))]
    for k in range(4):
        yaw = math.pi / 4 + k * math.pi / 2
        arm = trimesh.creation.box(extents=(0.22, 0.018, 0.012))
        arm.apply_translation((0.11 + 0.04, 0.0, 0.0))
        arm.apply_transform(trimesh.transformations.rotation_matrix(yaw, (0.0, 0.0, 1.0)))
        rotor = trimesh.creation.cylinder(radius=0.07, height=0.006, sections=24)
        rotor.apply_translation((0.26 * math.cos(yaw), 0.26 * math.sin(yaw), 0.02))
        parts.append(arm)
        parts.append(rotor)
    mesh = trimesh.util.concatenate(parts)
    assert isinstance(mesh, trimesh.Trimesh)
    return mesh


def _heading_mesh() -> trimesh.Trimesh:
    """An arrow along :data:`NOSE_AXIS` (+y) from the hub past the front rotors (the heading marker)."""
    shaft = trimesh.creation.cylinder(radius=0.008, height=0.3, sections=12)
    shaft.apply_transform(trimesh.transformations.rotation_matrix(math.pi / 2, (0.0, 1.0, 0.0)))
    shaft.apply_translation((0.15 + 0.06, 0.0, 0.03))
    head = trimesh.creation.cone(radius=0.03, height=0.08, sections=16)
    head.apply_transform(trimesh.transformations.rotation_matrix(math.pi / 2, (0.0, 1.0, 0.0)))
    head.apply_translation((0.36, 0.0, 0.03))
    mesh = trimesh.util.concatenate([shaft, head])
    assert isinstance(mesh, trimesh.Trimesh)
    mesh.apply_transform(trimesh.transformations.rotation_matrix(math.pi / 2, (0.0, 0.0, 1.0)))  # x -> y
    return mesh


def _object_mesh(obj: SceneObject) -> trimesh.Trimesh:
    mesh: trimesh.Trimesh
    if obj.kind == "cylinder":
        mesh = trimesh.creation.cylinder(radius=obj.size_m[0], height=obj.size_m[2], sections=32)
    elif obj.kind == "capsule":
        mesh = trimesh.creation.capsule(height=obj.size_m[2], radius=obj.size_m[0], count=[24, 12])
    elif obj.kind == "box":
        mesh = trimesh.creation.box(extents=obj.size_m)
    elif obj.kind == "sphere":
        mesh = trimesh.creation.icosphere(subdivisions=2, radius=obj.size_m[0])
    else:
        raise ValueError(f"unknown object kind {obj.kind!r} (cylinder, box, sphere)")
    return mesh


_OBJECT_FIXED_COLOR = (150, 110, 70)
_OBJECT_FREE_COLOR = (200, 150, 60)


def scene_objects(objects: Sequence[Any]) -> list[SceneObject]:
    """Scene objects for the plant's objects (``hil.sim.mjcf.ObjectConfig``).

    Each is a cylinder or capsule of ``radius_m`` and ``length_m`` centred at ``pos_m`` along ``axis``,
    in the plant's world frame (the frame ``SimPoses`` and the shadow plant use). Free objects (with a
    mass) are drawn where they start: the board link carries no object poses. Anything that does not
    look like an object config is skipped.
    """
    out: list[SceneObject] = []
    for obj in objects:
        try:
            axis = np.asarray(obj.axis, dtype=np.float64).reshape(1, 3)
            norm = float(np.linalg.norm(axis))
            if not norm > 0:
                continue
            q = _align_z_to(axis / norm)[0]
            r = float(obj.radius_m)
            kind = "capsule" if getattr(obj, "shape", "cylinder") == "capsule" else "cylinder"
            free = getattr(obj, "mass_kg", None) is not None
            out.append(
                SceneObject(
                    str(obj.name),
                    kind,
                    (float(obj.pos_m[0]), float(obj.pos_m[1]), float(obj.pos_m[2])),
                    (r, r, float(obj.length_m)),
                    (float(q[0]), float(q[1]), float(q[2]), float(q[3])),
                    _OBJECT_FREE_COLOR if free else _OBJECT_FIXED_COLOR,
                )
            )
        except (AttributeError, TypeError, ValueError, IndexError):
            continue
    return out


# ---------------------------------------------------------------------- viser


@dataclass
class SceneHandles:
    """Handles of the scene nodes (one per kind of thing drawn)."""

    drone: Any
    heading: Any
    units: Any
    cables: Any
    trail: Any
    label: Any
    objects: list[Any]


class SceneView:
    """Owns the scene nodes and updates them from poses (call :meth:`update` from one thread)."""

    def __init__(self, server: viser.ViserServer, geom: ArmGeometry, handles: SceneHandles) -> None:
        """Wrap handles made by :func:`build_scene`."""
        self.server = server
        self.geom = geom
        self.handles = handles
        self.updates = 0
        self._trail: collections.deque[FloatArray] = collections.deque(maxlen=_TRAIL_LEN)
        self._n_units = geom.units
        self._lock = threading.Lock()
        self._label_text = ""
        pos, _ = default_hanging_pose(geom)
        self.drone = DronePose((float(pos[0][0]), float(pos[0][1]), float(pos[0][2])))
        """The pose of the arm's frame (body 0) last drawn (for the camera presets)."""
        self.centre_m = _xyz(np.mean(pos, axis=0))
        """The middle of the arm last drawn."""
        self.tip_m = _xyz(pos[-1])
        """The arm's tip last drawn."""

    def update(
        self,
        positions: FloatArray,
        quats: FloatArray,
        *,
        drone_override: DronePose | None = None,
        label: str | None = None,
        trail: bool = True,
        arms: int = 1,
    ) -> None:
        """Pose the drone and the arms (drone first, then units base to tip) in one atomic update.

        Args:
            positions: (1 + arms n, 3) body positions: the drone, then each arm's units, arm after arm.
            quats: (1 + arms n, 4) body orientations.
            drone_override: a drone pose from another source (MAVLink, forward-left-up body axes); the
                arm keeps its pose relative to the drone body, its frame turned by :func:`arm_frame`.
            label: text of the pose-source label (None: unchanged).
            trail: extend the tip trail (of arm 0).
            arms: the arms the units split into (an array's on its ring, :func:`array_drawing`).
        """
        positions = np.asarray(positions, dtype=np.float64)
        quats = np.asarray(quats, dtype=np.float64)
        if drone_override is not None:
            positions, quats = _reroot(positions, quats, arm_frame(drone_override))
        drawing = array_drawing(positions, quats, self.geom, arms)
        n = len(drawing.unit_positions)
        colors = None
        if n != self._n_units:
            self._n_units = n
            colors = _unit_colors(n // arms, arms)
        if trail:
            self._trail.append(drawing.tip_m)
        p0, q0, tip = positions[0], quats[0], drawing.tip_m
        self.drone = DronePose((float(p0[0]), float(p0[1]), float(p0[2])), _wxyz(q0))
        self.centre_m = _xyz(np.mean(positions, axis=0))
        self.tip_m = _xyz(tip)
        h = self.handles
        with self.server.atomic():
            h.drone.position = tuple(float(x) for x in positions[0])
            h.drone.wxyz = tuple(float(x) for x in quats[0])
            if colors is not None:
                # Changing the instance count: set every per-instance array together.
                h.units.batched_colors = colors
            h.units.batched_positions = drawing.unit_positions.astype(np.float32)
            h.units.batched_wxyzs = drawing.unit_wxyzs.astype(np.float32)
            h.units.batched_scales = drawing.unit_scales.astype(np.float32)
            h.cables.points = drawing.cable_segments.astype(np.float32)
            if len(drawing.cable_segments) != len(h.cables.colors):
                h.cables.colors = _cable_colors(drawing, self.geom, arms)
            if len(self._trail) >= 2:
                h.trail.points, h.trail.colors = _trail_segments(list(self._trail))
            if label is not None and label != self._label_text:
                self._label_text = label
                h.label.text = label
            if label is not None:
                h.label.position = tuple(float(x) for x in positions[0] + np.array([0.0, 0.0, 0.15]))
        self.server.flush()
        self.updates += 1


def _xyz(v: FloatArray) -> tuple[float, float, float]:
    return (float(v[0]), float(v[1]), float(v[2]))


def _wxyz(q: FloatArray) -> tuple[float, float, float, float]:
    return (float(q[0]), float(q[1]), float(q[2]), float(q[3]))


def _reroot(positions: FloatArray, quats: FloatArray, drone: DronePose) -> tuple[FloatArray, FloatArray]:
    """Move all bodies rigidly so body 0 lands on ``drone``."""
    q_new = np.asarray(drone.wxyz, dtype=np.float64)
    q_new = q_new / max(float(np.linalg.norm(q_new)), 1e-12)
    q_rel = (vtf.SO3(wxyz=q_new) @ vtf.SO3(wxyz=quats[0]).inverse()).wxyz
    rel = positions - positions[0]
    pos = np.asarray(drone.position_m, dtype=np.float64) + quat_rotate(
        np.broadcast_to(q_rel, (len(rel), 4)), rel
    )
    quat = quat_mul(np.broadcast_to(q_rel, quats.shape), quats)
    return pos, quat


def _unit_colors(units: int, arms: int = 1) -> npt.NDArray[np.uint8]:
    """Every arm's units shaded from base to tip (the same colours for every arm of an array)."""
    f = np.linspace(0.0, 1.0, units)[:, None]
    return np.tile((_UNIT_COLOR_BASE * (1 - f) + _UNIT_COLOR_TIP * f).astype(np.uint8), (arms, 1))


def _cable_colors(drawing: ArmDrawing, geom: ArmGeometry, arms: int = 1) -> npt.NDArray[np.uint8]:
    """Cable k of every arm in its colour (:data:`_CABLE_COLORS`), for segments arm after arm, cable after
    cable."""
    cables = len(geom.cable_angles_deg)
    per_cable = len(drawing.cable_segments) // (cables * arms)
    one_arm = [
        np.tile(np.asarray(_CABLE_COLORS[k % len(_CABLE_COLORS)], dtype=np.uint8), (per_cable, 2, 1))
        for k in range(cables)
    ]
    return np.concatenate(one_arm * arms).astype(np.uint8)


def _trail_segments(points: list[FloatArray]) -> tuple[npt.NDArray[np.float32], npt.NDArray[np.uint8]]:
    """A fixed number of segments (so the node keeps its size); older ones fade to the background."""
    pts = np.asarray(points, dtype=np.float64)
    if len(pts) < _TRAIL_LEN:
        pts = np.vstack((np.repeat(pts[:1], _TRAIL_LEN - len(pts), axis=0), pts))
    segs = np.stack((pts[:-1], pts[1:]), axis=1)
    age = np.linspace(1.0, 0.0, len(segs))[:, None]  # 1 = oldest
    col = _TRAIL_NEW * (1 - age) + _TRAIL_OLD * age
    cols = np.repeat(col[:, None, :], 2, axis=1)
    return segs.astype(np.float32), cols.astype(np.uint8)


def build_scene(
    server: viser.ViserServer,
    geom: ArmGeometry,
    objects: Sequence[SceneObject] = (),
) -> SceneView:
    """Create the scene nodes (ground grid, drone, arm, cables, trail, objects) in the hanging pose.

    Returns:
        The :class:`SceneView` that updates them.
    """
    scene = server.scene
    scene.set_up_direction("+z")
    scene.add_grid("/ground", width=4.0, height=4.0, cell_size=0.1, section_size=0.5, plane="xy")
    pos, quat = default_hanging_pose(geom)
    drawing = arm_drawing(pos, quat, geom)
    drone = _drone_mesh()
    drone_h = scene.add_mesh_simple(
        "/drone",
        vertices=np.asarray(drone.vertices, dtype=np.float32),
        faces=np.asarray(drone.faces, dtype=np.uint32),
        color=(70, 70, 80),
        position=pos[0],
    )
    unit = trimesh.creation.cylinder(radius=0.5, height=1.0, sections=20)
    units_h = scene.add_batched_meshes_simple(
        "/arm/units",
        vertices=np.asarray(unit.vertices, dtype=np.float32),
        faces=np.asarray(unit.faces, dtype=np.uint32),
        batched_wxyzs=drawing.unit_wxyzs.astype(np.float32),
        batched_positions=drawing.unit_positions.astype(np.float32),
        batched_scales=drawing.unit_scales.astype(np.float32),
        batched_colors=_unit_colors(geom.units),
        lod="off",
    )
    cables_h = scene.add_line_segments(
        "/arm/cables",
        points=drawing.cable_segments.astype(np.float32),
        colors=_cable_colors(drawing, geom),
        thickness=2.0,
        thickness_units="screen",
    )
    trail_pts, trail_cols = _trail_segments([drawing.tip_m, drawing.tip_m])
    trail_h = scene.add_line_segments(
        "/arm/tip_trail", points=trail_pts, colors=trail_cols, thickness=3.0, thickness_units="screen"
    )
    label_h = scene.add_label("/labels/pose_source", text="", position=pos[0])
    objs = []
    for obj in objects:
        mesh = _object_mesh(obj)
        objs.append(
            scene.add_mesh_simple(
                f"/objects/{obj.name}",
                vertices=np.asarray(mesh.vertices, dtype=np.float32),
                faces=np.asarray(mesh.faces, dtype=np.uint32),
                color=obj.color,
                position=obj.position_m,
                wxyz=obj.wxyz,
            )
        )
    # The drone's nose (NOSE_AXIS, stick forward): a child of /drone, so viser poses it with the drone.
    nose = _heading_mesh()
    heading_h = scene.add_mesh_simple(
        "/drone/heading",
        vertices=np.asarray(nose.vertices, dtype=np.float32),
        faces=np.asarray(nose.faces, dtype=np.uint32),
        color=(230, 50, 50),
    )
    scene.add_label(
        "/drone/heading/label", text="nose", position=(0.42 * NOSE_AXIS[0], 0.42 * NOSE_AXIS[1], 0.04)
    )
    handles = SceneHandles(drone_h, heading_h, units_h, cables_h, trail_h, label_h, objs)
    return SceneView(server, geom, handles)


PoseProvider = Callable[[], DronePose | None]
"""Returns the latest drone pose (e.g. from MAVLink), or None when unknown."""
