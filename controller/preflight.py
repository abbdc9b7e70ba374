"""``spirob-firmware --preflight``: the board's pre-arm checks, as an autopilot runs before arming.

One bounded run of the 1 kHz loop (:data:`WINDOW_US`, 2 s, on the clock the firmware would use) with
**zero current** commanded on every tick and the bus's current limit set to 0 besides, so nothing a
check does can move a motor. Each tick sends one 0x200 frame of zeros, drains the motors' feedback,
polls the RC source and reads the host link, exactly the I/O of the firmware's own control tick; the
loop's start lateness is the real-time test. Then one line per check (clock, lateness, can, motor 1-3,
rc, link), each failure with its fix; what each passes on is the table of docs/hardware.md.

The judgements are pure functions of what the loop measured (``judge_*``), so their logic is tested with
made-up figures; :func:`run_preflight` measures and judges.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

from controller.clock import Clock, StopSignal, monotonic_ns, run_periodic
from controller.config import MOTOR_COUNT, FirmwareConfig
from controller.hostlink import BoardLink
from controller.motorbus import MotorBus
from controller.preflight_checks import (
    PORT_FIX,
    WINDOW_US,
    Check,
    LatenessStats,
    LinkStats,
    MotorStats,
    PreflightReport,
    RcStats,
    Status,
    judge_can,
    judge_clock,
    judge_lateness,
    judge_link,
    judge_motor,
    judge_rc,
)
from controller.rc import LinkRcSource, RcSource
from controller.scheduler import Scheduler, TaskSpec
from controller.transport import Transport
from protocol.messages import ClockKind, Heartbeat, VirtualRc

__all__ = ["run_preflight"]

# --- the run ---------------------------------------------------------------------------------------------


@dataclass(slots=True)
class _Probe:
    """The tick body and what it measures (one per run)."""

    bus: MotorBus | None
    rc: RcSource | None
    link: BoardLink | None
    link_rc: LinkRcSource | None
    motors: list[MotorStats]
    rc_stats: RcStats = field(default_factory=RcStats)
    link_stats: LinkStats = field(default_factory=LinkStats)
    ticks: int = 0
    last_us: int = -1
    backwards: int = 0
    zero: tuple[int, ...] = (0,) * MOTOR_COUNT

    def tick(self, now_us: int) -> None:
        """One 1 ms tick: host link in, zero current out, feedback and RC in."""
        self.ticks += 1
        if now_us < self.last_us:
            self.backwards += 1
        self.last_us = now_us
        link = self.link
        if link is not None:
            for received in link.receive():
                msg = received.msg
                if isinstance(msg, Heartbeat):
                    self.link_stats.take_heartbeat(now_us)
                elif isinstance(msg, VirtualRc) and self.link_rc is not None:
                    self.link_rc.push(msg.data, now_us)
        bus = self.bus
        if bus is not None:
            bus.send_currents(self.zero)
            motors = self.motors
            for motor, fb in bus.read_feedback():
                motors[motor - 1].take(fb.angle, fb.current, fb.temperature)
        if self.rc is not None:
            self.rc_stats.take(now_us, self.rc.poll(now_us))


def run_preflight(
    clock: Clock,
    bus: MotorBus | None,
    rc: RcSource | None,
    link: Transport | None,
    *,
    config: FirmwareConfig | None = None,
    fifo_wanted: bool = True,
    can_error: str | None = None,
    rc_error: str | None = None,
    link_error: str | None = None,
    rc_name: str = "the RC port",
    link_name: str = "the link port",
    window_us: int = WINDOW_US,
    stop: StopSignal = None,
    exec_timer_ns: Callable[[], int] | None = None,
) -> PreflightReport:
    """Run the checks for ``window_us`` on ``clock`` with zero current commanded throughout.

    Args:
        clock: the loop's clock (the firmware's :class:`~controller.clock.RealTimeClock`; tests inject a
            fake one).
        bus: the motor bus, its current limit set to 0 for the run (restored after); None: CAN did not
            open (``can_error`` says why).
        rc: the radio's source; a :class:`~controller.rc.LinkRcSource` is fed the host's ``VirtualRc``.
        link: the host link, or None (the link check is skipped).
        config: the firmware's timeouts and control period (default ``FirmwareConfig()``).
        fifo_wanted: SCHED_FIFO was asked for (``--no-fifo`` not given).
        can_error: why the CAN bus did not open (with ``bus=None``).
        rc_error: why the RC port did not open (with ``rc=None``).
        link_error: why the link port did not open (with ``link=None``).
        rc_name: the RC source's name in messages (its port).
        link_name: the link's name in messages (its port).
        window_us: how long to listen (default 2 s).
        stop: ends the run early (Ctrl-C); the checks then judge what was measured.
        exec_timer_ns: execution-time timer of the loop's statistics (default CLOCK_MONOTONIC).

    Returns:
        The report; the bus has been sent zero current once more on the way out.

    Raises:
        ValueError: ``window_us`` shorter than a second, or a bus without the configuration's motors.
    """
    if window_us < 1_000_000:
        raise ValueError(f"window_us must be >= 1 s, got {window_us}")
    cfg = config or FirmwareConfig()
    if bus is not None and bus.motor_count != cfg.motor_count:
        raise ValueError(f"the bus has {bus.motor_count} motors, the configuration {cfg.motor_count}")
    period_us = cfg.control_period_us
    probe = _Probe(
        bus=bus,
        rc=rc,
        link=BoardLink(link) if link is not None else None,
        link_rc=rc if isinstance(rc, LinkRcSource) else None,
        motors=[MotorStats() for _ in range(cfg.motor_count)],
        zero=(0,) * cfg.motor_count,
    )
    sched = Scheduler((TaskSpec("preflight", period_us, probe.tick),), exec_timer_ns or monotonic_ns)
    task = sched["preflight"]
    started: list[int] = []
    kinds: list[ClockKind] = []

    def begin(start_us: int) -> int:
        kinds.append(clock.kind)  # inside clock.running(): SCHED_FIFO is known by now
        if rc is not None:
            rc.discard_pending()  # the backlog since the port opened is no frame of this window
        started.append(start_us)
        sched.start(start_us)
        return start_us

    asked = [0, 0]  # [the deadline the loop last slept to, when that sleep began]
    wakes = LatenessStats()

    def step(now_us: int) -> int:
        deadline, slept_at = asked
        if deadline and now_us - deadline >= period_us and slept_at < deadline:
            wakes.late_wakeups += 1  # asleep in time, woken a whole period late: not this program
            wakes.wakeup_overshoot_max_us = max(wakes.wakeup_overshoot_max_us, now_us - deadline)
        sched.run_due(now_us)
        asked[0] = sched.next_deadline_us()
        asked[1] = clock.now_us()
        wakes.work_max_us = max(wakes.work_max_us, asked[1] - now_us)
        return asked[0]

    limit = bus.current_limit_raw if bus is not None else 0
    if bus is not None:
        bus.current_limit_raw = 0  # belt and braces: nothing above zero can leave the bus
    try:
        run_periodic(clock, step, begin=begin, duration_us=window_us, stop=stop)
    finally:
        if bus is not None and not bus.is_shutdown:
            bus.send_currents(probe.zero)
            bus.current_limit_raw = limit
    start_us = started[0] if started else clock.now_us()
    end_us = min(clock.now_us(), start_us + window_us)  # earlier when stopped (Ctrl-C)
    task.update_p99()
    lateness = LatenessStats(
        runs=task.runs,
        expected_runs=(end_us - start_us) // period_us,
        late=task.late,
        skipped=task.skipped,
        p99_us=task.lateness_percentile_us(0.99),
        max_us=task.lateness_max_us,
        backwards=probe.backwards,
        work_max_us=wakes.work_max_us,
        late_wakeups=min(wakes.late_wakeups, task.late),
        wakeup_overshoot_max_us=wakes.wakeup_overshoot_max_us,
    )
    rc_stats = probe.rc_stats
    if rc is not None:
        rc_stats.bytes_dropped = rc.bytes_dropped
    if probe.link is not None:
        parser = probe.link.parser
        probe.link_stats.frames_ok = parser.frames_ok
        probe.link_stats.bad_bytes = parser.bytes_skipped + probe.link.crc_errors
    late = judge_lateness(lateness)
    checks: list[Check] = [
        judge_clock(
            kinds[0] if kinds else clock.kind,
            fifo_wanted=fifo_wanted,
            absolute_sleeps=clock.absolute_sleeps,
            backwards=probe.backwards,
        ),
        late,
        judge_can(
            opened=can_error if bus is None else None,
            frames_sent=bus.frames_sent if bus is not None else 0,
            send_errors=bus.can_errors if bus is not None else 0,
            ticks=probe.ticks,
        ),
    ]
    checks += [
        judge_motor(
            n, probe.motors[n - 1] if bus is not None else None, ticks=probe.ticks, window_us=window_us
        )
        for n in range(1, cfg.motor_count + 1)
    ]
    if rc is None and rc_error is not None:
        checks.append(Check("rc", Status.FAIL, rc_error, PORT_FIX))
    elif rc is not None:
        checks.append(
            judge_rc(
                rc_stats,
                source=rc_name,
                from_link=probe.link_rc is not None,
                start_us=start_us,
                end_us=end_us,
                rc_timeout_us=cfg.failsafe.rc_timeout_us,
                loop_stalled=late.failed,
            )
        )
    if link_error is not None:
        checks.append(Check("link", Status.FAIL, link_error, PORT_FIX))
    else:
        checks.append(
            judge_link(
                probe.link_stats if probe.link is not None else None,
                port=link_name,
                start_us=start_us,
                end_us=end_us,
                host_timeout_us=cfg.failsafe.host_timeout_us,
            )
        )
    return PreflightReport(tuple(checks))
