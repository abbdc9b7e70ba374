"""The firmware: a declared task table over the RC input, failsafe, modes, mapping, motor model and bus.

Task table (rates are the config's defaults; tasks due on the same tick run in this order)::

    name        period   body
    link_rx     1 kHz    board link in: heartbeat, virtual RC, commands, parameters   (with a link)
    control     1 kHz    RC + feedback in, failsafe, mode, tensions, currents, one 0x200 frame out
    detect      100 Hz   device liveness summary (RC, host) and its events
    telemetry   100 Hz   Telemetry, MotorFrames, RawRc, Event out                    (with a link)
    status      2 Hz     BoardStatus (per-task statistics) out                        (with a link)
    sim_poses   50 Hz    SimPoses out                               (with a link and a pose provider)

Two ways to drive it: :meth:`Firmware.run` is the real-time loop (any :class:`~controller.clock.Clock`);
a lockstep simulation calls :meth:`Firmware.run_due` with the simulated time after every 1 ms plant
step. Tasks receive ``now_us`` and never read a clock.

Safety rules (see ``controller.failsafe``): no current before the start-up gate; zero current on the
first tick after RC (30 ms), a motor (10 ms) or a required host heartbeat is lost, on E-stop, and in
SAFE mode. Invalid RC frames are counted and never acted on.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Any

from controller.clock import Clock, StopSignal, monotonic_ns, run_periodic
from controller.config import MOTOR_COUNT, PARAM_FIELDS, PARAMS, FirmwareConfig
from controller.errors import ConfigError
from controller.events import EventQueue
from controller.failsafe import Failsafe
from controller.grasp import GraspMachine
from controller.hostlink import BoardLink
from controller.mapping import CableMapper, TensionSlew
from controller.motor_model import MotorModel
from controller.motorbus import MotorBus
from controller.rc import LinkRcSource, RcSource
from controller.scheduler import Scheduler, TaskSpec
from controller.transport import Transport
from protocol.c610 import FEEDBACK_FORMAT, FEEDBACK_ID_BASE
from protocol.dbus import Lever, RcFrame
from protocol.errors import DecodeError
from protocol.link import LinkFrame
from protocol.messages import (
    PARAM_INDEX_BY_NAME,
    PARAM_LIST_ALL,
    AckResult,
    BoardStatus,
    ClockKind,
    Command,
    CommandAck,
    CommandCode,
    EventKind,
    GraspState,
    Heartbeat,
    Message,
    Mode,
    MotorFrames,
    ParamRequest,
    ParamSet,
    ParamValue,
    Phase,
    RawRc,
    SimPoses,
    TaskStats,
    Telemetry,
    TelemetryFlags,
    VirtualRc,
    decode,
    truncate_utf8,
)

__all__ = ["FIRMWARE_VERSION", "Firmware", "PoseProvider"]

FIRMWARE_VERSION = "spirob-fw 0.1.0"
"""Reported in ``BoardStatus`` (at most 16 ASCII characters)."""

PoseProvider = Callable[[], Any]
"""Returns a ``SimPoses``, or ``(positions_m, quats_wxyz)`` to be stamped with board time, or None."""

_RAW_RC_QUEUE = 16  # DBUS frames held for RawRc between telemetry ticks (14 ms apart: 1 normally)
_MAX_DT_US = 20_000  # a stalled loop never makes the slew limiter jump further than this
_GRASP_STICK_MIN = 0.5  # right stick deflection (of full scale) that picks the grasp direction
_ZERO_FRAME = (0, bytes(8))
_ACK_TEXT_MAX = 48
# Enum members the control tick compares by identity (no class attribute lookup per tick).
_SAFE, _MANUAL, _DIRECT, _GRASP = Mode.SAFE, Mode.MANUAL, Mode.DIRECT, Mode.GRASP
_PHASE_OK = Phase.OK
_LEVER_MIDDLE, _LEVER_UP = Lever.MIDDLE, Lever.UP
_FLAG_ARMED, _FLAG_HOST_REQUIRED, _FLAG_HOST_OK, _FLAG_RC_OK, _FLAG_SIM = (
    int(TelemetryFlags.ARMED),
    int(TelemetryFlags.HOST_REQUIRED),
    int(TelemetryFlags.HOST_OK),
    int(TelemetryFlags.RC_OK),
    int(TelemetryFlags.SIM),
)
_TELEMETRY_FLAGS = tuple(TelemetryFlags(bits) for bits in range(1 << 5))
"""Every combination of the five flags, by value (building an IntFlag per frame is slow)."""


class Firmware:
    """The C-board firmware emulator.

    Args:
        config: firmware constants (a runtime copy is kept; ``ParamSet`` replaces it).
        bus: the motor bus (owned by the caller).
        rc: the RC source (owned by the caller). With a :class:`~controller.rc.LinkRcSource` the host's
            ``VirtualRc`` frames feed it; with any other source they are ignored (the radio is master).
        link: the host link transport, or None to run without a host.
        poses: optional pose provider for ``SimPoses`` (default: the bus's ``poses`` method if any).
        exec_timer_ns: timer for execution-time statistics (default CLOCK_MONOTONIC; a lockstep run
            that wants bit-identical telemetry passes :func:`controller.clock.zero_ns`).

    Read-only state for observers: :attr:`mode`, :attr:`phase`, :attr:`grasp_state`,
    :attr:`commanded_currents`, :attr:`tensions_n`, :attr:`stats`, :attr:`counters`, :attr:`rc_frame`,
    :attr:`config`, and the component objects (:attr:`failsafe`, :attr:`motors`, :attr:`grasp`,
    :attr:`scheduler`, :attr:`events`).
    """

    def __init__(
        self,
        config: FirmwareConfig,
        bus: MotorBus,
        rc: RcSource,
        link: Transport | None = None,
        *,
        poses: PoseProvider | None = None,
        exec_timer_ns: Callable[[], int] | None = None,
    ) -> None:
        """Wire the firmware up (nothing runs until :meth:`run_due` or :meth:`run`)."""
        self.bus = bus
        self.rc = rc
        self.link = BoardLink(link) if link is not None else None
        if poses is None:
            candidate = getattr(bus, "poses", None)
            poses = candidate if callable(candidate) else None
        self._poses = poses
        self.events = EventQueue(config.event_queue_len)
        self.failsafe = Failsafe(config, self.events)
        self.motors = MotorModel(config)
        self.mapper = CableMapper(config)
        self.slew = TensionSlew(config)
        self.grasp = GraspMachine(config, self.events)
        self.clock_kind = ClockKind.LOCKSTEP
        self.mode = Mode.SAFE
        self.rc_frame: RcFrame | None = None
        self.rc_frames_ok = 0
        self.rc_rejected = 0
        self.virtual_rc_ignored = 0
        self.direct_requested = False
        self.direct_tensions_n = [config.pretension_n] * MOTOR_COUNT
        self.commanded_currents: tuple[int, ...] = (0,) * MOTOR_COUNT
        self._raw = [0] * MOTOR_COUNT
        self._zero = (0,) * MOTOR_COUNT
        self._last_control_us: int | None = None
        self._prev_left_lever = 0
        self._raw_rc: list[tuple[int, RcFrame]] = []
        self._tx_pending: list[Message] = []
        self._grasp_ack_seq = -1  # link seq of a host GRASP awaiting its final ack
        self._release_ack_seq = -1
        self._prev_grasp_state = GraspState.IDLE
        self._last_rc_ok = False
        self._last_host_ok = False
        self.config = config
        self._apply_config(config)
        self.scheduler = Scheduler(self._task_table(), exec_timer_ns or monotonic_ns)
        self._control_task = self.scheduler["control"]
        self._booted = False

    # --- the task table ---------------------------------------------------------------------------

    def _task_table(self) -> tuple[TaskSpec, ...]:
        """The task table: one row per task; offsets (in control ticks) stagger the slow tasks."""
        c = self.config
        have = {
            "": True,
            "link": self.link is not None,
            "poses": self.link is not None and self._poses is not None,
        }
        # fmt: off
        rows = (
            # name        period                 body                  offset  needs
            ("link_rx",   c.link_period_us,      self._task_link_rx,   0,      "link"),
            ("control",   c.control_period_us,   self._task_control,   0,      ""),
            ("detect",    c.detect_period_us,    self._task_detect,    2,      ""),
            ("telemetry", c.telemetry_period_us, self._task_telemetry, 5,      "link"),
            ("status",    c.status_period_us,    self._task_status,    7,      "link"),
            ("sim_poses", c.poses_period_us,     self._task_poses,     3,      "poses"),
        )
        # fmt: on
        tick = c.control_period_us
        return tuple(
            TaskSpec(name, period, body, (offset * tick) % period)
            for name, period, body, offset, needs in rows
            if have[needs]
        )

    # --- driving ----------------------------------------------------------------------------------

    def run_due(self, now_us: int) -> int:
        """Run every task whose deadline has come at ``now_us`` (lockstep drivers call this each 1 ms).

        Returns:
            The number of tasks that ran.
        """
        if not self._booted:
            self.start(now_us)
        return self.scheduler.run_due(now_us)

    def start(self, first_deadline_us: int) -> None:
        """Boot: log the BOOT event and put the task grid's first deadline at ``first_deadline_us``.

        :meth:`run_due` boots on its first call, at whatever time it is given. A driver with its own
        deadline grid (a real-time loop that also steps a plant) boots explicitly on that grid instead, so
        a tick that wakes slightly earlier than the first one still finds its task due.
        """
        self.events.push(first_deadline_us, EventKind.BOOT, 0, 0.0, FIRMWARE_VERSION)
        self.scheduler.start(first_deadline_us)
        self._booted = True

    def run(self, clock: Clock, duration_us: int | None = None, stop: StopSignal = None) -> None:
        """The real-time loop (:func:`~controller.clock.run_periodic`): run due tasks, sleep to the next
        absolute deadline, repeat.

        Returns after ``duration_us`` or when ``stop`` is set / returns True (checked every tick), and sends
        zero current once on the way out.
        """
        sched = self.scheduler
        run_due, next_deadline_us = sched.run_due, sched.next_deadline_us

        def begin(start_us: int) -> int:
            self.clock_kind = clock.kind  # inside clock.running(): SCHED_FIFO is known by now
            return start_us

        def step(now_us: int) -> int:
            run_due(now_us)
            return next_deadline_us()

        try:
            run_periodic(clock, step, begin=begin, duration_us=duration_us, stop=stop)
        finally:
            self._all_stop()

    def _all_stop(self) -> None:
        if not self.bus.is_shutdown:
            self.commanded_currents = self.bus.send_currents(self._zero)
        self.slew.reset()

    # --- observers --------------------------------------------------------------------------------

    @property
    def phase(self) -> Phase:
        """Failsafe phase."""
        return self.failsafe.phase

    @property
    def grasp_state(self) -> GraspState:
        """Grasp state machine state."""
        return self.grasp.state

    @property
    def tensions_n(self) -> tuple[float, ...]:
        """Commanded (slew-limited) cable tensions; 0 while no current flows."""
        return tuple(self.slew.tensions_n)

    @property
    def stats(self) -> tuple[TaskStats, ...]:
        """Per-task scheduler statistics (runs, late, exec max/p99, lateness max)."""
        return self.scheduler.stats()

    @property
    def counters(self) -> dict[str, int]:
        """Error and traffic counters by name (the telemetry counters and a few more)."""
        link = self.link
        return {
            "rc_frames_ok": self.rc_frames_ok,
            "rc_rejected": self.rc_rejected,
            "dbus_bytes_dropped": self.rc.bytes_dropped,
            "virtual_rc_ignored": self.virtual_rc_ignored,
            "link_frames_ok": link.parser.frames_ok if link else 0,
            "link_crc_errors": link.crc_errors if link else 0,
            "link_decode_errors": link.decode_errors if link else 0,
            "link_frames_dropped": link.transport.frames_dropped if link else 0,
            "motor_offline_events": self.failsafe.motor_offline_events,
            "can_errors": self.bus.can_errors,
            "events_dropped": self.events.dropped,
        }

    # --- configuration ----------------------------------------------------------------------------

    def _apply_config(self, config: FirmwareConfig) -> None:
        self.config = config
        self.failsafe.configure(config)
        self.motors.configure(config)
        self.mapper.configure(config)
        self.slew.configure(config)
        self.grasp.configure(config)
        self.bus.current_limit_raw = config.current_limit_raw

    def set_param(self, now_us: int, name: str, value: float) -> float:
        """Set a runtime parameter (wire name) if valid; return the value in force afterwards.

        Raises:
            ConfigError: unknown name (an invalid value is not an error: the old value stays).
        """
        if name not in PARAM_FIELDS:
            raise ConfigError(f"unknown parameter {name!r}")
        try:
            new = self.config.with_param(name, value)
        except ConfigError as exc:
            self.events.push(now_us, EventKind.PARAM, PARAMS.index(name), value, f"rejected: {exc}")
            return self.config.get_param(name)
        self._apply_config(new)
        now_value = new.get_param(name)
        self.events.push(now_us, EventKind.PARAM, PARAMS.index(name), now_value, f"{name} = {now_value:g}")
        return now_value

    # --- tasks ------------------------------------------------------------------------------------

    def _task_control(self, now_us: int) -> None:
        last = self._last_control_us
        dt = self.config.control_period_us if last is None else now_us - last
        if dt > _MAX_DT_US:
            dt = _MAX_DT_US
        self._last_control_us = now_us
        fs = self.failsafe

        frames = self.rc.poll(now_us)
        if frames:
            self._take_rc(now_us, frames)
        feedback = self.bus.read_feedback()
        if feedback:
            self.motors.update_frames(feedback, now_us)
            fs.on_motor_frames(now_us, feedback)

        phase = fs.update(now_us)
        mode = self._select_mode(now_us, phase)

        if mode is _SAFE:
            self.slew.reset()
            self.commanded_currents = self.bus.send_currents(self._zero)
            return
        rc = self.rc_frame
        if rc is None:  # cannot happen: phase OK needs a valid frame
            self.commanded_currents = self.bus.send_currents(self._zero)
            return
        if mode is _MANUAL:
            targets = self.mapper.manual(rc.channels)
        elif mode is _DIRECT:
            targets = self.mapper.direct(self.direct_tensions_n)
        else:
            targets = self._grasp_targets(now_us, dt, rc)
        tensions = self.slew.step(targets, dt)
        self.commanded_currents = self.bus.send_currents(self.motors.tensions_to_raw(tensions, self._raw))

    def _take_rc(self, now_us: int, frames: list[RcFrame]) -> None:
        keep_raw = self.link is not None
        for f in frames:
            if keep_raw:
                q = self._raw_rc
                if len(q) >= _RAW_RC_QUEUE:
                    del q[0]
                q.append((now_us, f))
            if f.is_valid():
                self.rc_frames_ok += 1
                self.rc_frame = f
                self.failsafe.on_rc_frame(now_us, f.right_lever)
            else:
                self.rc_rejected += 1

    def _select_mode(self, now_us: int, phase: Phase) -> Mode:
        rc = self.rc_frame
        if phase is not _PHASE_OK or rc is None:
            mode = _SAFE
        else:
            lever = rc.right_lever
            if lever == _LEVER_MIDDLE:
                if self.direct_requested and not self.failsafe.host_ok:
                    self.direct_requested = False
                    self.events.push(now_us, EventKind.INFO, 0, 0.0, "DIRECT ended: no host heartbeat")
                mode = _DIRECT if self.direct_requested else _MANUAL
            elif lever == _LEVER_UP:
                mode = _GRASP
            else:
                mode = _SAFE
        if mode is not self.mode:
            self._mode_changed(now_us, self.mode, mode)
        return mode

    def _mode_changed(self, now_us: int, old: Mode, new: Mode) -> None:
        self.mode = new
        if new != Mode.DIRECT and new != Mode.MANUAL:
            self.direct_requested = False  # DIRECT only while the lever stays MIDDLE
        if old == Mode.GRASP:
            self.grasp.reset(now_us)
            self._finish_grasp_acks(AckResult.FAILED, "grasp mode left")
        if new == Mode.GRASP:
            self.grasp.reset(now_us)
            self._prev_left_lever = self.rc_frame.left_lever if self.rc_frame else 0
            self._prev_grasp_state = self.grasp.state
        self.events.push(now_us, EventKind.MODE, int(new), 0.0, f"mode {new.name}")

    def _grasp_targets(self, now_us: int, dt: int, rc: RcFrame) -> list[float]:
        grasp = self.grasp
        left = rc.left_lever
        if left != self._prev_left_lever:
            self._prev_left_lever = left
            if left == Lever.UP:
                grasp.request_grasp(now_us, self.mapper.stick_direction(rc.channels, _GRASP_STICK_MIN))
            elif left == Lever.DOWN:
                grasp.request_release(now_us)
        curl = grasp.step(now_us, dt, self.motors.cable_speed_m_s, self.motors.tension_est_n)
        if grasp.state != self._prev_grasp_state:
            self._prev_grasp_state = grasp.state
            self._grasp_progress(now_us, grasp.state)
        return self.mapper.curl(curl, grasp.direction_rad)

    def _grasp_progress(self, now_us: int, state: GraspState) -> None:
        """Final acks for host GRASP / RELEASE commands (MAVLink DO_GRIPPER needs them)."""
        if self._grasp_ack_seq >= 0:
            if state == GraspState.HOLD:
                self._ack_later(CommandCode.GRASP, AckResult.ACCEPTED, self._grasp_ack_seq, "holding")
                self._grasp_ack_seq = -1
            elif state in (GraspState.FAILED, GraspState.RELEASE):
                self._ack_later(CommandCode.GRASP, AckResult.FAILED, self._grasp_ack_seq, state.name.lower())
                self._grasp_ack_seq = -1
        if self._release_ack_seq >= 0 and state == GraspState.IDLE:
            self._ack_later(CommandCode.RELEASE, AckResult.ACCEPTED, self._release_ack_seq, "released")
            self._release_ack_seq = -1

    def _finish_grasp_ack(self, result: AckResult, text: str) -> None:
        if self._grasp_ack_seq >= 0:
            self._ack_later(CommandCode.GRASP, result, self._grasp_ack_seq, text)
            self._grasp_ack_seq = -1

    def _finish_grasp_acks(self, result: AckResult, text: str) -> None:
        self._finish_grasp_ack(result, text)
        if self._release_ack_seq >= 0:
            self._ack_later(CommandCode.RELEASE, result, self._release_ack_seq, text)
            self._release_ack_seq = -1

    def _ack_later(self, code: int, result: AckResult, seq: int, text: str) -> None:
        if self.link is not None:
            self._tx_pending.append(CommandAck(code, result, seq, truncate_utf8(text, _ACK_TEXT_MAX)))

    def _task_detect(self, now_us: int) -> None:
        fs = self.failsafe
        rc_ok = fs.rc_ok
        if rc_ok != self._last_rc_ok:
            self._last_rc_ok = rc_ok
            self.events.push(
                now_us, EventKind.INFO, 0, float(rc_ok), "RC signal ok" if rc_ok else "RC signal lost"
            )
        host_ok = fs.host_ok
        if host_ok != self._last_host_ok:
            self._last_host_ok = host_ok
            text = "host heartbeat ok" if host_ok else "host heartbeat lost"
            self.events.push(now_us, EventKind.INFO, 1, float(host_ok), text)

    # --- link tasks -------------------------------------------------------------------------------

    def _task_link_rx(self, now_us: int) -> None:
        link = self.link
        if link is None:
            return
        if self._tx_pending:
            for msg in self._tx_pending:
                link.send(msg)
            self._tx_pending.clear()
        for frame in link.receive():
            try:
                msg = decode(frame)
            except DecodeError:
                link.decode_errors += 1
                self._unsupported_command(frame)
                continue
            self._dispatch(link, now_us, frame.seq, msg)

    def _dispatch(self, link: BoardLink, now_us: int, seq: int, msg: Message) -> None:
        if isinstance(msg, Heartbeat):
            self.failsafe.on_heartbeat(now_us)
        elif isinstance(msg, VirtualRc):
            if isinstance(self.rc, LinkRcSource):
                self.rc.push(msg.data, now_us)
            else:
                self.virtual_rc_ignored += 1
        elif isinstance(msg, Command):
            result, text = self._command(now_us, seq, msg)
            link.send(CommandAck(msg.code, result, seq, truncate_utf8(text, _ACK_TEXT_MAX)))
        elif isinstance(msg, ParamRequest):
            self._param_request(msg)
        elif isinstance(msg, ParamSet):
            if msg.name in PARAM_FIELDS:
                value = self.set_param(now_us, msg.name, msg.value)
                link.send(ParamValue(PARAMS.index(msg.name), len(PARAMS), msg.name, value))
            else:
                self.events.push(now_us, EventKind.PARAM, -1, msg.value, f"unknown parameter {msg.name}")
        else:  # a board -> host message sent to the board
            link.decode_errors += 1

    def _unsupported_command(self, frame: LinkFrame) -> None:
        if frame.cmd_id == Command.CMD_ID and len(frame.payload) == Command.FORMAT.size:
            self._send(CommandAck(frame.payload[0], AckResult.UNSUPPORTED, frame.seq, "unknown command code"))

    def _send(self, msg: Message) -> None:
        if self.link is not None:
            self.link.send(msg)

    def _param_request(self, req: ParamRequest) -> None:
        count = len(PARAMS)
        if req.index == PARAM_LIST_ALL:
            names: Sequence[str] = PARAMS
        elif req.index == PARAM_INDEX_BY_NAME:
            names = (req.name,) if req.name in PARAM_FIELDS else ()
        else:
            names = (PARAMS[req.index],) if req.index < count else ()
        for name in names:
            self._send(ParamValue(PARAMS.index(name), count, name, self.config.get_param(name)))

    def _command(self, now_us: int, seq: int, cmd: Command) -> tuple[AckResult, str]:
        code = cmd.code
        a0, a1, a2 = cmd.args
        fs = self.failsafe
        if code == CommandCode.ESTOP:
            fs.estop(now_us)
            return AckResult.ACCEPTED, "E-stop latched"
        if code == CommandCode.CLEAR_ESTOP:
            if fs.clear_estop(now_us):
                return AckResult.ACCEPTED, "E-stop cleared: re-arm through SAFE"
            return AckResult.ACCEPTED, "no E-stop was latched"
        if code == CommandCode.ARM:
            if fs.arm():
                return AckResult.ACCEPTED, "armed: gate opens with the right lever DOWN"
            return AckResult.REJECTED, "E-stop latched: clear it first"
        if code == CommandCode.DISARM:
            fs.disarm(now_us)
            return AckResult.ACCEPTED, "disarmed"
        if code == CommandCode.REQUIRE_HOST:
            if a0 not in (0.0, 1.0):
                return AckResult.DENIED, "args[0] must be 0 or 1"
            self.set_param(now_us, "HOST_REQUIRED", a0)
            return AckResult.ACCEPTED, "host required" if a0 else "host not required"
        if code == CommandCode.SET_TENSIONS:
            values = (a0, a1, a2)
            if not all(math.isfinite(v) and v >= 0.0 for v in values):
                return AckResult.DENIED, "tensions must be finite and >= 0"
            lo, hi = self.config.pretension_n, self.config.tension_max_n
            clamped = [min(hi, max(lo, v)) for v in values]
            self.direct_tensions_n[:] = clamped
            return AckResult.ACCEPTED, "clamped" if clamped != list(values) else "ok"
        if code == CommandCode.SET_MODE:
            return self._set_mode(now_us, a0)
        if code in (CommandCode.GRASP, CommandCode.RELEASE, CommandCode.HOLD):
            return self._grasp_command(now_us, seq, code, a0)
        return AckResult.UNSUPPORTED, "unsupported"

    def _set_mode(self, now_us: int, value: float) -> tuple[AckResult, str]:
        if value == Mode.MANUAL:
            self.direct_requested = False
            return AckResult.ACCEPTED, "manual (sticks)"
        if value == Mode.DIRECT:
            rc = self.rc_frame
            if self.failsafe.phase != Phase.OK or rc is None or rc.right_lever != Lever.MIDDLE:
                return AckResult.REJECTED, "DIRECT needs phase OK and the right lever MIDDLE"
            if not self.failsafe.host_ok:
                return AckResult.REJECTED, "DIRECT needs the host heartbeat"
            self.direct_requested = True
            return AckResult.ACCEPTED, "direct tensions"
        return AckResult.DENIED, "only MANUAL or DIRECT: the right lever selects SAFE and GRASP"

    def _grasp_command(self, now_us: int, seq: int, code: CommandCode, arg: float) -> tuple[AckResult, str]:
        if self.mode != Mode.GRASP:
            return AckResult.REJECTED, "right lever must be UP (GRASP)"
        grasp = self.grasp
        if code == CommandCode.GRASP:
            direction = None
            if math.isfinite(arg):
                direction = arg
            elif self.rc_frame is not None:
                direction = self.mapper.stick_direction(self.rc_frame.channels, _GRASP_STICK_MIN)
            result = grasp.request_grasp(now_us, direction)
            if result != AckResult.ACCEPTED:
                return result, "grasp already running"
            self._finish_grasp_ack(AckResult.FAILED, "superseded")
            self._grasp_ack_seq = seq
            return AckResult.IN_PROGRESS, "grasping"
        if code == CommandCode.RELEASE:
            grasp.request_release(now_us)
            self._finish_grasp_ack(AckResult.FAILED, "released")
            if grasp.state == GraspState.IDLE:
                return AckResult.ACCEPTED, "idle"
            self._release_ack_seq = seq
            return AckResult.IN_PROGRESS, "releasing"
        result = grasp.request_hold(now_us)
        if result == AckResult.ACCEPTED:
            self._finish_grasp_ack(AckResult.ACCEPTED, "holding")
            return result, "holding"
        return result, f"cannot hold in {grasp.state.name}"

    # --- telemetry --------------------------------------------------------------------------------

    def build_telemetry(self, now_us: int) -> Telemetry:
        """The ``Telemetry`` message for the present state (also usable without a link)."""
        fs = self.failsafe
        m = self.motors
        # Straight-line code (no enum arithmetic, no generator expressions): this runs every 10 ms,
        # always with cold caches right after a plant step in a lockstep simulation.
        flags = (
            (_FLAG_ARMED if fs.phase is _PHASE_OK else 0)
            | (_FLAG_HOST_REQUIRED if fs.host_required else 0)
            | (_FLAG_HOST_OK if fs.host_ok else 0)
            | (_FLAG_RC_OK if fs.rc_ok else 0)
            | (_FLAG_SIM if self.bus.simulated else 0)
        )
        rc = self.rc_frame
        ctl = self._control_task
        link = self.link
        t = self.slew.tensions_n
        est = m.tension_est_n
        length = m.cable_length_m
        u32 = 0xFFFF_FFFF
        return Telemetry(
            now_us,
            self.mode,
            fs.phase,
            self.grasp.state,
            _TELEMETRY_FLAGS[flags],
            fs.motors_online,
            rc.channels if rc else (0, 0, 0, 0),
            rc.right_lever if rc else 0,
            rc.left_lever if rc else 0,
            (m.angle[0], m.angle[1], m.angle[2]),
            (m.speed_rpm[0], m.speed_rpm[1], m.speed_rpm[2]),
            (m.current[0], m.current[1], m.current[2]),
            (self.commanded_currents[0], self.commanded_currents[1], self.commanded_currents[2]),
            (t[0], t[1], t[2]),
            (est[0], est[1], est[2]),
            (length[0], length[1], length[2]),
            ctl.late & u32,
            ctl.exec_p99_us,
            ctl.exec_max_us,
            min(ctl.lateness_max_us, u32),
            self.rc_frames_ok & u32,
            self.rc_rejected & u32,
            self.rc.bytes_dropped & u32,
            (link.parser.frames_ok if link else 0) & u32,
            (link.crc_errors if link else 0) & u32,
            fs.motor_offline_events & u32,
            self.bus.can_errors & u32,
            ctl.lateness_p99_us,  # cached like exec_p99_us: refreshed with BoardStatus, not per tick
            fs.arm_blocker(),  # computed here, at the telemetry rate, never by the control tick
        )

    def _task_telemetry(self, now_us: int) -> None:
        link = self.link
        if link is None:
            return
        link.send(self.build_telemetry(now_us))
        m = self.motors
        pack = FEEDBACK_FORMAT.pack
        seen = m.seen
        angle, speed, current, temperature = m.angle, m.speed_rpm, m.current, m.temperature
        frames = [_ZERO_FRAME, _ZERO_FRAME, _ZERO_FRAME]
        for i in range(MOTOR_COUNT):
            if seen[i]:
                frames[i] = (FEEDBACK_ID_BASE + 1 + i, pack(angle[i], speed[i], current[i], temperature[i]))
        link.send(MotorFrames(now_us, (frames[0], frames[1], frames[2])))
        raw_rc = self._raw_rc
        if raw_rc:
            for t_us, frame in raw_rc:
                link.send(RawRc(t_us, frame.pack()))  # the received bytes, kept by RcFrame.unpack
            raw_rc.clear()
        if len(self.events):
            for event in self.events.pop_all():
                link.send(event)
        link.transport.flush()

    def _task_status(self, now_us: int) -> None:
        self._send(BoardStatus(now_us, FIRMWARE_VERSION, self.clock_kind, self.scheduler.stats()))

    def _task_poses(self, now_us: int) -> None:
        provider = self._poses
        if provider is None:
            return
        poses = provider()
        if poses is None:
            return
        if isinstance(poses, SimPoses):
            self._send(poses)
        else:
            positions, quats = poses
            self._send(
                SimPoses(
                    now_us,
                    tuple((float(p[0]), float(p[1]), float(p[2])) for p in positions),
                    tuple((float(q[0]), float(q[1]), float(q[2]), float(q[3])) for q in quats),
                )
            )
