"""The length-hold cascade: its PID, against a simulated spool, and inside the firmware's failsafe paths."""

from __future__ import annotations

import math

import pytest

from controller.cables import MotorModel, TensionSlew
from controller.config import FirmwareConfig
from controller.lengthhold import LengthHold, Pid
from protocol.c610 import ANGLE_COUNTS, output_rad_s_to_rotor_rpm, output_rad_to_counts
from protocol.dbus import Lever
from protocol.messages import (
    HOLD_HERE,
    HOLD_RELEASE,
    HOLD_UNCHANGED,
    AckResult,
    Command,
    CommandAck,
    CommandCode,
    GraspState,
    Heartbeat,
    Mode,
    Phase,
    Telemetry,
    TelemetryFlags,
)
from tests.support.controller_harness import Rig, frame

DT_US = 1000
HERE = HOLD_HERE
RELEASE = HOLD_RELEASE
SAME = HOLD_UNCHANGED


# --- the PID --------------------------------------------------------------------------------------


def test_pid_clamps_its_output_and_its_integral() -> None:
    pid = Pid(kp=2.0, ki=10.0, kd=0.0, out_min=-1.0, out_max=3.0, imax=0.5)
    assert pid.step(1.0, 0.01) == pytest.approx(2.0 + 0.1)
    for _ in range(100):
        out = pid.step(1.0, 0.01)
    assert pid.iout == 0.5 and out == pytest.approx(2.5)
    assert pid.step(10.0, 0.01) == 3.0  # output limit
    assert pid.step(-10.0, 0.01) == -1.0


def test_pid_derivative_and_bumpless_reset() -> None:
    pid = Pid(kp=0.0, ki=0.0, kd=0.5, out_min=-10.0, out_max=10.0, imax=4.0)
    pid.step(0.0, 0.001)
    assert pid.step(0.001, 0.001) == pytest.approx(0.5)
    pid.reset(7.0)
    assert pid.iout == 4.0 and pid.last_error == 0.0  # the preload is clamped to the integral limit


# --- the cascade against a simulated spool ----------------------------------------------------------


class Spool:
    """One cable's drive as the plant models it: reflected mass, Coulomb friction, an external load.

    ``x_m`` is the cable paid in (the MotorModel's length); the load pulls the cable out.
    """

    def __init__(self, mass_kg: float = 1.3, friction_n: float = 1.0) -> None:
        self.mass_kg = mass_kg
        self.friction_n = friction_n
        self.x_m = 0.0
        self.v_m_s = 0.0
        self.load_n = 0.0

    def step(self, tension_n: float, dt_s: float) -> None:
        force = tension_n - self.load_n
        if self.v_m_s != 0.0:
            force -= math.copysign(self.friction_n, self.v_m_s)
        elif abs(force) <= self.friction_n:
            return  # static friction holds it
        else:
            force -= math.copysign(self.friction_n, force)
        v = self.v_m_s + force / self.mass_kg * dt_s
        if self.v_m_s != 0.0 and v * self.v_m_s < 0.0:
            v = 0.0  # friction stops it, never reverses it
        self.v_m_s = v
        self.x_m += v * dt_s

    def feedback(self, config: FirmwareConfig) -> tuple[int, int, int, int]:
        r = config.motor.spool_radius_m
        counts = output_rad_to_counts(self.x_m / r) % ANGLE_COUNTS
        rpm = round(output_rad_s_to_rotor_rpm(self.v_m_s / r))
        return counts, rpm, 0, 30


def _run(
    spool: Spool, hold: LengthHold, motors: MotorModel, tensions: list[float], ms: int, t0: int
) -> list[float]:
    config = FirmwareConfig()
    xs = []
    for k in range(ms):
        motors.update(0, spool.feedback(config), t0 + k * DT_US)
        hold.step(DT_US, tensions)
        spool.step(tensions[0], DT_US * 1e-6)
        xs.append(spool.x_m)
    return xs


def _cascade() -> tuple[FirmwareConfig, MotorModel, TensionSlew, LengthHold, Spool]:
    config = FirmwareConfig()
    motors = MotorModel(config)
    slew = TensionSlew(config)
    return config, motors, slew, LengthHold(config, motors, slew), Spool()


def test_a_held_cable_keeps_its_length_against_a_load_step() -> None:
    config, motors, slew, hold, spool = _cascade()
    spool.load_n = 3.0
    slew.tensions_n[0] = 3.0  # the tension that held the load before the hold
    motors.update(0, spool.feedback(config), 0)
    assert hold.engage(0)
    assert hold.count == 1 and hold.flags == 0b001 and hold.setpoint_m[0] == 0.0
    xs = _run(spool, hold, motors, slew.tensions_n, 300, DT_US)
    assert max(abs(x) for x in xs) < 0.5e-3  # bumpless: the speed loop starts at the load's tension
    spool.load_n = 10.0  # the load triples
    xs = _run(spool, hold, motors, slew.tensions_n, 2000, 400 * DT_US)
    # Stiffness of the cascade ~ (speed_kp * pos_kp + speed_ki) = 4500 N/m: 7 N sags it about 1.6 mm
    # before the integral takes it back; the rotor-count quantum is 2 µm.
    assert max(abs(x) for x in xs) < 3e-3
    assert abs(xs[-1]) < 0.1e-3
    assert slew.tensions_n[0] == pytest.approx(10.0, abs=1.2)  # holds the load (± the friction)


def test_a_host_set_length_is_reached_and_the_ceiling_still_clamps() -> None:
    config, motors, slew, hold, spool = _cascade()
    # The arm's elastic pull on its cable: a pull-only drive brakes only against it (and the friction).
    spool.load_n = 3.0
    slew.tensions_n[0] = 3.0
    motors.update(0, spool.feedback(config), 0)
    assert hold.engage(0, 0.02)  # reel 20 mm in
    xs = _run(spool, hold, motors, slew.tensions_n, 1500, DT_US)
    assert xs[-1] == pytest.approx(0.02, abs=0.1e-3)
    spool.load_n = 40.0  # more than the 20 N ceiling can hold: the cable is pulled out
    _run(spool, hold, motors, slew.tensions_n, 200, 2000 * DT_US)
    assert slew.tensions_n[0] == config.mapping.tension_max_n
    assert motors.tensions_to_raw(slew.tensions_n, [0, 0, 0])[0] <= config.motor.current_limit_raw


def test_engage_needs_feedback_and_release_is_per_cable() -> None:
    _, motors, _slew, hold, _ = _cascade()
    assert not hold.engage(1)  # motor 2 never answered
    motors.update(1, (0, 0, 0, 30), 0)
    motors.update(2, (0, 0, 0, 30), 0)
    assert hold.engage(1, 0.01) and hold.engage(2, by_grasp=True)
    assert hold.flags == 0b110
    hold.engage(1)  # already held: the set-point stays
    assert hold.setpoint_m[1] == 0.01
    hold.release_grasp()
    assert hold.held == [False, True, False]
    hold.release(1)
    assert hold.count == 0 and hold.flags == 0


# --- inside the firmware: host command, telemetry flags, and every failsafe wins ---------------------


def _direct_with_cable_1_held(config: FirmwareConfig | None = None) -> Rig:
    rig = Rig(config, link=True)
    rig.send(Heartbeat(0, 0))
    rig.arm()
    rig.set_rc(frame(right=Lever.MIDDLE))
    rig.until(lambda: rig.fw.mode == Mode.MANUAL, 30)
    rig.send(Command(CommandCode.SET_TENSIONS, (5.0, 5.0, 5.0)))
    rig.send(Command(CommandCode.SET_MODE, (float(Mode.DIRECT), 0.0, 0.0)))
    for _ in range(30):
        rig.send(Heartbeat(0, 0))
        rig.tick(10)
    rig.drain()
    rig.send(Command(CommandCode.HOLD_LENGTHS, (HERE, SAME, SAME)))
    rig.tick(2)
    acks = [m for m in rig.drain() if isinstance(m, CommandAck)]
    assert [(a.result, a.text) for a in acks] == [(AckResult.ACCEPTED, "held cables: 1")]
    assert rig.fw.hold.held == [True, False, False]
    return rig


def test_host_holds_one_cable_while_setting_another_in_direct_mode() -> None:
    rig = _direct_with_cable_1_held()
    length0 = rig.fw.motors.cable_length_m[0]
    rig.send(Command(CommandCode.SET_TENSIONS, (5.0, 12.0, 5.0)))  # Fig. S11B: one fixed, one pulls
    for _ in range(100):
        rig.send(Heartbeat(0, 0))
        rig.tick(10)
    assert abs(rig.fw.motors.cable_length_m[0] - length0) < 0.2e-3
    assert rig.fw.tensions_n[1] == pytest.approx(12.0)
    assert rig.currents[0] > 0
    telemetry = [m for m in rig.drain() if isinstance(m, Telemetry)]
    assert telemetry[-1].flags & TelemetryFlags.HOLD_1 and not telemetry[-1].flags & TelemetryFlags.HOLD_2
    rig.send(Command(CommandCode.HOLD_LENGTHS, (RELEASE, SAME, SAME)))
    rig.tick(2)
    assert rig.fw.hold.count == 0


def test_hold_is_refused_in_safe() -> None:
    rig = Rig(link=True)
    rig.arm()
    rig.send(Command(CommandCode.HOLD_LENGTHS, (HERE, HERE, HERE)))
    rig.tick(2)
    acks = [m for m in rig.drain() if isinstance(m, CommandAck)]
    assert acks[0].result == AckResult.REJECTED and rig.fw.hold.count == 0


def _zero_on_next_ticks(rig: Rig, max_ticks: int) -> None:
    rig.until(lambda: rig.currents == (0, 0, 0), max_ticks)
    assert rig.fw.mode == Mode.SAFE and rig.fw.hold.count == 0
    rig.tick(50)
    assert rig.currents == (0, 0, 0)


def test_a_held_cable_goes_to_zero_current_on_rc_loss() -> None:
    rig = _direct_with_cable_1_held()
    rig.set_rc(None)
    _zero_on_next_ticks(rig, rig.config.failsafe.rc_timeout_us // 1000 + 2)
    assert rig.fw.phase == Phase.RC_LOST


def test_a_held_cable_goes_to_zero_current_on_host_loss() -> None:
    config = FirmwareConfig().replaced(host_timeout_us=50_000, host_required=True)
    rig = _direct_with_cable_1_held(config)
    _zero_on_next_ticks(rig, 60)  # no more heartbeats
    assert rig.fw.phase == Phase.HOST_LOST


def test_a_held_cable_goes_to_zero_current_on_estop() -> None:
    rig = _direct_with_cable_1_held()
    assert rig.currents[0] > 0
    rig.send(Command(CommandCode.ESTOP))
    rig.tick()
    assert rig.currents == (0, 0, 0) and rig.fw.phase == Phase.ESTOP
    _zero_on_next_ticks(rig, 1)


def test_grasp_hold_length_freezes_the_pulling_cables_in_hold() -> None:
    config = FirmwareConfig().replaced(grasp_strategy_on=False, grasp_hold_length=True)
    rig = Rig(config)
    rig.arm()
    rig.set_rc(frame(right=Lever.UP))
    rig.until(lambda: rig.fw.mode == Mode.GRASP, 30)
    rig.set_rc(frame(right=Lever.UP, left=Lever.UP))
    rig.until(lambda: rig.fw.grasp_state == GraspState.HOLD, 5000)
    rig.tick()
    hold = rig.fw.hold
    assert hold.held == [True, False, False] and hold.by_grasp[0]  # toward cable 1 (0°): it alone pulls
    length0 = hold.setpoint_m[0]
    rig.tick(500)
    assert abs(rig.fw.motors.cable_length_m[0] - length0) < 0.1e-3
    rig.set_rc(frame(right=Lever.UP, left=Lever.DOWN))  # release: the hold ends with HOLD
    rig.until(lambda: rig.fw.grasp_state == GraspState.RELEASE, 30)
    rig.tick()
    assert hold.count == 0
