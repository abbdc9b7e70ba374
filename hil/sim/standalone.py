"""What an exported model carries in MJCF where the :class:`hil.sim.plant.Plant` uses Python.

The plant keeps three things out of its MJCF (``docs/plant.md``, "The exported model"): the drives'
torque-speed line and their command delay (:mod:`hil.sim.drives`), and the capstan friction of the cables in
the unit holes, recomputed every control period from the tensions. A model written with
``build_mjcf(..., standalone=True)`` (``spirob-hil model export``) must run in plain MuJoCo, so:

- each drive is a MuJoCo ``dcmotor`` in current (torque) mode: it delivers the commanded current exactly,
  back-EMF compensated like the C610's current loop, until its drive voltage reaches the supply, which is
  the torque-speed line ``I_stall·(1 − ω/ω_nl)`` (:func:`drive_circuit` derives the circuit);
- the command delay is the actuators' own ``delay``, read from a ``ctrl`` history with linear interpolation
  (:func:`delay_attributes`);
- the capstan friction, which depends on the tensions and the bending, is frozen at a stated reference
  (:func:`capstan_standin_nm`) and added to the joints' own dry friction.

These are the pieces; :func:`hil.sim.mjcf.build_mjcf` puts them in the file. Nothing here changes what the
plant builds.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

from hil.sim.config import MotorConfig

__all__ = [
    "CAPSTAN_REFERENCE_TENSION_N",
    "SUPPLY_VOLTAGE_V",
    "DriveCircuit",
    "capstan_standin_nm",
    "delay_attributes",
    "delay_samples",
    "drive_circuit",
]

SUPPLY_VOLTAGE_V = 24.0
"""The drives' supply, the dcmotor's ``Vmax``: the C610's rated 24 V (RoboMaster battery). Only the products
``Vmax·K/R`` and ``K²/R`` shape the torque-speed line; this value merely makes the voltage read as volts."""

CAPSTAN_REFERENCE_TENSION_N = 20.0
"""Total cable tension at which the exported model's constant capstan friction is evaluated, every joint
bent to its limit Δθ: the packed prototype held at about the tension that packs it (21.5 N,
``docs/plant.md``). Measured against the plant (``docs/plant.md``, "The exported model") it splits the
difference between a pack-and-release (where less would do) and random pulls up to 3 A (where more would)."""


@dataclass(frozen=True)
class DriveCircuit:
    """A drive as a MuJoCo ``dcmotor`` on its spool slider, in actuator units (``ctrl`` and force in amps).

    The actuator's length is ``gear · x`` (``x`` the wound cable), so its velocity ``gear · ẋ = kt·s·ω``
    (``s`` the torque scale, ``ω`` the output speed) is the output shaft's back-EMF in volts for a motor
    constant of 1.

    Attributes:
        gear: cable force per amp, ``kt · s / r_spool`` [N/A].
        motorconst: ``K`` of the equivalent circuit (dimensionless in these units).
        resistance_ohm: ``R`` of the equivalent circuit.
        vmax_v: the supply clamp ``Vmax`` of the dcmotor's controller.
        current_limit_a: the largest current it delivers either way (the dcmotor's ``saturation``).
        spool_radius_m: the spool's radius (``ẋ = r·ω``).
    """

    gear: float
    motorconst: float
    resistance_ohm: float
    vmax_v: float
    current_limit_a: float
    spool_radius_m: float

    def delivered_a(self, command_a: float, omega_rad_s: float) -> float:
        """The current the dcmotor delivers for a command at output speed ``omega_rad_s``: the voltage
        ``(R/K)·I_cmd + K·l̇`` clamped to ``±Vmax``, the current ``(V − K·l̇)·K/R`` within the limit."""
        k, r, lim = self.motorconst, self.resistance_ohm, self.current_limit_a
        ldot = self.gear * self.spool_radius_m * omega_rad_s
        volts = min(max(r / k * command_a + k * ldot, -self.vmax_v), self.vmax_v)
        return min(max(k / r * (volts - k * ldot), -lim), lim)


def drive_circuit(motor: MotorConfig) -> DriveCircuit:
    """The dcmotor that reproduces the drives' current loop and torque-speed line.

    In current mode (``input="ff"``) the dcmotor drives ``V = (R/K)·I_cmd + K·l̇`` (back-EMF compensated,
    like the C610's current loop) clamped to ``±Vmax`` and delivers ``I = (V − K·l̇)·K/R``: exactly
    ``I_cmd`` while the clamp is idle. Clamped at ``+Vmax`` it delivers ``Vmax·K/R − (K²/R)·l̇``. With
    ``l̇ = gear·ẋ = kt·s·ω`` (gear ``kt·s/r``, ``ẋ = r·ω``) that is the drives' line
    ``I_stall·(1 − ω/ω_nl)`` when

        ``Vmax·K/R = I_stall`` and ``(K²/R)·kt·s = I_stall/ω_nl``,

    so ``K = Vmax/(kt·s·ω_nl)`` and ``R = K·Vmax/I_stall`` (prototype: K = 2.546, R = 3.395 Ω at
    ``Vmax`` = 24 V). A positive command is delivered the same as by :class:`hil.sim.drives.Drives` for
    ``−ω_nl·(1 + I_cmd/I_stall) ≤ ω ≤ ω_nl`` (a negative one mirrored). Beyond, the spool is overrun
    faster than its no-load speed: the drives then deliver nothing (overrun in the command's direction)
    or exactly the command (overrun against it), where the dcmotor brakes, since its voltage cannot
    follow the back-EMF; its braking stops at the current limit.
    """
    kt_s = motor.torque_constant_nm_per_a * motor.torque_scale
    k = SUPPLY_VOLTAGE_V / (kt_s * motor.no_load_speed_rad_s)
    r = k * SUPPLY_VOLTAGE_V / motor.stall_current_a
    return DriveCircuit(
        motor.delivered_force_per_amp_n, k, r, SUPPLY_VOLTAGE_V, motor.current_limit_a, motor.spool_radius_m
    )


def delay_samples(delay_s: float, timestep_s: float) -> int:
    """History samples a ``delay_s`` needs at ``timestep_s`` (0: no delay): enough that the delayed time
    never reads before the oldest sample."""
    if delay_s <= 0.0:
        return 0
    return max(1, math.ceil(delay_s / timestep_s - 1e-9))


def delay_attributes(delay_s: float, timestep_s: float) -> str:
    """The actuator attributes of a command delay (``""`` for none).

    MuJoCo reads a delayed ``ctrl`` at ``time − delay`` from a history written after each step, with
    linear interpolation: at the plant's 1 ms step that is the drives' own rule (the setpoint
    ``command_delay_s`` ago, linear between periods). It reads before it writes, so a delay under one
    physics step acts as one step.
    """
    n = delay_samples(delay_s, timestep_s)
    if n == 0:
        return ""
    return f' delay="{delay_s:.9g}" nsample="{n}" interp="linear"'


def capstan_standin_nm(
    mu: float, hole_radii_m: Sequence[float], tension_n: float, angle_rad: float
) -> tuple[float, ...]:
    """The plant's capstan friction of each joint (base first), frozen at one tension and one bending.

    The plant charges joint i ``T·e^{−μ Σ_{j<i} α_j}·(1 − e^{−μ α_i})·r_i`` (``T`` the total cable tension,
    ``α`` the joints' bending, ``r_i`` the hole radius); here every ``α`` is ``angle_rad`` and ``T`` is
    ``tension_n``.
    """
    if mu <= 0.0 or tension_n <= 0.0:
        return tuple(0.0 for _ in hole_radii_m)
    lost = -math.expm1(-mu * angle_rad)
    return tuple(tension_n * math.exp(-mu * angle_rad * i) * lost * r for i, r in enumerate(hole_radii_m))
