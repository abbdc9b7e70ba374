"""Running maxima of what makes a simulated figure untrustworthy: penetration, tension, limit overshoot.

:class:`ExtremesMonitor` is updated by :class:`hil.sim.plant.Plant` at the end of every control period and
read
through :meth:`hil.sim.plant.Plant.extremes`. Every experiment and scenario reports these beside its figures.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import mujoco
import numpy as np
from numpy.typing import NDArray

from hil.sim.types import PhysicsExtremes

__all__ = ["ExtremesMonitor", "object_radii"]


class ExtremesMonitor:
    """Largest arm-object penetration, cable tension and joint-limit overshoot since :meth:`reset`.

    Args:
        m: the compiled ``mujoco.MjModel``.
        unit_bodies: body ids of the arm's units.
        object_radii_m: radius of each object, by its body id.
        tension_adr: ``sensordata`` address of each cable's tension sensor.
        limit_rad: the joints' bending limit Δθ.
    """

    def __init__(
        self,
        m: Any,
        unit_bodies: Sequence[int],
        object_radii_m: dict[int, float],
        tension_adr: Sequence[int],
        limit_rad: float,
    ) -> None:
        body = np.asarray(m.geom_bodyid)
        units = np.asarray(unit_bodies)
        self._is_arm: NDArray[np.bool_] = np.isin(body, units)
        # Radius of the object each geom belongs to; 0 for geoms that are not an object's.
        radius = np.zeros(m.ngeom)
        for b, r in object_radii_m.items():
            radius[body == b] = r
        self._radius = radius
        self._tension_adr = list(tension_adr)
        self._limit_rad = limit_rad
        self.reset()

    def reset(self) -> None:
        """Forget the maxima."""
        self._pen_m = 0.0
        self._ratio = 0.0
        self._tension_n = 0.0
        self._overshoot_rad = 0.0

    def update(self, d: Any, joint_angles_rad: NDArray[np.float64]) -> None:
        """Take the state at the end of a control period (``joint_angles_rad``: bending angle per joint)."""
        sens = d.sensordata
        for adr in self._tension_adr:
            t = sens[adr]
            if t > self._tension_n:
                self._tension_n = float(t)
        over = float(np.abs(joint_angles_rad).max(initial=0.0)) - self._limit_rad
        if over > self._overshoot_rad:
            self._overshoot_rad = over
        if d.ncon == 0:
            return
        con = d.contact
        dist = con.dist
        if not (dist < 0.0).any():
            return
        geom = con.geom
        arm = self._is_arm[geom]
        radius = self._radius[geom]
        # A contact between a unit and an object: the radius of its other side.
        other = np.where(arm[:, 0], radius[:, 1], np.where(arm[:, 1], radius[:, 0], 0.0))
        hit = (other > 0.0) & (dist < 0.0)
        if not hit.any():
            return
        depth = -dist[hit]
        pen = float(depth.max())
        if pen > self._pen_m:
            self._pen_m = pen
        ratio = float((depth / other[hit]).max())
        if ratio > self._ratio:
            self._ratio = ratio

    def include(self, earlier: PhysicsExtremes) -> None:
        """Carry maxima measured before (by the monitor of a model this one replaced)."""
        self._pen_m = max(self._pen_m, earlier.penetration_m)
        self._ratio = max(self._ratio, earlier.penetration_ratio)
        self._tension_n = max(self._tension_n, earlier.tension_n)
        self._overshoot_rad = max(self._overshoot_rad, earlier.limit_overshoot_rad)

    def extremes(self) -> PhysicsExtremes:
        """The maxima since :meth:`reset`."""
        return PhysicsExtremes(self._pen_m, self._ratio, self._tension_n, self._overshoot_rad)


def object_radii(m: Any, objects: Sequence[tuple[str, float]]) -> dict[int, float]:
    """``{body id: radius}`` of the named objects of ``m``."""
    return {int(mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, name)): r for name, r in objects}
