"""The board link's wire enums and flags (their numeric values are part of the wire) and ``Direction``."""

from __future__ import annotations

from enum import IntEnum, IntFlag, StrEnum


class Mode(IntEnum):
    """Operating mode (right lever: DOWN = SAFE, MIDDLE = MANUAL, UP = GRASP)."""

    SAFE = 0
    """Zero current."""
    MANUAL = 1
    """Stick teleop."""
    GRASP = 2
    """Grasp strategy."""
    DIRECT = 3
    """Host sets the per-cable tensions."""


class Phase(IntEnum):
    """Failsafe phase."""

    GATE = 0
    """Start-up gate: waiting for valid RC and the right lever DOWN."""
    OK = 1
    RC_LOST = 2
    MOTOR_FAULT = 3
    """Latched until re-armed through SAFE."""
    HOST_LOST = 4
    ESTOP = 5
    """Latched until cleared and re-armed through SAFE."""


class ArmBlocker(IntEnum):
    """``Telemetry.arm_blocker``: what holds the arming gate shut (``NONE`` while armed)."""

    NONE = 0
    RC_INVALID = 1
    """No valid RC frame within the RC timeout."""
    LEVER_NOT_DOWN = 2
    """The right lever has not been seen DOWN (SAFE) since the gate closed."""
    ESTOP_LATCHED = 3
    """An E-stop is latched until CLEAR_ESTOP."""
    MOTOR_FAULT = 4
    """A motor is silent."""
    HOST_MISSING = 5
    """The host heartbeat is required and missing."""
    DISARMED = 6
    """The host sent DISARM (until ARM)."""


class GraspState(IntEnum):
    """State of the grasp state machine."""

    IDLE = 0
    REACH = 1
    WRAP = 2
    HOLD = 3
    RELEASE = 4
    FAILED = 5


class TelemetryFlags(IntFlag):
    """Bits of ``Telemetry.flags``."""

    NONE = 0
    ARMED = 1 << 0
    """Current may flow (start-up gate passed, no latched fault)."""
    HOST_REQUIRED = 1 << 1
    """The board drops to zero current when the host heartbeat stops."""
    HOST_OK = 1 << 2
    """Host heartbeat fresh."""
    RC_OK = 1 << 3
    """A valid RC frame within the RC-lost timeout."""
    SIM = 1 << 4
    """Running against the simulated plant."""
    HOLD_1 = 1 << 5
    """Cable 1 is in length-hold (its current comes from the position loop, not a tension)."""
    HOLD_2 = 1 << 6
    """Cable 2 is in length-hold."""
    HOLD_3 = 1 << 7
    """Cable 3 is in length-hold."""


class CommandCode(IntEnum):
    """``Command.code`` (0 is never sent, so an all-zero payload is rejected)."""

    ARM = 1
    DISARM = 2
    ESTOP = 3
    CLEAR_ESTOP = 4
    GRASP = 5
    RELEASE = 6
    HOLD = 7
    SET_MODE = 8
    """args[0] = ``Mode`` value."""
    SET_TENSIONS = 9
    """args = per-cable tension targets in N (DIRECT mode)."""
    REQUIRE_HOST = 10
    """args[0] = 1.0 to require the host heartbeat, 0.0 to stop requiring it."""
    HOLD_LENGTHS = 11
    """args = per cable: NaN = unchanged, -inf = release (tension again), +inf = hold at the present
    length (a held cable keeps its set-point), finite = hold at that cable length in m (the board's
    ``cable_length_m`` frame)."""


class EventKind(IntEnum):
    """``Event.kind``."""

    BOOT = 0
    MODE = 1
    PHASE = 2
    FAULT = 3
    GRASP = 4
    PARAM = 5
    INFO = 6


class AckResult(IntEnum):
    """``CommandAck.result``; the values equal MAVLink's ``MAV_RESULT`` so bridges map them 1:1."""

    ACCEPTED = 0
    REJECTED = 1
    """Temporarily rejected (busy / wrong state): ``MAV_RESULT_TEMPORARILY_REJECTED``."""
    DENIED = 2
    """Bad arguments."""
    UNSUPPORTED = 3
    FAILED = 4
    IN_PROGRESS = 5


class ClockKind(IntEnum):
    """``BoardStatus.clock_kind``: how the firmware's loop is timed."""

    REALTIME_FIFO = 0
    """Real-time clock with SCHED_FIFO priority."""
    REALTIME_NORMAL = 1
    """Real-time clock without real-time priority (expect late ticks)."""
    LOCKSTEP = 2
    """Advanced by the simulation."""


class Direction(StrEnum):
    """Which way a message travels."""

    BOARD_TO_HOST = "board->host"
    HOST_TO_BOARD = "host->board"
