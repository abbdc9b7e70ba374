"""The telemetry builder: Telemetry from the components' state, and what the telemetry task sends."""

from __future__ import annotations

from controller.clock import zero_ns
from controller.config import FirmwareConfig
from controller.firmware import Firmware
from controller.motorbus import FakeMotorBus
from controller.rc import ScriptedRcSource
from protocol.dbus import Lever
from protocol.messages import (
    ArmBlocker,
    BoardStatus,
    ClockKind,
    Mode,
    MotorFrames,
    Phase,
    Telemetry,
    TelemetryFlags,
)
from tests.support.controller_harness import Rig, frame


def test_build_without_a_link_reads_the_components() -> None:
    fw = Firmware(FirmwareConfig(), FakeMotorBus(), ScriptedRcSource(frame()), exec_timer_ns=zero_ns)
    t = fw.telemetry.build(0, (1, 2, 3))
    assert (t.mode, t.phase, t.arm_blocker) == (Mode.SAFE, Phase.GATE, ArmBlocker.MOTOR_FAULT)
    assert t.commanded_current == (1, 2, 3) and t.rc_channels == (0, 0, 0, 0)
    fw.telemetry.send(0, (0, 0, 0))  # no link: nothing to send, no error
    fw.telemetry.send_status(0, ClockKind.LOCKSTEP)


def test_the_telemetry_task_sends_telemetry_motor_frames_raw_rc_and_status() -> None:
    rig = Rig(link=True, start=frame(right=Lever.MIDDLE))
    rig.tick(30)
    rig.drain()
    rig.fw.telemetry.send(rig.now_us, rig.fw.commanded_currents)
    rig.fw.telemetry.send_status(rig.now_us, ClockKind.REALTIME_NORMAL)
    got = rig.drain()
    kinds = [type(m) for m in got]
    assert kinds[:2] == [Telemetry, MotorFrames]
    tel = got[0]
    assert isinstance(tel, Telemetry)
    assert tel.arm_blocker == ArmBlocker.LEVER_NOT_DOWN and tel.flags & TelemetryFlags.RC_OK
    assert tel.right_lever == Lever.MIDDLE
    status = got[-1]
    assert isinstance(status, BoardStatus) and status.clock_kind == ClockKind.REALTIME_NORMAL
