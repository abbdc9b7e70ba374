"""What ``spirob-firmware --preflight`` measures and how it judges it: pure functions of figures.

The bounds (each with its source), the measured statistics of the window (:class:`LatenessStats`,
:class:`MotorStats`, :class:`RcStats`, :class:`LinkStats`) and the ``judge_*`` functions that turn them
into one :class:`Check` line each, with its fix. :mod:`controller.preflight` runs the loop that measures;
this module has no I/O, so every judgement is tested with made-up figures.
"""

from __future__ import annotations

import enum
from collections.abc import Sequence
from dataclasses import dataclass, field

from protocol.c610 import ANGLE_COUNTS, FEEDBACK_ID_BASE, RAW_PER_AMP, angle_delta_counts
from protocol.dbus import FRAME_LEN as DBUS_FRAME_LEN
from protocol.dbus import Lever, RcFrame
from protocol.messages import ClockKind

WINDOW_US = 2_000_000
"""How long the checks listen (and the lateness test runs): 2 s at 1 kHz, 2000 ticks."""
LATENESS_P99_MAX_US = 200
"""Largest p99 tick start lateness that passes. Measured on the project's 2-core VM under SCHED_FIFO with
absolute sleeps: p99 22-29 µs (``controller.clock``); without SCHED_FIFO 3-6 % of deadlines are missed."""
TEMPERATURE_MAX_C = 80
"""Hottest motor temperature (feedback byte 6) that passes; a C610 may report 0, which passes."""
ROTOR_TRAVEL_MAX_COUNTS = ANGLE_COUNTS
"""Rotor travel allowed with zero current: one rotor turn (10° at the M2006's output)."""
IDLE_CURRENT_MAX_RAW = RAW_PER_AMP // 2
"""|measured current| allowed while zero is commanded (0.5 A): more means another node drives it."""
MOTOR_ANSWER_RATIO = 0.5
"""A motor must answer on at least this share of the ticks (a C610 sends about 1000 frames/s)."""
RC_PERIOD_RANGE_US = (5_000, 16_000)
"""Median interval between valid frames that passes: the DR16's 14 ms, or 7 ms for some receivers."""
_TIMES_KEPT = 4096
"""Arrival times kept per stream (a DR16 sends 143 frames in 2 s, a host 20 heartbeats)."""


class Status(enum.Enum):
    """A check's verdict."""

    PASS = "PASS"
    FAIL = "FAIL"
    SKIP = "SKIP"


@dataclass(frozen=True, slots=True)
class Check:
    """One check's verdict, what was measured and, for a failure, what to do.

    Attributes:
        name: what was checked (``motor 2 (0x202)``, ``rc``, ...).
        status: the verdict.
        detail: the measured facts behind it.
        fix: what to do about a failure ("" otherwise).
    """

    name: str
    status: Status
    detail: str
    fix: str = ""

    @property
    def failed(self) -> bool:
        """The check failed."""
        return self.status is Status.FAIL

    def line(self) -> str:
        """The check as one line: ``FAIL rc: no DBUS frames ... -> fix: ...``."""
        text = f"{self.status.value} {self.name}: {self.detail}"
        return f"{text} -> fix: {self.fix}" if self.failed and self.fix else text


@dataclass(frozen=True, slots=True)
class PreflightReport:
    """Every check's verdict, in the order they are printed."""

    checks: tuple[Check, ...]

    @property
    def passed(self) -> bool:
        """No check failed (skipped ones do not count against it)."""
        return not any(c.failed for c in self.checks)

    def lines(self) -> list[str]:
        """One line per check, then a summary line."""
        failed = sum(c.failed for c in self.checks)
        passed = sum(c.status is Status.PASS for c in self.checks)
        skipped = len(self.checks) - failed - passed
        verdict = "ready" if not failed else "NOT ready: do not arm"
        tail = f", {skipped} skipped" if skipped else ""
        return [c.line() for c in self.checks] + [
            f"preflight: {passed} passed, {failed} failed{tail}: {verdict}"
        ]


# --- what the loop measures ---------------------------------------------------------------------------


@dataclass(slots=True)
class LatenessStats:
    """The 1 kHz loop's timing over the window (from its scheduler task).

    Attributes:
        runs: ticks that ran.
        expected_runs: ticks the window holds.
        late: ticks that started a whole period or more after their deadline.
        skipped: deadlines skipped by those late ticks.
        p99_us: 99th percentile start lateness.
        max_us: largest start lateness.
        backwards: times the clock read earlier than before.
        work_max_us: longest tick (the loop's own work, from its wake-up to its next sleep).
        late_wakeups: late ticks whose sleep began before their deadline: the loop asked to wake in
            time and was woken a whole period late (the OS or the hypervisor, not this program).
        wakeup_overshoot_max_us: the largest of those wake-ups' lateness.
    """

    runs: int = 0
    expected_runs: int = 0
    late: int = 0
    skipped: int = 0
    p99_us: int = 0
    max_us: int = 0
    backwards: int = 0
    work_max_us: int = 0
    late_wakeups: int = 0
    wakeup_overshoot_max_us: int = 0


@dataclass(slots=True)
class MotorStats:
    """One motor's feedback over the window.

    Attributes:
        frames: feedback frames received.
        angle: the last rotor angle (counts, 0..8191; -1 before the first frame).
        travel_counts: largest |rotor movement| from the first frame's angle, unwrapped.
        current_abs_max: largest |measured current| (raw, 1000 per amp).
        temperature_max: hottest temperature reported (°C).
    """

    frames: int = 0
    angle: int = -1
    travel_counts: int = 0
    current_abs_max: int = 0
    temperature_max: int = 0
    _unwrapped: int = 0

    def take(self, angle: int, current: int, temperature: int) -> None:
        """Account one feedback frame."""
        if self.frames:
            self._unwrapped += angle_delta_counts(self.angle, angle)
            self.travel_counts = max(self.travel_counts, abs(self._unwrapped))
        self.frames += 1
        self.angle = angle
        self.current_abs_max = max(self.current_abs_max, abs(current))
        self.temperature_max = max(self.temperature_max, temperature)


@dataclass(slots=True)
class RcStats:
    """RC frames over the window.

    Attributes:
        valid_us: arrival times of the valid frames (at most the first 4096).
        invalid: frames rejected (a channel beyond ±660 or a lever 0).
        bytes_dropped: UART bytes of bursts that were not 18 bytes (DBUS framing).
        last: the last valid frame.
    """

    valid_us: list[int] = field(default_factory=list)
    invalid: int = 0
    bytes_dropped: int = 0
    last: RcFrame | None = None

    def take(self, now_us: int, frames: Sequence[RcFrame]) -> None:
        """Account the frames one poll returned at ``now_us``."""
        for f in frames:
            if f.is_valid():
                if len(self.valid_us) < _TIMES_KEPT:
                    self.valid_us.append(now_us)
                self.last = f
            else:
                self.invalid += 1


@dataclass(slots=True)
class LinkStats:
    """The host link over the window.

    Attributes:
        heartbeats_us: arrival times of the host's ``Heartbeat`` (at most the first 4096).
        frames_ok: intact frames received.
        bad_bytes: bytes skipped and CRC errors (noise, a wrong baud rate, another program's traffic).
    """

    heartbeats_us: list[int] = field(default_factory=list)
    frames_ok: int = 0
    bad_bytes: int = 0

    def take_heartbeat(self, now_us: int) -> None:
        """Account a heartbeat received at ``now_us`` (the first 4096 are kept)."""
        if len(self.heartbeats_us) < _TIMES_KEPT:
            self.heartbeats_us.append(now_us)


# --- the judgements --------------------------------------------------------------------------------------

_HW = "docs/hardware.md"
PORT_FIX = (
    "is the adapter plugged in, the name right (ls /dev/serial/by-id) and the port free (another firmware "
    "running?); your user needs the dialout group"
)


def _largest_gap_us(times_us: Sequence[int], start_us: int, end_us: int) -> int:
    """Longest stretch of the window ``start_us..end_us`` without an arrival (the edges included)."""
    gap = 0
    prev = start_us
    for t in times_us:
        gap = max(gap, t - prev)
        prev = t
    return max(gap, end_us - prev)


def _median(values: Sequence[int]) -> int:
    ordered = sorted(values)
    return ordered[len(ordered) // 2]


def _ms(us: int) -> str:
    return f"{us / 1000:.1f} ms"


def judge_clock(kind: ClockKind, *, fifo_wanted: bool, absolute_sleeps: bool, backwards: int) -> Check:
    """The clock the loop ran on: real time, SCHED_FIFO (unless declined), absolute sleeps, monotonic."""
    name = "clock"
    if kind is ClockKind.LOCKSTEP:
        return Check(
            name, Status.FAIL, "a simulated (lockstep) clock", "run the preflight on the real-time clock"
        )
    if backwards:
        return Check(
            name,
            Status.FAIL,
            f"CLOCK_MONOTONIC read earlier than before {backwards} times",
            "a broken kernel clock source: check dmesg for clocksource messages",
        )
    if not absolute_sleeps:
        return Check(
            name,
            Status.FAIL,
            "no clock_nanosleep(TIMER_ABSTIME): sleeps are relative and drift",
            "run on Linux with glibc (a Raspberry Pi OS or Debian image)",
        )
    if kind is ClockKind.REALTIME_FIFO:
        return Check(name, Status.PASS, "CLOCK_MONOTONIC, absolute sleeps, SCHED_FIFO in force")
    if not fifo_wanted:
        return Check(name, Status.PASS, "CLOCK_MONOTONIC, absolute sleeps, normal priority (--no-fifo)")
    return Check(
        name,
        Status.FAIL,
        "SCHED_FIFO not permitted: the loop ran at normal priority",
        f"grant CAP_SYS_NICE (AmbientCapabilities= in the systemd unit) or an rtprio limit ({_HW})",
    )


def judge_lateness(stats: LatenessStats) -> Check:
    """The 1 kHz lateness test: every tick ran, none a whole period late, a small p99."""
    name = "lateness"
    detail = (
        f"{stats.runs} of {stats.expected_runs} ticks, {stats.late} late, p99 {stats.p99_us} us, "
        f"max {stats.max_us} us"
    )
    fix = (
        "give the firmware SCHED_FIFO, stop other loads on this computer, set the CPU governor to "
        f"'performance' ({_HW})"
    )
    if stats.expected_runs and stats.runs * 10 < stats.expected_runs * 9:
        return Check(name, Status.FAIL, f"{detail}: the loop fell behind", fix)
    if stats.late:
        why = f"{stats.skipped} deadlines missed; own work per tick at most {stats.work_max_us} us"
        if stats.late_wakeups == stats.late:
            why += (
                f"; every late tick had gone to sleep in time and was woken up to "
                f"{stats.wakeup_overshoot_max_us} us late: the OS or the hypervisor, not this program"
            )
            fix = (
                "this computer does not wake a SCHED_FIFO thread on time (a virtual machine cannot promise "
                "it): run on the companion computer, isolate a core for the firmware, disable deep CPU idle "
                f"states ({_HW})"
            )
        return Check(name, Status.FAIL, f"{detail}: {why}", fix)
    if stats.p99_us > LATENESS_P99_MAX_US:
        return Check(name, Status.FAIL, f"{detail}: p99 above {LATENESS_P99_MAX_US} us", fix)
    return Check(name, Status.PASS, detail)


def judge_can(*, opened: str | None, frames_sent: int, send_errors: int, ticks: int) -> Check:
    """The CAN bus: opened (``opened`` None, else why not), and a zero-current frame sent on every tick."""
    name = "can"
    if opened is not None:
        return Check(
            name,
            Status.FAIL,
            opened,
            "check the adapter is plugged in and named as python-can expects (--can-interface, "
            f"--can-channel; {_HW})",
        )
    detail = f"{frames_sent} zero-current frames sent on 0x200, {send_errors} errors"
    if send_errors or frames_sent < ticks:
        return Check(
            name,
            Status.FAIL,
            detail,
            "no node acknowledges the frames or the bus is off: power the C610s (battery), check CANH/CANL, "
            "a 120 ohm terminator at each end and 1 Mbit/s on both sides",
        )
    return Check(name, Status.PASS, detail)


def judge_motor(motor: int, stats: MotorStats | None, *, ticks: int, window_us: int) -> Check:
    """Motor 1..3 (id 0x200 + motor): answers, a sane temperature, still and currentless at zero command.

    ``stats`` None: the bus did not open (skipped). A C610 answers about once per tick.
    """
    can_id = FEEDBACK_ID_BASE + motor
    name = f"motor {motor} (0x{can_id:03X})"
    if stats is None:
        return Check(name, Status.SKIP, "CAN bus not open")
    window = f"{window_us / 1e6:.1f} s"
    if stats.frames == 0:
        return Check(
            name,
            Status.FAIL,
            f"no feedback in {window}",
            f"set the C610's ID to {motor} (its SET button, as the C610 manual says), power it, check "
            "its CAN cable in the chain",
        )
    travel_deg = 360.0 * stats.travel_counts / ANGLE_COUNTS / 36.0
    detail = (
        f"{stats.frames} frames, angle {stats.angle}, {stats.temperature_max} C, "
        f"moved {travel_deg:.1f} deg, |current| <= {stats.current_abs_max / RAW_PER_AMP:.2f} A"
    )
    if stats.frames < MOTOR_ANSWER_RATIO * ticks:
        return Check(
            name,
            Status.FAIL,
            f"{detail}: answered on fewer than half of {ticks} ticks",
            "frames are lost: check the bus load and errors (candump -e), the terminators and the adapter",
        )
    if stats.temperature_max > TEMPERATURE_MAX_C:
        return Check(
            name, Status.FAIL, f"{detail}: too hot", "let the motor cool; check the spool turns freely"
        )
    if stats.current_abs_max > IDLE_CURRENT_MAX_RAW or stats.travel_counts > ROTOR_TRAVEL_MAX_COUNTS:
        return Check(
            name,
            Status.FAIL,
            f"{detail}: it moves or draws current with zero commanded",
            "another controller is on the CAN bus (disconnect the C-board or any other node sending 0x200), "
            "or the cable is loaded: unload it",
        )
    return Check(name, Status.PASS, detail)


def judge_rc(
    stats: RcStats,
    *,
    source: str,
    from_link: bool,
    start_us: int,
    end_us: int,
    rc_timeout_us: int,
    loop_stalled: bool = False,
) -> Check:
    """The radio: valid frames only, at the DR16's period, no gap as long as the RC timeout.

    Args:
        stats: what the source delivered.
        source: where the frames come from, for the messages (a port, or the host link).
        from_link: the frames are the host's ``VirtualRc`` (no UART).
        start_us: the window's start (``end_us``: its end).
        rc_timeout_us: the firmware's RC timeout (``FailsafeConfig.rc_timeout_us``).
        loop_stalled: the loop itself missed deadlines: bursts and gaps may be its own doing (a reader
            that stalls a whole frame period reads two frames as one 36-byte burst).
    """
    name = "rc"
    stall_fix = "the board's own loop stalled (see the lateness line): fix that first"
    window = f"{(end_us - start_us) / 1e6:.1f} s"
    n = len(stats.valid_us)
    if from_link:
        absent_fix = "start spirob-host --port on the host computer (its panel is the radio), or give --rc"
        wiring_fix = "the host's frames are corrupted: check the link (see the link line)"
    else:
        absent_fix = (
            "switch the DT7 on and bind it to the DR16, power the DR16, and wire its DBUS output through "
            f"the inverter to the UART's RX ({_HW})"
        )
        wiring_fix = (
            "the UART must run 100000 baud 8E1 and see the DBUS signal inverted (the inverter), on a UART "
            f"with parity (not a Raspberry Pi's mini UART; {_HW})"
        )
    if n == 0 and stats.invalid == 0:
        if stats.bytes_dropped:
            return Check(
                name,
                Status.FAIL,
                f"{stats.bytes_dropped} bytes on {source} but no 18-byte DBUS frame in {window}",
                wiring_fix,
            )
        return Check(name, Status.FAIL, f"no RC frames from {source} in {window}", absent_fix)
    detail = f"{n} valid frames on {source}"
    if stats.invalid:
        return Check(
            name,
            Status.FAIL,
            f"{detail}, {stats.invalid} invalid (a channel beyond +-660 or a lever reading 0)",
            "rebind the DR16 to the DT7; if it persists, bit errors: check the inverter and the wiring"
            if not from_link
            else wiring_fix,
        )
    if stats.bytes_dropped > DBUS_FRAME_LEN:  # one partial frame when the port opened mid-frame is expected
        return Check(
            name,
            Status.FAIL,
            f"{detail}, {stats.bytes_dropped} bytes in bursts that were not 18 bytes",
            stall_fix if loop_stalled else wiring_fix,
        )
    if n < 2:
        return Check(name, Status.FAIL, f"{detail} in {window}", absent_fix)
    intervals = [b - a for a, b in zip(stats.valid_us, stats.valid_us[1:], strict=False)]
    period = _median(intervals)
    gap = _largest_gap_us(stats.valid_us, start_us, end_us)
    last = stats.last
    levers = f"right lever {Lever(last.right_lever).name}" if last is not None else ""
    detail = f"{detail}, one every {_ms(period)} (median), longest gap {_ms(gap)}, {levers}"
    lo, hi = RC_PERIOD_RANGE_US
    if not lo <= period <= hi:
        return Check(
            name,
            Status.FAIL,
            f"{detail}: a DR16 sends every 14 ms (or 7 ms)",
            "another receiver or a wrong baud rate: a DR16 on 100000 baud 8E1"
            if not from_link
            else absent_fix,
        )
    if gap >= rc_timeout_us:
        return Check(
            name,
            Status.FAIL,
            f"{detail}: the board latches RC_LOST after {_ms(rc_timeout_us)}",
            stall_fix
            if loop_stalled
            else "frames arrive in bursts: on a USB-serial adapter set its latency timer to 1 ms; check the "
            f"antennas and the radio's range ({_HW})"
            if not from_link
            else "the host or its link stalls: a quieter host computer, or USB instead of Wi-Fi",
        )
    return Check(name, Status.PASS, detail)


def judge_link(
    stats: LinkStats | None, *, port: str, start_us: int, end_us: int, host_timeout_us: int
) -> Check:
    """The host link: heartbeats arrive, no gap as long as the host timeout (``stats`` None: skipped)."""
    name = "link"
    if stats is None:
        return Check(name, Status.SKIP, "no --link: the board runs without a host")
    window = f"{(end_us - start_us) / 1e6:.1f} s"
    n = len(stats.heartbeats_us)
    host_fix = (
        "start spirob-host --port on the host computer (the board's USB gadget serial is /dev/ttyACM0 "
        f"there; {_HW})"
    )
    if n == 0:
        if stats.frames_ok == 0 and stats.bad_bytes == 0:
            return Check(name, Status.FAIL, f"no bytes from the host on {port} in {window}", host_fix)
        return Check(
            name,
            Status.FAIL,
            f"{stats.frames_ok} frames and {stats.bad_bytes} bad bytes on {port}, no heartbeat in {window}",
            "something other than spirob-host is on this port, or a real UART at the wrong baud rate",
        )
    gap = _largest_gap_us(stats.heartbeats_us, start_us, end_us)
    detail = f"{n} heartbeats on {port}, longest gap {_ms(gap)}, {stats.bad_bytes} bad bytes"
    if gap >= host_timeout_us:
        return Check(
            name,
            Status.FAIL,
            f"{detail}: with the host required the board latches HOST_LOST after {_ms(host_timeout_us)}",
            "the host or its link stalls: a quieter host computer, or USB instead of Wi-Fi",
        )
    return Check(name, Status.PASS, detail)
