"""The firmware: a declared task table and thin task bodies (Betaflight's ``fc/tasks.c``).

Task table (rates are the config's defaults; tasks due on the same tick run in this order)::

    name        period   body
    link_rx     1 kHz    board link in: heartbeat, virtual RC, commands, parameters   (with a link)
    control     1 kHz    RC + feedback in, failsafe, mode, tensions, currents, 0x200 (+ 0x1FF) out
    detect      100 Hz   device liveness summary (RC, host) and its events
    telemetry   100 Hz   Telemetry, MotorFrames, RawRc, Event out                    (with a link)
    status      2 Hz     BoardStatus (per-task statistics) out                        (with a link)
    sim_poses   50 Hz    SimPoses (+ an array's ArmPoses) out         (with a link and a pose provider)

Each body calls into a module: RC intake (``controller.rc.RcInput``), the failsafe
(``controller.failsafe``), mode selection (``controller.modes``), the cables' mapping, slew and motor
model (``controller.cables``), the length-hold cascade (``controller.lengthhold``), the motor bus; the
command and parameter server (``controller.commands``); telemetry building (``controller.telemetry``).

Two ways to drive it: :meth:`Firmware.run` is the real-time loop (:func:`controller.clock.run_periodic`
on any :class:`~controller.clock.Clock`); a lockstep simulation calls :meth:`Firmware.run_due` with the
simulated time after every 1 ms plant step. Tasks receive ``now_us`` and never read a clock.

Safety rules (see ``controller.failsafe``): no current before the start-up gate; zero current on the
first tick after RC (30 ms), a motor (10 ms) or a required host heartbeat is lost, on E-stop, and in
SAFE mode. Invalid RC frames are counted and never acted on.
The speed governor (``MotorModel.govern``) is the last stage before the currents in every mode: a
cable reeling in faster than ``payin_limit_m_per_s`` has its tension cut back toward the pretension,
so a slack cable snaps taut gently.
"""

from __future__ import annotations

from collections.abc import Callable

from controller.cables import CableMapper, MotorModel, TensionSlew
from controller.clock import Clock, StopSignal, monotonic_ns, run_periodic
from controller.commands import CommandServer, GraspAcks, Params
from controller.config import FirmwareConfig
from controller.errors import ConfigError
from controller.events import EventQueue
from controller.failsafe import Failsafe
from controller.grasp import GraspMachine
from controller.hostlink import BoardLink
from controller.lengthhold import LengthHold
from controller.modes import ModeSelector
from controller.motorbus import MotorBus
from controller.rc import RcInput, RcSource
from controller.scheduler import Scheduler, TaskSpec
from controller.telemetry import FIRMWARE_VERSION, PoseProvider, TelemetryBuilder
from controller.transport import Transport
from protocol.dbus import RcFrame
from protocol.messages import ClockKind, EventKind, GraspState, Mode, Phase, TaskStats, Telemetry

__all__ = ["Firmware"]

_MAX_DT_US = 20_000  # a stalled loop never makes the slew limiter jump further than this
_LAYOUT_EVENT = 100  # INFO code of the layout event (0 RC, 1 host, 2 link changed; motors 1-8 online)
# Enum members the control tick compares by identity (no class attribute lookup per tick).
_SAFE, _MANUAL, _DIRECT = Mode.SAFE, Mode.MANUAL, Mode.DIRECT


class Firmware:
    """The C-board firmware emulator.

    Args:
        config: firmware constants (a runtime copy is kept; ``ParamSet`` replaces it). Its layout of arms
            and cables (``FirmwareConfig.motor_count``, ``arm_count``, ``cables_per_arm``) is fixed at
            start-up.
        bus: the motor bus (owned by the caller), with ``config.motor_count`` motors.
        rc: the RC source (owned by the caller). With a :class:`~controller.rc.LinkRcSource` the host's
            ``VirtualRc`` frames feed it; with any other source they are ignored (the radio is master).
        link: the host link transport, or None to run without a host.
        poses: optional pose provider for ``SimPoses`` (default: the bus's ``poses`` method if any).
        exec_timer_ns: timer for execution-time statistics (default CLOCK_MONOTONIC; a lockstep run
            that wants bit-identical telemetry passes :func:`controller.clock.zero_ns`).

    Read-only state for observers: :attr:`mode`, :attr:`phase`, :attr:`grasp_state`,
    :attr:`commanded_currents`, :attr:`tensions_n`, :attr:`stats`, :attr:`counters`, :attr:`rc_frame`,
    :attr:`config`, and the component objects (:attr:`failsafe`, :attr:`motors`, :attr:`grasp`,
    :attr:`modes`, :attr:`hold`, :attr:`scheduler`, :attr:`events`, :attr:`link`).
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
        """Wire the firmware up (nothing runs until :meth:`run_due` or :meth:`run`).

        Raises:
            ConfigError: the bus has not the configuration's number of motors.
        """
        if bus.motor_count != config.motor_count:
            raise ConfigError(
                f"the motor bus has {bus.motor_count} motors, the configuration {config.motor_count} "
                f"({config.arm_count} arm(s) of {config.cables_per_arm} cable(s))"
            )
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
        self.hold = LengthHold(config, self.motors, self.slew)
        self.grasp = GraspMachine(config, self.events)
        self.rc_input = RcInput(self.failsafe.on_rc_frame, keep_raw=self.link is not None)
        self.acks = GraspAcks(self.link is not None)
        self.modes = ModeSelector(
            config, self.failsafe, self.grasp, self.mapper, self.motors, self.hold, self.events, self.acks
        )
        self.params = Params(config, self.events, self._apply_config, self._disarmed)
        self._apply_config(config)
        self.commands = (
            CommandServer(
                self.link,
                rc,
                self.rc_input,
                self.failsafe,
                self.modes,
                self.grasp,
                self.mapper,
                self.hold,
                self.params,
                self.acks,
                self.events,
            )
            if self.link is not None
            else None
        )
        self.clock_kind = ClockKind.LOCKSTEP
        n = config.motor_count
        self.commanded_currents: tuple[int, ...] = (0,) * n
        self._raw = [0] * n
        self._zero = (0,) * n
        self._last_control_us: int | None = None
        self._last_rc_ok = False
        self._last_host_ok = False
        # The control tick's calls into the modules, bound once (no attribute lookups per tick).
        self._select_mode = self.modes.select
        self._grasp_targets = self.modes.grasp_targets
        self.scheduler = Scheduler(self._task_table(), exec_timer_ns or monotonic_ns)
        self.telemetry = TelemetryBuilder(
            failsafe=self.failsafe,
            motors=self.motors,
            slew=self.slew,
            hold=self.hold,
            grasp=self.grasp,
            modes=self.modes,
            bus=bus,
            rc=rc,
            rc_input=self.rc_input,
            scheduler=self.scheduler,
            events=self.events,
            link=self.link,
            layout=(config.arm_count, config.cables_per_arm),
        )
        self._booted = False

    # --- the task table ---------------------------------------------------------------------------

    def _task_table(self) -> tuple[TaskSpec, ...]:
        """The task table: one row per task; offsets (in control ticks) stagger the slow tasks."""
        c = self.config
        serve = self.commands.serve if self.commands is not None else None  # the body itself, no wrapper
        have = {
            "": True,
            "link": self.link is not None,
            "poses": self.link is not None and self._poses is not None,
        }
        # fmt: off
        rows = (
            # name        period                 body                  offset  needs
            ("link_rx",   c.link_period_us,      serve,                0,      "link"),
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
            if have[needs] and body is not None
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
        self._say_layout(first_deadline_us)
        self.scheduler.start(first_deadline_us)
        self._booted = True

    def run(self, clock: Clock, duration_us: int | None = None, stop: StopSignal = None) -> None:
        """The real-time loop: run due tasks, sleep to the next absolute deadline, repeat.

        The loop is :func:`~controller.clock.run_periodic`, inside ``clock.running()``. Returns after
        ``duration_us`` or when ``stop`` is set / returns True (checked every tick), and sends zero
        current once on the way out.
        """
        sched = self.scheduler
        run_due, next_deadline_us = sched.run_due, sched.next_deadline_us

        def begin(start_us: int) -> int:
            self.clock_kind = clock.kind  # inside clock.running(): SCHED_FIFO is known by now
            self.rc.discard_pending()  # stick positions buffered since the port opened are stale
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
    def config(self) -> FirmwareConfig:
        """The configuration in force (``ParamSet`` and :meth:`set_param` replace it)."""
        return self.params.config

    @property
    def mode(self) -> Mode:
        """Operating mode of the last control tick."""
        return self.modes.mode

    @property
    def phase(self) -> Phase:
        """Failsafe phase."""
        return self.failsafe.phase

    @property
    def grasp_state(self) -> GraspState:
        """Grasp state machine state."""
        return self.grasp.state

    @property
    def rc_frame(self) -> RcFrame | None:
        """The last valid RC frame (None before the first)."""
        return self.rc_input.frame

    @property
    def rc_frames_ok(self) -> int:
        """Valid RC frames accepted."""
        return self.rc_input.frames_ok

    @property
    def rc_rejected(self) -> int:
        """RC frames rejected as invalid."""
        return self.rc_input.rejected

    @property
    def virtual_rc_ignored(self) -> int:
        """``VirtualRc`` frames received while the radio is the RC source."""
        return self.commands.virtual_rc_ignored if self.commands else 0

    @property
    def direct_tensions_n(self) -> list[float]:
        """The host's DIRECT tensions (``SET_TENSIONS``, clamped), one per cable of an arm."""
        return self.modes.direct_tensions_n

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
            "rc_frames_ok": self.rc_input.frames_ok,
            "rc_rejected": self.rc_input.rejected,
            "dbus_bytes_dropped": self.rc.bytes_dropped,
            "virtual_rc_ignored": self.virtual_rc_ignored,
            "link_frames_ok": link.parser.frames_ok if link else 0,
            "link_crc_errors": link.crc_errors if link else 0,
            "link_decode_errors": link.decode_errors if link else 0,
            "link_frames_dropped": link.transport.frames_dropped if link else 0,
            "link_id_errors": link.stream.id_errors if link else 0,
            "link_oversize_errors": link.stream.oversize_errors if link else 0,
            "link_rx_bytes_dropped": link.rx_bytes_dropped if link else 0,
            "link_rx_frames_dropped": link.rx_frames_dropped if link else 0,
            "motor_offline_events": self.failsafe.motor_offline_events,
            "can_errors": self.bus.can_errors,
            "events_dropped": self.events.dropped,
        }

    def build_telemetry(self, now_us: int) -> Telemetry:
        """The ``Telemetry`` message for the present state (also usable without a link)."""
        return self.telemetry.build(now_us, self.commanded_currents)

    # --- configuration ----------------------------------------------------------------------------

    def _disarmed(self) -> bool:
        """Safety parameters may change: SAFE, zero current (``Params``)."""
        return self.modes.mode is _SAFE

    def _apply_config(self, config: FirmwareConfig) -> None:
        self.failsafe.configure(config)
        self.modes.configure(config)
        self.motors.configure(config)
        self.mapper.configure(config)
        self.slew.configure(config)
        self.hold.configure(config)
        self.grasp.configure(config)
        self.bus.current_limit_raw = config.motor.current_limit_raw

    def set_param(self, now_us: int, name: str, value: float) -> float:
        """Set a runtime parameter (wire name) if valid; return the value in force afterwards.

        Safety parameters (``controller.params.SAFETY_PARAMS``) change only in SAFE, as by ``ParamSet``.

        Raises:
            ConfigError: unknown name (an invalid value is not an error: the old value stays).
        """
        return self.params.set(now_us, name, value)

    # --- tasks ------------------------------------------------------------------------------------

    def _task_control(self, now_us: int) -> None:
        last = self._last_control_us
        dt = self.params.config.control_period_us if last is None else now_us - last
        if dt > _MAX_DT_US:
            dt = _MAX_DT_US
        self._last_control_us = now_us
        fs = self.failsafe

        frames = self.rc.poll(now_us)
        if frames:
            self.rc_input.take(now_us, frames)
        feedback = self.bus.read_feedback()
        if feedback:
            self.motors.update_frames(feedback, now_us)
            fs.on_motor_frames(now_us, feedback)

        phase = fs.update(now_us)
        rc = self.rc_input.frame
        mode = self._select_mode(now_us, phase, rc)

        if mode is _SAFE:
            self.slew.reset()
            self.commanded_currents = self.bus.send_currents(self._zero)
            return
        if rc is None:  # cannot happen: phase OK needs a valid frame
            self.commanded_currents = self.bus.send_currents(self._zero)
            return
        if mode is _MANUAL:
            targets = self.mapper.manual(rc.channels)
        elif mode is _DIRECT:
            targets = self.mapper.direct(self.modes.direct_tensions_n)
        else:
            targets = self._grasp_targets(now_us, dt, rc)
        tensions = self.slew.step(targets, dt)
        hold = self.hold
        if hold.count:  # only after the SAFE return above: a failsafe always wins over a hold
            hold.step(dt, tensions)
        motors = self.motors
        # the speed governor last: it caps whatever mode, slew or length-hold asked for (safety)
        self.commanded_currents = self.bus.send_currents(
            motors.tensions_to_raw(motors.govern(tensions), self._raw)
        )

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
            if host_ok:
                self._say_layout(now_us)

    def _say_layout(self, now_us: int) -> None:
        """An array's layout as an INFO event (code 3), for hosts that cannot read ``ArmsTelemetry``."""
        t = self.telemetry
        if t.is_array:
            self.events.push(now_us, EventKind.INFO, _LAYOUT_EVENT, float(t.layout[0]), t.layout_text())

    def _task_telemetry(self, now_us: int) -> None:
        self.telemetry.send(now_us, self.commanded_currents)

    def _task_status(self, now_us: int) -> None:
        self.telemetry.send_status(now_us, self.clock_kind)

    def _task_poses(self, now_us: int) -> None:
        if self._poses is not None:
            self.telemetry.send_poses(now_us, self._poses)
