"""Foxglove's well-known schemas for what a run shows: the arm's frames and shape, events, telemetry.

One :class:`FoxgloveView` turns what a recorder or a live server is handed (body poses, decoded telemetry)
into messages on a fixed set of channels (:data:`CHANNELS`), so an MCAP recording (:mod:`hil.recording`,
``spirob-host --record``) and the live server (``spirob-host --foxglove``) carry the same topics,
schemas and encodings:

- :data:`TF` (``foxglove.FrameTransforms``, protobuf): a tree, ``world`` -> ``drone`` -> ``arm_base`` ->
  ``unit_00`` .. (base to tip), each pose relative to its parent (:func:`frame_transforms`), so moving the
  drone's frame moves the arm with it; composed down the tree they give back the plant's world poses;
- :data:`SCENE` (``foxglove.SceneUpdate``): one truncated cone per unit locked to its frame, and a flat box
  for the drone, so Foxglove's 3D panel draws the arm with no set-up; sent with the first poses and
  again every :data:`SCENE_PERIOD_US` of board time (a panel opened mid-run, or a seek, finds it);
- :data:`EVENTS` (``foxglove.Log``): mode, failsafe phase, grasp state and arming-gate changes read from
  telemetry, and a motor going offline;
- :data:`TELEMETRY` (JSON with :data:`TELEMETRY_SCHEMA`): every field of the firmware's telemetry, one
  layout whoever wrote the file.

The messages are encoded by the ``foxglove-sdk`` package (its ``encode()`` and ``get_schema()``), so the
schemas are Foxglove's own definitions: a protobuf ``FileDescriptorSet`` for each well-known type.
Every Foxglove stamp inside a message (``FrameTransform.timestamp``, ``Log.timestamp``) is the message's
log time (Unix time, except in a lockstep recording: :mod:`hil.recording`), because the 3D panel looks
transforms up at the playback time; MCAP's ``publish_time`` is the same instant, and the board's own clock
is in the telemetry payload (``time_us``).
"""

from __future__ import annotations

import dataclasses
import enum
import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Final

import mujoco
import numpy as np
import numpy.typing as npt
from foxglove.messages import (
    Color,
    CubePrimitive,
    CylinderPrimitive,
    Duration,
    FrameTransform,
    FrameTransforms,
    Log,
    LogLevel,
    Pose,
    Quaternion,
    SceneEntity,
    SceneUpdate,
    Timestamp,
    Vector3,
)

from protocol.messages import ArmBlocker, GraspState, Mode, Phase, Telemetry, TelemetryFlags

TF: Final = "/tf"
"""``foxglove.FrameTransforms``: ``world`` -> ``drone`` -> ``arm_base`` -> every unit, each in its parent."""
SCENE: Final = "/arm/scene"
"""``foxglove.SceneUpdate``: the arm's shape, each unit locked to its frame."""
EVENTS: Final = "/events"
"""``foxglove.Log``: what changed in the board's state."""
TELEMETRY: Final = "/telemetry"
"""The firmware's telemetry, JSON with :data:`TELEMETRY_SCHEMA`."""

WORLD_FRAME: Final = "world"
DRONE_FRAME: Final = "drone"
ARM_BASE_FRAME: Final = "arm_base"
"""Where the arm is fixed to the drone: the base unit's frame (``unit_00`` is rigid on the drone), so its
pose in ``drone`` is constant and ``unit_00`` sits at the identity in it."""
SCENE_PERIOD_US: Final = 1_000_000
"""The arm's shape is sent again every second of board time."""
LOG_NAME: Final = "spirob"
"""``Log.name`` of the events."""


def unit_frame(index: int) -> str:
    """Frame id of unit ``index`` (0 = base)."""
    return f"unit_{index:02d}"


@dataclass(frozen=True, slots=True)
class ChannelSpec:
    """How a channel is declared (MCAP channel + schema, or a live server's channel).

    Attributes:
        topic: the channel's topic.
        message_encoding: ``protobuf`` or ``json``.
        schema_name: the schema's name (``foxglove.FrameTransforms``, ...).
        schema_encoding: ``protobuf`` (a ``FileDescriptorSet``) or ``jsonschema``.
        schema_data: the schema itself.
    """

    topic: str
    message_encoding: str
    schema_name: str
    schema_encoding: str
    schema_data: bytes


def _protobuf_spec(topic: str, message_type: Any) -> ChannelSpec:
    schema = message_type.get_schema()
    return ChannelSpec(topic, schema.encoding, schema.name, schema.encoding, bytes(schema.data))


# ---------------------------------------------------------------------- telemetry


_ENUM_FIELDS: Final[dict[str, type[enum.IntEnum]]] = {
    "mode": Mode,
    "phase": Phase,
    "grasp_state": GraspState,
    "arm_blocker": ArmBlocker,
}


def _telemetry_schema() -> dict[str, Any]:
    """The JSON schema of :func:`telemetry_json`, read off the ``Telemetry`` message's own fields."""
    props: dict[str, Any] = {}
    for f in dataclasses.fields(Telemetry):
        default = f.default if f.default is not dataclasses.MISSING else 0
        if f.name in _ENUM_FIELDS:
            cls = _ENUM_FIELDS[f.name]
            names = ", ".join(f"{m.value} {m.name}" for m in cls)
            props[f.name] = {"type": "integer", "enum": [m.value for m in cls], "description": names}
            props[f"{f.name}_name"] = {"type": "string", "enum": [m.name for m in cls]}
        elif f.name == "flags":
            bits = ", ".join(f"{m.value} {m.name}" for m in TelemetryFlags if m.value)
            props[f.name] = {"type": "integer", "minimum": 0, "description": f"bit mask: {bits}"}
        elif isinstance(default, tuple):
            item = "number" if isinstance(default[0], float) else "integer"
            props[f.name] = {
                "type": "array",
                "items": {"type": item},
                "minItems": len(default),
                "maxItems": len(default),
            }
        else:
            props[f.name] = {"type": "number" if isinstance(default, float) else "integer"}
    props["time_us"]["description"] = "board time [µs]"
    return {
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "title": "spirob.Telemetry",
        "type": "object",
        "properties": props,
        "required": sorted(props),
        "additionalProperties": False,
    }


TELEMETRY_SCHEMA: Final[dict[str, Any]] = _telemetry_schema()
"""JSON schema of the ``/telemetry`` payload: every ``Telemetry`` field, enums as their values plus a
``<field>_name`` string, vectors as fixed-length arrays."""


def telemetry_json(msg: Telemetry) -> dict[str, Any]:
    """A telemetry message in the one ``/telemetry`` layout (:data:`TELEMETRY_SCHEMA`)."""
    out: dict[str, Any] = {}
    for f in dataclasses.fields(msg):
        v = getattr(msg, f.name)
        if isinstance(v, enum.Enum):
            out[f.name] = int(v.value)
            if f.name in _ENUM_FIELDS:
                out[f"{f.name}_name"] = v.name
        elif isinstance(v, tuple):
            out[f.name] = list(v)
        else:
            out[f.name] = v
    return out


BOARD_CONFIG_SCHEMA: Final[dict[str, Any]] = {
    "$schema": "https://json-schema.org/draft/2020-12/schema",
    "title": "spirob.BoardConfig",
    "description": "the virtual board's configuration; design and firmware are JSON objects as strings",
    "type": "object",
    "additionalProperties": {"type": "string"},
}


def _json_spec(topic: str, schema: Mapping[str, Any]) -> ChannelSpec:
    data = json.dumps(schema, separators=(",", ":"), sort_keys=True).encode()
    return ChannelSpec(topic, "json", str(schema["title"]), "jsonschema", data)


CHANNELS: Final[dict[str, ChannelSpec]] = {
    TF: _protobuf_spec(TF, FrameTransforms),
    SCENE: _protobuf_spec(SCENE, SceneUpdate),
    EVENTS: _protobuf_spec(EVENTS, Log),
    TELEMETRY: _json_spec(TELEMETRY, TELEMETRY_SCHEMA),
}
"""Every channel a :class:`FoxgloveView` writes, by topic."""


def json_spec(topic: str, schema: Mapping[str, Any]) -> ChannelSpec:
    """A JSON channel with its JSON schema (``schema["title"]`` names it)."""
    return _json_spec(topic, schema)


# ---------------------------------------------------------------------- poses


def _stamp(ns: int) -> Timestamp:
    return Timestamp(ns // 1_000_000_000, ns % 1_000_000_000)


def _quat(wxyz: npt.NDArray[np.float64]) -> Quaternion:
    return Quaternion(x=float(wxyz[1]), y=float(wxyz[2]), z=float(wxyz[3]), w=float(wxyz[0]))


def _quat_mul(a: npt.NDArray[np.float64], b: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """Hamilton products of rows of w, x, y, z quaternions (broadcast)."""
    aw, ax, ay, az = a[..., 0], a[..., 1], a[..., 2], a[..., 3]
    bw, bx, by, bz = b[..., 0], b[..., 1], b[..., 2], b[..., 3]
    return np.stack(
        [
            aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
        ],
        axis=-1,
    )


def in_parent(
    parent_p: npt.NDArray[np.float64],
    parent_q: npt.NDArray[np.float64],
    p: npt.NDArray[np.float64],
    q: npt.NDArray[np.float64],
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """Poses ``(p, q)`` (world) expressed in the frame whose world pose is ``(parent_p, parent_q)``:
    the parent's inverse applied, ``q_parent* (p - p_parent) q_parent`` and ``q_parent* q``."""
    norm = float(np.dot(parent_q, parent_q))
    conj = parent_q * np.array([1.0, -1.0, -1.0, -1.0]) / norm  # the inverse, a unit quaternion or not
    d = np.zeros((len(p), 4))
    d[:, 1:] = p - parent_p
    rel_p = _quat_mul(_quat_mul(conj, d), parent_q)[:, 1:]
    return rel_p, _quat_mul(conj, q)


def tree_poses(
    positions_m: npt.ArrayLike, quats_wxyz: npt.ArrayLike
) -> list[tuple[str, str, npt.NDArray[np.float64], npt.NDArray[np.float64]]]:
    """The frame tree of one set of world poses (drone first, then the units base to tip).

    Returns (parent, child, position in the parent, quaternion w x y z in the parent), parents first:
    ``world`` -> ``drone`` (its world pose), ``drone`` -> ``arm_base`` (the base unit's pose on the drone,
    constant: it is rigid there), ``arm_base`` -> ``unit_k`` (each unit in the arm's base frame).
    """
    pos = np.asarray(positions_m, dtype=np.float64).reshape(-1, 3)
    quat = np.asarray(quats_wxyz, dtype=np.float64).reshape(-1, 4)
    if len(pos) != len(quat):
        raise ValueError(f"{len(pos)} positions but {len(quat)} quaternions")
    if len(pos) == 0:
        return []
    out = [(WORLD_FRAME, DRONE_FRAME, pos[0], quat[0])]
    if len(pos) == 1:
        return out
    base_p, base_q = in_parent(pos[0], quat[0], pos[1:2], quat[1:2])
    out.append((DRONE_FRAME, ARM_BASE_FRAME, base_p[0], base_q[0]))
    unit_p, unit_q = in_parent(pos[1], quat[1], pos[1:], quat[1:])
    out.extend(
        (ARM_BASE_FRAME, unit_frame(i), p, q) for i, (p, q) in enumerate(zip(unit_p, unit_q, strict=True))
    )
    return out


def frame_transforms(stamp_ns: int, positions_m: npt.ArrayLike, quats_wxyz: npt.ArrayLike) -> bytes:
    """``foxglove.FrameTransforms`` of the bodies' world poses (drone first, then the units base to tip) as
    the tree of :func:`tree_poses`, encoded."""
    stamp = _stamp(stamp_ns)
    transforms = [
        FrameTransform(
            timestamp=stamp,
            parent_frame_id=parent,
            child_frame_id=child,
            translation=Vector3(x=float(p[0]), y=float(p[1]), z=float(p[2])),
            rotation=_quat(q),
        )
        for parent, child, p, q in tree_poses(positions_m, quats_wxyz)
    ]
    return FrameTransforms(transforms=transforms).encode()


@dataclass(frozen=True, slots=True)
class UnitShape:
    """One unit as drawn in its own frame: a truncated cone from its joint towards the next joint.

    Attributes:
        axis: unit vector in the unit's frame from its joint towards the next one.
        length_m: joint-to-joint length.
        base_width_m: width at the joint.
        tip_width_m: width at the far end.
    """

    axis: tuple[float, float, float]
    length_m: float
    base_width_m: float
    tip_width_m: float


def unit_shapes(
    positions_m: npt.ArrayLike,
    quats_wxyz: npt.ArrayLike,
    widths_m: Sequence[tuple[float, float]] | None = None,
    lengths_m: Sequence[float] | None = None,
) -> list[UnitShape]:
    """The units' shapes from one set of body poses (drone first), with the design's sizes when known.

    A unit's axis is the direction to the next body expressed in its own frame (joints are fixed in their
    parent's frame, so one pose is enough); the tip reuses its neighbour's axis. Without the design's
    widths (or when the pose has another unit count) a unit is drawn 0.8 times as wide as it is long.
    """
    pos = np.asarray(positions_m, dtype=np.float64).reshape(-1, 3)[1:]
    quat = np.asarray(quats_wxyz, dtype=np.float64).reshape(-1, 4)[1:]
    n = len(pos)
    if widths_m is not None and len(widths_m) != n:
        widths_m = None
    if lengths_m is not None and len(lengths_m) != n:
        lengths_m = None
    shapes: list[UnitShape] = []
    neg = np.zeros(4)
    local = np.zeros(3)
    axis: tuple[float, float, float] = (0.0, 0.0, -1.0)
    for i in range(n):
        if i + 1 < n:
            delta = pos[i + 1] - pos[i]
            dist = float(np.linalg.norm(delta))
            if dist > 1e-9:
                mujoco.mju_negQuat(neg, quat[i])
                mujoco.mju_rotVecQuat(local, delta / dist, neg)
                axis = (float(local[0]), float(local[1]), float(local[2]))
        else:
            dist = shapes[-1].length_m if shapes else 0.02
        length = float(lengths_m[i]) if lengths_m is not None else dist
        if widths_m is not None:
            base_w, tip_w = float(widths_m[i][0]), float(widths_m[i][1])
        else:
            base_w = tip_w = 0.8 * length
        shapes.append(UnitShape(axis, length, base_w, tip_w))
    return shapes


_UNIT_COLOR_BASE = (0.16, 0.43, 0.78)
_UNIT_COLOR_TIP = (0.47, 0.82, 1.0)
_DRONE_COLOR = Color(r=0.3, g=0.3, b=0.32, a=1.0)


def scene_update(stamp_ns: int, shapes: Sequence[UnitShape]) -> bytes:
    """``foxglove.SceneUpdate``: every unit locked to its frame, and the drone's body, encoded."""
    stamp = _stamp(stamp_ns)
    forever = Duration(0, 0)
    z2v = np.zeros(4)
    entities = [
        SceneEntity(
            timestamp=stamp,
            frame_id=DRONE_FRAME,
            id="drone",
            lifetime=forever,
            frame_locked=True,
            cubes=[CubePrimitive(pose=Pose(), size=Vector3(x=0.3, y=0.3, z=0.04), color=_DRONE_COLOR)],
        )
    ]
    n = len(shapes)
    for i, s in enumerate(shapes):
        axis = np.asarray(s.axis, dtype=np.float64)
        mujoco.mju_quatZ2Vec(z2v, axis)  # the cylinder's +z along the unit, base at its joint
        centre = axis * (s.length_m / 2.0)
        widest = max(s.base_width_m, s.tip_width_m, 1e-6)
        k = i / max(n - 1, 1)
        rgb = [a + (b - a) * k for a, b in zip(_UNIT_COLOR_BASE, _UNIT_COLOR_TIP, strict=True)]
        cone = CylinderPrimitive(
            pose=Pose(
                position=Vector3(x=float(centre[0]), y=float(centre[1]), z=float(centre[2])),
                orientation=_quat(z2v),
            ),
            size=Vector3(x=widest, y=widest, z=s.length_m),
            bottom_scale=s.base_width_m / widest,
            top_scale=s.tip_width_m / widest,
            color=Color(r=rgb[0], g=rgb[1], b=rgb[2], a=1.0),
        )
        entities.append(
            SceneEntity(
                timestamp=stamp,
                frame_id=unit_frame(i),
                id=unit_frame(i),
                lifetime=forever,
                frame_locked=True,
                cylinders=[cone],
            )
        )
    return SceneUpdate(entities=entities).encode()


def log_message(stamp_ns: int, level: LogLevel, text: str) -> bytes:
    """``foxglove.Log`` of one event, encoded."""
    return Log(timestamp=_stamp(stamp_ns), level=level, message=text, name=LOG_NAME).encode()


# ---------------------------------------------------------------------- the view


def design_sizes(design_json: str | None) -> tuple[list[tuple[float, float]], list[float]] | None:
    """Unit widths (base side, tip side) and lengths of a design stored as JSON in a recording's
    metadata (``dataclasses.asdict(SpiralDesign)``); None when absent or unreadable."""
    if not design_json:
        return None
    from hil.sim.spiral import SpiralDesign

    try:
        fields = json.loads(design_json)
        fields["inputs"] = tuple(tuple(p) for p in fields.get("inputs", ()))
        design = SpiralDesign(**fields)
    except (TypeError, ValueError, AttributeError):  # not a design: draw from the poses alone
        return None
    return list(design.unit_widths_m()), list(design.unit_chords_m())


class FoxgloveView:
    """Turns poses and telemetry into messages on :data:`CHANNELS` (one per recording or live server).

    Args:
        sizes: unit widths and lengths of the design (:func:`design_sizes`); None draws units from the
            poses alone.
    """

    def __init__(self, sizes: tuple[Sequence[tuple[float, float]], Sequence[float]] | None = None) -> None:
        self._sizes = sizes
        self._shapes: list[UnitShape] | None = None
        self._next_scene_us: int | None = None
        self._last: dict[str, Any] | None = None

    def poses(
        self, stamp_ns: int, board_us: int, positions_m: npt.ArrayLike, quats_wxyz: npt.ArrayLike
    ) -> list[tuple[str, bytes]]:
        """The transforms of one set of body poses, and the arm's shape when it is due."""
        out = [(TF, frame_transforms(stamp_ns, positions_m, quats_wxyz))]
        if self._shapes is None:
            widths, lengths = self._sizes if self._sizes is not None else (None, None)
            self._shapes = unit_shapes(positions_m, quats_wxyz, widths, lengths)
        if self._next_scene_us is None or board_us >= self._next_scene_us:
            self._next_scene_us = board_us + SCENE_PERIOD_US
            out.append((SCENE, scene_update(stamp_ns, self._shapes)))
        return out

    def telemetry(self, stamp_ns: int, obj: Mapping[str, Any]) -> list[tuple[str, bytes]]:
        """The telemetry payload, and a log message for each change of state it shows."""
        out = [(TELEMETRY, json.dumps(obj, separators=(",", ":")).encode())]
        out.extend((EVENTS, log_message(stamp_ns, level, text)) for level, text in self._events(obj))
        self._last = dict(obj)
        return out

    def _events(self, obj: Mapping[str, Any]) -> list[tuple[LogLevel, str]]:
        last = self._last
        t_s = float(obj.get("time_us", 0)) / 1e6
        events: list[tuple[LogLevel, str]] = []
        for name, cls in _ENUM_FIELDS.items():
            if name not in obj:
                continue
            new = obj[name]
            old = None if last is None else last.get(name)
            if new == old:
                continue
            try:
                new_name = cls(new).name
                old_name = "-" if old is None else cls(old).name
            except ValueError:
                continue
            warn = (name == "phase" and new not in (Phase.GATE, Phase.OK)) or (
                name == "grasp_state" and new == GraspState.FAILED
            )
            level = LogLevel.Warning if warn else LogLevel.Info
            events.append((level, f"{name} {old_name} -> {new_name} (board t={t_s:.3f} s)"))
        offline = obj.get("motor_offline_events")
        if (
            last is not None
            and isinstance(offline, int)
            and offline > int(last.get("motor_offline_events", 0))
        ):
            events.append((LogLevel.Warning, f"a motor went offline (board t={t_s:.3f} s)"))
        return events
