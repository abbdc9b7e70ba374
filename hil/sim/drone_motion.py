"""Scripted drone motion for a lockstep run: piecewise-constant acceleration in the world frame.

The arm hangs from the drone and the plant simulates it in the drone's frame
(:mod:`hil.sim.plant`): the drone's
linear acceleration ``a`` enters as the fictitious force ``−m·a`` on every body of the scene, i.e. gravity
becomes ``g − a`` (hanging mounting only). A :class:`DroneMotion` therefore **holds the drone's pose and
applies only the acceleration**. Why not integrate the pose as well:

- the acceleration is the whole effect of a translating drone on what hangs from it; the scene (the arm, the
  objects, their supports) lives in the drone's frame, so this is exact for a drone that does not rotate
  (rotational fictitious forces are neglected, as the plant neglects them);
- moving the ``drone`` mocap body too would count the motion twice and wrongly: MuJoCo gives a mocap body no
  velocity, so the arm would be teleported without inertia, through objects and supports that stay put in
  the world, and 1 s at 2 m/s² is a metre of travel for a scene a few centimetres wide.

The acceleration is piecewise constant (each :class:`AccelSegment` a start, a duration and a vector), so a
step in acceleration is an instantaneous jerk: harsher on a swinging load than a real drone's ramp, so a
load that survives it survives the real manoeuvre too. Everything here is frozen and picklable (plans
carry it across process pools), and :class:`DroneMotionPlayer` applies it to the plant only when the
acceleration changes: nothing is computed or allocated on the ticks in between.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Final

from hil.sim.plant import Plant

__all__ = ["AccelSegment", "DroneMotion", "DroneMotionPlayer", "Vector3", "accelerate_and_brake"]

Vector3 = tuple[float, float, float]

ZERO: Final[Vector3] = (0.0, 0.0, 0.0)
NEVER_US: Final = 1 << 62
"""A time no run reaches (the player's next change once the motion is over)."""


def _time_us(name: str, value: object) -> int:
    if isinstance(value, bool) or not isinstance(value, int):
        raise ValueError(f"{name} must be an integer number of microseconds, got {value!r}")
    return value


@dataclass(frozen=True, slots=True)
class AccelSegment:
    """The drone accelerates at ``accel_m_s2`` (world frame) from ``start_us`` for ``duration_us``.

    Raises:
        ValueError: a negative start, a duration that is not positive, or an acceleration that is not
            three finite numbers.
    """

    start_us: int
    duration_us: int
    accel_m_s2: Vector3

    def __post_init__(self) -> None:
        if _time_us("start_us", self.start_us) < 0:
            raise ValueError(f"start_us must be >= 0, got {self.start_us}")
        if _time_us("duration_us", self.duration_us) <= 0:
            raise ValueError(f"duration_us must be > 0, got {self.duration_us}")
        acc: Sequence[object] = self.accel_m_s2
        if isinstance(acc, str | bytes) or len(acc) != 3:
            raise ValueError(f"accel_m_s2 must be three numbers (x, y, z), got {acc!r}")
        vec = []
        for a in acc:
            if isinstance(a, bool) or not isinstance(a, int | float) or not math.isfinite(a):
                raise ValueError(f"accel_m_s2 must be three finite numbers (x, y, z), got {acc!r}")
            vec.append(float(a))
        object.__setattr__(self, "accel_m_s2", (vec[0], vec[1], vec[2]))

    @property
    def end_us(self) -> int:
        """When the segment ends (its acceleration no longer applies from this time)."""
        return self.start_us + self.duration_us


def accelerate_and_brake(start_us: int, accel_m_s2: Sequence[float], duration_us: int) -> list[AccelSegment]:
    """Accelerate at ``accel_m_s2`` for ``duration_us``, then brake as hard for as long (back to rest).

    Raises:
        ValueError: as :class:`AccelSegment`.
    """
    acc = tuple(accel_m_s2)
    if len(acc) != 3:
        raise ValueError(f"accel_m_s2 must be three numbers (x, y, z), got {acc!r}")
    forward = AccelSegment(start_us, duration_us, (acc[0], acc[1], acc[2]))
    ax, ay, az = forward.accel_m_s2
    return [forward, AccelSegment(forward.end_us, duration_us, (-ax, -ay, -az))]


@dataclass(frozen=True, slots=True)
class DroneMotion:
    """A drone's scripted motion: its acceleration over time, zero outside the segments (pose held).

    Args:
        segments: in time order, none overlapping another (one may start where the previous ends).

    Raises:
        ValueError: no segment, or segments out of order or overlapping.
    """

    segments: tuple[AccelSegment, ...]

    def __post_init__(self) -> None:
        segs = tuple(self.segments)
        if not segs:
            raise ValueError("a drone motion needs at least one segment")
        for i, (a, b) in enumerate(itertools.pairwise(segs)):
            if b.start_us < a.end_us:
                raise ValueError(
                    f"drone motion segment {i + 1} starts at {b.start_us} us, before segment {i} ends "
                    f"at {a.end_us} us"
                )
        object.__setattr__(self, "segments", segs)

    @property
    def end_us(self) -> int:
        """When the last segment ends (the acceleration is zero from then on)."""
        return self.segments[-1].end_us

    def accel_at(self, t_us: int) -> Vector3:
        """The acceleration in force at ``t_us`` (a segment covers ``[start_us, end_us)``)."""
        for s in self.segments:
            if s.start_us <= t_us < s.end_us:
                return s.accel_m_s2
        return ZERO

    def changes(self) -> tuple[tuple[int, Vector3], ...]:
        """Every time the acceleration changes, with the value from then on, in time order."""
        out: list[tuple[int, Vector3]] = []
        for s, nxt in zip(self.segments, (*self.segments[1:], None), strict=True):
            out.append((s.start_us, s.accel_m_s2))
            if nxt is None or nxt.start_us > s.end_us:
                out.append((s.end_us, ZERO))
        return tuple(out)


class DroneMotionPlayer:
    """Applies a :class:`DroneMotion` to a plant, in the plant's (physics) time.

    Call :meth:`apply` before each control period once the plant's time has reached :attr:`next_us`; the
    acceleration set then holds for the periods until the next change. The drone's pose is kept as it is.

    Args:
        motion: the motion to play.
        period_us: the plant's control period: every change must fall on it, so that no segment is
            shortened or skipped between two periods.

    Raises:
        ValueError: a change that does not fall on the control period.
    """

    def __init__(self, motion: DroneMotion, period_us: int) -> None:
        self._changes = motion.changes()
        for t_us, _ in self._changes:
            if t_us % period_us:
                raise ValueError(
                    f"the drone motion changes at {t_us} us, not on the {period_us} us control period"
                )
        self._i = 0
        self.next_us = self._changes[0][0]
        """Plant time of the next change (:data:`NEVER_US` once the motion is over)."""

    def apply(self, plant: Plant) -> None:
        """Set the acceleration in force at the plant's time (the last change due wins)."""
        now_us, changes = plant.time_us, self._changes
        acc: Vector3 | None = None
        while self._i < len(changes) and changes[self._i][0] <= now_us:
            acc = changes[self._i][1]
            self._i += 1
        self.next_us = changes[self._i][0] if self._i < len(changes) else NEVER_US
        if acc is not None:
            pose = plant.drone_pose()
            plant.set_drone_pose(pose.pos_m.tolist(), pose.quat_wxyz.tolist(), acc)
