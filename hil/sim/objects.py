"""The objects of a plant's scene: placing, holding on a support, releasing, throwing and loading them.

:class:`SceneObjects` works on one ``MjModel``/``MjData`` pair; :class:`hil.sim.plant.Plant` makes a new one
whenever it rebuilds its model and exposes its methods under the same names (``plant.hold_object`` ...).
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Iterable, Sequence
from typing import Any, Protocol

import mujoco

from hil.sim.config import ObjectConfig
from hil.sim.types import Contact, Pose, finite_vector, unit_quat

__all__ = ["SceneObjects", "contact_angles", "contact_units", "contact_wrap_deg", "wrap_deg"]


class SceneObjects:
    """The objects of one compiled model (see :class:`hil.sim.config.ObjectConfig`).

    Args:
        m: the ``mujoco.MjModel``.
        d: its ``mujoco.MjData``.
        objects: the objects the model was built with.
    """

    def __init__(self, m: Any, d: Any, objects: Sequence[ObjectConfig]) -> None:
        def bid(name: str) -> int:
            return int(mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, name))

        self._m = m
        self._d = d
        self.names = tuple(o.name for o in objects)
        """Names of the objects, in model order."""
        self.bodies = {o.name: bid(o.name) for o in objects}
        """Body id of each object."""
        self.supports = {
            o.name: (
                int(m.body_mocapid[bid(f"{o.name}_support")]),
                int(mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_EQUALITY, f"{o.name}_support")),
            )
            for o in objects
            if o.mass_kg is not None
        }
        """Mocap id and weld id of each free object's support."""

    def set_object_pose(
        self, name: str, pos_m: Sequence[float], quat_wxyz: Sequence[float] = (1.0, 0.0, 0.0, 0.0)
    ) -> None:
        """Place an object (fixed: moves its body; free: sets its position and stops it).

        Raises:
            KeyError: no object of that name.
            ValueError: bad vector.
        """
        if name not in self.bodies:
            raise KeyError(f"no object named {name!r}; objects: {', '.join(self.names) or 'none'}")
        pos = finite_vector("pos_m", pos_m, 3)
        quat = unit_quat(quat_wxyz)
        m, d = self._m, self._d
        body = self.bodies[name]
        jnt = int(m.body_jntadr[body])
        if jnt < 0:
            m.body_pos[body] = pos
            m.body_quat[body] = quat
        else:
            qa, da = int(m.jnt_qposadr[jnt]), int(m.jnt_dofadr[jnt])
            d.qpos[qa : qa + 3] = pos
            d.qpos[qa + 3 : qa + 7] = quat
            d.qvel[da : da + 6] = 0.0
        mujoco.mj_forward(m, d)

    def object_pose(self, name: str) -> Pose:
        """Current pose of an object.

        Raises:
            KeyError: no object of that name.
        """
        if name not in self.bodies:
            raise KeyError(f"no object named {name!r}")
        b = self.bodies[name]
        return Pose(self._d.xpos[b].copy(), self._d.xquat[b].copy())

    def hold_object(
        self, name: str, pos_m: Sequence[float] | None = None, quat_wxyz: Sequence[float] | None = None
    ) -> None:
        """Hold a free object still on its support (a weld to a mocap body), where it is or at a pose.

        The support is a stiff constraint, so the arm can push against a held object as against a fixed
        one (an object on a stand, or offered by a hand). :meth:`release_object` lets it go.

        Raises:
            KeyError: no free object of that name (fixed objects are always held).
            ValueError: bad vector.
        """
        mocap, eq = self._support(name)
        if pos_m is not None or quat_wxyz is not None:
            here = self.object_pose(name)
            pos: Sequence[float] = here.pos_m.tolist() if pos_m is None else pos_m
            quat: Sequence[float] = here.quat_wxyz.tolist() if quat_wxyz is None else quat_wxyz
            self.set_object_pose(name, pos, quat)
        else:
            mujoco.mj_kinematics(self._m, self._d)  # xpos after mj_step lags qpos by one step
        d = self._d
        body = self.bodies[name]
        d.mocap_pos[mocap] = d.xpos[body]
        d.mocap_quat[mocap] = d.xquat[body]
        d.eq_active[eq] = 1

    def _support(self, name: str) -> tuple[int, int]:
        """The mocap body and the weld of a free object's support.

        Raises:
            KeyError: no free object of that name.
        """
        if name not in self.supports:
            raise KeyError(
                f"no free object named {name!r}; free objects: {', '.join(self.supports) or 'none'}"
            )
        return self.supports[name]

    def release_object(self, name: str) -> None:
        """Take a held free object off its support (it keeps its velocity, zero if it was held).

        Raises:
            KeyError: no free object of that name.
        """
        self._d.eq_active[self._support(name)[1]] = 0

    def object_held(self, name: str) -> bool:
        """Whether a free object is on its support (fixed objects: always True).

        Raises:
            KeyError: no object of that name.
        """
        if name not in self.bodies:
            raise KeyError(f"no object named {name!r}")
        if name not in self.supports:
            return True
        return bool(self._d.eq_active[self.supports[name][1]])

    def set_object_velocity(
        self,
        name: str,
        linear_m_s: Sequence[float],
        angular_rad_s: Sequence[float] = (0.0, 0.0, 0.0),
    ) -> None:
        """Give a free object a velocity, e.g. to throw it at the arm.

        ``linear_m_s`` is in the world frame; ``angular_rad_s`` in the object's own frame (MuJoCo's free
        joint convention).

        Raises:
            KeyError: no free object of that name.
            ValueError: bad vector.
        """
        self._support(name)
        lin = finite_vector("linear_m_s", linear_m_s, 3)
        ang = finite_vector("angular_rad_s", angular_rad_s, 3)
        m, d = self._m, self._d
        jnt = int(m.body_jntadr[self.bodies[name]])
        da = int(m.jnt_dofadr[jnt])
        d.qvel[da : da + 3] = lin
        d.qvel[da + 3 : da + 6] = ang

    def apply_object_force(self, name: str, force_n: Sequence[float]) -> None:
        """Push a free object with a constant external force (world frame, at its centre of mass) until
        changed; ``(0, 0, 0)`` removes it (so does :meth:`add_object`, which rebuilds the data). Used as an
        extra load: a downward force F acts like F/g kg more.

        Raises:
            KeyError: no free object of that name.
            ValueError: bad vector.
        """
        self._support(name)
        force = finite_vector("force_n", force_n, 3)
        self._d.xfrc_applied[self.bodies[name], :3] = force


class ContactView(Protocol):
    """What the wrap measures need of a plant (:class:`hil.sim.plant.Plant` has it)."""

    def contacts(self) -> list[Contact]: ...

    def object_pose(self, name: str) -> Pose: ...


def contact_units(plant: ContactView, name: str) -> set[str]:
    """The arm units touching the object ``name``."""
    return {c.unit for c in plant.contacts() if c.other == name}


def contact_wrap_deg(plant: ContactView, name: str) -> float:
    """Angular extent of the arm's contacts around an object's axis (y), in degrees (0..360).

    The largest gap between contact directions is the part not wrapped; 360° minus it is the wrap.
    """
    return wrap_deg(contact_angles(plant, name))


def contact_angles(plant: ContactView, name: str) -> list[float]:
    """Directions of the arm's contacts on the object ``name``, around its axis (y), in radians."""
    centre = plant.object_pose(name).pos_m
    mine = [c.pos_m for c in plant.contacts() if c.other == name]
    return [math.atan2(p[2] - centre[2], p[0] - centre[0]) for p in mine]


def wrap_deg(angles_rad: Iterable[float]) -> float:
    """360° minus the largest gap between contact directions (radians); 0 with fewer than two."""
    angles = sorted(angles_rad)
    if len(angles) < 2:
        return 0.0
    gaps = [b - a for a, b in itertools.pairwise(angles)] + [angles[0] + 2 * math.pi - angles[-1]]
    return math.degrees(2 * math.pi - max(gaps))
