"""The harness's CAN buses (hil.canbus) with stand-in motors, no plant: the frames that cross, the faults on
them, what is recorded, and the replay bus."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from hil import recording
from hil.canbus import PayloadMotors, ReplayBus, SimMotorBus
from hil.faults import Fault, FaultKind, FaultSet
from hil.recording import Recorder, read_records
from protocol.c610 import COMMAND_ID_LOW, MotorFeedback


class _Motors:
    """Three motors that report fixed feedback and keep every setpoint they were given."""

    def __init__(self) -> None:
        self.frames = [MotorFeedback(100 * k, 10 * k, k, 30) for k in (1, 2, 3)]
        self.applied: list[tuple[int, ...]] = []

    def apply_currents(self, raw: Sequence[int]) -> object:
        self.applied.append(tuple(raw))
        return None

    def feedback(self) -> Sequence[MotorFeedback]:
        return self.frames


class _PayloadMotors(_Motors):
    """The same motors, also giving their feedback packed (as the plant does)."""

    def feedback_payloads(self) -> Sequence[bytes]:
        return [f.pack() for f in self.frames]


def _faults(*faults: Fault) -> FaultSet:
    return FaultSet(faults, np.random.default_rng(0))


def test_feedback_crosses_when_delivered_packed_or_not() -> None:
    for motors in (_Motors(), _PayloadMotors()):
        assert isinstance(motors, PayloadMotors) == hasattr(motors, "feedback_payloads")
        bus = SimMotorBus(motors, lambda: 0)
        assert bus.read_feedback() == []  # nothing until the driver delivers
        bus.deliver_feedback()
        assert bus.read_feedback() == list(enumerate(motors.frames, start=1))
        assert bus.read_feedback() == []


def test_a_command_reaches_the_motors_once_and_only_when_it_changes() -> None:
    motors = _Motors()
    bus = SimMotorBus(motors, lambda: 0, current_limit_raw=3000)
    bus.deliver_command()
    assert motors.applied == []  # nothing sent yet
    assert bus.send_currents([5000, -100, 7]) == (3000, -100, 7)
    bus.deliver_command()
    bus.send_currents([3000, -100, 7])
    bus.deliver_command()  # the ESCs already hold these setpoints
    assert motors.applied == [(3000, -100, 7)] and bus.applied == (3000, -100, 7)
    assert bus.commands_applied == 2
    bus.shutdown()  # zero current once, delivered on the way out
    assert motors.applied[-1] == (0, 0, 0)


def test_motor_faults_act_on_the_feedback_frames() -> None:
    now = [0]
    motors = _PayloadMotors()
    faults = _faults(Fault(FaultKind.MOTOR_SILENCE, 1000, 2000, motor=2))
    bus = SimMotorBus(motors, lambda: now[0], faults=faults)
    bus.deliver_feedback()
    assert [m for m, _ in bus.read_feedback()] == [1, 2, 3]
    now[0] = 1500
    bus.deliver_feedback()
    assert [m for m, _ in bus.read_feedback()] == [1, 3]
    assert faults.injected == {"feedback_suppressed": 1}


def test_a_bus_off_fails_sends_and_carries_no_feedback() -> None:
    motors = _Motors()
    bus = SimMotorBus(motors, lambda: 0, faults=_faults(Fault(FaultKind.CAN_BUS_OFF, 0)))
    bus.send_currents([100, 100, 100])
    assert not bus.last_send_ok and bus.can_errors == 1
    bus.deliver_command()
    bus.deliver_feedback()
    assert motors.applied == [] and bus.read_feedback() == []


def test_every_frame_that_crosses_is_recorded(tmp_path: Path) -> None:
    path = tmp_path / "can.mcap"
    motors = _PayloadMotors()
    with Recorder(path) as rec:
        bus = SimMotorBus(motors, lambda: 1000, recorder=rec)
        bus.deliver_feedback()
        bus.send_currents([1, 2, 3])
    frames = [(r.topic, *recording.unpack_can(r.data)) for r in read_records(path)]
    assert frames[:3] == [(recording.CAN_RX, 0x200 + k, f.pack()) for k, f in enumerate(motors.frames, 1)]
    topic, can_id, _ = frames[3]
    assert (topic, can_id) == (recording.CAN_TX, COMMAND_ID_LOW)


def test_the_replay_bus_reads_recorded_feedback_and_collects_commands() -> None:
    bus = ReplayBus(current_limit_raw=2000)
    frame = MotorFeedback(1, 2, 3, 30)
    bus.inbox.append((0x202, frame.pack()))
    assert bus.read_feedback() == [(2, frame)] and bus.inbox == []
    bus.send_currents([2500, 0, 0])
    (sent,) = bus.sent
    can_id, data = recording.unpack_can(sent)
    assert can_id == COMMAND_ID_LOW and int.from_bytes(data[:2], "big", signed=True) == 2000
