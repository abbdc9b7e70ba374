"""The three-motor arm stays byte-identical: a scripted 3-motor run's CAN frames and board-link bytes.

The digests below were recorded from the firmware before it learned to drive up to eight motors (main at
fbe9907). A change that alters one byte a three-motor board sends, on the CAN bus or to the host, fails
here: the default arm must not notice the array support.

The run: boot, the start-up gate with the right lever DOWN, MANUAL with the sticks out (curl and
bend), DIRECT with host tensions (one clamped) and a length-hold on cable 2, GRASP with the left lever UP
(pack, reach, contact, wrap, hold), a release, a silent motor 2 (motor fault, re-armed through SAFE),
MANUAL at full curl and SAFE again. Every frame the firmware puts on the motor bus and every byte it
writes to the host link is hashed.
"""

from __future__ import annotations

import hashlib
import math

import pytest

from controller.motorbus import FakeMotorBus
from protocol.dbus import Lever
from protocol.messages import Command, CommandAck, CommandCode, GraspState, Heartbeat, Mode
from protocol.session import HostSession
from tests.support.controller_harness import Rig, frame

# Recorded on main (fbe9907) before the array support; see the module docstring.
GOLDEN_CAN_FRAMES = 14_300
GOLDEN_CAN_SHA256 = "6f5d15df676ec52c92bb5b8db55d34af45b51451c481927b9437493a82eeb631"
GOLDEN_LINK_BYTES = 303_408
GOLDEN_LINK_SHA256 = "f5da4e6fc783842b62437c1f1030cbd33a88dae738cfc1c22b48a64989a42c80"


class _RecordingFakeBus(FakeMotorBus):
    """The fake C610 trio's bus, keeping every frame the firmware sends."""

    def __init__(self) -> None:
        super().__init__()
        self.sent: list[tuple[int, bytes]] = []

    def _send_frame(self, can_id: int, data: bytes) -> None:
        self.sent.append((can_id, bytes(data)))
        super()._send_frame(can_id, data)


def three_motor_run() -> tuple[list[tuple[int, bytes]], bytes]:
    """The scripted run: ``(CAN frames sent, board-link bytes written)``."""
    bus = _RecordingFakeBus()
    rig = Rig(link=True, bus=bus)
    link_bytes = bytearray()
    assert rig.host is not None

    def run(ticks: int) -> None:
        for _ in range(ticks):
            rig.tick()
            link_bytes.extend(rig.host.read())  # type: ignore[union-attr]

    rig.set_rc(frame())
    run(100)
    rig.set_rc(frame(right=Lever.MIDDLE, ch3=400, ch0=300, ch1=-200))
    run(600)
    rig.set_rc(frame(right=Lever.MIDDLE, ch3=-100, ch0=-500, ch1=600))
    run(600)
    for i in range(8):  # DIRECT: host tensions under a fresh heartbeat, then a length-hold on cable 2
        rig.send(Heartbeat(rig.now_us, i))
        run(2)
        if i == 0:
            rig.send(Command(CommandCode.SET_MODE, (float(Mode.DIRECT), 0.0, 0.0)))
            rig.send(Command(CommandCode.SET_TENSIONS, (3.0, 4.0, 25.0)))
        if i == 4:
            rig.send(Command(CommandCode.HOLD_LENGTHS, (math.nan, math.inf, math.nan)))
        run(98)
    rig.set_rc(frame(right=Lever.UP, left=Lever.MIDDLE))
    run(200)
    grasp = rig.fw.grasp  # no object on the fake trio's springs: contact 0.8 s into the reach
    grasp.contact_override = lambda now_us: now_us - grasp._t_state_us >= 800_000
    rig.set_rc(frame(right=Lever.UP, left=Lever.UP, ch0=0, ch1=500))
    run(10_000)
    assert grasp.state is GraspState.HOLD
    rig.set_rc(frame(right=Lever.UP, left=Lever.DOWN))
    run(1000)
    rig.bus.c610s.silent.add(2)
    run(50)
    rig.bus.c610s.silent.clear()
    rig.set_rc(frame())
    run(150)
    rig.set_rc(frame(right=Lever.MIDDLE, ch3=660))
    run(500)
    rig.set_rc(frame())
    run(300)
    received = HostSession(heartbeats=False).receive_data(bytes(link_bytes), rig.now_us)
    acks = [m.text for m in received if isinstance(m, CommandAck)]
    assert acks == ["direct tensions", "clamped", "held cables: 2"]
    return bus.sent, bytes(link_bytes)


def _digest(frames: list[tuple[int, bytes]]) -> str:
    h = hashlib.sha256()
    for can_id, data in frames:
        h.update(can_id.to_bytes(2, "big") + data)
    return h.hexdigest()


@pytest.fixture(scope="module")
def run() -> tuple[list[tuple[int, bytes]], bytes]:
    return three_motor_run()


def test_three_motor_can_frames_are_byte_identical_to_before(
    run: tuple[list[tuple[int, bytes]], bytes],
) -> None:
    frames, _ = run
    assert {can_id for can_id, _ in frames} == {0x200}  # never a 0x1FF frame with three motors
    assert len(frames) == GOLDEN_CAN_FRAMES
    assert _digest(frames) == GOLDEN_CAN_SHA256


def test_three_motor_link_bytes_are_byte_identical_to_before(
    run: tuple[list[tuple[int, bytes]], bytes],
) -> None:
    _, link = run
    assert len(link) == GOLDEN_LINK_BYTES
    assert hashlib.sha256(link).hexdigest() == GOLDEN_LINK_SHA256


def test_the_run_exercises_the_arm(run: tuple[list[tuple[int, bytes]], bytes]) -> None:
    """The golden run is worth its digest: currents flowed on every motor, and stopped."""
    frames, _ = run
    for slot in range(3):
        assert sum(1 for _, data in frames if any(data[2 * slot : 2 * slot + 2])) > 5000
    assert frames[-1][1] == bytes(8)
    assert all(data[6:8] == b"\x00\x00" for _, data in frames)  # slot 4 of a three-motor 0x200 is 0
