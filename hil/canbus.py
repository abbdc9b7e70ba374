"""The harness's CAN buses: the ``sim`` back ends of :class:`controller.motorbus.MotorBus`.

The bus is where bytes cross, so faults are injected and frames recorded here, and the plant's drives
(:mod:`hil.sim.drives`) know neither. As python-can's virtual bus does for its tests, each bus gives the
firmware exactly what a real CAN bus gives it, with no hardware:

- :class:`SimMotorBus`: the far end is the simulated C610s (the plant: a trio, or an array's 1-8), one
  0x200 frame out per control tick (and 0x1FF for motors 5-8) and 0x201-0x20n feedback frames in. The
  driver of the simulation decides when frames cross:

  1. :meth:`SimMotorBus.deliver_feedback` after each plant step puts the motors' feedback frames (through
     the fault set) in the bus's receive queue;
  2. the firmware's control task drains them with ``read_feedback()`` and sends its command;
  3. :meth:`SimMotorBus.deliver_command` hands the last command frame to the drives.

  Every frame that crosses is recorded (raw CAN channels) when a recorder is attached.
- :class:`ReplayBus`: the far end is a recording (:mod:`hil.replay`): feedback frames from it, commands
  collected to be compared with it.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import ClassVar, Protocol, runtime_checkable

from controller.errors import BusError
from controller.motorbus import MotorBus
from hil import recording
from hil.faults import FaultSet
from hil.recording import Recorder
from protocol.c610 import (
    COMMAND_FORMAT,
    COMMAND_ID_HIGH,
    COMMAND_ID_LOW,
    CURRENT_RAW_MAX,
    FEEDBACK_ID_BASE,
    MotorFeedback,
    unpack_currents3,
)

__all__ = ["Motors", "PayloadMotors", "ReplayBus", "SimMotorBus"]


_FEEDBACK_IDS = range(FEEDBACK_ID_BASE + 1, FEEDBACK_ID_BASE + 9)
"""Feedback CAN ids of motors 1..8, in order."""


class Motors(Protocol):
    """What the bus needs of the plant: C610-shaped commands in, C610-shaped feedback out."""

    def apply_currents(self, raw: Sequence[int]) -> object:
        """Set the ESCs' current setpoints (raw, 1000 per amp), one per motor."""

    def feedback(self) -> Sequence[MotorFeedback]:
        """Every motor's feedback now, motor 1 first."""


@runtime_checkable
class PayloadMotors(Motors, Protocol):
    """Motors that can also give their feedback as packed frame data (the plant: no frame objects)."""

    def feedback_payloads(self) -> Sequence[bytes]:
        """The 8 data bytes of each motor's feedback frame now, as ``MotorFeedback.pack`` gives them."""


class SimMotorBus(MotorBus):
    """Motor bus whose far end is simulated C610s (a trio by default).

    Args:
        motors: the plant (anything with ``apply_currents`` and ``feedback``).
        motor_count: the motors (1..8; an array's arms x cables). Above four the command is two frames
            (0x200 for motors 1-4, 0x1FF for 5-8); the ESCs take a command once both have crossed.
        now_us: the simulation clock, for fault windows and recording timestamps.
        faults: faults on the bus (silence, stuck, wrong feedback, bus off).
        recorder: optional recording of every frame that crosses.
        current_limit_raw: the firmware's clamp (the ESC clamps again at 10 A).
    """

    simulated: ClassVar[bool] = True

    def __init__(
        self,
        motors: Motors,
        now_us: Callable[[], int],
        *,
        faults: FaultSet | None = None,
        recorder: Recorder | None = None,
        current_limit_raw: int = CURRENT_RAW_MAX,
        motor_count: int = 3,
    ) -> None:
        super().__init__(current_limit_raw=current_limit_raw, motor_count=motor_count)
        self.motors = motors
        self._now_us = now_us
        self.faults = faults
        self.recorder = recorder
        self._inbox: list[tuple[int, bytes]] = []
        self._command: bytes | None = None
        self._command_high: bytes | None = None
        self._applied: bytes | None = None
        self._applied_high: bytes | None = None
        self.applied: tuple[int, ...] = (0,) * motor_count
        """The setpoints the ESCs hold now (raw), one per motor."""
        self.commands_applied = 0

    @property
    def motors(self) -> Motors:
        """The motors at the far end (replaceable, e.g. by a wrapper that adds a spare motor)."""
        return self._motors

    @motors.setter
    def motors(self, motors: Motors) -> None:
        self._motors = motors
        # Resolved here, not per tick: a runtime Protocol check costs microseconds.
        self._feedback_payloads = motors.feedback_payloads if isinstance(motors, PayloadMotors) else None

    def deliver_feedback(self) -> None:
        """Queue the motors' current feedback frames for the firmware (after a plant step)."""
        faults = self.faults if self.faults is not None and self.faults.faults else None
        inbox = self._inbox
        recorder = self.recorder
        payloads = self._feedback_payloads
        if faults is None and payloads is not None:
            # No fault can touch the frames: take them packed (the same bytes, without building and
            # validating three MotorFeedback objects per millisecond).
            frames = zip(_FEEDBACK_IDS, payloads(), strict=False)
            if recorder is None:
                inbox.extend(frames)
                return
            t = self._now_us()
            for can_id, data in frames:
                inbox.append((can_id, data))
                recorder.write_raw(recording.CAN_RX, t, recording.pack_can(can_id, data))
            return
        t = self._now_us()
        for motor, fb in enumerate(self._motors.feedback(), start=1):
            frame: MotorFeedback | None = fb if faults is None else faults.feedback(t, motor, fb)
            if frame is None:
                continue
            can_id = FEEDBACK_ID_BASE + motor
            data = frame.pack()
            inbox.append((can_id, data))
            if recorder is not None:
                recorder.write_raw(recording.CAN_RX, t, recording.pack_can(can_id, data))

    def deliver_command(self) -> None:
        """Hand the last command frame(s), if new ones were sent, to the ESCs."""
        data = self._command
        if self._two_frames:
            self._deliver_two(data)
            return
        if data is None:
            return
        self._command = None
        self.commands_applied += 1
        if data == self._applied:  # the ESCs already hold these setpoints
            return
        self._applied = data
        n = self.motor_count
        # MotorBus packed it: 8 bytes.
        self.applied = unpack_currents3(data) if n == 3 else COMMAND_FORMAT.unpack(data)[:n]
        self._motors.apply_currents(self.applied)

    def _deliver_two(self, low: bytes | None) -> None:
        """Motors 5-8 as well: each frame's ESCs take their own frame (a lost one keeps its old setpoints)."""
        high = self._command_high
        if low is None and high is None:
            return
        self._command = self._command_high = None
        self.commands_applied += 1
        low = low if low is not None else self._applied
        high = high if high is not None else self._applied_high
        if low == self._applied and high == self._applied_high:
            return
        self._applied, self._applied_high = low, high
        zeros = (0, 0, 0, 0)
        values = (COMMAND_FORMAT.unpack(low) if low is not None else zeros) + (
            COMMAND_FORMAT.unpack(high) if high is not None else zeros
        )
        self.applied = values[: self.motor_count]
        self._motors.apply_currents(self.applied)

    def _send_frame(self, can_id: int, data: bytes) -> None:
        faults = self.faults
        if faults is not None and faults.faults and faults.bus_off(self._now_us()):
            raise BusError("CAN bus off")
        if can_id == COMMAND_ID_LOW:
            self._command = data
        elif can_id == COMMAND_ID_HIGH:
            self._command_high = data
        if self.recorder is not None:
            self.recorder.write_raw(recording.CAN_TX, self._now_us(), recording.pack_can(can_id, data))

    def _recv_frames(self) -> list[tuple[int, bytes]]:
        frames, self._inbox = self._inbox, []
        return frames

    def _shutdown_backend(self) -> None:
        self.deliver_command()


class ReplayBus(MotorBus):
    """A motor bus whose feedback comes from a recording and whose commands are collected.

    It reports itself as simulated, as the recorded board's bus was (telemetry carries that flag).
    """

    simulated: ClassVar[bool] = True

    def __init__(self, current_limit_raw: int = CURRENT_RAW_MAX, motor_count: int = 3) -> None:
        super().__init__(current_limit_raw=current_limit_raw, motor_count=motor_count)
        self.inbox: list[tuple[int, bytes]] = []
        """Feedback frames ``(can_id, data)`` the firmware reads next."""
        self.sent: list[bytes] = []
        """Every frame sent, packed as the recording's CAN channels hold them."""

    def _send_frame(self, can_id: int, data: bytes) -> None:
        self.sent.append(recording.pack_can(can_id, data))

    def _recv_frames(self) -> list[tuple[int, bytes]]:
        frames, self.inbox = self.inbox, []
        return frames
