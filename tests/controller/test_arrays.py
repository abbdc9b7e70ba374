"""Boards of up to eight motors: arrays of one-, two- and three-cable arms (issue 27, item 1).

The layout (``controller.config``): one sign per motor, one angle per cable of an arm; motor m drives
cable (m-1) % C of arm (m-1) // C. Every arm takes the same tensions; the failsafe and the current clamp
are per motor; motors 5-8 are commanded on 0x1FF.
"""

from __future__ import annotations

import math
import os
import random
import time

import can
import pytest

from controller.clock import RealTimeClock
from controller.config import FirmwareConfig
from controller.errors import ConfigError
from controller.events import EventQueue
from controller.fake_c610 import FakeC610Set
from controller.firmware import Firmware
from controller.grasp import GraspMachine
from controller.motorbus import CanMotorBus, FakeMotorBus
from controller.rc import ScriptedRcSource
from protocol.c610 import command_frames, unpack_currents
from protocol.dbus import Lever
from protocol.messages import (
    ArmsTelemetry,
    Command,
    CommandAck,
    CommandCode,
    Event,
    EventKind,
    GraspState,
    Heartbeat,
    Mode,
    MotorFrames,
    Phase,
    Telemetry,
    TelemetryFlags,
)
from tests.support.c610_rigs import C610SetServer
from tests.support.controller_harness import Rig, frame

EIGHT = FirmwareConfig().with_arms(8, 1)


class RecordingFakeBus(FakeMotorBus):
    """A fake C610 set's bus that keeps every frame the firmware sends."""

    def __init__(self, motors: int, **kwargs: int) -> None:
        super().__init__(FakeC610Set.of(motors), **kwargs)
        self.sent: list[tuple[int, bytes]] = []

    def _send_frame(self, can_id: int, data: bytes) -> None:
        self.sent.append((can_id, bytes(data)))
        super()._send_frame(can_id, data)


def rig_of(config: FirmwareConfig) -> Rig:
    return Rig(config, bus=RecordingFakeBus(config.motor_count))


# --- the layout ------------------------------------------------------------------------------------


def test_the_default_is_one_three_cable_arm() -> None:
    c = FirmwareConfig()
    assert (c.motor_count, c.arm_count, c.cables_per_arm) == (3, 1, 3)
    assert c.with_arms(1) == c


@pytest.mark.parametrize(
    ("arms", "cables", "angles"),
    [(8, 1, (0.0,)), (4, 2, (0.0, 180.0)), (2, 3, (0.0, 120.0, 240.0)), (2, 1, (0.0,)), (3, 2, (0.0, 180.0))],
)
def test_with_arms_lays_out_a_board(arms: int, cables: int, angles: tuple[float, ...]) -> None:
    c = FirmwareConfig().with_arms(arms, cables)
    assert (c.motor_count, c.arm_count, c.cables_per_arm) == (arms * cables, arms, cables)
    assert c.mapping.cable_angles_deg == angles and c.motor.motor_signs == (1,) * (arms * cables)
    assert FirmwareConfig.from_dict(c.to_dict()) == c  # a configuration file holds the layout


def test_with_arms_refuses_what_a_board_cannot_drive() -> None:
    with pytest.raises(ConfigError, match="need 9 motors"):
        FirmwareConfig().with_arms(3)  # three three-cable arms
    with pytest.raises(ConfigError, match="cables per arm"):
        FirmwareConfig().with_arms(1, 4)
    mirrored = FirmwareConfig().replaced(motor_signs=(1, -1, 1))
    with pytest.raises(ConfigError, match="mirrored"):
        mirrored.with_arms(8, 1)
    assert mirrored.with_arms(1, 3) == mirrored  # its own layout: kept


@pytest.mark.parametrize(
    ("angles", "signs", "field"),
    [
        ((0.0, 120.0, 240.0), (1, 1, 1, 1), "motor_signs"),  # not whole arms
        ((0.0, 90.0, 180.0, 270.0), (1, 1, 1, 1), "cable_angles_deg"),  # a four-cable arm
        ((0.0,), (1,) * 9, "motor_signs"),  # nine motors
        ((), (1,), "cable_angles_deg"),
    ],
)
def test_the_layout_is_validated(angles: tuple[float, ...], signs: tuple[int, ...], field: str) -> None:
    with pytest.raises(ConfigError, match=field):
        FirmwareConfig().replaced(cable_angles_deg=angles, motor_signs=signs)


def test_a_bus_of_another_size_is_refused() -> None:
    with pytest.raises(ConfigError, match="the motor bus has 3 motors, the configuration 8"):
        Firmware(EIGHT, FakeMotorBus(), ScriptedRcSource(frame()))


# --- an eight-motor board on the fake C610 set ----------------------------------------------------


def test_an_eight_motor_board_sends_0x200_and_0x1ff_every_tick() -> None:
    rig = rig_of(EIGHT)
    bus = rig.bus
    assert isinstance(bus, RecordingFakeBus)
    rig.arm()
    assert rig.fw.failsafe.motors_online == 0xFF
    rig.set_rc(frame(right=Lever.MIDDLE, ch3=500))
    bus.sent.clear()
    rig.tick(300)
    assert [can_id for can_id, _ in bus.sent] == [0x200, 0x1FF] * 300
    currents = rig.currents
    assert len(currents) == 8 and len(set(currents)) == 1 and currents[0] > 0  # every arm alike
    assert bus.sent[-2:] == command_frames(list(currents))  # byte for byte the C610's layout
    assert unpack_currents(bus.sent[-1][1]) == currents[4:]
    assert [m.current_raw for m in bus.c610s.motors] == list(currents)  # motors 5-8 took it


def test_a_silent_motor_7_zeroes_all_eight_and_latches() -> None:
    rig = rig_of(EIGHT)
    bus = rig.bus
    assert isinstance(bus, RecordingFakeBus)
    rig.arm()
    rig.set_rc(frame(right=Lever.MIDDLE, ch3=660))
    rig.tick(200)
    assert all(rig.currents)
    bus.c610s.silent.add(7)
    t_silent = rig.now_us
    t_fault = rig.until(lambda: rig.fw.phase == Phase.MOTOR_FAULT, 30)
    assert rig.fw.failsafe.motors_online == 0xFF & ~(1 << 6)
    assert rig.currents == (0,) * 8
    assert bus.sent[-2:] == [(0x200, bytes(8)), (0x1FF, bytes(8))]
    assert t_fault - t_silent <= EIGHT.failsafe.motor_timeout_us + 2_000  # DJI: offline after 10 ms
    bus.c610s.silent.clear()  # motor 7 back: still latched until the right lever is seen DOWN
    rig.tick(50)
    assert rig.fw.phase == Phase.MOTOR_FAULT and rig.currents == (0,) * 8
    rig.set_rc(frame())
    rig.until(lambda: rig.fw.phase == Phase.OK, 50)


def test_the_current_limit_clamps_motors_5_to_8() -> None:
    config = EIGHT.replaced(current_limit_a=0.5, common_max_n=20.0)
    rig = rig_of(config)
    bus = rig.bus
    assert isinstance(bus, RecordingFakeBus)
    rig.arm()
    rig.set_rc(frame(right=Lever.MIDDLE, ch3=660))  # 20.5 N on a 10 mm spool: 1.14 A asked
    rig.tick(1500)
    assert rig.fw.tensions_n[7] > 20.0 * 0.18 / 0.010 * 0.5 / 1000 * 10  # slewed far above 9 N
    assert rig.currents == (500,) * 8
    assert bus.sent[-1] == (0x1FF, bytes.fromhex("01f401f401f401f4"))


def test_a_mirrored_motor_6_is_commanded_negative() -> None:
    config = FirmwareConfig().replaced(cable_angles_deg=(0.0,), motor_signs=(1, 1, 1, 1, 1, -1, 1, 1))
    rig = rig_of(config)
    rig.arm()
    rig.set_rc(frame(right=Lever.MIDDLE, ch3=500))
    rig.tick(300)
    c = rig.currents
    assert c[5] == -c[4] < 0 and c[:5] == (c[0],) * 5


# --- the mapping: every arm takes the lone arm's command ------------------------------------------


@pytest.mark.parametrize(
    "rc",
    [
        frame(right=Lever.MIDDLE, ch3=400),
        frame(right=Lever.MIDDLE, ch3=200, ch0=500, ch1=-300),
        frame(right=Lever.MIDDLE, ch0=-660),
    ],
)
def test_two_three_cable_arms_each_take_the_lone_arms_currents(rc: object) -> None:
    lone, pair = Rig(), rig_of(FirmwareConfig().with_arms(2))
    for r in (lone, pair):
        r.arm()
        r.set_rc(rc)  # type: ignore[arg-type]
    for _ in range(400):
        lone.tick()
        pair.tick()
        assert pair.currents == lone.currents * 2


def test_four_two_cable_arms_bend_in_their_plane() -> None:
    rig = rig_of(FirmwareConfig().with_arms(4, 2))
    rig.arm()
    rig.set_rc(frame(right=Lever.MIDDLE, ch0=660))  # toward cable 1 of every arm
    rig.tick(400)
    t = rig.fw.tensions_n
    pre = rig.config.mapping.pretension_n
    assert t[0::2] == (t[0],) * 4 and t[0] == pytest.approx(pre + rig.config.mapping.bend_max_n)
    assert t[1::2] == (pre,) * 4
    rig.set_rc(frame(right=Lever.MIDDLE, ch1=660))  # out of the arms' plane: no bending
    rig.tick(400)
    assert rig.fw.tensions_n == (pre,) * 8


def test_one_stick_closes_eight_one_cable_arms_together() -> None:
    rig = rig_of(EIGHT)
    rig.arm()
    m = rig.config.mapping
    rig.set_rc(frame(right=Lever.MIDDLE, ch3=330))
    rig.tick(1000)
    curl_n = m.pretension_n + m.common_max_n * (330 - m.stick_deadband) / 660
    assert rig.fw.tensions_n == pytest.approx((curl_n,) * 8)


def _acks(rig: Rig) -> list[str]:
    return [m.text for m in rig.drain() if isinstance(m, CommandAck)]


def test_host_tensions_and_length_holds_are_per_cable_of_every_arm() -> None:
    """SET_TENSIONS and HOLD_LENGTHS name the cables of an arm (their args beyond its cables unused):
    every arm of the array takes them."""
    config = FirmwareConfig().with_arms(4, 2)
    rig = Rig(config, link=True, bus=RecordingFakeBus(8))
    rig.arm()
    rig.set_rc(frame(right=Lever.MIDDLE))
    rig.send(Heartbeat(rig.now_us, 0))
    rig.tick(20)
    rig.send(Command(CommandCode.SET_MODE, (float(Mode.DIRECT), 0.0, 0.0)))
    rig.send(Command(CommandCode.SET_TENSIONS, (2.0, 3.0, -1.0)))  # the third arg is unused: no denial
    rig.tick(5)
    assert _acks(rig) == ["direct tensions", "ok"]
    rig.tick(300)
    assert rig.fw.mode == Mode.DIRECT
    assert rig.fw.tensions_n == pytest.approx((2.0, 3.0) * 4)
    rig.send(Command(CommandCode.HOLD_LENGTHS, (math.nan, math.inf, math.inf)))
    rig.tick(5)
    assert _acks(rig) == ["held cables: 2"]
    assert rig.fw.hold.held == [False, True] * 4
    rig.send(Command(CommandCode.HOLD_LENGTHS, (math.inf, -math.inf, math.nan)))
    rig.tick(5)
    assert _acks(rig) == ["held cables: 1"]
    assert rig.fw.hold.held == [True, False] * 4


@pytest.mark.parametrize(("arms", "cables"), [(1, 1), (2, 1), (8, 1), (2, 3)])
def test_the_links_telemetry_reports_motors_1_to_3(arms: int, cables: int) -> None:
    """The board link's Telemetry and MotorFrames keep their three-motor layout (issue 27 item 2 widens
    them): a board with more motors reports motors 1-3, one with fewer zeros; the online mask has all."""
    config = FirmwareConfig().with_arms(arms, cables)
    n = config.motor_count
    rig = Rig(config, link=True, bus=RecordingFakeBus(n))
    rig.arm()
    rig.set_rc(frame(right=Lever.MIDDLE, ch3=400))
    rig.tick(300)
    rig.fw.hold.engage(n - 1)  # a hold on the last motor: beyond cable 3 it is not in the flags
    rig.tick(20)
    received = rig.drain()
    assert any(isinstance(m, Telemetry) for m in received)
    frames = [m for m in received if isinstance(m, MotorFrames)][-1]
    tel = rig.fw.build_telemetry(rig.last_us)  # what the next Telemetry carries
    assert tel.motors_online == (1 << n) - 1
    shown = min(n, 3)
    assert tel.commanded_current[:shown] == rig.currents[:shown] and all(rig.currents)
    assert tel.commanded_current[shown:] == (0,) * (3 - shown)
    assert tel.motor_angle[shown:] == (0,) * (3 - shown)
    assert [can_id for can_id, _ in frames.frames] == [0x201 + i if i < n else 0 for i in range(3)]
    assert rig.fw.hold.held[n - 1]
    hold_bits = int(tel.flags) & (0b111 * TelemetryFlags.HOLD_1)
    assert hold_bits == (TelemetryFlags.HOLD_1 << (n - 1) if n <= 3 else 0)  # motors 4-8: not on the link


@pytest.mark.parametrize(
    ("arms", "cables", "sent"), [(1, 3, False), (1, 2, False), (2, 1, True), (8, 1, True), (2, 3, True)]
)
def test_an_array_sends_every_motor_in_arms_telemetry_and_says_its_layout(
    arms: int, cables: int, sent: bool
) -> None:
    """ArmsTelemetry (0x0109) with each Telemetry carries every motor of an array, with its layout; a board
    of one arm of up to three cables sends none (its bytes stay as they were). The layout is also an INFO
    event at boot and when a host's heartbeat comes back, for hosts that cannot read 0x0109."""
    config = FirmwareConfig().with_arms(arms, cables)
    n = config.motor_count
    rig = Rig(config, link=True, bus=RecordingFakeBus(n))
    rig.arm()
    rig.set_rc(frame(right=Lever.MIDDLE, ch3=400))
    rig.tick(300)
    rig.fw.hold.engage(n - 1)
    rig.tick(20)
    received = rig.drain()
    arrays = [m for m in received if isinstance(m, ArmsTelemetry)]
    telemetry = [m for m in received if isinstance(m, Telemetry)]
    layout = [m for m in received if isinstance(m, Event) and m.kind == EventKind.INFO and m.code == 100]
    if not sent:
        assert not arrays and not layout
        return
    assert len(arrays) == len(telemetry) > 0  # one with each Telemetry
    last, tel = arrays[-1], telemetry[-1]  # sent together
    assert (last.arms, last.cables_per_arm, len(last.motor_angle)) == (arms, cables, n)
    assert all(last.commanded_current) and last.time_us == tel.time_us
    shown = min(n, 3)
    for field in ("commanded_current", "motor_angle", "motor_current", "tension_target_n", "cable_length_m"):
        assert getattr(last, field)[:shown] == pytest.approx(getattr(tel, field)[:shown]), field
    assert last.hold == tuple(i == n - 1 for i in range(n))  # the hold of motor n, beyond Telemetry's three
    text = f"array: {arms} arms x {cables} cable(s); Telemetry has motors 1-3 only"
    assert [e.text for e in layout] == [text]


# --- the grasp: the array is one gripper ----------------------------------------------------------


def test_the_grasp_machine_drives_eight_arms_as_one_gripper() -> None:
    config = EIGHT.replaced(grasp_hold_length=True)
    rig = rig_of(config)
    grasp = rig.fw.grasp
    rig.arm()
    rig.set_rc(frame(right=Lever.UP, left=Lever.MIDDLE))
    rig.tick(50)
    reach_at: list[int] = []

    def contact(now_us: int) -> bool:
        if not reach_at:
            reach_at.append(now_us)
        return now_us - reach_at[0] >= 500_000

    grasp.contact_override = contact
    rig.set_rc(frame(right=Lever.UP, left=Lever.UP))
    seen: set[GraspState] = set()
    for _ in range(15_000):
        rig.tick()
        seen.add(grasp.state)
        t = rig.fw.tensions_n
        assert t == (t[0],) * 8  # one command for every arm
        if grasp.state == GraspState.HOLD:
            break
    assert {GraspState.IDLE, GraspState.REACH, GraspState.WRAP, GraspState.HOLD} <= seen
    assert rig.fw.hold.held == [True] * 8  # a one-cable arm's wrap pulls its one cable: every arm holds it
    assert rig.fw.tensions_n[0] > config.grasp.wrap_n - 1.0
    rig.set_rc(frame(right=Lever.UP, left=Lever.DOWN))
    rig.until(lambda: grasp.state == GraspState.RELEASE, 30)  # the next DBUS frame (14 ms)
    assert rig.fw.hold.held == [False] * 8


def test_a_two_cable_array_grasps_toward_the_nearer_cable() -> None:
    config = FirmwareConfig().with_arms(4, 2)
    rig = rig_of(config)
    rig.arm()
    rig.set_rc(frame(right=Lever.UP, left=Lever.MIDDLE, ch0=-600, ch1=300))  # toward cable 2's side
    rig.tick(50)
    rig.set_rc(frame(right=Lever.UP, left=Lever.UP, ch0=-600, ch1=300))
    rig.tick(1000)
    assert rig.fw.grasp.target_rad == pytest.approx(math.pi)
    t = rig.fw.tensions_n
    pre = config.mapping.pretension_n
    assert t[1::2] == (t[1],) * 4 and t[1] > 5.0 and t[0::2] == (pre,) * 4  # packing on cable 2


def _profile(k: int, reach_at: int | None) -> float:
    """A pack-side cable through a grasp: still while packed, paying out in the reach, then stalled."""
    if reach_at is None:
        return 0.0
    t = k - reach_at
    return -0.03 if 50 <= t < 400 else 0.0


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_the_array_senses_with_the_mean_of_its_arms(seed: int) -> None:
    """Two three-cable arms whose cables run ±d (up to 5 cm/s, ten times the stall speed) about a lone
    arm's take the same grasp decisions as it, tick for tick: the array senses each cable's mean."""
    rng = random.Random(seed)
    config = FirmwareConfig().replaced(grasp_pack_rate_n_per_s=1000.0)
    lone = GraspMachine(config, EventQueue(64))
    pair = GraspMachine(config.with_arms(2), EventQueue(64))
    for g in (lone, pair):
        g.request_grasp(0)
    reach_at: int | None = None
    seen = []
    for k in range(4000):
        now = (k + 1) * 1000
        v = _profile(k, reach_at)
        speeds = [v, 0.0, 0.0]
        tensions = [5.0, 0.5, 0.5]
        d = [rng.uniform(-0.05, 0.05) for _ in range(3)]
        lone.step(now, 1000, speeds, tensions)
        pair.step(
            now,
            1000,
            [x + e for x, e in zip(speeds, d, strict=True)] + [x - e for x, e in zip(speeds, d, strict=True)],
            [x + 10 * e for x, e in zip(tensions, d, strict=True)]
            + [x - 10 * e for x, e in zip(tensions, d, strict=True)],
        )
        assert pair.state == lone.state, k
        assert pair.curl_n == pytest.approx(lone.curl_n, abs=1e-9)
        if lone.state == GraspState.REACH and reach_at is None:
            reach_at = k
        if not seen or seen[-1] != lone.state:
            seen.append(lone.state)
    assert seen == [GraspState.IDLE, GraspState.REACH, GraspState.WRAP, GraspState.HOLD]


# --- an eight-motor board in real time on python-can's virtual bus --------------------------------


def test_an_eight_motor_board_runs_its_1_khz_loop_on_a_python_can_virtual_bus() -> None:
    """The firmware's real-time loop, CanMotorBus on python-can's ``virtual`` interface, eight fake
    C610s answering every tick: the gate opens (all eight answer), the curl reaches motors 5-8 over
    0x1FF, and the run ends with zero current on both frames."""
    channel = f"test-arrays-{os.getpid()}"
    # a generous motor timeout: this checks the frames, not how promptly a thread answers on 2 cores
    config = EIGHT.replaced(motor_timeout_us=200_000)
    c610s = FakeC610Set.of(8)
    radio = ScriptedRcSource(frame())
    peak = [0] * 8
    ticks = [0]

    def stop() -> bool:
        ticks[0] += 1
        if ticks[0] == 200:
            radio.set_frame(frame(right=Lever.MIDDLE, ch3=600))
        for i, m in enumerate(c610s.motors):
            peak[i] = max(peak[i], m.current_raw)
        return ticks[0] >= 900

    with C610SetServer(can.Bus(interface="virtual", channel=channel), c610s) as server:
        with CanMotorBus(channel, "virtual", motor_count=8) as bus:
            fw = Firmware(config, bus, radio)
            fw.run(RealTimeClock(fifo=False), stop=stop)
            assert fw.failsafe.motors_online == 0xFF
            assert fw.phase == Phase.OK and fw.mode == Mode.MANUAL
            assert bus.can_errors == 0 and bus.frames_sent >= 2 * 800
        deadline = time.monotonic() + 5.0  # the server thread takes the last frames (bounded)
        while any(m.current_raw for m in c610s.motors) and time.monotonic() < deadline:
            time.sleep(0.001)
        assert server.error is None
    assert all(p > 0 for p in peak) and len(set(peak)) == 1  # motors 5-8 as 1-4: one command for all
    assert all(m.current_raw == 0 for m in c610s.motors)
    assert c610s.commands >= 2 * 800  # 0x200 and 0x1FF on every tick


def test_an_array_says_its_layout_again_when_a_hosts_heartbeat_returns() -> None:
    """A host that connects after boot (or comes back) learns the layout from the INFO event too."""
    rig = Rig(FirmwareConfig().with_arms(4, 2), link=True, bus=RecordingFakeBus(8))
    rig.tick(30)  # past a telemetry period: the boot's layout event has gone out
    assert any(isinstance(m, Event) and m.code == 100 for m in rig.drain())
    for k in range(3):  # heartbeats: the host is back
        rig.send(Heartbeat(k * 100_000, k))
        rig.tick(100)
    said = [m for m in rig.drain() if isinstance(m, Event) and m.kind == EventKind.INFO and m.code == 100]
    assert [e.text for e in said] == ["array: 4 arms x 2 cable(s); Telemetry has motors 1-3 only"]
