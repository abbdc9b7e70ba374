"""A fake set of C610/M2006 motors (1 to 8, a trio by default) for tests and examples (no hardware, no
MuJoCo).

Each fake motor winds a cable against a linear spring (a stand-in for the arm): the C610's current loop
is taken as ideal (measured current = command), the output shaft integrates
``J dω/dt = K_t I - r T_cable - b ω`` with ``T_cable = k · max(0, paid-in length)``. Feedback frames
carry the wrapped rotor angle (8192 counts per rotor turn, 36 rotor turns per output turn), the rotor
speed in rpm and the current, byte for byte as ``protocol.c610`` defines them.

It is stepped synchronously by :class:`~controller.motorbus.FakeMotorBus` (``python -m controller
--can-interface fake``) or directly with :meth:`FakeC610Set.step`.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

from protocol.c610 import (
    ANGLE_COUNTS,
    COMMAND_ID_HIGH,
    COMMAND_ID_LOW,
    FEEDBACK_ID_BASE,
    FRAME_LEN,
    MOTORS_MAX,
    MOTORS_PER_COMMAND,
    RAW_PER_AMP,
    MotorFeedback,
    output_rad_s_to_rotor_rpm,
    output_rad_to_counts,
    unpack_currents,
)

__all__ = ["FakeC610", "FakeC610Set"]

_INT16_MAX = 32767


class FakeC610:
    """One M2006 P36 behind a C610, winding a cable against a spring.

    Attributes:
        angle_out_rad: output shaft angle (positive = cable reeled in).
        speed_out_rad_s: output shaft speed.
        current_raw: current command in force (raw, 1000 per amp).
    """

    def __init__(
        self,
        *,
        spool_radius_m: float = 0.010,
        torque_constant_nm_per_a: float = 0.18,
        spring_n_per_m: float = 200.0,
        inertia_kg_m2: float = 2e-4,
        damping_nm_s: float = 0.02,
        start_angle_counts: int = 0,
    ) -> None:
        """Create a motor at rest with the cable just taut."""
        self.r = spool_radius_m
        self.kt = torque_constant_nm_per_a
        self.k = spring_n_per_m
        self.j = inertia_kg_m2
        self.b = damping_nm_s
        self.angle_out_rad = 0.0
        self.speed_out_rad_s = 0.0
        self.current_raw = 0
        self._angle0_counts = start_angle_counts

    @property
    def cable_tension_n(self) -> float:
        """Tension in the cable (0 when slack)."""
        paid_in = self.r * self.angle_out_rad
        return self.k * paid_in if paid_in > 0.0 else 0.0

    def step(self, dt_s: float) -> None:
        """Advance the dynamics by ``dt_s`` (semi-implicit Euler)."""
        torque = self.kt * self.current_raw / RAW_PER_AMP - self.r * self.cable_tension_n
        self.speed_out_rad_s += (torque - self.b * self.speed_out_rad_s) / self.j * dt_s
        self.angle_out_rad += self.speed_out_rad_s * dt_s

    def feedback(self) -> MotorFeedback:
        """The C610 feedback frame for the present state."""
        rotor_counts = output_rad_to_counts(self.angle_out_rad)
        rpm = round(output_rad_s_to_rotor_rpm(self.speed_out_rad_s))
        rpm = max(-_INT16_MAX, min(_INT16_MAX, rpm))
        return MotorFeedback((self._angle0_counts + rotor_counts) % ANGLE_COUNTS, rpm, self.current_raw, 30)


class FakeC610Set:
    """Fake motors on C610 ids 1..n (n = 1..8; three by default): commands on 0x200 (motors 1-4) and
    0x1FF (motors 5-8), feedback on 0x201..0x200+n.

    Attributes:
        motors: the motors, motor 1 first.
        silent: motor numbers (1..n) that stop answering (fault injection).
        commands: command frames handled (0x200, and 0x1FF when the set has motors 5-8).
    """

    def __init__(self, start_angles_counts: Iterable[int] = (0, 0, 0), **motor_kwargs: Any) -> None:
        """One motor per start angle; ``motor_kwargs`` go to each :class:`FakeC610`.

        Raises:
            ValueError: no start angle or more than eight.
        """
        self.motors = [FakeC610(start_angle_counts=a, **motor_kwargs) for a in start_angles_counts]
        if not 1 <= len(self.motors) <= MOTORS_MAX:
            raise ValueError(f"a C610 set has 1..{MOTORS_MAX} motors, got {len(self.motors)}")
        self.silent: set[int] = set()
        self.commands = 0

    @classmethod
    def of(cls, motor_count: int, **motor_kwargs: Any) -> FakeC610Set:
        """``motor_count`` motors at rest, every encoder at 0."""
        return cls((0,) * motor_count, **motor_kwargs)

    def handle_frame(self, can_id: int, data: bytes) -> None:
        """Take a frame from the bus; only 8-byte 0x200 / 0x1FF commands matter (each to its four ids)."""
        if len(data) != FRAME_LEN:
            return
        if can_id == COMMAND_ID_LOW:
            first = 0
        elif can_id == COMMAND_ID_HIGH:
            first = MOTORS_PER_COMMAND
        else:
            return
        if first >= len(self.motors):
            return  # a 0x1FF to a set of four or fewer: for motors it does not have
        self.commands += 1
        values = unpack_currents(data)
        for motor, raw in zip(self.motors[first : first + MOTORS_PER_COMMAND], values, strict=False):
            motor.current_raw = raw

    def step(self, dt_us: int) -> list[tuple[int, bytes]]:
        """Advance every motor by ``dt_us``; return the feedback frames of the motors that answer."""
        dt_s = dt_us / 1e6
        out: list[tuple[int, bytes]] = []
        for n, motor in enumerate(self.motors, start=1):
            motor.step(dt_s)
            if n not in self.silent:
                out.append((FEEDBACK_ID_BASE + n, motor.feedback().pack()))
        return out
