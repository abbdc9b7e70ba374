"""Ten objects an array of arms meets (issue 27, item 4), each with its size, mass, friction and reason.

The supplement's Table S2 reports arrays grasping "ten objects" without describing them, so these are
chosen to span what decides a grasp by arms that wrap around an object from several sides:

- curvature: everywhere the same (spheres), none on faces (cube, disc), changing along the object
  (ellipsoid, cone, an irregular stone);
- aspect: compact (sphere, cube, stone), long (rod, lying cylinder), flat (disc);
- orientation of the long axis against the ring of arms: along it (standing cylinder), across it (lying
  cylinder, rod);
- a taper that lets a ring of wraps slide off one end (cone);
- size and weight: from a light 25 mm ball (near the smallest a single arm holds) to a 70 g stone.

Masses are of everyday objects of these sizes in plastic, wood or stone (10-70 g); frictions are the
usual dry coefficients against the arms' TPU (0.5 for smooth plastic, 0.6 for wood, 0.7 for stone, 0.9 for
rubber). The arm units' own friction is the plant's (``ArmConfig.geom_friction``); MuJoCo takes the larger
of the two sides'.

Every object is a free body with a support (:meth:`hil.sim.plant.Plant.hold_object`); it waits out of
reach at :data:`~hil.trial.scene.FAR_M` until a trial places it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from hil.sim.config import ObjectConfig
from hil.trial.scene import FAR_M, OBJ

__all__ = ["ARRAY_OBJECTS", "ArrayObject", "stone_vertices"]

_ALONG_Y = (0.0, 1.0, 0.0)
_UP = (0.0, 0.0, 1.0)


def stone_vertices(radius_m: float, seed: int = 7, n: int = 24) -> tuple[tuple[float, float, float], ...]:
    """An irregular convex stone: ``n`` points on a sphere of ``radius_m``, each pushed in or out by up to
    25 % and the whole flattened 20 % along z and stretched 20 % along x (seeded: the same stone every run).
    MuJoCo collides with their convex hull."""
    rng = np.random.default_rng(seed)
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    r = radius_m * rng.uniform(0.75, 1.25, size=(n, 1))
    p = d * r * np.array([1.2, 1.0, 0.8])
    return tuple((round(float(x), 6), round(float(y), 6), round(float(z), 6)) for x, y, z in p)


@dataclass(frozen=True)
class ArrayObject:
    """One of the ten objects.

    Attributes:
        key: its short name (``sphere``, ``cube`` ...).
        what: what it stands for, in words.
        why: what it tests in a grasp.
        config: the object, named :data:`~hil.trial.scene.OBJ`, waiting at :data:`~hil.trial.scene.FAR_M`.
    """

    key: str
    what: str
    why: str
    config: ObjectConfig

    @property
    def size_m(self) -> float:
        """Its largest extent (the diameter of the smallest sphere about its centre that holds it)."""
        c = self.config
        if c.shape == "mesh":
            return 2.0 * max(math.dist((0.0, 0.0, 0.0), v) for v in c.vertices)
        if c.shape == "sphere":
            return 2.0 * c.radius_m
        across = math.sqrt(2.0) * c.radius_m if c.shape == "box" else c.radius_m
        return 2.0 * math.hypot(across, 0.5 * c.length_m)

    def placed(self, pos_m: tuple[float, float, float]) -> ObjectConfig:
        """The object at ``pos_m``."""
        return replace(self.config, pos_m=pos_m)


def _obj(
    key: str, what: str, why: str, shape: str, r: float, length: float, mass: float, mu: float, **kw: object
) -> ArrayObject:
    cfg = ObjectConfig(OBJ, r, length, FAR_M, mass_kg=mass, friction=mu, shape=shape, **kw)  # type: ignore[arg-type]
    cfg.validate()
    return ArrayObject(key, what, why, cfg)


ARRAY_OBJECTS: tuple[ArrayObject, ...] = (
    _obj(
        "sphere",
        "a 60 mm plastic ball, 50 g",
        "every contact normal points at the centre: a grasp holds only if the wraps surround it",
        "sphere",
        0.030,
        0.060,
        0.050,
        0.5,
    ),
    _obj(
        "small-sphere",
        "a 25 mm rubber ball, 10 g",
        "small and light: near the smallest a wrap closes on; few arms touch it at once",
        "sphere",
        0.0125,
        0.025,
        0.010,
        0.9,
    ),
    _obj(
        "cube",
        "a 50 mm wooden cube, 60 g",
        "flat faces and hard edges: contacts gather at the edges, a wrap cannot follow a face",
        "box",
        0.025,
        0.050,
        0.060,
        0.6,
        axis=_UP,
    ),
    _obj(
        "standing-cylinder",
        "a 40 x 80 mm bottle standing, 50 g",
        "long axis along the ring's axis: every arm wraps the same side-on circle",
        "cylinder",
        0.020,
        0.080,
        0.050,
        0.5,
        axis=_UP,
    ),
    _obj(
        "lying-cylinder",
        "a 40 x 100 mm can on its side, 50 g",
        "long axis across the ring: the arms on its ends find nothing to wrap (the single arm's object)",
        "cylinder",
        0.020,
        0.100,
        0.050,
        0.5,
        axis=_ALONG_Y,
    ),
    _obj(
        "cone",
        "a 60 mm x 80 mm plastic cone, point up, 40 g",
        "a taper: wraps around the narrow end slide off it",
        "cone",
        0.030,
        0.080,
        0.040,
        0.5,
        axis=_UP,
    ),
    _obj(
        "ellipsoid",
        "a 50 x 90 mm egg-shaped fruit lying, 60 g",
        "curvature that changes along the object: a wrap tightens where it is most curved",
        "ellipsoid",
        0.025,
        0.090,
        0.060,
        0.6,
        axis=_ALONG_Y,
    ),
    _obj(
        "rod",
        "a 10 x 200 mm wooden rod lying, 30 g",
        "thin and long: only the arms near its middle reach it, and it levers out of a one-sided grasp",
        "cylinder",
        0.005,
        0.200,
        0.030,
        0.6,
        axis=_ALONG_Y,
    ),
    _obj(
        "disc",
        "a 90 x 15 mm plastic lid lying flat, 40 g",
        "flat and wide: arms reach its rim from below and above, little to wrap around",
        "cylinder",
        0.045,
        0.015,
        0.040,
        0.5,
        axis=_UP,
    ),
    _obj(
        "stone",
        "an irregular 60 mm stone, 70 g",
        "no symmetry to rely on, the heaviest: a grasp must hold where the wraps happen to land",
        "mesh",
        0.030,
        0.060,
        0.070,
        0.7,
        vertices=stone_vertices(0.030),
    ),
)
"""The ten objects, compact to long to flat (keys unique)."""
