"""The plant's drives: per cable one C610 ESC, one M2006 P36 motor and its spool.

The drives stand between the C610 wire and the MuJoCo physics (:class:`hil.sim.plant.Plant`):

- in: the raw int16 setpoints of a 0x200 frame, clamped to the configured current limit like the ESC does;
- per control period: the C610 current loop, taken as ideal up to the motor's torque-speed line (in the
  direction of motion the drive delivers at most ``I_stall·(1 − ω/ω_nl)``), into the spool actuators;
- out: one feedback frame per motor, from the spool's state through the 36:1 gearbox and the spool
  radius: rotor angle wrapping at 8192 counts per *rotor* turn (with an arbitrary zero), rotor rpm, and
  the current the drive delivered (with optional noise).

With another actuator (:class:`hil.sim.config.ActuatorConfig`: an ideal tension source behind a lag,
or a muscle) the frames are the same: a current asks for the tension ``I · kt / r_spool`` (the
firmware's force per amp), the angle is still the wound cable, and the fed-back current is the force the
actuator delivered in the last physics step converted back with that force per amp.

The spool is a slide joint in MuJoCo (its coordinate is cable length in metres); the drives read its
position and speed and write its actuator's control through plain buffer views of one ``MjData``, given
by :meth:`Drives.attach` (again after every model rebuild). Their own state (setpoints, delivered
currents, encoder zeros) survives a rebuild.

The drives know no bus, fault or recording: the CAN bus they sit on is the harness's
(:class:`hil.canbus.SimMotorBus`), which injects faults and records where the bytes cross.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import cast

import numpy as np
from numpy.typing import NDArray

from hil.sim.config import ActuatorConfig, MotorConfig
from protocol.c610 import ANGLE_COUNTS, CURRENT_RAW_MAX, RAW_PER_AMP, MotorFeedback, pack_feedback

__all__ = ["Drives"]

FloatArray = NDArray[np.float64]

_INT16_MAX = 32767


class Drives:
    """The C610/M2006/spool drives of a plant's cables, in cable order (motor k + 1 drives cable k).

    Args:
        motor: the drives' figures (all drives are alike).
        count: number of drives (= motors, 1..8: an array's arms x cables).
        rng: the only source of randomness (encoder zeros at :meth:`reset`, current noise). ``None`` = no
            randomness: encoders start at 0 and ``motor.current_noise_raw`` must be 0.
        actuator: what the spool actuators are (default: the motor). For ``tension`` the actuator's
            control is the asked tension [N]; for ``muscle`` its activation, the asked tension over
            ``muscle_force_n`` (capped at 1).
        muscle_force_n: the muscle's peak force F0 (needed by ``muscle``; see
            :attr:`hil.sim.config.ModelConfig.muscle_force_n`).
        control_period_s: how often :meth:`drive` runs (a command delay is counted in these).

    Raises:
        ValueError: current noise without an rng, or a muscle without its peak force.
    """

    def __init__(
        self,
        motor: MotorConfig,
        count: int,
        rng: np.random.Generator | None,
        actuator: ActuatorConfig | None = None,
        muscle_force_n: float | None = None,
        control_period_s: float = 1e-3,
    ) -> None:
        if rng is None and motor.current_noise_raw > 0:
            raise ValueError("current noise needs an rng (numpy.random.Generator)")
        kind = "motor" if actuator is None else actuator.kind
        if kind == "muscle" and muscle_force_n is None:
            raise ValueError("a muscle actuator needs muscle_force_n")
        self.actuator_kind = kind
        """``motor``, ``tension`` or ``muscle``."""
        self._motor_kind = kind == "motor"
        # Asked tension per amp, in the actuator's control units (N for tension, activation for muscle).
        fpa = motor.delivered_force_per_amp_n
        self._ctrl_per_a = fpa / muscle_force_n if muscle_force_n is not None and kind == "muscle" else fpa
        self._ctrl_max = 1.0 if kind == "muscle" else math.inf
        self._amps_per_n = 1.0 / fpa
        if not 1 <= count <= 8:
            raise ValueError(f"drives: 1..8 motors on a C610 bus, got {count}")
        self._n = count
        self._slots = -(-count // 4) * 4  # the command frames' slots (four per frame)
        self._rng = rng
        self.spool_radius_m = motor.spool_radius_m
        """Cable spool radius [m]."""
        self.gear_ratio = motor.gear_ratio
        """Rotor turns per output (spool) turn."""
        self._limit_raw = round(motor.current_limit_a * RAW_PER_AMP)
        self._limit_a = motor.current_limit_a
        self._inv_r_spool = 1.0 / motor.spool_radius_m
        self._counts_per_m = motor.gear_ratio * ANGLE_COUNTS / (2.0 * math.pi * motor.spool_radius_m)
        self._rpm_per_m_s = motor.gear_ratio * 60.0 / (2.0 * math.pi * motor.spool_radius_m)
        self._noise_raw = motor.current_noise_raw
        self._temperature_c = motor.temperature_c
        self._inv_no_load = 1.0 / motor.no_load_speed_rad_s
        self._stall_a = motor.stall_current_a
        self._current_raw_list = [0] * count
        # Command delay, in control periods: the setpoints of the last periods, newest last.
        self._delay_periods = motor.command_delay_s / control_period_s
        self._history: list[list[int]] = [[0] * count] * (int(self._delay_periods) + 2)
        self._applied_a = np.zeros(count)
        self._applied_mv = _float_view(self._applied_a)
        self._angle_offset_list = [0] * count
        self._qpos_mv = _float_view(np.empty(0))
        self._qvel_mv = self._qpos_mv
        self._ctrl_mv = self._qpos_mv
        self._force_mv = self._qpos_mv
        self._spool_qadr_list: list[int] = []
        self._spool_dadr_list: list[int] = []

    def attach(
        self,
        qpos: FloatArray,
        qvel: FloatArray,
        ctrl: FloatArray,
        spool_qadr: Sequence[int],
        spool_dadr: Sequence[int],
        qfrc_actuator: FloatArray | None = None,
    ) -> None:
        """Wire the drives to one ``MjData``: its ``qpos``, ``qvel`` and ``ctrl`` (actuator k = drive k).

        Plain buffer views are kept, valid while that ``MjData`` lives: the 1 kHz paths index them
        without numpy's per-element cost.

        Args:
            qpos: the ``MjData``'s ``qpos``.
            qvel: its ``qvel``.
            ctrl: its ``ctrl``; the first ``count`` actuators are the spools' motors, in cable order.
            spool_qadr: ``qpos`` address of each spool joint, in cable order.
            spool_dadr: ``qvel`` address of each spool joint, in cable order.
            qfrc_actuator: its ``qfrc_actuator`` (the force each actuator delivered to its spool); needed
                by the ``tension`` and ``muscle`` actuators, whose fed-back current is that force.

        Raises:
            ValueError: a ``tension`` or ``muscle`` actuator without ``qfrc_actuator``.
        """
        if qfrc_actuator is None and not self._motor_kind:
            raise ValueError(f"a {self.actuator_kind} actuator needs qfrc_actuator")
        if qfrc_actuator is not None:
            self._force_mv = _float_view(qfrc_actuator)
        self._qpos_mv = _float_view(qpos)
        self._qvel_mv = _float_view(qvel)
        self._ctrl_mv = _float_view(ctrl)
        self._spool_qadr_list = [int(a) for a in spool_qadr]
        self._spool_dadr_list = [int(a) for a in spool_dadr]

    def reset(self) -> None:
        """No current, and new encoder zeros drawn from the rng (all 0 without one)."""
        self._current_raw_list = [0] * self._n
        self._history = [[0] * self._n] * len(self._history)
        self._applied_a[:] = 0.0
        if self._rng is not None:
            self._angle_offset_list = [int(v) for v in self._rng.integers(0, ANGLE_COUNTS, size=self._n)]
        else:
            self._angle_offset_list = [0] * self._n

    @property
    def angle_offsets_counts(self) -> tuple[int, ...]:
        """Each encoder's zero: rotor counts added to the spool's angle before wrapping."""
        return tuple(self._angle_offset_list)

    def drive(self) -> None:
        """Run the current loops for one control period: each drive's delivered current into its actuator.

        The C610's current loop on a supply of limited voltage: the command is delivered exactly while
        the voltage it needs, ``I_cmd + I_stall·ω/ω_nl`` in amps of stall current, stays within
        ``±I_stall``; beyond, the drive delivers what the supply allows. In the direction of motion that
        is the torque-speed line ``I_stall·(1 − ω/ω_nl)``, and past the no-load speed it brakes (the
        back-EMF exceeds the supply), up to the current limit: the law of MuJoCo's ``dcmotor`` actuator
        in current mode, which the exported model uses (:mod:`hil.sim.standalone`), so the file and the
        plant drive alike. A tension source or a muscle gets the asked tension (pull only) in its control
        units; MuJoCo applies its lag or activation dynamics. Plain floats over buffer views: three
        motors are cheaper in Python than in numpy.
        """
        ctrl = self._ctrl_mv
        currents: list[int] | list[float] = self._current_raw_list
        if self._delay_periods > 0.0:
            currents = self._delayed()
        if not self._motor_kind:
            gain = self._ctrl_per_a / RAW_PER_AMP
            ctrl_max = self._ctrl_max
            for k in range(self._n):
                asked = currents[k] * gain
                ctrl[k] = 0.0 if asked <= 0.0 else asked if asked < ctrl_max else ctrl_max
            return
        qvel = self._qvel_mv
        applied_a = self._applied_mv
        dadr = self._spool_dadr_list
        inv_r_spool = self._inv_r_spool
        stall_a = self._stall_a
        inv_no_load = self._inv_no_load
        limit_a = self._limit_a
        for k in range(self._n):
            cmd = currents[k] / RAW_PER_AMP
            omega = qvel[dadr[k]] * inv_r_spool
            need = cmd + stall_a * omega * inv_no_load  # the voltage the command needs, in stall amps
            if -stall_a <= need <= stall_a:
                applied = cmd
            else:
                sign = 1.0 if need > 0 else -1.0
                applied = sign * stall_a * (1.0 - sign * omega * inv_no_load)
                applied = limit_a if applied > limit_a else -limit_a if applied < -limit_a else applied
            applied_a[k] = applied
            ctrl[k] = applied

    def _delayed(self) -> list[float]:
        """The setpoints ``command_delay_s`` ago (linear between the two periods around it), raw units."""
        hist = self._history
        hist.append(self._current_raw_list)
        del hist[0]
        whole = int(self._delay_periods)
        frac = self._delay_periods - whole
        newer = hist[-1 - whole]
        older = hist[-2 - whole]
        return [(1.0 - frac) * a + frac * b for a, b in zip(newer, older, strict=True)]

    def apply_currents(self, currents_raw: Sequence[int]) -> tuple[int, ...]:
        """Set the motors' current setpoints in raw C610 units (1000 per amp), one per cable.

        Values beyond the configured current limit are clamped, like the ESC does. A C610 command frame
        has four slots (motors 1-4 on 0x200, 5-8 on 0x1FF): values beyond the drives up to the end of
        the last frame (e.g. slot 3 for a 2-cable arm) are accepted and ignored, like a slot with no ESC.

        Args:
            currents_raw: one int per motor (up to the frames' slots); positive winds the cable in.

        Returns:
            The setpoints actually applied (after clamping), one per cable.

        Raises:
            ValueError: fewer values than motors or more than their frames' slots, or a value that is not an
                integer.
        """
        slots = self._slots
        if not self._n <= len(currents_raw) <= slots:
            raise ValueError(f"expected {self._n} currents (at most {slots}), got {len(currents_raw)}")
        lim = self._limit_raw
        out = []
        for i, value in enumerate(currents_raw):
            if type(value) is not int:  # the bus always passes plain ints: one test for them
                if isinstance(value, bool) or not isinstance(value, int | np.integer):
                    raise ValueError(f"current[{i}] must be an int, got {type(value).__name__}")
                value = int(value)
            out.append(lim if value > lim else -lim if value < -lim else value)
        del out[self._n :]
        self._current_raw_list = out
        return tuple(out)

    def feedback(self) -> tuple[MotorFeedback, ...]:
        """One C610 feedback frame per motor, as the motor would report it now.

        Angle: rotor position, 0..8191 per *rotor* turn (the output turns 36x slower), with an arbitrary
        zero drawn from the rng at :meth:`reset`. Speed: rotor rpm. Current: the current the drive actually
        delivers (the torque-speed line can make it smaller than the setpoint), raw units, with the
        configured noise. (Decoded from :meth:`feedback_payloads`: one computation for both.)
        """
        unpack = MotorFeedback.unpack
        return tuple(unpack(data) for data in self.feedback_payloads())

    def feedback_payloads(self) -> list[bytes]:
        """The 8 data bytes of each motor's feedback frame now (see :meth:`feedback` for the fields).

        The simulated bus calls this every millisecond, right after a MuJoCo step has evicted most of
        Python's working set from the caches; so it is straight-line code over locals, memoryviews of the
        state instead of numpy indexing, and no comprehensions or temporary tuples (measured: half the
        time of the same arithmetic written with gathers and comprehensions). The fields are in range by
        construction: the angle is wrapped, speed and current are clamped to int16 and ±10000, and the
        temperature is validated by the motor config.
        """
        qpos = self._qpos_mv
        qvel = self._qvel_mv
        applied = self._applied_mv
        if not self._motor_kind:
            self._sense_forces()
        qadr = self._spool_qadr_list
        dadr = self._spool_dadr_list
        offsets = self._angle_offset_list
        counts_per_m = self._counts_per_m
        rpm_per_m_s = self._rpm_per_m_s
        temperature = self._temperature_c
        noise = None
        if self._noise_raw > 0 and self._rng is not None:
            noise = self._rng.normal(0.0, self._noise_raw, self._n).tolist()
        pack = pack_feedback
        out = []
        for k in range(self._n):
            rpm = round(qvel[dadr[k]] * rpm_per_m_s)
            if rpm > _INT16_MAX or rpm < -_INT16_MAX:
                rpm = _INT16_MAX if rpm > 0 else -_INT16_MAX
            current_raw = applied[k] * RAW_PER_AMP
            if noise is not None:
                current_raw += noise[k]
            current = round(current_raw)
            if current > CURRENT_RAW_MAX or current < -CURRENT_RAW_MAX:
                current = CURRENT_RAW_MAX if current > 0 else -CURRENT_RAW_MAX
            angle = (round(qpos[qadr[k]] * counts_per_m) + offsets[k]) % ANGLE_COUNTS
            out.append(pack(angle, rpm, current, temperature))
        return out

    def commanded_currents_raw(self) -> tuple[int, ...]:
        """The setpoints last applied (after clamping), raw units."""
        return tuple(self._current_raw_list)

    def applied_currents_a(self) -> FloatArray:
        """Current each drive delivered in the last period (after the torque-speed line) [A].

        For a tension source or a muscle: the force it delivered in the last physics step over the
        firmware's force per amp.
        """
        if not self._motor_kind:
            self._sense_forces()
        return self._applied_a.copy()

    def _sense_forces(self) -> None:
        """Delivered current of a tension source or muscle: its force on the spool over the force per amp."""
        force = self._force_mv
        applied = self._applied_mv
        dadr = self._spool_dadr_list
        amps_per_n = self._amps_per_n
        for k in range(self._n):
            applied[k] = force[dadr[k]] * amps_per_n


def _float_view(array: FloatArray) -> memoryview[float]:
    """The buffer of a float64 array as a memoryview (its items are Python floats)."""
    return cast("memoryview[float]", array.data)
