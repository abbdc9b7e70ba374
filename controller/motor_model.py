"""Motor model: cable tension <-> C610 current, and feedback -> cable length, speed and tension.

Tension T [N] on a spool of radius r needs an output torque T·r, i.e. a current T·r / K_t (K_t at the
output shaft, gearbox included), sent as raw units (1000 per amp) and clamped to the current limit.
Feedback: the rotor angle (0..8191 per rotor turn) is unwrapped into multi-turn counts, divided by the
gear ratio into the output angle, and times r gives the cable paid in since the first feedback. The
measured current times K_t / r estimates the tension (the same constant the plant must use).

Sign convention: with ``motor_signs[i] = +1`` a positive current reels cable ``i`` in (raises its
tension) and the rotor angle increases while reeling in; ``-1`` mirrors a motor.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence

from controller.config import MOTOR_COUNT, FirmwareConfig
from protocol.c610 import ANGLE_COUNTS, RAW_PER_AMP, MotorFeedback

__all__ = ["MotorModel"]

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
        n = MOTOR_COUNT
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
