"""The scene every trial is set in: board-time units, where the drone, the arm's base and a waiting object
are, and what counts as a held object.

The drone sits at (0, 0, 1) m and the arm's base (its mount) 20 mm below it; the arm hangs along −z and
cable 0 is on its +x side. Object positions are given relative to the base, in the x-z plane (the plane
cable 0 bends the arm in): :func:`world_m`.
"""

from __future__ import annotations

from hil.sim.config import ObjectConfig

MS = 1000
"""Microseconds per millisecond (board time is in µs)."""
S = 1_000_000
"""Microseconds per second."""
DRONE_Z_M = 1.0
BASE_Z_M = DRONE_Z_M - 0.02  # the mount is 20 mm under the drone (DroneConfig.mount_offset_m)
FAR_M = (0.6, 0.0, 0.4)  # where an object waits, out of reach, until its trial places it
OBJ = "target"
"""Name of the one object of a trial in the plant's scene."""
HELD_DROP_MM = 60.0
"""A released object counts as held if it ends up less than this below where it was let go (the wrap
settles and swings it by a few centimetres; a dropped object falls far more) ..."""
HELD_SPEED_M_S = 0.05
"""... and is not moving faster than this at the end (not slipping out)."""
SUCCESS_WRAP_DEG = 180.0
"""A grasp succeeds if the object is held and the arm's contacts span at least half its circumference
(fixed before the strategy experiment was run; eq. 15's "half way around")."""


PENETRATION_GOAL_M = 0.001
PENETRATION_GOAL_RATIO = 0.1
"""The experiments' physics goal for arm-object contacts: a penetration under 1 mm or under 10 % of the
object's radius (docs/experiments.md)."""


def beyond_goal(depth_m: float, radius_m: float) -> bool:
    """An arm-object overlap of ``depth_m`` on an object of ``radius_m`` misses the penetration goal (NaN:
    no)."""
    return depth_m > PENETRATION_GOAL_M and depth_m > PENETRATION_GOAL_RATIO * radius_m


def world_m(x_m: float, z_m: float) -> tuple[float, float, float]:
    """World position of a point given relative to the arm's base in the x-z plane."""
    return (x_m, 0.0, BASE_Z_M + z_m)


def target_object(
    radius_m: float, length_m: float, mass_kg: float, friction: float = ObjectConfig.friction
) -> ObjectConfig:
    """The trial's one object (:data:`OBJ`): a free cylinder across the x-z plane, waiting out of reach at
    :data:`FAR_M` until its trial places it."""
    return ObjectConfig(
        OBJ, radius_m=radius_m, length_m=length_m, pos_m=FAR_M, mass_kg=mass_kg, friction=friction
    )
