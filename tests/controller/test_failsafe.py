"""Failsafe phase machine, given/when/then in simulated time (1 ms ticks, fake C610 trio, scripted RC).

Every "lost" must give zero current on the first tick after the timeout expires, not later.
"""

from __future__ import annotations

import math

from controller.config import FirmwareConfig
from controller.events import EventQueue
from controller.failsafe import Failsafe
from protocol.dbus import Lever, RcFrame
from protocol.messages import ArmBlocker, Command, CommandCode, EventKind, Heartbeat, Phase
from tests.support.controller_harness import Rig, frame

ZERO = (0, 0, 0)
MANUAL_CURL = frame(right=Lever.MIDDLE, ch3=400)


def armed_manual_rig(**cfg: object) -> Rig:
    rig = Rig(FirmwareConfig.from_dict(cfg), link=bool(cfg.get("host_required")))
    if cfg.get("host_required"):
        rig.send(Heartbeat(0, 0))
    rig.arm()
    rig.set_rc(MANUAL_CURL)
    rig.until(lambda: all(c > 0 for c in rig.currents), 50)
    return rig


# --- start-up gate --------------------------------------------------------------------------------


def test_gate_no_current_before_any_rc() -> None:
    # given a board with the radio silent
    rig = Rig(start=None)
    rig.radio.set_frame(None)
    # when it runs for a second
    for _ in range(1000):
        rig.tick()
        # then no current ever flows and the phase stays GATE
        assert rig.currents == ZERO
    assert rig.fw.phase == Phase.GATE


def test_gate_holds_while_right_lever_is_not_down_at_boot() -> None:
    # given the radio powered up with the right lever already in MANUAL and the left stick up
    rig = Rig(start=frame(right=Lever.MIDDLE, ch3=600))
    # when the board boots
    for _ in range(200):
        rig.tick()
        # then it refuses to drive the motors
        assert rig.currents == ZERO
    assert rig.fw.phase == Phase.GATE
    # when the lever is put DOWN, the gate opens (SAFE: still zero current)
    rig.set_rc(frame())
    rig.until(lambda: rig.fw.phase == Phase.OK, 30)
    assert rig.currents == ZERO
    # and MIDDLE now gives current
    rig.set_rc(frame(right=Lever.MIDDLE, ch3=600))
    rig.until(lambda: all(c > 0 for c in rig.currents), 30)


def test_gate_needs_all_motors() -> None:
    # given motor 3 never answers
    rig = Rig()
    rig.bus.c610s.silent.add(3)
    # when the lever is DOWN for a while
    rig.tick(100)
    # then the gate stays closed
    assert rig.fw.phase == Phase.GATE
    # when motor 3 comes up, the gate opens
    rig.bus.c610s.silent.clear()
    rig.until(lambda: rig.fw.phase == Phase.OK, 20)


# --- RC lost --------------------------------------------------------------------------------------


def test_rc_lost_zero_current_on_the_tick_after_30_ms() -> None:
    # given an armed board in MANUAL with current flowing
    rig = armed_manual_rig()
    # when the radio goes silent right after delivering a frame
    rig.until(lambda: rig.radio.frames_sent > 0 and rig.fw.rc_frame is not None and _fresh(rig), 20)
    last_frame_us = rig.last_us
    rig.set_rc(None)
    # then current flows through last + 30 ms ...
    while rig.now_us <= last_frame_us + 30_000:
        rig.tick()
        assert all(c > 0 for c in rig.currents), rig.last_us - last_frame_us
    assert rig.fw.phase == Phase.OK
    # ... and is zero on the very next tick, in phase RC_LOST
    rig.tick()
    assert rig.last_us == last_frame_us + 31_000
    assert rig.currents == ZERO
    assert rig.fw.phase == Phase.RC_LOST


def _fresh(rig: Rig) -> bool:
    return rig.fw.failsafe._last_rc_us == rig.last_us


def test_rc_regained_stays_latched_until_rearmed_then_resumes_from_the_floor() -> None:
    # given RC lost
    rig = armed_manual_rig()
    rig.set_rc(None)
    rig.until(lambda: rig.fw.phase == Phase.RC_LOST, 40)
    # when frames return with the lever still in MANUAL
    rig.set_rc(MANUAL_CURL)
    for _ in range(100):
        rig.tick()
        # then nothing moves: the radio came back, the pilot has not re-armed
        assert rig.currents == ZERO and rig.fw.phase == Phase.RC_LOST
    # when the pilot re-arms through SAFE
    rig.set_rc(frame(right=Lever.DOWN))
    rig.until(lambda: rig.fw.phase == Phase.OK, 20)
    assert rig.currents == ZERO  # SAFE mode
    rig.set_rc(MANUAL_CURL)
    rig.until(lambda: any(c > 0 for c in rig.currents), 20)
    # then the tensions restart at the floor and ramp (slew-limited), not jump to the stick value
    pretension = rig.config.mapping.pretension_n
    first = rig.fw.tensions_n
    assert all(abs(t - pretension) <= rig.config.mapping.slew_n_per_s * 1e-3 + 1e-9 for t in first)


def test_invalid_frames_are_counted_and_never_acted_on() -> None:
    # given an armed board in SAFE
    rig = Rig()
    rig.arm()
    # when only out-of-range frames with the lever in MIDDLE arrive
    bad = RcFrame((700, 0, 0, 660), Lever.MIDDLE, Lever.DOWN)
    lever0 = RcFrame((0, 0, 0, 600), 0, Lever.DOWN)
    rig.set_rc(bad)
    rig.radio.inject(lever0)
    for _ in range(25):
        rig.tick()
        # then they never move the motors
        assert rig.currents == ZERO
    assert rig.fw.rc_rejected >= 2
    assert rig.fw.rc_frame is not None and rig.fw.rc_frame.right_lever == Lever.DOWN
    # and RC counts as lost once the last valid frame is 30 ms old
    rig.until(lambda: rig.fw.phase == Phase.RC_LOST, 40)


# --- motor lost -----------------------------------------------------------------------------------


def test_motor_silent_over_10_ms_zero_on_next_tick_and_latched() -> None:
    # given an armed board in MANUAL
    rig = armed_manual_rig()
    # when motor 2 stops answering
    rig.bus.c610s.silent.add(2)
    rig.tick()
    last_fb_us = rig.fw.motors.last_feedback_us[1]
    while rig.now_us <= last_fb_us + 10_000:
        rig.tick()
        assert all(c > 0 for c in rig.currents)
    # then all three currents are zero on the next tick
    rig.tick()
    assert rig.last_us == last_fb_us + 11_000
    assert rig.currents == ZERO
    assert rig.fw.phase == Phase.MOTOR_FAULT
    assert rig.fw.failsafe.motor_offline_events == 1
    # when the motor comes back with the lever still in MIDDLE
    rig.bus.c610s.silent.clear()
    for _ in range(100):
        rig.tick()
        # then the fault stays latched
        assert rig.currents == ZERO
    assert rig.fw.phase == Phase.MOTOR_FAULT
    # when the operator re-arms through SAFE
    rig.set_rc(frame())
    rig.until(lambda: rig.fw.phase == Phase.OK, 30)
    rig.set_rc(MANUAL_CURL)
    rig.until(lambda: all(c > 0 for c in rig.currents), 30)


def test_motor_fault_needs_the_motor_back_before_rearming() -> None:
    rig = armed_manual_rig()
    rig.bus.c610s.silent.add(1)
    rig.until(lambda: rig.fw.phase == Phase.MOTOR_FAULT, 20)
    # lever DOWN while the motor is still silent: stays latched
    rig.set_rc(frame())
    rig.tick(50)
    assert rig.fw.phase == Phase.MOTOR_FAULT
    rig.bus.c610s.silent.clear()
    rig.until(lambda: rig.fw.phase == Phase.OK, 20)


# --- host lost ------------------------------------------------------------------------------------


def test_host_lost_zero_current_when_host_required() -> None:
    # given a board that requires the host, armed, host heartbeat sent once
    rig = armed_manual_rig(host_required=True, host_timeout_us=100_000)
    hb_us = rig.fw.failsafe._last_hb_us
    # when the host goes silent
    while rig.now_us <= hb_us + 100_000:
        rig.tick()
        assert all(c > 0 for c in rig.currents)
    # then current is zero on the next tick
    rig.tick()
    assert rig.currents == ZERO
    assert rig.fw.phase == Phase.HOST_LOST
    # when heartbeats return, the loss stays latched until the pilot re-arms through SAFE
    rig.send(Heartbeat(1, 1))
    for _ in range(50):
        rig.tick()
        assert rig.currents == ZERO and rig.fw.phase == Phase.HOST_LOST
    rig.send(Heartbeat(2, 2))
    rig.set_rc(frame(right=Lever.DOWN))
    rig.until(lambda: rig.fw.phase == Phase.OK, 20)
    rig.send(Heartbeat(3, 3))
    rig.set_rc(MANUAL_CURL)
    rig.until(lambda: all(c > 0 for c in rig.currents), 20)


def test_host_not_required_ignores_missing_heartbeat() -> None:
    rig = armed_manual_rig()
    rig.tick(1000)
    assert rig.fw.phase == Phase.OK and all(c > 0 for c in rig.currents)


def test_gate_waits_for_host_when_required() -> None:
    rig = Rig(FirmwareConfig().replaced(host_required=True), link=True)
    rig.tick(100)
    assert rig.fw.phase == Phase.GATE
    rig.send(Heartbeat(0, 0))
    rig.until(lambda: rig.fw.phase == Phase.OK, 5)


# --- E-stop, arm, disarm --------------------------------------------------------------------------


def test_estop_latched_until_cleared_and_rearmed_through_safe() -> None:
    # given an armed board in MANUAL with a host link
    rig = Rig(link=True)
    rig.arm()
    rig.set_rc(MANUAL_CURL)
    rig.until(lambda: all(c > 0 for c in rig.currents), 50)
    # when the host sends E-stop
    rig.send(Command(CommandCode.ESTOP))
    rig.tick()
    # then current is zero on that very tick (link_rx runs before control)
    assert rig.currents == ZERO
    assert rig.fw.phase == Phase.ESTOP
    # and stays zero whatever the sticks do
    rig.tick(100)
    assert rig.currents == ZERO
    # when cleared with the lever still MIDDLE: the gate, still zero
    rig.send(Command(CommandCode.CLEAR_ESTOP))
    rig.tick(50)
    assert rig.fw.phase == Phase.GATE and rig.currents == ZERO
    # when re-armed through SAFE, MANUAL works again
    rig.set_rc(frame())
    rig.until(lambda: rig.fw.phase == Phase.OK, 30)
    rig.set_rc(MANUAL_CURL)
    rig.until(lambda: all(c > 0 for c in rig.currents), 30)


def test_disarm_needs_arm_command() -> None:
    rig = Rig(link=True)
    rig.arm()
    rig.send(Command(CommandCode.DISARM))
    rig.tick(50)
    assert rig.fw.phase == Phase.GATE  # lever DOWN is not enough after a DISARM
    rig.send(Command(CommandCode.ARM))
    rig.until(lambda: rig.fw.phase == Phase.OK, 5)


def test_arm_refused_during_estop() -> None:
    rig = Rig(link=True)
    rig.arm()
    rig.send(Command(CommandCode.ESTOP))
    rig.tick()
    rig.send(Command(CommandCode.ARM))
    rig.tick()
    assert rig.fw.phase == Phase.ESTOP


# --- the machine alone ----------------------------------------------------------------------------


def test_phase_events_carry_board_time() -> None:
    events = EventQueue(16)
    fs = Failsafe(FirmwareConfig(), events)
    fs.on_motor_frames(5_000, [(1, None), (2, None), (3, None)])
    fs.on_rc_frame(5_000, Lever.DOWN)
    assert fs.update(5_000) == Phase.OK
    assert fs.update(40_000) == Phase.MOTOR_FAULT  # motors silent first (priority over RC)
    got = [(e.time_us, e.kind, e.code) for e in events.pop_all()]
    assert (5_000, EventKind.PHASE, Phase.OK) in got
    assert (40_000, EventKind.PHASE, Phase.MOTOR_FAULT) in got
    assert sum(1 for _, k, _ in got if k == EventKind.FAULT) == 3


def test_arm_blocker_names_what_holds_the_gate() -> None:
    fs = Failsafe(FirmwareConfig().replaced(host_required=True), EventQueue(64))
    fs.update(0)
    assert fs.arm_blocker() == ArmBlocker.MOTOR_FAULT  # nothing seen yet: motors come first
    fs.on_motor_frames(1_000, [(1, None), (2, None), (3, None)])
    fs.update(1_000)
    assert fs.arm_blocker() == ArmBlocker.RC_INVALID
    fs.on_rc_frame(2_000, Lever.MIDDLE)
    fs.update(2_000)
    assert fs.arm_blocker() == ArmBlocker.HOST_MISSING
    fs.on_heartbeat(3_000)
    fs.disarm(3_000)
    fs.update(3_000)
    assert fs.arm_blocker() == ArmBlocker.DISARMED
    assert fs.arm()
    fs.update(3_000)
    assert fs.arm_blocker() == ArmBlocker.LEVER_NOT_DOWN
    fs.on_motor_frames(4_000, [(1, None), (2, None), (3, None)])
    fs.on_rc_frame(4_000, Lever.DOWN)
    assert fs.update(4_000) == Phase.OK
    assert fs.arm_blocker() == ArmBlocker.NONE
    fs.estop(4_000)
    assert fs.arm_blocker() == ArmBlocker.ESTOP_LATCHED


# --- speed governor -------------------------------------------------------------------------------


def _slack_cable_snap(payin_limit_m_per_s: float) -> tuple[float, float]:
    """Reel 50 mm of slack in on every cable under a full MANUAL curl; the cables' largest tension and
    pay-in speed. The fake drives carry the M2006's 1.3 kg of reflected inertia on a stiff cable."""
    rig = Rig(FirmwareConfig().replaced(payin_limit_m_per_s=payin_limit_m_per_s))
    for motor in rig.bus.c610s.motors:
        motor.k = 48_000.0  # N/m: a 0.5 mm UHMWPE cable about 0.25 m long
        motor.j = 1.3 * motor.r**2  # 1.3 kg at the cable
        motor.b = 5.0 * motor.r**2  # 5 N·s/m at the cable: the drive's 1 N of friction at 0.2 m/s
        motor.angle_out_rad = -0.05 / motor.r  # 50 mm slack
    rig.arm()
    rig.set_rc(frame(right=Lever.MIDDLE, ch3=660))
    peak_n = peak_m_s = 0.0
    for _ in range(1500):
        rig.tick()
        for motor in rig.bus.c610s.motors:
            peak_n = max(peak_n, motor.cable_tension_n)
            peak_m_s = max(peak_m_s, motor.speed_out_rad_s * motor.r)
    return peak_n, peak_m_s


def test_governor_a_slack_cable_is_reeled_in_slowly_and_snaps_taut_gently() -> None:
    off_n, off_m_s = _slack_cable_snap(10.0)  # above any speed the drive reaches: no governing
    limit_m_s = FirmwareConfig().motor.payin_limit_m_per_s
    on_n, on_m_s = _slack_cable_snap(limit_m_s)
    assert off_m_s > 0.5 and off_n > 100.0  # without it: v·sqrt(k·m) of a spool run up by 8.5 N
    assert 0.0 < on_m_s < 2 * limit_m_s  # the cut reaches the pretension at twice the limit
    assert on_n > 0.0  # the slack was taken in
    # it snaps taut at most at twice the limit: v·sqrt(k·m), plus the 8.5 N the curl asked for
    assert on_n < 0.5 * off_n and on_n < 2 * limit_m_s * math.sqrt(48_000.0 * 1.3) + 8.5


# --- the failsafe alone, on its own clock (what the mutation benchmark found untested) -------------


def _alone() -> Failsafe:
    """A failsafe of the default board, fed by hand (:func:`_feed`)."""
    return Failsafe(FirmwareConfig(), EventQueue(64))


def _feed(fs: Failsafe, t_us: int, lever: int = Lever.DOWN, rc: bool = True) -> Phase:
    """Every motor answers at ``t_us``; a valid RC frame with ``lever`` unless ``rc`` is False."""
    fs.on_motor_frames(t_us, [(1, None), (2, None), (3, None)])
    if rc:
        fs.on_rc_frame(t_us, lever)
    return fs.update(t_us)


def test_armed_is_exactly_phase_ok() -> None:
    fs = _alone()
    assert not fs.armed and fs.phase == Phase.GATE
    assert _feed(fs, 1000) == Phase.OK and fs.armed
    t = 1000
    while fs.phase == Phase.OK and t < 200_000:  # the radio falls silent: RC_LOST, not armed
        t += 1000
        _feed(fs, t, rc=False)
    assert fs.phase == Phase.RC_LOST and not fs.armed
    fs.estop(t)
    assert fs.phase == Phase.ESTOP and not fs.armed


def test_an_estop_over_a_latched_rc_loss_holds_until_cleared_whatever_the_radio_does() -> None:
    """E-stop pressed while RC_LOST is latched: the radio coming back with the lever DOWN re-arms
    nothing; only CLEAR_ESTOP leaves ESTOP, and then the latched loss still needs the lever DOWN."""
    fs = _alone()
    assert _feed(fs, 1000) == Phase.OK
    t = 1000
    while fs.phase == Phase.OK and t < 200_000:
        t += 1000
        _feed(fs, t, rc=False)
    assert fs.phase == Phase.RC_LOST
    fs.estop(t)
    for _ in range(500):  # half a second of valid frames, lever DOWN
        t += 1000
        assert _feed(fs, t, lever=Lever.DOWN) == Phase.ESTOP and not fs.armed
    assert fs.clear_estop(t)
    assert _feed(fs, t + 1000, lever=Lever.MIDDLE) != Phase.OK  # not without the lever DOWN
    assert _feed(fs, t + 2000, lever=Lever.DOWN) == Phase.OK


def test_a_motor_going_and_coming_back_is_said_once_each_naming_it() -> None:
    events = EventQueue(64)
    fs = Failsafe(FirmwareConfig(), events)
    assert _feed(fs, 1000) == Phase.OK
    events.pop_all()
    t = 1000
    for _ in range(200):  # motor 2 silent, the others answer
        t += 1000
        fs.on_motor_frames(t, [(1, None), (3, None)])
        fs.on_rc_frame(t, Lever.DOWN)
        fs.update(t)
    fs.on_motor_frames(t + 1000, [(1, None), (2, None), (3, None)])
    fs.update(t + 1000)
    got = [e for e in events.pop_all() if e.kind in (EventKind.FAULT, EventKind.INFO)]
    assert fs.motor_offline_events == 1
    assert [(e.kind, e.code, e.value, e.text) for e in got] == [
        (EventKind.FAULT, 2, 0.0, "motor 2 offline"),
        (EventKind.INFO, 2, 1.0, "motor 2 online"),
    ]


def test_only_the_motors_that_answer_are_said_online() -> None:
    events = EventQueue(64)
    fs = Failsafe(FirmwareConfig(), events)
    fs.on_motor_frames(1000, [(1, None), (2, None)])  # motor 3 never answers
    fs.update(1000)
    online = [e.code for e in events.pop_all() if e.kind == EventKind.INFO and "online" in e.text]
    assert online == [1, 2] and fs.motors_online == 0b011
