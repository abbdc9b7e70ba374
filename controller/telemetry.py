"""What the board tells the host: ``Telemetry``, ``MotorFrames``, ``RawRc``, events, ``BoardStatus``, poses.

:class:`TelemetryBuilder` reads the components' state (it owns none) at the telemetry, status and pose
rates; nothing here runs on the control tick. Which arming blocker holds the gate is computed here, so
the control tick never pays for it.

The board link's ``Telemetry`` and ``MotorFrames`` carry three motors (their layout is the three-cable
arm's): a board with more reports motors 1-3 there (and the length-holds of cables 1-3), one with fewer
reports zeros in the missing slots. ``motors_online`` has a bit for each of up to eight motors. A board
laid out as an array also sends ``ArmsTelemetry`` (every motor, with the layout) and tells any host its
layout in an INFO event at boot and whenever a host's heartbeat comes back (docs/board-link.md, 0x0109).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

from controller.cables import MotorModel, TensionSlew
from controller.events import EventQueue
from controller.failsafe import Failsafe
from controller.grasp import GraspMachine
from controller.hostlink import BoardLink
from controller.lengthhold import LengthHold
from controller.modes import ModeSelector
from controller.motorbus import MotorBus
from controller.rc import RcInput, RcSource
from controller.scheduler import Scheduler
from protocol.c610 import FEEDBACK_FORMAT, FEEDBACK_ID_BASE
from protocol.messages import (
    ArmsTelemetry,
    BoardStatus,
    ClockKind,
    MotorFrames,
    Phase,
    RawRc,
    SimPoses,
    Telemetry,
    TelemetryFlags,
)

__all__ = ["FIRMWARE_VERSION", "PoseProvider", "TelemetryBuilder"]

FIRMWARE_VERSION = "spirob-fw 0.1.0"
"""Reported in ``BoardStatus`` (at most 16 ASCII characters)."""

PoseProvider = Callable[[], Any]
"""Returns a ``SimPoses``, a list of messages (an array's ``SimPoses`` then one ``ArmPoses`` per further arm,
sent in order), ``(positions_m, quats_wxyz)`` to be stamped with board time, or None."""

_ZERO_FRAME = (0, bytes(8))
_U32 = 0xFFFF_FFFF
_PHASE_OK = Phase.OK
_FLAG_ARMED, _FLAG_HOST_REQUIRED, _FLAG_HOST_OK, _FLAG_RC_OK, _FLAG_SIM = (
    int(TelemetryFlags.ARMED),
    int(TelemetryFlags.HOST_REQUIRED),
    int(TelemetryFlags.HOST_OK),
    int(TelemetryFlags.RC_OK),
    int(TelemetryFlags.SIM),
)
_HOLD_SHIFT = 5  # LengthHold.flags bit i -> TelemetryFlags.HOLD_1 << i
_HOLD_MASK = 0b111  # the link's flags hold cables 1-3 (HOLD_1..HOLD_3)
_LINK_MOTORS = 3  # motors in Telemetry's and MotorFrames' per-motor fields
_TELEMETRY_FLAGS = tuple(TelemetryFlags(bits) for bits in range(1 << 8))
"""Every combination of the eight flags, by value (building an IntFlag per frame is slow)."""


class TelemetryBuilder:
    """Builds and sends the board's reports from the firmware's components (read only).

    Args:
        failsafe, motors, slew, hold, grasp, modes, bus, rc, rc_input, scheduler, events: the firmware's
            components.
        link: the host link, or None (then only :meth:`build` is useful).
    """

    def __init__(
        self,
        *,
        failsafe: Failsafe,
        motors: MotorModel,
        slew: TensionSlew,
        hold: LengthHold,
        grasp: GraspMachine,
        modes: ModeSelector,
        bus: MotorBus,
        rc: RcSource,
        rc_input: RcInput,
        scheduler: Scheduler,
        events: EventQueue,
        link: BoardLink | None,
        layout: tuple[int, int] = (1, 3),
    ) -> None:
        """Keep references to the components; ``layout`` is (arms, cables per arm)."""
        self._failsafe = failsafe
        self._motors = motors
        self._slew = slew
        self._hold = hold
        self._grasp = grasp
        self._modes = modes
        self._bus = bus
        self._rc = rc
        self._rc_input = rc_input
        self._scheduler = scheduler
        self._control_task = scheduler["control"]
        self._events = events
        self._link = link
        self.layout = layout
        arms, cables = layout
        self.is_array = arms > 1 or arms * cables > _LINK_MOTORS
        """The board sends ``ArmsTelemetry``: more than one arm, or more motors than ``Telemetry`` holds."""

    def build(self, now_us: int, commanded_currents: tuple[int, ...]) -> Telemetry:
        """The ``Telemetry`` message for the present state (also usable without a link)."""
        fs = self._failsafe
        m = self._motors
        # Straight-line code (no enum arithmetic, no generator expressions): this runs every 10 ms,
        # always with cold caches right after a plant step in a lockstep simulation.
        flags = (
            (_FLAG_ARMED if fs.phase is _PHASE_OK else 0)
            | (_FLAG_HOST_REQUIRED if fs.host_required else 0)
            | (_FLAG_HOST_OK if fs.host_ok else 0)
            | (_FLAG_RC_OK if fs.rc_ok else 0)
            | (_FLAG_SIM if self._bus.simulated else 0)
            | ((self._hold.flags & _HOLD_MASK) << _HOLD_SHIFT)
        )
        rc_input = self._rc_input
        rc = rc_input.frame
        ctl = self._control_task
        link = self._link
        t = self._slew.tensions_n
        est = m.tension_est_n
        length = m.cable_length_m
        u32 = _U32
        return Telemetry(
            now_us,
            self._modes.mode,
            fs.phase,
            self._grasp.state,
            _TELEMETRY_FLAGS[flags],
            fs.motors_online,
            rc.channels if rc else (0, 0, 0, 0),
            rc.right_lever if rc else 0,
            rc.left_lever if rc else 0,
            _three(m.angle, 0),
            _three(m.speed_rpm, 0),
            _three(m.current, 0),
            _three(commanded_currents, 0),
            _three(t, 0.0),
            _three(est, 0.0),
            _three(length, 0.0),
            ctl.late & u32,
            ctl.exec_p99_us,
            ctl.exec_max_us,
            min(ctl.lateness_max_us, u32),
            rc_input.frames_ok & u32,
            rc_input.rejected & u32,
            self._rc.bytes_dropped & u32,
            (link.parser.frames_ok if link else 0) & u32,
            (link.crc_errors if link else 0) & u32,
            fs.motor_offline_events & u32,
            self._bus.can_errors & u32,
            ctl.lateness_p99_us,  # cached like exec_p99_us: refreshed with BoardStatus, not per tick
            fs.arm_blocker(),  # computed here, at the telemetry rate, never by the control tick
        )

    def send(self, now_us: int, commanded_currents: tuple[int, ...]) -> None:
        """The telemetry task: ``Telemetry``, ``MotorFrames``, the ``RawRc`` and events since the last."""
        link = self._link
        if link is None:
            return
        link.send(self.build(now_us, commanded_currents))
        m = self._motors
        pack = FEEDBACK_FORMAT.pack
        seen = m.seen
        angle, speed, current, temperature = m.angle, m.speed_rpm, m.current, m.temperature
        frames = [_ZERO_FRAME, _ZERO_FRAME, _ZERO_FRAME]
        for i in range(min(m.motor_count, _LINK_MOTORS)):
            if seen[i]:
                frames[i] = (FEEDBACK_ID_BASE + 1 + i, pack(angle[i], speed[i], current[i], temperature[i]))
        link.send(MotorFrames(now_us, (frames[0], frames[1], frames[2])))
        if self.is_array:
            link.send(self.build_arms(now_us, commanded_currents))
        raw_rc = self._rc_input.raw
        if raw_rc:
            for t_us, frame in raw_rc:
                link.send(RawRc(t_us, frame.pack()))  # the received bytes, kept by RcFrame.unpack
            raw_rc.clear()
        events = self._events
        if len(events):
            for event in events.pop_all():
                link.send(event)
        link.transport.flush()

    def build_arms(self, now_us: int, commanded_currents: tuple[int, ...]) -> ArmsTelemetry:
        """The ``ArmsTelemetry`` message: every motor of an array (also usable without a link)."""
        m = self._motors
        n = m.motor_count
        held = self._hold.flags
        return ArmsTelemetry(
            now_us,
            self.layout[0],
            self.layout[1],
            tuple(m.angle[:n]),
            tuple(m.speed_rpm[:n]),
            tuple(m.current[:n]),
            tuple(commanded_currents[:n]),
            tuple(self._slew.tensions_n[:n]),
            tuple(m.tension_est_n[:n]),
            tuple(m.cable_length_m[:n]),
            tuple(bool(held >> i & 1) for i in range(n)),
        )

    def layout_text(self) -> str:
        """The INFO event that tells any host the layout (a host that predates ``ArmsTelemetry`` shows it)."""
        arms, cables = self.layout
        return f"array: {arms} arms x {cables} cable(s); Telemetry has motors 1-3 only"

    def send_status(self, now_us: int, clock_kind: ClockKind) -> None:
        """The status task: ``BoardStatus`` with every task's statistics."""
        if self._link is not None:
            self._link.send(BoardStatus(now_us, FIRMWARE_VERSION, clock_kind, self._scheduler.stats()))

    def send_poses(self, now_us: int, provider: PoseProvider) -> None:
        """The poses task: the provider's ``SimPoses`` (stamped with ``now_us`` if it gives arrays), or each
        message of its list (an array's ``SimPoses`` and ``ArmPoses``)."""
        link = self._link
        if link is None:
            return
        poses = provider()
        if poses is None:
            return
        if isinstance(poses, SimPoses):
            link.send(poses)
        elif isinstance(poses, list):
            for msg in poses:
                link.send(msg)
        else:
            positions, quats = poses
            link.send(
                SimPoses(
                    now_us,
                    tuple((float(p[0]), float(p[1]), float(p[2])) for p in positions),
                    tuple((float(q[0]), float(q[1]), float(q[2]), float(q[3])) for q in quats),
                )
            )


def _three(values: Sequence[Any], pad: Any) -> tuple[Any, Any, Any]:
    """Motors 1-3 of a per-motor list (``pad`` for a motor the board does not have)."""
    if len(values) >= _LINK_MOTORS:
        return (values[0], values[1], values[2])
    return (*values, *(pad,) * (_LINK_MOTORS - len(values)))  # type: ignore[return-value]
