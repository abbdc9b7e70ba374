"""The firmware's cables: sticks -> tension targets -> motor currents, and feedback -> cable state.

**Mapping** (:class:`CableMapper`, :class:`TensionSlew`): pull-only, clamped per cable, slew-rate limited.
Three cables sit at 120° around the arm. A bending moment of magnitude ``m`` toward ``direction`` is
made pull-only with the smallest tensions by

    share_i = (2 / n) * (cos(direction - angle_i) - min_j cos(direction - angle_j))

(n = 3 cables with sum(unit vectors) = 0, so the common offset adds no moment): toward a cable that
cable alone pulls ``m``; between two cables both pull ``m``. A two-cable arm (0° and 180°, bending in
its plane) uses ``1/2`` for ``2/n``, so that the cable toward which the stick points pulls
``m·cos(direction - angle)`` and the other none; a one-cable arm bends only toward its cable, which takes
every bending share (1). Each cable's target is

    pretension + common + bend * share_i, clamped to [pretension, tension_max]

and the tension actually commanded moves toward the target by at most ``slew_n_per_s * dt``.

**Arrays** (``controller.config``: motor m = cable (m-1) % C of arm (m-1) // C): the mapping shapes the
C targets of one arm and every arm takes them, so one stick closes every arm together and the grasp
machine drives the array as one gripper. Slew, governor, length-hold and motor model work per motor.

Stick conventions (DBUS channels, ±660): left stick vertical ch3 up = common tension (curl), centred or
down = none; right stick (ch0 = x right, ch1 = y up) = bending, direction ``atan2(ch1, ch0)`` measured
from cable 1 (at ``cable_angles_deg[0]``, 0° by default) counter-clockwise, magnitude = deflection.

**Motor model** (:class:`MotorModel`): cable tension <-> C610 current, and feedback -> cable length,
speed and tension. Tension T [N] on a spool of radius r needs an output torque T·r, i.e. a current T·r /
K_t (K_t at the output shaft, gearbox included), sent as raw units (1000 per amp) and clamped to the
current limit. Feedback: the rotor angle (0..8191 per rotor turn) is unwrapped into multi-turn counts,
divided by the gear ratio into the output angle, and times r gives the cable paid in since the first
feedback. The measured current times K_t / r estimates the tension (the same constant the plant must
use).

**Speed governor** (:meth:`MotorModel.govern`, the output stage of every mode): a spool carries about
1.3 kg of reflected rotor inertia, so a slack cable reeled in fast snaps taut with ``v·sqrt(k·m)`` of
tension (0.5 m/s on a 48 kN/m cable: about 125 N; a slack cable under 20 N reels in at metres per
second). While a cable reels in faster than ``payin_limit_m_per_s`` (from the unfiltered rotor speed:
the filter's lag would let the spool run away) its tension is cut back toward the pretension,
linearly, down to it at twice that speed: a slack cable is reeled in slowly and snaps taut gently,
and a curl that pays cable in faster is slowed to about that speed.

Sign convention: with ``motor_signs[i] = +1`` a positive current reels cable ``i`` in (raises its
tension) and the rotor angle increases while reeling in; ``-1`` mirrors a motor.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, MutableSequence, Sequence

from controller.config import FirmwareConfig
from protocol.c610 import ANGLE_COUNTS, RAW_PER_AMP, MotorFeedback

__all__ = ["CableMapper", "MotorModel", "TensionSlew", "bend_shares"]

_CH_LIMIT = 660.0  # DBUS: |channel| <= 660 when valid


def _share_scale(cables: int) -> float:
    """``k`` of the module notes: 2/n for three cables, 1/2 for two (1 toward a cable)."""
    return 0.5 if cables == 2 else 2.0 / cables


def bend_shares(direction_rad: float, cable_angles_rad: Sequence[float]) -> tuple[float, ...]:
    """Per-cable shares (>= 0) of a unit bending moment toward ``direction_rad``, pull-only.

    Exact for three cables evenly spread around the arm (the moments of a common tension cancel); two
    cables (a planar arm) share ``cos`` of the direction; one cable takes it all (it can only curl).
    """
    n = len(cable_angles_rad)
    if n == 1:
        return (1.0,)
    cosines = [math.cos(direction_rad - a) for a in cable_angles_rad]
    low = min(cosines)
    k = _share_scale(n)
    return tuple(k * (c - low) for c in cosines)


class CableMapper:
    """Targets per motor from the sticks, the grasp curl, or host tensions (preallocated).

    One arm's targets are shaped (:attr:`arm_targets_n`, one per cable) and every arm of an array takes
    them (:attr:`targets_n`, one per motor; the same list when there is one arm).
    """

    def __init__(self, config: FirmwareConfig) -> None:
        """Create the mapper for ``config`` (see :meth:`configure`)."""
        self.targets_n: list[float] = [0.0] * config.motor_count
        """The last computed targets per motor, clamped (written in place)."""
        cables = config.cables_per_arm
        self.arm_targets_n: list[float] = self.targets_n if config.arm_count == 1 else [0.0] * cables
        """The last computed targets of one arm, per cable (written in place)."""
        self._cables = cables
        self._cosines = [0.0] * cables
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
        self._k = _share_scale(len(self._angles_rad))

    def _clamp(self, value: float) -> float:
        lo = self._pretension_n
        hi = self._tension_max_n
        return lo if value < lo else hi if value > hi else value

    def _spread(self) -> list[float]:
        """Every arm takes the arm's targets (nothing to do for one arm: the same list)."""
        out = self.targets_n
        arm = self.arm_targets_n
        if out is not arm:
            c = self._cables
            for i in range(len(out)):
                out[i] = arm[i % c]
        return out

    def _shape(self, common_n: float, bend_n: float, direction_rad: float) -> list[float]:
        out = self.arm_targets_n
        lo = self._pretension_n
        hi = self._tension_max_n
        base = lo + common_n
        if bend_n <= 0.0:
            v = lo if base < lo else hi if base > hi else base
            for i in range(self._cables):
                out[i] = v
            return self._spread()
        if self._cables != 3:
            return self._shape_few(base, bend_n, direction_rad)
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
        return self._spread()

    def _shape_few(self, base: float, bend_n: float, direction_rad: float) -> list[float]:
        """:meth:`_shape` for a one- or two-cable arm (shares as :func:`bend_shares`)."""
        out = self.arm_targets_n
        lo = self._pretension_n
        hi = self._tension_max_n
        if self._cables == 1:
            v = base + bend_n
            out[0] = lo if v < lo else hi if v > hi else v
            return self._spread()
        cos = self._cosines
        for i, a in enumerate(self._angles_rad):
            cos[i] = math.cos(direction_rad - a)
        low = min(cos)
        scale = bend_n * self._k
        for i in range(self._cables):
            v = base + scale * (cos[i] - low)
            out[i] = lo if v < lo else hi if v > hi else v
        return self._spread()

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
        """DIRECT mode: host tensions per cable of an arm (every arm alike), clamped to [pretension,
        tension_max]."""
        out = self.arm_targets_n
        for i in range(self._cables):
            out[i] = self._clamp(tensions_n[i])
        return self._spread()

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
        self.tensions_n: list[float] = [0.0] * config.motor_count
        """Commanded tensions per motor (written in place)."""
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
        for i in range(len(t)):
            t[i] = 0.0

    def step(self, targets_n: Sequence[float], dt_us: int) -> MutableSequence[float]:
        """Move each tension toward its target by at most ``slew_n_per_s * dt``; return the tensions."""
        t = self.tensions_n
        floor = self._pretension_n
        n = len(t)
        if not self.active:
            self.active = True
            for i in range(n):
                t[i] = floor
        step = self._rate_n_per_us * dt_us
        for i in range(n):
            cur = t[i]
            d = targets_n[i] - cur
            if d > step:
                d = step
            elif d < -step:
                d = -step
            cur += d
            t[i] = cur if cur > floor else floor
        return t


# --- the motor model ---------------------------------------------------------------------------

_HALF_TURN = ANGLE_COUNTS // 2


class MotorModel:
    """Per-motor conversion constants and feedback-derived state (all preallocated lists).

    Attributes:
        seen: a feedback frame has arrived from the motor.
        last_feedback_us: arrival time of the motor's last feedback (0 before the first).
        angle: last rotor angle, counts 0..8191.
        speed_rpm: last rotor speed, rpm.
        current: last measured current, raw.
        temperature: last temperature, °C.
        counts: unwrapped rotor counts since the first feedback.
        cable_length_m: cable paid in since the first feedback (sign-corrected).
        cable_speed_m_s: low-pass filtered paid-in speed (from the rotor speed).
        tension_est_n: tension estimated from the measured current.
    """

    def __init__(self, config: FirmwareConfig) -> None:
        """Create the model for ``config``."""
        n = config.motor_count
        self.motor_count = n
        self.seen = [False] * n
        self.last_feedback_us = [0] * n
        self.angle = [0] * n
        self.speed_rpm = [0] * n
        self.current = [0] * n
        self.temperature = [0] * n
        self.counts = [0] * n
        self.cable_length_m = [0.0] * n
        self.cable_speed_m_s = [0.0] * n
        self.tension_est_n = [0.0] * n
        self.governed_n = [0.0] * n
        """The tensions after the speed governor (:meth:`govern`, written in place)."""
        self.configure(config)

    def configure(self, config: FirmwareConfig) -> None:
        """Recompute the conversion constants (start-up and parameter changes)."""
        motor = config.motor
        r = motor.spool_radius_m
        kt = motor.torque_constant_nm_per_a
        self._signs = tuple(motor.motor_signs)
        self._raw_per_n = r / kt * RAW_PER_AMP
        self._n_per_raw = kt / r / RAW_PER_AMP
        self._limit_raw = motor.current_limit_raw
        self._m_per_count = r * 2.0 * math.pi / (ANGLE_COUNTS * motor.gear_ratio)
        self._m_s_per_rpm = r * 2.0 * math.pi / (60.0 * motor.gear_ratio)
        self._tau_us = motor.speed_filter_tau_us
        self._payin_limit_m_s = motor.payin_limit_m_per_s
        self._pretension_n = config.mapping.pretension_n

    def govern(self, tensions_n: Sequence[float]) -> list[float]:
        """The speed governor: ``tensions_n`` with each fast-reeling cable's tension cut (module notes).

        A cable reeling in at ``v`` above the limit ``L`` gets ``pretension + (T - pretension)·(2 - v/L)``
        (not below the pretension, never above ``T``). Written into :attr:`governed_n`, which is returned.
        """
        out = self.governed_n
        limit = self._payin_limit_m_s
        pre = self._pretension_n
        k = self._m_s_per_rpm
        signs = self._signs
        rpm = self.speed_rpm
        for i in range(self.motor_count):
            t = tensions_n[i]
            v = signs[i] * rpm[i] * k
            if v > limit and t > pre:
                f = 2.0 - v / limit
                t = pre + (t - pre) * f if f > 0.0 else pre
            out[i] = t
        return out

    def tension_to_raw(self, index: int, tension_n: float) -> int:
        """Raw C610 current for cable ``index`` (0-based) to pull ``tension_n`` (< 0 treated as 0).

        Clamped to ±current limit, sign-corrected for the motor's mounting.
        """
        if tension_n <= 0.0:
            return 0
        raw = round(tension_n * self._raw_per_n)
        lim = self._limit_raw
        if raw > lim:
            raw = lim
        return raw if self._signs[index] > 0 else -raw

    def tensions_to_raw(self, tensions_n: Sequence[float], out: list[int]) -> list[int]:
        """:meth:`tension_to_raw` of every cable at once, written into ``out`` (the control tick's path)."""
        raw_per_n = self._raw_per_n
        lim = self._limit_raw
        for i, sign in enumerate(self._signs):
            tension_n = tensions_n[i]
            if tension_n <= 0.0:
                out[i] = 0
                continue
            raw = round(tension_n * raw_per_n)
            if raw > lim:
                raw = lim
            out[i] = raw if sign > 0 else -raw
        return out

    def raw_to_tension(self, index: int, raw: int) -> float:
        """Cable tension (N) that the raw current ``raw`` on motor ``index`` pulls with."""
        return self._signs[index] * raw * self._n_per_raw

    def update(self, index: int, fb: MotorFeedback, now_us: int) -> None:
        """Take one feedback frame of motor ``index`` (0-based) that arrived at ``now_us``."""
        self.update_frames(((index + 1, fb),), now_us)

    def update_frames(self, frames: Iterable[tuple[int, MotorFeedback]], now_us: int) -> None:
        """Take the feedback frames ``(motor 1..n, frame)`` that arrived at ``now_us``, in order.

        One call per control tick for all motors (what ``MotorBus.read_feedback`` returns).
        """
        signs = self._signs
        seen = self.seen
        angles = self.angle
        counts = self.counts
        last_us = self.last_feedback_us
        speeds = self.cable_speed_m_s
        m_s_per_rpm = self._m_s_per_rpm
        tau = self._tau_us
        for motor, fb in frames:
            i = motor - 1
            sign = signs[i]
            angle, speed_rpm, current, temperature = fb
            speed = sign * speed_rpm * m_s_per_rpm
            if seen[i]:
                d = angle - angles[i]
                # shortest way round: valid while the rotor turns < half a turn between frames
                if d >= _HALF_TURN:
                    d -= ANGLE_COUNTS
                elif d < -_HALF_TURN:
                    d += ANGLE_COUNTS
                counts[i] += d
                dt = now_us - last_us[i]
                if tau > 0 and dt > 0:
                    prev = speeds[i]
                    speed = prev + (speed - prev) * (dt / (tau + dt))
            else:
                seen[i] = True
            speeds[i] = speed
            angles[i] = angle
            self.speed_rpm[i] = speed_rpm
            self.current[i] = current
            self.temperature[i] = temperature
            last_us[i] = now_us
            self.cable_length_m[i] = sign * counts[i] * self._m_per_count
            self.tension_est_n[i] = sign * current * self._n_per_raw
