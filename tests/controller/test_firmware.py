"""The firmware as a whole: modes, the board link (telemetry, commands, parameters), the loops."""

from __future__ import annotations

import contextlib
import math
import os
import time
from collections import Counter
from collections.abc import Iterator

import pytest

from controller.clock import LockstepClock, RealTimeClock
from controller.commands import PARAM_VALUES_PER_TICK
from controller.config import FirmwareConfig
from controller.firmware import Firmware
from controller.motorbus import FakeMotorBus
from controller.params import PARAMS
from controller.rc import ScriptedRcSource
from controller.transport import MemoryTransport, SerialTransport
from protocol.dbus import Lever
from protocol.link import LinkParser, encode_frame
from protocol.messages import (
    PARAM_INDEX_BY_NAME,
    AckResult,
    ArmBlocker,
    ArmPoses,
    BoardStatus,
    Command,
    CommandAck,
    CommandCode,
    Event,
    EventKind,
    Heartbeat,
    Mode,
    MotorFrames,
    ParamRequest,
    ParamSet,
    ParamValue,
    Phase,
    RawRc,
    SimPoses,
    Telemetry,
    TelemetryFlags,
    VirtualRc,
    decode,
    encode,
)
from tests.support.controller_harness import Rig, frame, link_rc_rig

ZERO = (0, 0, 0)


def settle(rig: Rig, ms: int = 1000) -> None:
    rig.tick(ms)


# --- modes ----------------------------------------------------------------------------------------


def test_manual_common_tension_reaches_the_current_the_model_predicts() -> None:
    rig = Rig()
    rig.arm()
    rig.set_rc(frame(right=Lever.MIDDLE, ch3=660))
    settle(rig)
    c = rig.config
    tension = c.mapping.pretension_n + c.mapping.common_max_n * (660 - c.mapping.stick_deadband) / 660
    raw = round(tension * c.motor.spool_radius_m / c.motor.torque_constant_nm_per_a * 1000)
    assert rig.fw.mode == Mode.MANUAL
    assert rig.currents == (raw, raw, raw)
    assert rig.fw.tensions_n == pytest.approx((tension,) * 3)


def test_manual_bend_pulls_the_cable_on_that_side() -> None:
    rig = Rig()
    rig.arm()
    rig.set_rc(frame(right=Lever.MIDDLE, ch0=-330, ch1=-572))  # toward 240° = cable 3
    settle(rig)
    i1, i2, i3 = rig.currents
    assert i3 > i1 and i3 > i2 and i1 == i2


def test_safe_mode_is_zero_current_whatever_the_sticks() -> None:
    rig = Rig()
    rig.arm()
    rig.set_rc(frame(right=Lever.DOWN, ch0=660, ch3=660))
    settle(rig, 200)
    assert rig.fw.mode == Mode.SAFE and rig.currents == ZERO


def test_grasp_mode_packs_the_arm() -> None:
    rig = Rig()
    rig.arm()
    rig.set_rc(frame(right=Lever.UP))
    settle(rig, 2000)
    assert rig.fw.mode == Mode.GRASP
    assert rig.currents[0] > rig.currents[1] == rig.currents[2] > 0  # curl toward cable 1 (0°)


def test_direct_mode_follows_host_tensions_while_the_lever_is_middle() -> None:
    rig = Rig(link=True)
    rig.send(Heartbeat(0, 0))
    rig.arm()
    rig.set_rc(frame(right=Lever.MIDDLE))
    rig.until(lambda: rig.fw.mode == Mode.MANUAL, 30)
    rig.send(Command(CommandCode.SET_TENSIONS, (2.0, 4.0, 100.0)))
    rig.send(Command(CommandCode.SET_MODE, (float(Mode.DIRECT), 0.0, 0.0)))
    rig.tick(2)
    acks = [m for m in rig.drain() if isinstance(m, CommandAck)]
    assert [(a.result, a.text) for a in acks] == [
        (AckResult.ACCEPTED, "clamped"),
        (AckResult.ACCEPTED, "direct tensions"),
    ]
    for _ in range(100):
        rig.send(Heartbeat(0, 0))
        rig.tick(10)
    assert rig.fw.mode == Mode.DIRECT
    assert rig.fw.tensions_n == pytest.approx((2.0, 4.0, rig.config.mapping.tension_max_n))
    # the radio stays master: the lever leaves MIDDLE, DIRECT ends for good
    rig.set_rc(frame(right=Lever.UP))
    rig.until(lambda: rig.fw.mode == Mode.GRASP, 30)
    rig.set_rc(frame(right=Lever.MIDDLE))
    rig.until(lambda: rig.fw.mode == Mode.MANUAL, 30)


def test_direct_mode_ends_when_the_host_goes_silent() -> None:
    cfg = FirmwareConfig().replaced(host_timeout_us=50_000)
    rig = Rig(cfg, link=True)
    rig.send(Heartbeat(0, 0))
    rig.arm()
    rig.set_rc(frame(right=Lever.MIDDLE))
    rig.tick(20)
    rig.send(Command(CommandCode.SET_MODE, (float(Mode.DIRECT), 0.0, 0.0)))
    rig.until(lambda: rig.fw.mode == Mode.DIRECT, 5)
    rig.until(lambda: rig.fw.mode == Mode.MANUAL, 60)
    assert rig.fw.phase == Phase.OK  # host not required: only DIRECT ends


def test_set_mode_refuses_what_the_lever_owns() -> None:
    rig = Rig(link=True)
    rig.arm()
    rig.send(Command(CommandCode.SET_MODE, (float(Mode.GRASP), 0.0, 0.0)))
    rig.send(Command(CommandCode.SET_MODE, (float(Mode.DIRECT), 0.0, 0.0)))  # lever DOWN
    rig.send(Command(CommandCode.SET_TENSIONS, (math.nan, 0.0, 0.0)))
    rig.tick(2)
    results = [m.result for m in rig.drain() if isinstance(m, CommandAck)]
    assert results == [AckResult.DENIED, AckResult.REJECTED, AckResult.DENIED]


# --- the link -------------------------------------------------------------------------------------


def test_telemetry_rates_and_contents() -> None:
    rig = Rig(link=True)
    rig.arm()
    rig.set_rc(frame(right=Lever.MIDDLE, ch3=330))
    rig.drain()
    rig.tick(1000)
    msgs = rig.drain()
    counts = Counter(type(m) for m in msgs)
    assert counts[Telemetry] == 100 and counts[MotorFrames] == 100
    assert counts[BoardStatus] == 2
    assert counts[RawRc] in (71, 72)  # one per DR16 frame, every 14 ms
    tel = [m for m in msgs if isinstance(m, Telemetry)][-1]
    assert (tel.mode, tel.phase) == (Mode.MANUAL, Phase.OK)
    assert tel.flags & TelemetryFlags.ARMED and tel.flags & TelemetryFlags.RC_OK
    assert not tel.flags & TelemetryFlags.SIM
    assert tel.motors_online == 0b111
    assert tel.rc_channels == (0, 0, 0, 330) and tel.right_lever == Lever.MIDDLE
    assert tel.commanded_current == rig.currents
    assert all(t > 0 for t in tel.tension_est_n) and all(x > 0 for x in tel.cable_length_m)
    assert tel.rc_frames_ok > 70 and tel.rc_rejected == 0
    raw = [m for m in msgs if isinstance(m, RawRc)][-1]
    assert raw.frame == frame(right=Lever.MIDDLE, ch3=330)
    mf = [m for m in msgs if isinstance(m, MotorFrames)][-1]
    assert [f[0] for f in mf.frames] == [0x201, 0x202, 0x203]
    status = [m for m in msgs if isinstance(m, BoardStatus)][-1]
    names = [t.name for t in status.tasks]
    assert names == ["link_rx", "control", "detect", "telemetry", "status"]
    control = status.tasks[1]
    assert control.period_us == 1000 and control.runs >= 500 and control.late == 0


def test_telemetry_carries_the_control_lateness_p99() -> None:
    rig = Rig(link=True)
    # One control tick in ten starts 40 µs late (start-up jitter): p99 40 µs, max 40 µs.
    for k in range(1000):
        rig.fw.run_due(k * 1000 + (40 if k % 10 == 3 else 0))
    tel = [m for m in rig.drain() if isinstance(m, Telemetry)]
    assert tel[0].control_lateness_p99_us == 0  # refreshed with BoardStatus (2 Hz), like the exec p99
    assert tel[-1].control_lateness_p99_us == 40
    assert tel[-1].control_lateness_max_us == 40 and tel[-1].control_late == 0
    assert rig.fw.build_telemetry(1_000_000).control_lateness_p99_us == 40


def test_telemetry_says_which_arming_blocker_holds_the_gate() -> None:
    rig = Rig(link=True, start=frame(right=Lever.MIDDLE))
    rig.tick(20)
    assert rig.fw.build_telemetry(rig.now_us).arm_blocker == ArmBlocker.LEVER_NOT_DOWN
    rig.arm()
    rig.tick(20)
    assert [m for m in rig.drain() if isinstance(m, Telemetry)][-1].arm_blocker == ArmBlocker.NONE
    rig.send(Command(CommandCode.DISARM))
    rig.tick(20)
    assert [m for m in rig.drain() if isinstance(m, Telemetry)][-1].arm_blocker == ArmBlocker.DISARMED


def test_events_carry_board_time() -> None:
    rig = Rig(link=True)
    rig.arm()
    rig.tick(20)
    events = [m for m in rig.drain() if isinstance(m, Event)]
    kinds = [e.kind for e in events]
    assert kinds[0] == EventKind.BOOT
    ok = [e for e in events if e.kind == EventKind.PHASE and e.code == Phase.OK]
    assert ok and 0 <= ok[0].time_us < rig.now_us


def test_virtual_rc_drives_a_link_rc_board_and_is_ignored_with_a_radio() -> None:
    rig = link_rc_rig()
    for _ in range(10):
        rig.send(VirtualRc.from_frame(frame()))
        rig.tick(14)
    assert rig.fw.phase == Phase.OK
    for _ in range(50):
        rig.send(VirtualRc.from_frame(frame(right=Lever.MIDDLE, ch3=660)))
        rig.tick(14)
    assert rig.fw.mode == Mode.MANUAL and all(c > 0 for c in rig.currents)
    # the sticks stop: RC lost after 30 ms
    rig.until(lambda: rig.currents == ZERO, 40)
    radio = Rig(link=True)
    radio.send(VirtualRc.from_frame(frame(right=Lever.MIDDLE, ch3=660)))
    radio.tick(5)
    assert radio.fw.virtual_rc_ignored == 1


def test_parameters_get_and_set() -> None:
    rig = Rig(link=True)
    rig.tick()
    rig.drain()
    rig.send(ParamRequest())
    rig.send(ParamRequest(PARAM_INDEX_BY_NAME, "PRETENSION_N"))
    rig.send(ParamRequest(0))
    rig.send(ParamRequest(PARAM_INDEX_BY_NAME, "NO_SUCH"))
    rig.tick()
    # single values at once; the list streams PARAM_VALUES_PER_TICK per tick from the next tick on
    values = [m for m in rig.drain() if isinstance(m, ParamValue)]
    assert len(values) == 2
    assert values[0].name == "PRETENSION_N" and values[0].value == pytest.approx(0.5)
    assert values[1].index == 0 and values[1].count == len(PARAMS)
    ticks = -(-len(PARAMS) // PARAM_VALUES_PER_TICK)
    rig.tick(ticks - 1)
    assert len([m for m in rig.drain() if isinstance(m, ParamValue)]) == (ticks - 1) * PARAM_VALUES_PER_TICK
    rig.tick()
    listed = [m for m in rig.drain() if isinstance(m, ParamValue)]
    assert len(listed) == len(PARAMS) - (ticks - 1) * PARAM_VALUES_PER_TICK
    # a valid set changes the runtime copy and is echoed
    rig.send(ParamSet("PRETENSION_N", 1.25))
    # an invalid one is answered with the value in force
    rig.send(ParamSet("CURRENT_LIMIT_A", 50.0))
    rig.send(ParamSet("NO_SUCH", 1.0))
    rig.tick(20)
    msgs = rig.drain()
    echoed = [(v.name, v.value) for v in msgs if isinstance(v, ParamValue)]
    assert echoed == [("PRETENSION_N", 1.25), ("CURRENT_LIMIT_A", 3.0)]
    assert rig.fw.config.mapping.pretension_n == 1.25
    assert rig.fw.config.motor.current_limit_a == 3.0
    params = [e for e in msgs if isinstance(e, Event) and e.kind == EventKind.PARAM]
    assert [p.text.split(":")[0] for p in params] == [
        "PRETENSION_N = 1.25",
        "rejected",
        "unknown parameter NO_SUCH",
    ]


def test_current_limit_parameter_reaches_the_bus() -> None:
    rig = Rig(link=True)
    rig.send(ParamSet("CURRENT_LIMIT_A", 0.5))
    rig.arm()
    rig.set_rc(frame(right=Lever.MIDDLE, ch3=660, ch0=660))
    settle(rig)
    assert max(rig.currents) == 500 and rig.bus.current_limit_raw == 500


def test_unknown_command_code_is_answered_unsupported_and_garbage_is_counted() -> None:
    rig = Rig(link=True)
    assert rig.host is not None
    rig.host.write(encode_frame(Command.CMD_ID, bytes([99]) + bytes(12), 7))
    rig.host.write(b"\xa5\x00\x01garbage" + encode(Heartbeat(0, 0), 1)[:-1] + b"\x00")
    rig.tick(2)
    acks = [m for m in rig.drain() if isinstance(m, CommandAck)]
    assert (acks[0].command, acks[0].result, acks[0].request_seq) == (99, AckResult.UNSUPPORTED, 7)
    assert rig.fw.counters["link_crc_errors"] >= 1
    assert rig.fw.counters["link_decode_errors"] == 1


def test_require_host_command() -> None:
    rig = Rig(link=True)
    rig.arm()
    rig.send(Command(CommandCode.REQUIRE_HOST, (1.0, 0.0, 0.0)))
    rig.tick(2)
    assert rig.fw.phase == Phase.HOST_LOST and rig.fw.config.failsafe.host_required
    rig.send(Command(CommandCode.REQUIRE_HOST, (0.0, 0.0, 0.0)))
    rig.tick(2)
    assert rig.fw.phase == Phase.OK


Poses = tuple[tuple[tuple[float, float, float], ...], tuple[tuple[float, float, float, float], ...]]


class PosingBus(FakeMotorBus):
    simulated = True

    def poses(self) -> Poses:
        return ((0.0, 0.0, 1.0), (0.0, 0.0, 0.9)), ((1.0, 0.0, 0.0, 0.0), (1.0, 0.0, 0.0, 0.0))


def test_sim_poses_only_when_the_bus_provides_them() -> None:
    host, board = MemoryTransport.pair()
    fw = Firmware(FirmwareConfig(), PosingBus(), ScriptedRcSource(frame()), board)
    for t in range(0, 100_000, 1000):
        fw.run_due(t)
    msgs = [decode(f) for f in LinkParser().feed(host.read())]
    poses = [m for m in msgs if isinstance(m, SimPoses)]
    assert len(poses) == 5 and poses[0].tip_position_m == pytest.approx((0.0, 0.0, 0.9))
    tel = [m for m in msgs if isinstance(m, Telemetry)][-1]
    assert tel.flags & TelemetryFlags.SIM


def test_an_arrays_pose_messages_are_sent_in_order() -> None:
    """A provider's list (an array: SimPoses with arm 0, then ArmPoses of arms 1..) goes out in order."""
    one = ((0.0, 0.0, 0.5),), ((1.0, 0.0, 0.0, 0.0),)
    batch: list[SimPoses | ArmPoses] = [
        SimPoses(7, ((0.0, 0.0, 1.0), *one[0]), ((1.0, 0.0, 0.0, 0.0), *one[1]))
    ]
    batch += [ArmPoses(7, arm, 3, *one) for arm in (1, 2)]
    host, board = MemoryTransport.pair()
    fw = Firmware(FirmwareConfig(), FakeMotorBus(), ScriptedRcSource(frame()), board, poses=lambda: batch)
    for t in range(0, 20_000, 1000):
        fw.run_due(t)
    msgs = [decode(f) for f in LinkParser().feed(host.read())]
    msgs = [m for m in msgs if isinstance(m, SimPoses | ArmPoses)]
    assert msgs == batch


def test_lockstep_runs_are_deterministic() -> None:
    def run_once() -> bytes:
        rig = Rig(link=True)
        rig.arm()
        rig.set_rc(frame(right=Lever.MIDDLE, ch0=200, ch1=-300, ch3=500))
        rig.tick(500)
        assert rig.host is not None
        return rig.host.read()

    assert run_once() == run_once()


# --- the loops ------------------------------------------------------------------------------------


def test_run_with_a_lockstep_clock_for_a_duration() -> None:
    bus = FakeMotorBus()
    fw = Firmware(FirmwareConfig(), bus, ScriptedRcSource(frame(right=Lever.DOWN)), exec_timer_ns=lambda: 0)
    clock = LockstepClock()
    fw.run(clock, duration_us=250_000)
    assert fw.scheduler["control"].runs == 250
    assert fw.scheduler["control"].late == 0
    assert clock.now_us() == 250_000
    assert fw.phase == Phase.OK and bus.frames_sent == 251  # 250 ticks + the zero on exit


def test_run_stops_on_a_stop_callable_and_sends_zero() -> None:
    rc = ScriptedRcSource(frame())
    rc.schedule(100_000, frame(right=Lever.MIDDLE, ch3=660))
    bus = FakeMotorBus()
    fw = Firmware(FirmwareConfig(), bus, rc)
    clock = LockstepClock()
    fw.run(clock, stop=lambda: clock.now_us() >= 300_000)
    assert fw.scheduler["control"].runs == 300
    assert all(m.current_raw == 0 for m in bus.c610s.motors)
    assert fw.commanded_currents == ZERO


def test_run_in_real_time_briefly() -> None:
    fw = Firmware(FirmwareConfig(), FakeMotorBus(), ScriptedRcSource(frame()))
    fw.run(RealTimeClock(fifo=False), duration_us=10_000_000, stop=lambda: fw.scheduler["control"].runs >= 30)
    assert fw.scheduler["control"].runs == 30
    assert fw.phase == Phase.OK and fw.commanded_currents == ZERO


@pytest.fixture
def pty_link() -> Iterator[tuple[int, SerialTransport]]:
    master, slave = os.openpty()
    os.set_blocking(master, False)
    transport = SerialTransport(os.ttyname(slave))
    try:
        yield master, transport
    finally:
        transport.close()
        os.close(slave)
        os.close(master)


def test_board_link_over_a_pty(pty_link: tuple[int, SerialTransport]) -> None:
    master, transport = pty_link
    fw = Firmware(FirmwareConfig(), FakeMotorBus(), ScriptedRcSource(frame()), transport)
    parser = LinkParser()
    os.write(master, encode(Heartbeat(1, 1), 0) + encode(Command(CommandCode.ESTOP), 1))
    received = []
    t = 0
    deadline = time.monotonic() + 10.0
    while t < 200_000 and time.monotonic() < deadline:
        fw.run_due(t)
        t += 1000
        with contextlib.suppress(BlockingIOError):
            received += [decode(f) for f in parser.feed(os.read(master, 65536))]
    assert parser.header_crc_errors == parser.body_crc_errors == 0
    acks = [m for m in received if isinstance(m, CommandAck)]
    assert acks and acks[0].command == CommandCode.ESTOP and acks[0].result == AckResult.ACCEPTED
    tel = [m for m in received if isinstance(m, Telemetry)]
    assert len(tel) >= 15 and tel[-1].phase == Phase.ESTOP
    assert tel[-1].flags & TelemetryFlags.HOST_OK


def test_firmware_over_python_can_virtual_bus_in_lockstep() -> None:
    import can

    from controller.fake_c610 import FakeC610Set
    from controller.motorbus import CanMotorBus

    channel = f"test-fw-virtual-{os.getpid()}"
    peer = can.Bus(interface="virtual", channel=channel)
    trio = FakeC610Set(start_angles_counts=(8190, 5, 4096))

    def motors_answer() -> None:  # the trio on the far side of the bus, stepped synchronously
        while (msg := peer.recv(timeout=0)) is not None:
            trio.handle_frame(msg.arbitration_id, bytes(msg.data))
            if msg.arbitration_id == 0x200:
                for can_id, data in trio.step(1000):
                    peer.send(can.Message(arbitration_id=can_id, data=data, is_extended_id=False))

    rc = ScriptedRcSource(frame())
    rc.schedule(100_000, frame(right=Lever.MIDDLE, ch3=660))
    try:
        with CanMotorBus(channel, "virtual") as bus:
            fw = Firmware(FirmwareConfig(), bus, rc)
            for t in range(0, 1_000_000, 1000):
                fw.run_due(t)
                motors_answer()
            assert fw.phase == Phase.OK and fw.mode == Mode.MANUAL
            assert all(c > 0 for c in fw.commanded_currents)
            assert fw.failsafe.motors_online == 0b111 and bus.can_errors == 0
            assert all(x > 0 for x in fw.motors.cable_length_m)  # reeled in, across the 8191/0 wrap
        motors_answer()
        assert all(m.current_raw == 0 for m in trio.motors)  # shutdown sent zero current
    finally:
        peer.shutdown()
