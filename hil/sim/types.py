"""The plant's value types: its configuration, the poses and contacts its accessors return, and the checks
of the vectors and quaternions its setters take.

They live apart from :mod:`hil.sim.plant` (which re-exports them) so that the MuJoCo physics module stays
about the physics; importing them does not import MuJoCo.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from controller.config import CONTROL_PERIOD_US
from hil.sim.config import ModelConfig

__all__ = ["MAX_ARMS", "BodyPoses", "Contact", "PhysicsExtremes", "PlantConfig", "Pose", "RingConfig"]

FloatArray = NDArray[np.float64]


MAX_ARMS = 8
"""Arms an array may have (the C-board drives up to eight C610s; the supplement's arrays have 2-8 arms)."""


@dataclass(frozen=True)
class RingConfig:
    """Where the arms of an array hang (:mod:`hil.sim.array`).

    Arm ``i`` hangs at angle ``π + 2πi/N`` from the drone's +x, ``ring_radius_m`` from its axis, with its
    cable 0 facing the axis: a one-cable arm curls inwards, around what is under the drone.

    Attributes:
        arms: how many (1..:data:`MAX_ARMS`).
        ring_radius_m: their bases' distance from the drone's axis.
        tilt_rad: each arm's tilt outwards from straight down (0 = hanging plumb).
    """

    arms: int = 4
    ring_radius_m: float = 0.06
    tilt_rad: float = 0.0

    def validate(self) -> None:
        """Raise ``ValueError`` for a value out of range."""
        if isinstance(self.arms, bool) or not isinstance(self.arms, int) or not 1 <= self.arms <= MAX_ARMS:
            raise ValueError(f"arms must be 1..{MAX_ARMS}, got {self.arms!r}")
        if not (math.isfinite(self.ring_radius_m) and 0.0 <= self.ring_radius_m <= 1.0):
            raise ValueError(f"ring_radius_m must be 0..1 m, got {self.ring_radius_m!r}")
        if not (math.isfinite(self.tilt_rad) and abs(self.tilt_rad) <= math.pi / 2):
            raise ValueError(f"tilt_rad must be within ±90°, got {self.tilt_rad!r}")


@dataclass(frozen=True)
class PlantConfig:
    """Configuration of a :class:`Plant`.

    Attributes:
        model: everything the MJCF generator needs besides the design (arm, motors, drone, solver,
            objects).
        control_period_us: length of one :meth:`Plant.step`; must be a whole number of physics steps.
        max_joint_speed_rad_s: any arm joint faster than this counts as divergence.
        max_spool_speed_m_s: any spool (cable) faster than this counts as divergence.
        ring: ``None``: one arm (the classic plant). Else an array of ``ring.arms`` arms of the design on a
            ring under the drone (:mod:`hil.sim.array`), motor ``m`` driving cable ``(m-1) % C`` of arm
            ``(m-1) // C`` (the firmware's layout, ``controller.config``).
        track_extremes: measure :meth:`Plant.extremes` every period (an identification rollout, which
            never reads them, turns it off; the physics is the same either way).
    """

    model: ModelConfig = field(default_factory=ModelConfig)
    control_period_us: int = CONTROL_PERIOD_US
    max_joint_speed_rad_s: float = 5.0e3
    max_spool_speed_m_s: float = 50.0
    ring: RingConfig | None = None
    track_extremes: bool = True

    def validate(self) -> None:
        """Raise ``ValueError`` if a value is out of range."""
        self.model.validate()
        if isinstance(self.control_period_us, bool) or not isinstance(self.control_period_us, int):
            raise ValueError(f"control_period_us must be an int, got {self.control_period_us!r}")
        if self.control_period_us <= 0:
            raise ValueError(f"control_period_us must be > 0, got {self.control_period_us}")
        for name in ("max_joint_speed_rad_s", "max_spool_speed_m_s"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be > 0, got {value!r}")
        if self.ring is not None:
            self.ring.validate()


@dataclass(frozen=True)
class Pose:
    """A position and orientation in world coordinates.

    Attributes:
        pos_m: position, shape (3,).
        quat_wxyz: unit quaternion w, x, y, z (MuJoCo's and viser's convention), shape (4,).
    """

    pos_m: FloatArray
    quat_wxyz: FloatArray


@dataclass(frozen=True)
class BodyPoses:
    """Poses of the drone and every unit, for drawing (drone first, then ``unit_00`` ... tip).

    A unit's frame has its origin on the joint at its base-side face and its axis along −z towards the
    tip; its size is given by :meth:`Plant.unit_dimensions_m`.

    Attributes:
        names: body names, ``("drone", "unit_00", ...)``.
        positions_m: shape (n, 3).
        quats_wxyz: shape (n, 4).
    """

    names: tuple[str, ...]
    positions_m: FloatArray
    quats_wxyz: FloatArray


@dataclass(frozen=True)
class Contact:
    """A contact between a unit and something else.

    Attributes:
        unit: the unit's body name (``unit_07``).
        other: the other body's name (an object's name, or ``world`` for the floor).
        pos_m: contact point, world frame.
        normal_force_n: force along the contact normal (>= 0).
        depth_m: how far the two overlap (0 when they only touch or are within the contact margin).
    """

    unit: str
    other: str
    pos_m: tuple[float, float, float]
    normal_force_n: float
    depth_m: float = 0.0


@dataclass(frozen=True)
class PhysicsExtremes:
    """The worst the physics did over a stretch of simulated time: what says whether a figure can be trusted.

    Sampled at the end of every control period (so a peak inside a period of several physics steps can be
    missed; at the default 1 ms step there is one physics step per period).

    Attributes:
        penetration_m: largest depth of an arm unit inside an object (0 if they never overlapped) [m].
        penetration_ratio: largest such depth over that object's radius.
        tension_n: largest cable tension [N].
        limit_overshoot_rad: largest bending angle of a joint beyond its limit Δθ [rad].
    """

    penetration_m: float
    penetration_ratio: float
    tension_n: float
    limit_overshoot_rad: float

    def as_dict(self) -> dict[str, float]:
        """The fields in SI units, for JSON."""
        return {
            "penetration_m": self.penetration_m,
            "penetration_ratio": self.penetration_ratio,
            "tension_n": self.tension_n,
            "limit_overshoot_rad": self.limit_overshoot_rad,
        }


def finite_vector(name: str, value: Sequence[float], n: int) -> FloatArray:
    """``value`` as a float64 array of ``n`` finite numbers.

    Raises:
        ValueError: another shape, or a NaN or infinity.
    """
    arr = np.asarray(value, dtype=np.float64)
    if arr.shape != (n,) or not np.isfinite(arr).all():
        raise ValueError(f"{name} must be {n} finite numbers, got {value!r}")
    return arr


def unit_quat(value: Sequence[float]) -> FloatArray:
    """``value`` (w, x, y, z) normalised to a unit quaternion.

    Raises:
        ValueError: not four finite numbers, or all zero.
    """
    q = finite_vector("quat_wxyz", value, 4)
    norm = float(np.linalg.norm(q))
    if norm == 0.0:
        raise ValueError("quat_wxyz must be non-zero")
    return q / norm
