"""Length-hold: a cascade position loop per motor that keeps a cable at a fixed length.

DJI's RoboMaster C-board examples drive their motors with two PID loops in cascade (angle -> speed ->
current). :class:`LengthHold` does the same per held cable, in cable units: the length error (set-point
minus ``MotorModel.cable_length_m``, from the rotor's multi-turn angle) gives a speed set-point, the
speed error (against the unfiltered rotor speed: the control tick needs no 20 ms filter lag) gives
the cable tension, which the firmware then turns into current like any other tension. So the output
is clamped to [pretension, per-cable tension ceiling] (pull-only: a cable cannot push) and then to the
current limit, and it only runs on the control tick after the SAFE check: every failsafe still zeroes
the current, and going SAFE drops every hold.

A hold is engaged at the cable's present length (or a length the host sets) and starts bumpless: the
speed loop's integral starts at the cable's present commanded tension. The held tension is written
into the slew limiter's tensions, so a released cable slews from there toward its mapped target.

Who holds: the host (``HOLD_LENGTHS``, any active mode) or the grasp machine (``grasp_hold_length``:
HOLD freezes the pulling cables' length); every mode change drops every hold.
"""

from __future__ import annotations

import math
from collections.abc import MutableSequence

from controller.cables import MotorModel, TensionSlew
from controller.config import FirmwareConfig

__all__ = ["LengthHold", "Pid"]


class Pid:
    """A position-form PID with output and integral-term limits (DJI's ``PID_calc``, ``PID_POSITION``).

    ``out = kp·e + iout + kd·de/dt`` with ``iout += ki·e·dt`` clamped to ±``imax`` and ``out`` clamped
    to [``out_min``, ``out_max``].

    Attributes:
        iout: the integral term (output units).
        last_error: the previous error (for the derivative).
    """

    __slots__ = ("imax", "iout", "kd", "ki", "kp", "last_error", "out_max", "out_min")

    def __init__(self, kp: float, ki: float, kd: float, out_min: float, out_max: float, imax: float) -> None:
        """Create the loop with zero state."""
        self.kp = kp
        self.ki = ki
        self.kd = kd
        self.out_min = out_min
        self.out_max = out_max
        self.imax = imax
        self.iout = 0.0
        self.last_error = 0.0

    def reset(self, iout: float = 0.0) -> None:
        """Clear the state; start the integral term at ``iout`` (clamped) for a bumpless start."""
        lim = self.imax
        self.iout = lim if iout > lim else -lim if iout < -lim else iout
        self.last_error = 0.0

    def step(self, error: float, dt_s: float) -> float:
        """One update with ``error`` after ``dt_s`` seconds; return the clamped output."""
        iout = self.iout + self.ki * error * dt_s
        lim = self.imax
        iout = lim if iout > lim else -lim if iout < -lim else iout
        self.iout = iout
        out = self.kp * error + iout
        if self.kd and dt_s > 0.0:
            out += self.kd * (error - self.last_error) / dt_s
        self.last_error = error
        lo = self.out_min
        hi = self.out_max
        return lo if out < lo else hi if out > hi else out


class LengthHold:
    """Per-cable length-hold (preallocated; nothing runs for cables that are not held).

    Attributes:
        held: cable ``i`` is held.
        by_grasp: cable ``i``'s hold was engaged by the grasp machine (released when HOLD ends).
        setpoint_m: held length per cable (``MotorModel.cable_length_m`` frame).
        count: number of held cables (the control tick checks only this when none is held).
        flags: bit ``i`` set = cable ``i`` held (``TelemetryFlags.HOLD_1 << i``).
    """

    def __init__(self, config: FirmwareConfig, motors: MotorModel, slew: TensionSlew) -> None:
        """Create the loops for ``config``, reading feedback from ``motors`` and tensions from ``slew``."""
        self._motors = motors
        self._tensions_n = slew.tensions_n  # written in place by the slew limiter, never replaced
        n = config.motor_count
        self._n = n
        self.held = [False] * n
        self.by_grasp = [False] * n
        self.setpoint_m = [0.0] * n
        self.count = 0
        self.flags = 0
        self._pos: list[Pid] = []
        self._speed: list[Pid] = []
        for _ in range(n):
            self._pos.append(Pid(0.0, 0.0, 0.0, 0.0, 0.0, 0.0))
            self._speed.append(Pid(0.0, 0.0, 0.0, 0.0, 0.0, 0.0))
        self.configure(config)

    def configure(self, config: FirmwareConfig) -> None:
        """Take new gains and limits (the loops keep their state)."""
        h = config.hold
        lo = config.mapping.pretension_n
        hi = config.mapping.tension_max_n
        for pos, speed in zip(self._pos, self._speed, strict=True):
            pos.kp, pos.ki, pos.kd = h.pos_kp_per_s, h.pos_ki_per_s2, h.pos_kd
            pos.out_min, pos.out_max, pos.imax = -h.pos_max_m_per_s, h.pos_max_m_per_s, h.pos_imax_m_per_s
            speed.kp, speed.ki, speed.kd = h.speed_kp_n_s_per_m, h.speed_ki_n_per_m, 0.0
            speed.out_min, speed.out_max, speed.imax = lo, hi, h.speed_imax_n
        motor = config.motor
        self._signs = tuple(motor.motor_signs)
        # The rotor speed in rpm -> cable paid-in speed (the MotorModel's constant, unfiltered).
        self._m_s_per_rpm = motor.spool_radius_m * 2.0 * math.pi / (60.0 * motor.gear_ratio)

    def engage(self, index: int, length_m: float | None = None, *, by_grasp: bool = False) -> bool:
        """Hold cable ``index`` at ``length_m`` (None: its present length; kept if already held).

        The speed loop's integral starts at the cable's present commanded tension (bumpless).

        Args:
            index: cable 0..2.
            length_m: the set-point, or None for the present length.
            by_grasp: the grasp machine engages it (its end releases it).

        Returns:
            False if the motor has never answered (no length to hold).
        """
        if not self._motors.seen[index]:
            return False
        if not self.held[index]:
            self._pos[index].reset()
            self._speed[index].reset(self._tensions_n[index])
            self.setpoint_m[index] = self._motors.cable_length_m[index]
        if length_m is not None:
            self.setpoint_m[index] = length_m
        self.held[index] = True
        self.by_grasp[index] = by_grasp
        self._count()
        return True

    def release(self, index: int) -> None:
        """Cable ``index`` back to the tension mapping."""
        self.held[index] = False
        self.by_grasp[index] = False
        self._count()

    def release_all(self) -> None:
        """Drop every hold (SAFE, a mode change)."""
        if self.count:
            for i in range(self._n):
                self.held[i] = False
                self.by_grasp[i] = False
            self._count()

    def release_host(self) -> None:
        """Drop the holds the host engaged (``HOLD_LENGTHS``; on link loss)."""
        for i in range(self._n):
            if self.held[i] and not self.by_grasp[i]:
                self.release(i)

    def release_grasp(self) -> None:
        """Drop the holds the grasp machine engaged."""
        for i in range(self._n):
            if self.by_grasp[i]:
                self.release(i)

    def _count(self) -> None:
        self.count = sum(self.held)
        self.flags = sum(1 << i for i in range(self._n) if self.held[i])

    def step(self, dt_us: int, tensions_n: MutableSequence[float]) -> None:
        """One control tick: overwrite the held cables' tensions with the cascade's output.

        Call only when :attr:`count` > 0 and current may flow (the firmware calls it after the SAFE
        check and the slew limiter).
        """
        dt_s = dt_us * 1e-6
        m = self._motors
        held = self.held
        for i in range(self._n):
            if not held[i]:
                continue
            v_ref = self._pos[i].step(self.setpoint_m[i] - m.cable_length_m[i], dt_s)
            speed = self._signs[i] * m.speed_rpm[i] * self._m_s_per_rpm
            tensions_n[i] = self._speed[i].step(v_ref - speed, dt_s)
