"""Stick -> cable-tension mapping: pull-only, clamped per cable, slew-rate limited.

Three cables sit at 120° around the arm. A bending moment of magnitude ``m`` toward ``direction`` is
made pull-only with the smallest tensions by

    share_i = (2 / n) * (cos(direction - angle_i) - min_j cos(direction - angle_j))

(n = 3 cables with sum(unit vectors) = 0, so the common offset adds no moment): toward a cable that
cable alone pulls ``m``; between two cables both pull ``m``. Each cable's target is

    pretension + common + bend * share_i, clamped to [pretension, tension_max]

and the tension actually commanded moves toward the target by at most ``slew_n_per_s * dt``.

Stick conventions (DBUS channels, ±660): left stick vertical ch3 up = common tension (curl), centred or
down = none; right stick (ch0 = x right, ch1 = y up) = bending, direction ``atan2(ch1, ch0)`` measured
from cable 1 (at ``cable_angles_deg[0]``, 0° by default) counter-clockwise, magnitude = deflection.
"""

from __future__ import annotations

import math
from collections.abc import MutableSequence, Sequence

from controller.config import MOTOR_COUNT, FirmwareConfig

__all__ = ["CableMapper", "TensionSlew", "bend_shares"]

_CH_LIMIT = 660.0  # DBUS: |channel| <= 660 when valid


def bend_shares(direction_rad: float, cable_angles_rad: Sequence[float]) -> tuple[float, ...]:
    """Per-cable shares (>= 0) of a unit bending moment toward ``direction_rad``, pull-only.

    Exact for cables evenly spread around the arm (the moments of a common tension cancel).
    """
    n = len(cable_angles_rad)
    cosines = [math.cos(direction_rad - a) for a in cable_angles_rad]
    low = min(cosines)
    k = 2.0 / n
    return tuple(k * (c - low) for c in cosines)


class CableMapper:
    """Targets per cable from the sticks, the grasp curl, or host tensions (preallocated)."""

    def __init__(self, config: FirmwareConfig) -> None:
        """Create the mapper for ``config`` (see :meth:`configure`)."""
        self.targets_n: list[float] = [0.0] * MOTOR_COUNT
        """The last computed targets, clamped (written in place)."""
        self.configure(config)

    def configure(self, config: FirmwareConfig) -> None:
        """Take new limits (called at start-up and when a parameter changes)."""
        m = config.mapping
        self._angles_rad = tuple(math.radians(a) for a in m.cable_angles_deg)
        self._pretension_n = m.pretension_n
        self._tension_max_n = m.tension_max_n
        self._common_per_count = m.common_max_n / _CH_LIMIT
        self._bend_max_n = m.bend_max_n
        self._deadband = m.stick_deadband
        self._k = 2.0 / MOTOR_COUNT

    def _clamp(self, value: float) -> float:
        lo = self._pretension_n
        hi = self._tension_max_n
        return lo if value < lo else hi if value > hi else value

    def _shape(self, common_n: float, bend_n: float, direction_rad: float) -> list[float]:
        out = self.targets_n
        lo = self._pretension_n
        hi = self._tension_max_n
        base = lo + common_n
        if bend_n <= 0.0:
            v = lo if base < lo else hi if base > hi else base
            for i in range(MOTOR_COUNT):
                out[i] = v
            return out
        a0, a1, a2 = self._angles_rad
        c0 = math.cos(direction_rad - a0)
        c1 = math.cos(direction_rad - a1)
        c2 = math.cos(direction_rad - a2)
        low = min(c0, c1, c2)
        scale = bend_n * self._k
        # clamped to [pretension, tension_max] inline (:meth:`_clamp`): this runs every control tick
        v = base + scale * (c0 - low)
        out[0] = lo if v < lo else hi if v > hi else v
        v = base + scale * (c1 - low)
        out[1] = lo if v < lo else hi if v > hi else v
        v = base + scale * (c2 - low)
        out[2] = lo if v < lo else hi if v > hi else v
        return out

    def manual(self, channels: Sequence[int]) -> list[float]:
        """MANUAL mode targets from DBUS channels (ch0, ch1 right stick; ch3 left vertical)."""
        db = self._deadband
        x = channels[0]
        y = channels[1]
        up = channels[3]
        common_n = (up - db) * self._common_per_count if up > db else 0.0
        mag = math.hypot(x, y)
        if mag <= db:
            return self._shape(common_n, 0.0, 0.0)
        frac = (mag - db) / (_CH_LIMIT - db)
        bend_n = self._bend_max_n * (frac if frac < 1.0 else 1.0)
        return self._shape(common_n, bend_n, math.atan2(y, x))

    def curl(self, curl_n: float, direction_rad: float) -> list[float]:
        """Targets for a curl (bending) tension toward ``direction_rad`` (the grasp strategy)."""
        return self._shape(0.0, curl_n if curl_n > 0.0 else 0.0, direction_rad)

    def direct(self, tensions_n: Sequence[float]) -> list[float]:
        """DIRECT mode: host tensions per cable, clamped to [pretension, tension_max]."""
        out = self.targets_n
        for i in range(MOTOR_COUNT):
            out[i] = self._clamp(tensions_n[i])
        return out

    def stick_direction(self, channels: Sequence[int], min_fraction: float) -> float | None:
        """Right-stick direction (rad) if deflected by at least ``min_fraction`` of full scale, else None."""
        x = channels[0]
        y = channels[1]
        if math.hypot(x, y) < min_fraction * _CH_LIMIT:
            return None
        return math.atan2(y, x)


class TensionSlew:
    """Commanded tensions that follow their targets at a bounded rate (preallocated state).

    While inactive the tensions are 0 (no current); on activation they start at the pretension floor
    (pull-only: an active cable is never below it) and then slew toward their targets.
    """

    def __init__(self, config: FirmwareConfig) -> None:
        """Create the limiter for ``config`` (see :meth:`configure`)."""
        self.tensions_n: list[float] = [0.0] * MOTOR_COUNT
        """Commanded tensions (written in place)."""
        self.active = False
        self.configure(config)

    def configure(self, config: FirmwareConfig) -> None:
        """Take a new rate limit and floor."""
        self._rate_n_per_us = config.mapping.slew_n_per_s / 1e6
        self._pretension_n = config.mapping.pretension_n

    def reset(self) -> None:
        """Go inactive: tensions 0."""
        self.active = False
        t = self.tensions_n
        for i in range(MOTOR_COUNT):
            t[i] = 0.0

    def step(self, targets_n: Sequence[float], dt_us: int) -> MutableSequence[float]:
        """Move each tension toward its target by at most ``slew_n_per_s * dt``; return the tensions."""
        t = self.tensions_n
        floor = self._pretension_n
        if not self.active:
            self.active = True
            for i in range(MOTOR_COUNT):
                t[i] = floor
        step = self._rate_n_per_us * dt_us
        for i in range(MOTOR_COUNT):
            cur = t[i]
            d = targets_n[i] - cur
            if d > step:
                d = step
            elif d < -step:
                d = -step
            cur += d
            t[i] = cur if cur > floor else floor
        return t
