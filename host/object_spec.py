"""``--object`` specs: objects added to the virtual board's scene from the command line.

Form: ``SHAPE:KEY=VALUE,...``, e.g. ``cylinder:d=20mm,x=40mm,z=-110mm``. Shapes are those the plant
models (``cylinder``: flat ends; ``capsule``: rounded ends). Keys:

===== =========================================================== ==========
key   meaning                                                     default
===== =========================================================== ==========
d     diameter                                                    (required)
len   length along the axis                                       60mm
x     centre, right of the arm's base (the grasp side, cable 1)   0mm
y     centre, forward of the base (toward the drone's nose)       0mm
z     centre, above the arm's base (negative: below it)           (required)
axis  the axis direction: ``x``, ``y`` or ``z``                   y
===== =========================================================== ==========

Lengths need a unit (``mm``, ``cm`` or ``m``): a bare number is refused rather than guessed. Objects are
fixed to the world (a pole or a branch to grasp): the board link carries no object poses, so a free object
would be drawn where it started while it fell.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from typing import Any

__all__ = [
    "AXES",
    "DEFAULT_OBJECT",
    "MAX_DIAMETER_M",
    "MAX_DISTANCE_M",
    "SHAPES",
    "ObjectSpec",
    "describe_object",
    "format_object",
    "parse_object",
    "plant_objects",
]

SHAPES = ("cylinder", "capsule")
"""The shapes the plant models (``hil.sim.config.ObjectConfig.shape``)."""
AXES = {"x": (1.0, 0.0, 0.0), "y": (0.0, 1.0, 0.0), "z": (0.0, 0.0, 1.0)}
"""``axis=`` choices and their directions."""
MAX_DIAMETER_M = 0.5
"""The largest diameter or length accepted (the prototype arm is 0.3 m long)."""
MAX_DISTANCE_M = 2.0
"""The farthest centre accepted from the arm's base, per coordinate."""

_UNITS_M = {"mm": 1e-3, "cm": 1e-2, "m": 1.0}
_VALUE = re.compile(r"^([+-]?(?:\d+(?:\.\d*)?|\.\d+)(?:[eE][+-]?\d+)?)\s*(mm|cm|m)?$")
_KEYS = ("d", "len", "x", "y", "z", "axis")


@dataclass(frozen=True, slots=True)
class ObjectSpec:
    """One object of the scene, placed relative to the arm's base.

    Attributes:
        shape: one of :data:`SHAPES`.
        diameter_m: diameter.
        length_m: length along the axis.
        x_m: centre, right of the base (the side of cable 1, where a grasp goes by default).
        y_m: centre, forward of the base (toward the drone's nose, ``host.panel.scene.NOSE_AXIS``).
        z_m: centre, above the base (negative: below).
        axis: ``"x"``, ``"y"`` or ``"z"`` (:data:`AXES`).
    """

    shape: str
    diameter_m: float
    length_m: float
    x_m: float
    y_m: float
    z_m: float
    axis: str = "y"

    def validate(self) -> None:
        """Check every value.

        Raises:
            ValueError: one line naming the bad value.
        """
        if self.shape not in SHAPES:
            raise ValueError(f"unknown shape {self.shape!r} (one of {', '.join(SHAPES)})")
        if self.axis not in AXES:
            raise ValueError(f"axis must be one of {', '.join(AXES)}, got {self.axis!r}")
        for key, value in (("d", self.diameter_m), ("len", self.length_m)):
            if not (math.isfinite(value) and 0.0 < value <= MAX_DIAMETER_M):
                raise ValueError(f"{key} must be more than 0 and at most {MAX_DIAMETER_M * 1000:g}mm")
        for key, value in (("x", self.x_m), ("y", self.y_m), ("z", self.z_m)):
            if not (math.isfinite(value) and abs(value) <= MAX_DISTANCE_M):
                raise ValueError(f"{key} must be within ±{MAX_DISTANCE_M:g}m of the arm's base")

    def world_pos_m(self, base_m: tuple[float, float, float]) -> tuple[float, float, float]:
        """The centre in the plant's world frame, given where the arm's base is in it."""
        return (base_m[0] + self.x_m, base_m[1] + self.y_m, base_m[2] + self.z_m)


DEFAULT_OBJECT = ObjectSpec("cylinder", diameter_m=0.020, length_m=0.060, x_m=0.070, y_m=0.0, z_m=-0.140)
"""The default demo's object: a 20 mm pole the grasp strategy wraps from the default start (the arm
hanging straight, GRASP mode packing it, then the grasp request): found by running the grasp in lockstep
at candidate placements (``tests/host/test_object_spec.py`` runs it)."""


def _length(key: str, text: str) -> float:
    m = _VALUE.match(text.strip())
    if m is None:
        raise ValueError(f"{key}={text}: not a length (a number and mm, cm or m, e.g. {key}=20mm)")
    if m.group(2) is None:
        raise ValueError(f"{key}={text}: give a unit (mm, cm or m)")
    return float(m.group(1)) * _UNITS_M[m.group(2)]


def parse_object(text: str) -> ObjectSpec:
    """Parse one ``--object`` value (see the module's docstring for the form).

    Raises:
        ValueError: one line saying what is wrong.
    """
    shape, sep, rest = text.partition(":")
    shape = shape.strip().lower()
    if not sep:
        raise ValueError(f"expected SHAPE:KEY=VALUE,... (e.g. cylinder:d=20mm,x=40mm,z=-110mm), got {text!r}")
    if shape not in SHAPES:
        raise ValueError(f"unknown shape {shape!r} (one of {', '.join(SHAPES)})")
    values: dict[str, str] = {}
    for item in rest.split(","):
        key, eq, value = item.partition("=")
        key = key.strip().lower()
        if not eq or not key:
            raise ValueError(f"{item.strip()!r}: expected KEY=VALUE")
        if key not in _KEYS:
            raise ValueError(f"unknown key {key!r} (one of {', '.join(_KEYS)})")
        if key in values:
            raise ValueError(f"{key} given twice")
        values[key] = value.strip()
    for key in ("d", "z"):
        if key not in values:
            raise ValueError(f"{key}= is required")
    axis = values.get("axis", "y").lower()
    spec = ObjectSpec(
        shape,
        diameter_m=_length("d", values["d"]),
        length_m=_length("len", values.get("len", "60mm")),
        x_m=_length("x", values.get("x", "0mm")),
        y_m=_length("y", values.get("y", "0mm")),
        z_m=_length("z", values["z"]),
        axis=axis,
    )
    spec.validate()
    return spec


def format_object(spec: ObjectSpec) -> str:
    """The ``--object`` text of ``spec`` (:func:`parse_object` reads it back to an equal spec)."""

    # Metres with repr's shortest exact digits: a round trip gives the same floats (mm would round).
    return (
        f"{spec.shape}:d={spec.diameter_m!r}m,len={spec.length_m!r}m,x={spec.x_m!r}m,"
        f"y={spec.y_m!r}m,z={spec.z_m!r}m,axis={spec.axis}"
    )


def describe_object(spec: ObjectSpec) -> str:
    """``spec`` as ``--object`` text in millimetres, rounded to 0.1 mm (for people; see
    :func:`format_object` for the exact form)."""

    def mm(value_m: float) -> str:
        return f"{round(value_m * 1000, 1):g}mm"

    return (
        f"{spec.shape}:d={mm(spec.diameter_m)},len={mm(spec.length_m)},x={mm(spec.x_m)},"
        f"y={mm(spec.y_m)},z={mm(spec.z_m)},axis={spec.axis}"
    )


def plant_objects(specs: tuple[ObjectSpec, ...] | list[ObjectSpec], model: Any) -> tuple[Any, ...]:
    """The plant's objects (``hil.sim.config.ObjectConfig``) for ``specs``, named ``object1``, ...

    Args:
        specs: the objects, placed relative to the arm's base.
        model: the plant's ``hil.sim.config.ModelConfig``; its drone gives where the base is.

    Returns:
        Fixed objects in the plant's world frame.
    """
    from hil.sim.config import ObjectConfig  # type: ignore[import-not-found,unused-ignore]

    drone = model.drone
    w, qx, qy, qz = (float(v) for v in drone.quat_wxyz)
    norm = math.sqrt(w * w + qx * qx + qy * qy + qz * qz)
    w, qx, qy, qz = w / norm, qx / norm, qy / norm, qz / norm
    # The mount hangs mount_offset_m along the drone's own -z: the third column of its rotation, negated.
    down = (-2 * (qx * qz + w * qy), -2 * (qy * qz - w * qx), -(1 - 2 * (qx * qx + qy * qy)))
    off = float(drone.mount_offset_m)
    base = tuple(float(p) + off * d for p, d in zip(drone.pos_m, down, strict=True))
    taken = {o.name for o in model.objects}
    out = []
    n = 0
    for spec in specs:
        n += 1
        while f"object{n}" in taken:
            n += 1
        out.append(
            ObjectConfig(
                f"object{n}",
                radius_m=spec.diameter_m / 2,
                length_m=spec.length_m,
                pos_m=spec.world_pos_m((base[0], base[1], base[2])),
                axis=AXES[spec.axis],
                shape=spec.shape,
            )
        )
    return tuple(out)
