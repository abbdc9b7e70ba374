"""The plant's drives (hil.sim.drives) on plain arrays, without MuJoCo: clamping, the torque-speed line,
feedback frames with the 8192-count wrap, the rng, and state kept across a re-attach."""

from __future__ import annotations

import math

import numpy as np
import pytest

from hil.sim.config import ActuatorConfig, MotorConfig
from hil.sim.drives import Drives
from protocol.c610 import ANGLE_COUNTS, MotorFeedback

MOTOR = MotorConfig()


def attached(motor: MotorConfig = MOTOR, rng: np.random.Generator | None = None) -> tuple[Drives, np.ndarray]:
    """Three drives on a state of [spool q0..q2, spool v0..v2] (qpos and qvel share one array here)."""
    drives = Drives(motor, 3, rng)
    state = np.zeros(6)
    drives.attach(state, state, np.zeros(3), [0, 1, 2], [3, 4, 5])
    drives.reset()
    return drives, state


def test_apply_currents_clamps_like_the_esc() -> None:
    drives, _ = attached(MotorConfig(current_limit_a=3.0))
    assert drives.apply_currents([5000, -4000, np.int16(1200), 7]) == (3000, -3000, 1200)  # type: ignore[list-item]
    assert drives.commanded_currents_raw() == (3000, -3000, 1200)
    with pytest.raises(ValueError, match="expected 3"):
        drives.apply_currents([0, 0])
    with pytest.raises(ValueError, match="int"):
        drives.apply_currents([True, 0, 0])


def test_drive_follows_the_torque_speed_line() -> None:
    ctrl = np.zeros(3)
    drives = Drives(MOTOR, 3, None)
    state = np.zeros(6)
    drives.attach(state, state, ctrl, [0, 1, 2], [3, 4, 5])
    omega_nl = MOTOR.no_load_speed_rad_s
    r = MOTOR.spool_radius_m
    state[3:] = (0.5 * omega_nl * r, 0.5 * omega_nl * r, 0.0)  # half the no-load speed, winding in
    drives.apply_currents([10_000, -2000, 0])
    drives.drive()
    available_a = MOTOR.stall_current_a * 0.5  # 9 A in the direction of motion, below the 10 A asked
    assert ctrl.tolist() == pytest.approx([available_a, -2.0, 0.0])  # braking: the full 2 A
    state[3] = 1.1 * omega_nl * r  # beyond no-load speed: the back-EMF exceeds the supply, it brakes
    drives.drive()
    assert ctrl[0] == pytest.approx(-0.1 * MOTOR.stall_current_a)
    state[3] = 3.0 * omega_nl * r  # dragged far past it: braking up to the current limit
    drives.drive()
    assert ctrl[0] == pytest.approx(-MOTOR.current_limit_a)
    assert drives.applied_currents_a().tolist() == ctrl.tolist()


def test_feedback_wraps_per_rotor_turn_and_clamps_speed() -> None:
    drives, state = attached()
    rotor_turn_m = 2.0 * math.pi * MOTOR.spool_radius_m / MOTOR.gear_ratio
    state[0] = 2.5 * rotor_turn_m  # two and a half rotor turns wound in
    state[3] = 1e3  # far beyond int16 rpm
    state[4] = -1e3
    frames = drives.feedback()
    assert frames[0].angle == ANGLE_COUNTS // 2
    assert (frames[0].speed_rpm, frames[1].speed_rpm) == (32767, -32767)
    assert drives.feedback_payloads() == [f.pack() for f in frames]
    assert frames[2] == MotorFeedback(0, 0, 0, MOTOR.temperature_c)


def test_rng_draws_encoder_zeros_and_noise() -> None:
    with pytest.raises(ValueError, match="rng"):
        Drives(MotorConfig(current_noise_raw=5.0), 3, None)
    one, _ = attached(rng=np.random.default_rng(3))
    two, _ = attached(rng=np.random.default_rng(3))
    assert one.angle_offsets_counts == two.angle_offsets_counts != (0, 0, 0)
    assert [f.angle for f in one.feedback()] == list(one.angle_offsets_counts)
    noisy, _ = attached(MotorConfig(current_noise_raw=5.0), rng=np.random.default_rng(4))
    assert any(f.current != 0 for f in noisy.feedback())


def test_state_survives_a_re_attach() -> None:
    drives, _ = attached(rng=np.random.default_rng(1))
    drives.apply_currents([100, 200, 300])
    offsets = drives.angle_offsets_counts
    ctrl = np.zeros(3)
    state = np.zeros(6)
    drives.attach(state, state, ctrl, [0, 1, 2], [3, 4, 5])  # a rebuilt model's MjData
    drives.drive()
    assert drives.commanded_currents_raw() == (100, 200, 300)
    assert drives.angle_offsets_counts == offsets
    assert ctrl.tolist() == pytest.approx([0.1, 0.2, 0.3])


@pytest.mark.parametrize(("kind", "per_amp"), [("tension", MOTOR.force_per_amp_n), ("muscle", 0.5)])
def test_light_actuators_get_the_asked_tension_and_report_their_force(kind: str, per_amp: float) -> None:
    """A current asks for I·kt/r: newtons for a tension source, that over F0 for a muscle (capped at 1);
    pull only. The fed-back current is the delivered force over the force per amp."""
    f0 = MOTOR.force_per_amp_n / 0.5  # 36 N: one amp asks for half the muscle's peak
    drives = Drives(MOTOR, 3, None, ActuatorConfig(kind=kind), f0)
    ctrl = np.zeros(3)
    state = np.zeros(6)
    force = np.zeros(6)
    drives.attach(state, state, ctrl, [0, 1, 2], [3, 4, 5], force)
    drives.apply_currents([1000, -2000, 10_000])
    drives.drive()
    assert ctrl.tolist() == pytest.approx(
        [per_amp, 0.0, min(10 * per_amp, 1.0) if kind == "muscle" else 10 * per_amp]
    )
    force[3:] = (9.0, 0.0, 36.0)  # what the actuators delivered to the spools [N]
    fpa = MOTOR.force_per_amp_n
    assert drives.applied_currents_a().tolist() == pytest.approx([9.0 / fpa, 0.0, 36.0 / fpa])
    assert [fb.current for fb in drives.feedback()] == [round(9000 / fpa), 0, round(36000 / fpa)]


def test_light_actuators_need_their_force_buffer() -> None:
    drives = Drives(MOTOR, 3, None, ActuatorConfig(kind="tension"))
    state = np.zeros(6)
    with pytest.raises(ValueError, match="qfrc_actuator"):
        drives.attach(state, state, np.zeros(3), [0, 1, 2], [3, 4, 5])
    with pytest.raises(ValueError, match="muscle_force_n"):
        Drives(MOTOR, 3, None, ActuatorConfig(kind="muscle"))


def test_a_command_delay_acts_late_and_interpolates_between_periods() -> None:
    ctrl = np.zeros(3)
    drives = Drives(MotorConfig(command_delay_s=0.0015), 3, None, control_period_s=1e-3)
    state = np.zeros(6)
    drives.attach(state, state, ctrl, [0, 1, 2], [3, 4, 5])
    drives.reset()
    seen = []
    for k in range(5):
        drives.apply_currents([1000 * (k + 1), 0, 0])  # 1, 2, 3 ... A, one per period
        drives.drive()
        seen.append(ctrl[0])
    # 1.5 periods late: halfway between the setpoints of one and two periods before.
    assert seen == pytest.approx([0.0, 0.5, 1.5, 2.5, 3.5])


def test_no_delay_applies_the_setpoint_of_the_same_period() -> None:
    ctrl = np.zeros(3)
    drives = Drives(MotorConfig(), 3, None)
    state = np.zeros(6)
    drives.attach(state, state, ctrl, [0, 1, 2], [3, 4, 5])
    drives.apply_currents([1234, 0, 0])
    drives.drive()
    assert ctrl[0] == 1.234


def test_torque_scale_changes_the_force_not_the_reported_current() -> None:
    scaled = MotorConfig(torque_scale=1.25)
    assert scaled.delivered_force_per_amp_n == pytest.approx(1.25 * MOTOR.force_per_amp_n)
    drives = Drives(scaled, 3, None, ActuatorConfig(kind="tension"))
    ctrl, force = np.zeros(3), np.zeros(6)
    state = np.zeros(6)
    drives.attach(state, state, ctrl, [0, 1, 2], [3, 4, 5], qfrc_actuator=force)
    drives.apply_currents([1000, 0, 0])
    drives.drive()
    assert ctrl[0] == pytest.approx(1.25 * MOTOR.force_per_amp_n)  # the tension 1 A really gives
    force[3] = ctrl[0]
    assert drives.applied_currents_a()[0] == pytest.approx(1.0)  # the ESC still measures 1 A
