"""The shapes of the objects a plant's scene holds, as MJCF: each shape's geom attributes and the meshes a
cone and a mesh object are made of (``ObjectConfig.shape``; docs/plant.md, "Drone and objects")."""

from __future__ import annotations

import math

from hil.sim.config import ObjectConfig
from hil.sim.mjcf_text import num as _f
from hil.sim.mjcf_text import vec as _v

__all__ = ["CONE_SIDES", "object_mesh_vertices", "object_shape_xml"]


CONE_SIDES = 24
"""Sides of the pyramid that stands for a cone (its volume is 99 % of the cone's)."""


def object_mesh_vertices(obj: ObjectConfig) -> tuple[tuple[float, float, float], ...]:
    """The mesh an object is made of, in its own frame (z along its axis): a mesh's own vertices, a cone's
    base circle and apex (base at -length/2, apex at +length/2), none for the other shapes."""
    if obj.shape == "mesh":
        return obj.vertices
    if obj.shape != "cone":
        return ()
    r, h = obj.radius_m, 0.5 * obj.length_m
    ring = [
        (r * math.cos(2 * math.pi * k / CONE_SIDES), r * math.sin(2 * math.pi * k / CONE_SIDES), -h)
        for k in range(CONE_SIDES)
    ]
    return (*ring, (0.0, 0.0, h))


def object_shape_xml(obj: ObjectConfig) -> str:
    """The shape attributes of an object's geom: its type, size and orientation (from its axis)."""
    norm = math.sqrt(sum(v * v for v in obj.axis))
    axis = [v / norm for v in obj.axis]
    if obj.shape in ("cylinder", "capsule"):
        half = 0.5 * obj.length_m
        ends = [v * -half for v in axis] + [v * half for v in axis]
        return f'type="{obj.shape}" fromto="{_v(*ends)}" size="{_f(obj.radius_m)}"'
    zaxis = f'zaxis="{_v(*axis)}"'
    if obj.shape == "sphere":
        return f'type="sphere" size="{_f(obj.radius_m)}"'
    if obj.shape == "box":
        return f'type="box" size="{_v(obj.radius_m, obj.radius_m, 0.5 * obj.length_m)}" {zaxis}'
    if obj.shape == "ellipsoid":
        return f'type="ellipsoid" size="{_v(obj.radius_m, obj.radius_m, 0.5 * obj.length_m)}" {zaxis}'
    return f'type="mesh" mesh="{obj.name}_mesh" {zaxis}'  # cone, mesh: the asset object_mesh_vertices made
