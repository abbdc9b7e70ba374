"""Scenarios against a board-link endpoint in real time: ``spirob-hil run NAME... --port PORT``.

:func:`run_scenario_on_port` plays the host's part of a lockstep scenario (:mod:`hil.scenarios`) over a
real port (``/dev/ttyACM0``, a pty path, ``socket://...``, any pyserial URL) against a real C-board or
``spirob-hil board``, and judges the board from what it reports: its ``Telemetry`` (100 Hz: board time,
commanded currents, phase, mode, tension targets, counters), ``RawRc`` (every RC frame it received, with
its board time) and ``Event`` messages. There is no plant to look at (a real board has none), so every
check is about currents, phases, modes and counters, and every time is measured on the board's clock.

What the host sends (DESIGN.md sections 2-4):

- **RC**: the board takes RC from the link (``VirtualRc``), as ``spirob-hil board`` does by default and as a
  board whose radio is the host's panel does. The scenario's radio script goes out as one frame every
  14 ms (the DR16's rate). RC faults are emulated in what is sent: ``rc-silence`` sends nothing,
  ``rc-frozen`` repeats the frame from the start of the fault, ``rc-out-of-range`` puts one channel beyond
  ±660, ``rc-garbage`` sends random 18-byte payloads with both levers 0 (never a valid frame; the link
  delimits frames, so the lockstep's framing noise has no counterpart here).
- **Heartbeats** at 10 Hz (``host-loss`` stops them) and the scenario's scripted commands.
- **Link faults**: ``link-byte-loss``, ``link-bit-flip`` and ``link-delay`` act on the host's link traffic
  (heartbeats, commands, parameters) and on every received byte. The ``VirtualRc`` frames bypass them:
  they stand in for the radio, which has its own wire in lockstep; corrupted at 1 % per byte, two lost
  frames in a row (a 30 ms RC loss, latched) would come about every third of a second and end every
  scenario in ``RC_LOST``. ``link-disconnect`` closes the port and reopens it at the end of the window; the
  RC rides the link, so on a port a disconnect is also an RC loss.

Before each scenario the board is brought to the state the lockstep board boots in: ``DISARM``, SAFE
frames until the phase is ``GATE`` with our RC in force (a marker value on the unused left horizontal
stick proves the board takes RC from the link), the scenario's firmware settings applied with
``ParamSet`` (only those it changes from the defaults; restored afterwards), MIDDLE frames so that the gate
needs the lever DOWN again, then ``ARM``. Afterwards SAFE frames put the board in zero current.

Faults that only the board side can inject (motor feedback silence, stuck or wrong; CAN bus off; DBUS
byte loss and bit flips; loop delay and jitter) make a scenario lockstep-only: :func:`check_port_run`
raises :class:`~hil.errors.HilError` naming the fault before the port is opened, and so does a scenario
whose checks need the simulated plant.

Resolution (see docs/realtime.md): currents are seen once per telemetry period (10 ms), so a "zero
current within X" bound becomes X + 10 ms; the times of RC frames (``RawRc``) and phase changes
(``Event``) are exact to the board's 1 ms tick; the board time of something the host sent is estimated
through the host-to-board clock offset (the smallest telemetry latency) and carries
:data:`LINK_ALLOWANCE_US`.
"""

from __future__ import annotations

import contextlib
import dataclasses
import itertools
import logging
import math
import queue
import select
import threading
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Final

import numpy as np
import numpy.typing as npt

from controller.clock import RealTimeClock
from controller.config import CONTROL_PERIOD_US, PARAM_FIELDS, PARAMS, FirmwareConfig
from controller.errors import ConfigError, PortError
from controller.transport import SerialTransport
from protocol.dbus import FRAME_LEN, FRAME_PERIOD_US, Lever, RcFrame
from protocol.link import LinkFrame, LinkParser
from protocol.messages import (
    HEARTBEAT_PERIOD_US,
    PARAM_LIST_ALL,
    AckResult,
    Command,
    CommandAck,
    CommandCode,
    Event,
    EventKind,
    Heartbeat,
    Message,
    Mode,
    ParamRequest,
    ParamSet,
    ParamValue,
    Phase,
    RawRc,
    Telemetry,
    VirtualRc,
    decode,
    encode,
)

from . import recording
from .errors import HilError
from .faults import Fault, FaultKind, FaultSet
from .radio import RadioScript
from .recording import Recorder
from .scenarios import MS, SCENARIOS, TICK_US, Check, Plan, ScenarioResult, telemetry_json

__all__ = [
    "BOARD_ONLY_FAULTS",
    "LINK_ALLOWANCE_US",
    "PORT_CHECKS",
    "RC_GAP_CHECK",
    "SETTLE_US",
    "TELEMETRY_PERIOD_US",
    "TICK_LATENESS_US",
    "PortRun",
    "check_port_run",
    "port_scenario_names",
    "run_scenario_on_port",
]

_log = logging.getLogger(__name__)

TELEMETRY_PERIOD_US: Final = FirmwareConfig().telemetry_period_us
"""The board's telemetry period (100 Hz): currents, phases and modes are seen once per period, so a
bound on "zero current within X" is widened by it."""
LINK_ALLOWANCE_US: Final = 2_000
"""Extra board time allowed for something the host sent to take effect: the board polls the link once
per 1 ms tick, and a USB full-speed CDC transfer waits for the next 1 ms frame."""
TICK_LATENESS_US: Final = 2_000
"""Allowance for a real-time board's tick starting late: the tick that acts on a timeout may run this
much after its deadline (the virtual board on this shared 2-core machine: up to about 2 ms, as its
``BoardStatus`` lateness shows; a real C-board: microseconds). A board later than that fails the
timing checks, and its ``control_late`` counter says why."""
SETTLE_US: Final = 100_000
"""After the scenario's duration the host keeps playing its last state this long, so the telemetry of
the last moments arrives, then puts the board in SAFE."""
LOOP_PERIOD_US: Final = CONTROL_PERIOD_US
"""The host loop's period: RC, heartbeat and command times are quantised to it."""

BOARD_ONLY_FAULTS: Final = frozenset(
    {
        FaultKind.DBUS_BYTE_LOSS,
        FaultKind.DBUS_BIT_FLIP,
        FaultKind.MOTOR_SILENCE,
        FaultKind.MOTOR_STUCK,
        FaultKind.MOTOR_WRONG,
        FaultKind.CAN_BUS_OFF,
        FaultKind.LOOP_DELAY,
        FaultKind.LOOP_JITTER,
    }
)
"""Faults injected between the board's own parts (UART, CAN, its loop): no host can emulate them."""

_PREAMBLE_TIMEOUT_US = 3_000_000  # the board answers within a few ms; 3 s covers a slow USB enumeration
_REPLY_TIMEOUT_US = 1_000_000
_RESEND_US = 500_000
_REOPEN_TIMEOUT_US = 2_000_000
_FINISH_SAFE_US = 150_000
_EOF_READS = 200  # readable but empty this many times in a row (>= 1 ms apart): the board closed the link
_READER_POLL_S = 0.01  # the reader thread checks for a stop this often
_HOST_FIFO_PRIORITY = 30  # below the virtual board's 50: a board on the same machine keeps its deadlines
_MARKER_CH2 = 321  # left horizontal stick: no mode reads it; seeing it in telemetry proves our RC rules
_SETTLED_N = 1e-4  # float32 telemetry: tensions equal to this are the same set-point
_AFTER_REARM_US = 200 * MS  # lockstep checks "current after re-arming" 200 ms after the pull resumes
_STEP_TAIL_US = 500 * MS  # manual-teleop: judge each stick step over its last 0.5 s (slew done)


# --- the run's record and its check helpers -------------------------------------------------------


@dataclass
class PortRun:
    """Everything a real-time check may look at, on the board's clock in µs since the scenario started.

    Attributes:
        plan: the scenario's plan.
        config: the firmware configuration in force: the plan's, with the values the board reported for
            its runtime parameters (calibration such as the spool radius is the board's own).
        duration_us: the scenario's duration.
        t_us: board time of each telemetry sample in ``[0, duration_us)``.
        current_raw: commanded currents (raw C610 units), shape (n, 3).
        target_n: tension targets, shape (n, 3).
        phase: failsafe phase per sample.
        mode: mode per sample.
        rc_frames_ok: the board's count of valid RC frames per sample.
        rc_rejected: the board's count of rejected RC frames per sample.
        link_crc_errors: the board's count of link CRC errors per sample.
        rc: every RC frame the board reported receiving (``RawRc``), as (board time, frame).
        events: board events, as (board time, event).
        sent: what the host sent (before link faults), as (estimated board time, message).
        rc_sent_us: estimated board times of the host's ``VirtualRc`` frames.
        reconnects_us: estimated board times at which the port was reopened after a disconnect.
        decode_errors: intact frames the host could not decode.
        telemetry: the telemetry messages behind the arrays.
        board_telemetry_us: board times of the telemetry frames as the board sent them, before the
            host-side link faults (only while a scenario runs).
        board_rc_us: board receive times of the valid RC frames, from the ``RawRc`` the board sent,
            before the host-side link faults (only while a scenario runs).
    """

    plan: Plan
    config: FirmwareConfig
    duration_us: int
    t_us: npt.NDArray[np.int64]
    current_raw: npt.NDArray[np.int64]
    target_n: npt.NDArray[np.float64]
    phase: npt.NDArray[np.int64]
    mode: npt.NDArray[np.int64]
    rc_frames_ok: npt.NDArray[np.int64]
    rc_rejected: npt.NDArray[np.int64]
    link_crc_errors: npt.NDArray[np.int64]
    rc: list[tuple[int, RcFrame]] = field(default_factory=list)
    events: list[tuple[int, Event]] = field(default_factory=list)
    sent: list[tuple[int, Message]] = field(default_factory=list)
    rc_sent_us: list[int] = field(default_factory=list)
    reconnects_us: list[int] = field(default_factory=list)
    decode_errors: int = 0
    telemetry: list[Telemetry] = field(default_factory=list)
    board_telemetry_us: list[int] = field(default_factory=list)
    board_rc_us: list[int] = field(default_factory=list)

    @property
    def n(self) -> int:
        """Number of telemetry samples."""
        return int(self.t_us.size)

    @property
    def limit_raw(self) -> int:
        """The current limit in raw units."""
        return self.config.motor.current_limit_raw

    def window(self, start_us: float, end_us: float | None = None) -> npt.NDArray[np.bool_]:
        """Mask of the samples with ``start_us <= t < end_us``."""
        mask = self.t_us >= start_us
        if end_us is not None:
            mask &= self.t_us < end_us
        return mask

    def abs_current(self) -> npt.NDArray[np.int64]:
        """Largest |commanded current| over the three motors, per sample."""
        out: npt.NDArray[np.int64] = np.abs(self.current_raw).max(axis=1) if self.n else np.zeros(0, np.int64)
        return out

    def max_current(self, start_us: float, end_us: float | None = None) -> float:
        """Largest |commanded current| on ``start_us <= t < end_us`` (NaN, never passing, if no sample)."""
        cur = self.abs_current()[self.window(start_us, end_us)]
        return float(cur.max()) if cur.size else math.nan

    def zero_after(self, t_us: float) -> float:
        """Time from ``t_us`` to the first sample at or after it with zero current on every motor.

        The current became zero at a tick after the previous sample, so this overstates the true time
        by less than :data:`TELEMETRY_PERIOD_US`.
        """
        if math.isnan(t_us):
            return math.nan
        idx = np.flatnonzero(self.window(t_us) & (self.abs_current() == 0))
        return float(self.t_us[idx[0]] - t_us) if idx.size else math.nan

    def count(self, start_us: float, end_us: float | None = None) -> int:
        """Telemetry samples received on ``start_us <= t < end_us``."""
        return int(np.count_nonzero(self.window(start_us, end_us)))

    def last_valid_rc_before(self, t_us: float) -> float:
        """Board time at which the last valid RC frame before ``t_us`` was received (NaN if none).

        From ``RawRc`` (exact); when the board sent none, from the telemetry's ``rc_frames_ok``: then the
        time of the sample before the last increase (the earliest the frame can have come).
        """
        times = [t for t, f in self.rc if t < t_us and f.is_valid()]
        if times:
            return float(max(times))
        mask = self.t_us < t_us
        ok = self.rc_frames_ok[mask]
        inc = np.flatnonzero(np.diff(ok) > 0)
        return float(self.t_us[mask][inc[-1]]) if inc.size else math.nan

    def first_rc_at_or_after(self, t_us: float, right_lever: int) -> float | None:
        """Board time of the first valid RC frame at or after ``t_us`` with that right lever."""
        times = [t for t, f in self.rc if t >= t_us and f.is_valid() and f.right_lever == right_lever]
        return float(min(times)) if times else None

    def event_after(self, t_us: float, kind: EventKind, code: int) -> float:
        """Time from ``t_us`` to the first board event of that kind and code at or after it (NaN if none)."""
        times = [t for t, e in self.events if t >= t_us and e.kind == kind and e.code == code]
        return float(min(times) - t_us) if times and not math.isnan(t_us) else math.nan

    def last_sent_before(self, kind: type[Message], t_us: float) -> float:
        """Estimated board time of the last message of that type the host sent before ``t_us``."""
        times = [t for t, m in self.sent if isinstance(m, kind) and t < t_us]
        return float(max(times)) if times else math.nan


def _fault_window(plan: Plan, kind: FaultKind) -> tuple[int, int]:
    for f in plan.faults:
        if f.kind is kind:
            return f.start_us, f.end_us if f.end_us is not None else 1 << 62
    raise HilError(f"the plan has no {kind} fault")  # a catalogue change the port checks do not know


def _rearm_pull_us(plan: Plan) -> int:
    """When the stick pull resumes after re-arming (the radio script's last step)."""
    return plan.radio[-1][0]


RC_GAP_CHECK: Final = "largest unplanned gap between the RC frames the board received"
"""Name prefix of every run's validity check (see :func:`_rc_gap_check`)."""

_RC_CUTS = (FaultKind.RC_SILENCE, FaultKind.RC_GARBAGE, FaultKind.RC_OUT_OF_RANGE, FaultKind.LINK_DISCONNECT)


def _rc_gap_check(run: PortRun) -> Check:
    """The run's own validity: the RC stream reached the board without a gap the scenario did not plan.

    A longer gap than the RC timeout makes the board declare RC lost (and latch it), rightly: then the
    host or the link stalled (a pty's delivery waits for a normal-priority kernel worker), and the run
    says nothing about the checks that follow. Measured on the board's own receive times (``RawRc``, as
    the board sent them, before any emulated noise); from the host's send times when it sends none.
    """
    cuts = [
        (f.start_us, f.end_us if f.end_us is not None else 1 << 62)
        for f in run.plan.faults
        if f.kind in _RC_CUTS
    ]
    times = run.board_rc_us or run.rc_sent_us
    seen = [t for t in times if 0 <= t < run.duration_us]
    gaps = [b - a for a, b in itertools.pairwise(seen) if not any(a < e and b > s for s, e in cuts)]
    bound = (
        run.config.failsafe.rc_timeout_us
        if run.board_rc_us
        else run.config.failsafe.rc_timeout_us - LINK_ALLOWANCE_US
    )
    return Check(
        f"{RC_GAP_CHECK} (longer: the host or the link stalled; the run is void)",
        float(max(gaps, default=0)),
        bound,
        "<=",
        "us",
    )


def _rc_acted_us(run: PortRun) -> int:
    """Latest board time after the last valid frame at which the board must have cut the current."""
    return run.config.failsafe.rc_timeout_us + TICK_US + TICK_LATENESS_US


def _rc_zero_checks(run: PortRun, last: float) -> list[Check]:
    return [
        Check(
            "zero current after the last valid frame",
            run.zero_after(last),
            _rc_acted_us(run) + TELEMETRY_PERIOD_US,
            "<=",
            "us",
        ),
        Check(
            "RC_LOST reported after the last valid frame (board event)",
            run.event_after(last, EventKind.PHASE, Phase.RC_LOST),
            _rc_acted_us(run),
            "<=",
            "us",
        ),
    ]


# --- the checks of each scenario on a port --------------------------------------------------------


def _startup_gate(run: PortRun) -> list[Check]:
    # "Before the lever was seen DOWN": up to the board time of the first DOWN frame it received.
    down = run.first_rc_at_or_after(0, Lever.DOWN)
    end = down if down is not None else 600 * MS
    armed_from = max((t for t, f in run.plan.radio if f.right_lever == Lever.MIDDLE), default=0)
    return [
        Check("max |current| before the lever was seen DOWN", run.max_current(0, end), 0, "<=", "raw"),
        Check(
            "phase OK before the lever was seen DOWN",
            float(np.any(run.phase[run.window(0, end)] == Phase.OK)),
            0,
            "==",
        ),
        Check(
            "max |current| once armed (stick up)",
            run.max_current(armed_from + _AFTER_REARM_US),
            1,
            ">=",
            "raw",
        ),
    ]


def _manual_teleop(run: PortRun) -> list[Check]:
    cfg = run.config
    angles = np.radians(np.asarray(cfg.mapping.cable_angles_deg, dtype=np.float64))
    unit = np.stack([np.cos(angles), np.sin(angles)], axis=1)
    steps = list(run.plan.radio)
    checks: list[Check] = []
    curl: tuple[int, int] | None = None
    for i, (start, frame) in enumerate(steps):
        end = steps[i + 1][0] if i + 1 < len(steps) else run.duration_us
        ch0, ch1, _, ch3 = frame.channels
        if frame.right_lever != Lever.MIDDLE:
            continue
        if ch3 > 0:
            curl = (end - _STEP_TAIL_US, end)
        if not (ch0 or ch1):
            continue
        label = ", ".join(f"{k}={v:+d}" for k, v in (("ch0", ch0), ("ch1", ch1)) if v)
        mask = run.window(max(start, end - _STEP_TAIL_US), end)
        # The cables' moments: the sum of tension x cable direction; a common tension cancels out.
        resultant = (run.target_n[mask] @ unit).mean(axis=0) if mask.any() else np.full(2, np.nan)
        moved = float(np.hypot(*resultant))
        want = math.atan2(ch1, ch0)
        err = abs(math.remainder(math.atan2(resultant[1], resultant[0]) - want, 2 * math.pi))
        deflection = (math.hypot(ch0, ch1) - cfg.mapping.stick_deadband) / (660 - cfg.mapping.stick_deadband)
        asked = cfg.mapping.bend_max_n * min(1.0, deflection)
        checks.append(Check(f"bending tension with {label}", moved, asked / 2, ">=", "N"))
        checks.append(
            Check(f"bending tension direction error with {label}", math.degrees(err), 5, "<=", "deg")
        )
    if curl is not None:
        during = run.target_n[run.window(*curl)]
        checks.append(
            Check(
                "least target tension with the curl stick up",
                float(during.min()) if during.size else math.nan,
                2.0,
                ">=",
                "N",
            )
        )
    checks.append(
        Check(
            "largest target tension",
            float(run.target_n.max()) if run.n else math.nan,
            cfg.mapping.tension_max_n + _SETTLED_N,
            "<=",
            "N",
        )
    )
    checks.append(Check("largest |current|", run.max_current(0), run.limit_raw, "<=", "raw"))
    return checks


def _rc_loss(run: PortRun) -> list[Check]:
    start, end = _fault_window(run.plan, FaultKind.RC_SILENCE)
    last = run.last_valid_rc_before(end)  # no valid frame arrives during the silence
    rearm = run.first_rc_at_or_after(end, Lever.DOWN)
    return [
        Check("|current| before the loss", run.max_current(start - 500 * MS, start), 1, ">=", "raw"),
        *_rc_zero_checks(run, last),
        Check(
            "max |current| from 30 ms after the loss to re-arming",
            run.max_current(last + _rc_acted_us(run), rearm if rearm is not None else math.nan),
            0,
            "<=",
            "raw",
        ),
        Check(
            "|current| after re-arming",
            run.max_current(_rearm_pull_us(run.plan) + _AFTER_REARM_US),
            1,
            ">=",
            "raw",
        ),
    ]


def _rc_garbage(run: PortRun) -> list[Check]:
    start, end = _fault_window(run.plan, FaultKind.RC_GARBAGE)
    last = run.last_valid_rc_before(end)
    during = run.window(start, end)
    telemetry_changes = int(np.count_nonzero(np.diff(run.mode[during]) != 0))
    event_changes = sum(1 for t, e in run.events if start <= t < end and e.kind == EventKind.MODE)
    return [
        Check(
            "garbage frames rejected and counted",
            _counter_rise(run, run.rc_rejected, start, end),
            50,
            ">=",
            "frames",
        ),
        *_rc_zero_checks(run, last),
        Check(
            "max |current| while garbage arrives",
            run.max_current(last + _rc_acted_us(run), end),
            0,
            "<=",
            "raw",
        ),
        Check("mode changes during the garbage", float(max(telemetry_changes, event_changes)), 1, "<="),
    ]


def _rc_out_of_range(run: PortRun) -> list[Check]:
    start, end = _fault_window(run.plan, FaultKind.RC_OUT_OF_RANGE)
    before = run.window(start - 500 * MS, start)
    during = run.window(start, end)
    last = run.last_valid_rc_before(end)
    rise = (
        float(run.target_n[during].max() - run.target_n[before].max())
        if during.any() and before.any()
        else math.nan
    )
    return [
        Check(
            "out-of-range frames rejected and counted",
            _counter_rise(run, run.rc_rejected, start, end),
            60,
            ">=",
            "frames",
        ),
        Check(
            "largest target tension while they arrive (never above the last valid command)",
            rise,
            0.0,
            "<=",
            "N",
        ),
        *_rc_zero_checks(run, last),
    ]


def _counter_rise(run: PortRun, counter: npt.NDArray[np.int64], start_us: int, end_us: int) -> float:
    """How much a board counter rose from before ``start_us`` to shortly after ``end_us``."""
    before = counter[run.window(0, start_us)]
    after = counter[run.window(0, end_us + TELEMETRY_PERIOD_US)]
    if not before.size or not after.size:
        return math.nan
    return float(after.max() - before.max())


def _link_noise(run: PortRun) -> list[Check]:
    cfg = run.config
    lo, hi = cfg.mapping.pretension_n, cfg.mapping.tension_max_n
    sent = [
        tuple(min(hi, max(lo, v)) for v in m.args)
        for _, m in run.sent
        if isinstance(m, Command) and m.code == CommandCode.SET_TENSIONS
    ]
    sent.append((lo, lo, lo))  # the board's set-point before any SET_TENSIONS
    # A DIRECT sample whose targets did not move since the previous sample has finished slewing: its
    # targets are the set-point in force (float32 on the wire).
    applied: list[tuple[float, ...]] = []
    direct = run.mode == Mode.DIRECT
    for k in range(1, run.n):
        if direct[k] and direct[k - 1] and np.array_equal(run.target_n[k], run.target_n[k - 1]):
            point = tuple(float(x) for x in run.target_n[k])
            if not any(np.allclose(point, p, atol=_SETTLED_N, rtol=0) for p in applied):
                applied.append(point)
    foreign = [p for p in applied if not any(np.allclose(p, s, atol=_SETTLED_N, rtol=0) for s in sent)]
    # The lockstep counts what survives the noise in each 0.5 s; here the noise is drawn anew on every
    # run (the byte stream's timing is not repeatable), so the per-window minimum of a 27 % survival
    # rate would fail about one run in 75 for no fault of the board's. What the board sent is counted
    # per window, what got through on average.
    half_s = 500 * MS
    windows = range(0, run.duration_us, half_s)
    sent_t = np.asarray(run.board_telemetry_us, dtype=np.int64)
    per_window = [int(np.count_nonzero((sent_t >= t) & (sent_t < t + half_s))) for t in windows]
    delivered = run.count(0, run.duration_us) / max(1, len(windows))
    crc = run.link_crc_errors
    return [
        Check("direct-mode tension sets applied", float(len(applied)), 2, ">=", "sets"),
        Check("applied tension sets that the host never sent", float(len(foreign)), 0, "<=", "sets"),
        Check(
            "corrupted frames the board dropped (counted)",
            float(crc.max() - crc.min()) if crc.size else math.nan,
            1,
            ">=",
            "frames",
        ),
        Check(
            "fewest telemetry frames the board sent in any 0.5 s",
            float(min(per_window, default=0)),
            40,
            ">=",
            "frames",
        ),
        Check("telemetry frames delivered per 0.5 s through the noise", delivered, 5, ">=", "frames"),
        Check("host decode errors on delivered frames", float(run.decode_errors), 0, "<=", "frames"),
    ]


def _host_gone_common(run: PortRun, kind: FaultKind) -> tuple[int, int, float, list[Check]]:
    start, end = _fault_window(run.plan, kind)
    rearm = run.first_rc_at_or_after(end, Lever.DOWN)
    checks = [
        Check("|current| before the loss", run.max_current(start - 500 * MS, start), 1, ">=", "raw"),
    ]
    return start, end, rearm if rearm is not None else math.nan, checks


def _rearmed(run: PortRun) -> Check:
    return Check(
        "|current| after re-arming through SAFE",
        run.max_current(_rearm_pull_us(run.plan) + _AFTER_REARM_US),
        1,
        ">=",
        "raw",
    )


def _host_loss(run: PortRun) -> list[Check]:
    start, end, rearm, checks = _host_gone_common(run, FaultKind.HOST_LOSS)
    acted = run.config.failsafe.host_timeout_us + TICK_US + LINK_ALLOWANCE_US + TICK_LATENESS_US
    last_hb = run.last_sent_before(Heartbeat, start)
    lost = np.count_nonzero(run.phase[run.window(start, end)] == Phase.HOST_LOST)
    checks += [
        Check(
            "zero current after the last heartbeat",
            run.zero_after(last_hb),
            acted + TELEMETRY_PERIOD_US,
            "<=",
            "us",
        ),
        Check(
            "HOST_LOST reported after the last heartbeat (board event)",
            run.event_after(last_hb, EventKind.PHASE, Phase.HOST_LOST),
            acted,
            "<=",
            "us",
        ),
        Check(
            "max |current| from the timeout to re-arming (latched)",
            run.max_current(last_hb + acted, rearm),
            0,
            "<=",
            "raw",
        ),
        _rearmed(run),
        Check(
            "telemetry frames while heartbeats are missing", float(run.count(start, end)), 80, ">=", "frames"
        ),
        Check("telemetry frames reporting HOST_LOST", float(lost), 1, ">=", "frames"),
    ]
    return checks


def _link_disconnect(run: PortRun) -> list[Check]:
    # Nothing crosses an unplugged link, so the board cannot be watched while it is down: the checks
    # are what it reports once the link is back (still latched) and after re-arming.
    start, end, rearm, checks = _host_gone_common(run, FaultKind.LINK_DISCONNECT)
    back = next((t for t in run.reconnects_us if t >= start), math.nan)
    latched = run.window(back, rearm) if not math.isnan(back) and not math.isnan(rearm) else run.window(0, 0)
    checks += [
        Check(
            "max |current| after reconnecting, before re-arming (latched)",
            run.max_current(back, rearm),
            0,
            "<=",
            "raw",
        ),
        Check(
            "telemetry frames reporting OK after reconnecting, before re-arming",
            float(np.count_nonzero(run.phase[latched] == Phase.OK)) if latched.any() else math.nan,
            0,
            "<=",
            "frames",
        ),
        _rearmed(run),
        Check(
            "telemetry frames after reconnecting",
            float(run.count(end + 100 * MS)),
            100,
            ">=",
            "frames",
        ),
    ]
    return checks


def _overcurrent(run: PortRun) -> list[Check]:
    cfg = run.config
    asked = cfg.mapping.common_max_n * cfg.motor.spool_radius_m / cfg.motor.torque_constant_nm_per_a * 1000
    return [
        Check("current the mapping asks for", asked, run.limit_raw, ">=", "raw"),
        Check("largest |current| sent", run.max_current(0), run.limit_raw, "<=", "raw"),
        Check("the clamp engaged (largest |current| sent)", run.max_current(0), run.limit_raw, ">=", "raw"),
    ]


PORT_CHECKS: dict[str, Callable[[PortRun], list[Check]]] = {
    "startup-gate": _startup_gate,
    "manual-teleop": _manual_teleop,
    "rc-loss": _rc_loss,
    "rc-garbage": _rc_garbage,
    "rc-out-of-range": _rc_out_of_range,
    "link-noise": _link_noise,
    "link-disconnect": _link_disconnect,
    "host-loss": _host_loss,
    "overcurrent": _overcurrent,
}
"""The telemetry-based checks of every scenario that runs on a port (the rest are lockstep-only)."""


def port_scenario_names() -> list[str]:
    """The scenarios that can run on a port, in the order of the catalogue."""
    return [n for n in SCENARIOS if n in PORT_CHECKS and _lockstep_only_reason(n, ()) is None]


# --- what can run on a port -----------------------------------------------------------------------


def _plan_params(plan: Plan) -> dict[str, float]:
    """The runtime parameters the plan sets away from the defaults (wire name -> value)."""
    default = FirmwareConfig()
    return {
        name: plan.firmware.get_param(name)
        for name in PARAMS
        if plan.firmware.get_param(name) != default.get_param(name)
    }


def _lockstep_only_reason(name: str, faults: Sequence[Fault]) -> str | None:
    scenario = SCENARIOS[name]
    plan = scenario.plan()
    for f in plan.faults:
        if f.kind in BOARD_ONLY_FAULTS:
            return (
                f"scenario {name!r} needs fault {f.kind}, which only a lockstep run can inject "
                "(the board side injects it); run it without --port"
            )
    for f in faults:
        if f.kind in BOARD_ONLY_FAULTS:
            return f"fault {f.kind} can only be injected in a lockstep run (the board side injects it)"
    if name not in PORT_CHECKS or plan.objects or plan.start_packed:
        return (
            f"scenario {name!r} has no real-time checks (its checks need the simulated plant); "
            "run it without --port"
        )
    default = FirmwareConfig().to_dict()
    settable = set(PARAM_FIELDS.values())
    for key, value in plan.firmware.to_dict().items():
        if key not in settable and value != default[key]:
            return f"scenario {name!r} changes {key}, which a board takes only at start-up; use lockstep"
    return None


def check_port_run(name: str, faults: Sequence[Fault] = ()) -> None:
    """Raise unless ``name`` (with the extra ``faults``) can run on a port.

    Cheap: the CLI calls it for every name before the first run starts.

    Raises:
        KeyError: unknown scenario name.
        HilError: the scenario or a fault is lockstep-only (the message says which and why).
    """
    reason = _lockstep_only_reason(name, faults)
    if reason is not None:
        raise HilError(reason)


# --- the host's end of the link -------------------------------------------------------------------


def _open(port: str) -> SerialTransport:
    try:
        transport = SerialTransport(port)
    except PortError as exc:
        raise HilError(str(exc).splitlines()[0] if str(exc) else f"cannot open {port}") from exc
    with contextlib.suppress(Exception):  # stale bytes a pty kept while nobody listened
        transport.serial.reset_input_buffer()
    return transport


def _fileno(transport: SerialTransport) -> int | None:
    try:
        fd = int(transport.serial.fileno())
    except Exception:  # loop:// and friends: no descriptor, the host polls every tick instead
        return None
    return fd


class _Reader:
    """Reads the port on a thread of its own and queues what arrives with its receive time.

    Why a thread: on a pty, ``read`` and ``poll`` wait for the kernel's tty flush worker, a
    normal-priority kworker; on this shared machine a real-time host loop was measured waiting 20-80 ms
    in them, long enough to miss two RC frames (an RC loss the board rightly latches). Writes never wait
    for it, so the loop that sends RC and heartbeats on time never reads the port itself.
    """

    def __init__(self, transport: SerialTransport, clock: RealTimeClock) -> None:
        self.transport = transport
        self.clock = clock
        self.fd = _fileno(transport)
        self.queue: queue.SimpleQueue[tuple[int, bytes]] = queue.SimpleQueue()
        self.closed = False
        """The port reported end of file (the board closed the link)."""
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="board-link-reader", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        empty = 0
        while not self._stop.is_set():
            if self.fd is not None:
                try:
                    readable, _, _ = select.select([self.fd], [], [], _READER_POLL_S)
                except (OSError, ValueError):  # closed under us
                    return
                if not readable:
                    continue
            data = self.transport.read()
            if data:
                empty = 0
                self.queue.put((self.clock.now_us(), data))
                continue
            if self.fd is not None:  # readable but empty: end of file, or an error
                empty += 1
                if empty >= _EOF_READS:
                    self.closed = True
                    return
            self._stop.wait(LOOP_PERIOD_US / 1e6)

    def drain(self) -> list[tuple[int, bytes]]:
        """Everything received so far, oldest first."""
        out: list[tuple[int, bytes]] = []
        with contextlib.suppress(queue.Empty):
            while True:
                out.append(self.queue.get_nowait())
        return out

    def stop(self) -> None:
        """Stop and join the thread (safe twice)."""
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout=2.0)


class _Host:
    """The host's side of the board link on a port: scheduled RC and heartbeats, link faults, decoding.

    Times are the host's CLOCK_MONOTONIC in µs. Everything received is kept with the board times it
    carries; ``offset_us`` (host receive time minus board time, the smallest seen) maps host times to
    board times.
    """

    def __init__(self, port: str, clock: RealTimeClock, recorder: Recorder | None = None) -> None:
        self.port = port
        self.clock = clock
        self.recorder = recorder
        """Records the bytes on the link (board's view: ``link_rx`` what reached it after the emulated
        faults, ``link_tx`` what it sent before them) and the decoded telemetry, on the host's clock."""
        self.transport: SerialTransport | None = _open(port)
        self._reader: _Reader | None = _Reader(self.transport, clock)
        self.parser = LinkParser()
        self._clean_parser = LinkParser()
        self.board_telemetry_us: list[int] = []
        self.board_rc_us: list[int] = []
        self.faults: FaultSet | None = None
        self.t0_us = 0
        self.rc_at: Callable[[int], bytes | None] = lambda slot_us: None
        self.heartbeat_on: Callable[[int], bool] = lambda now_us: True
        self.commands: list[tuple[int, Message]] = []
        now = clock.now_us()
        self.next_rc_us = now
        self.next_hb_us = now
        self._seq = 0
        self._hb_count = 0
        self._pending = bytearray()
        self._down_since: int | None = None
        self.telemetry: list[Telemetry] = []
        self.raw_rc: list[RawRc] = []
        self.events: list[Event] = []
        self.acks: list[tuple[CommandAck, int]] = []  # with the telemetry count when it arrived
        self.params: dict[str, float] = {}
        self.param_log: list[str] = []
        self.param_count = 0
        self.decode_errors = 0
        self.sent: list[tuple[int, Message]] = []
        self.rc_sent_us: list[int] = []
        self.reconnects_us: list[int] = []
        self.offset_us: int | None = None
        self.counters: dict[str, int] = {}

    # --- sending ----------------------------------------------------------------------------------

    def _next_seq(self) -> int:
        seq = self._seq
        self._seq = (seq + 1) & 0xFF
        return seq

    def send(self, now_us: int, msg: Message) -> int:
        """Send a link message (through the link faults while a scenario runs); returns its seq."""
        seq = self._next_seq()
        frame = encode(msg, seq)
        self.sent.append((now_us, msg))
        if self.faults is None:
            self._write(frame)
        else:
            self._pending += frame
        return seq

    def send_rc(self, now_us: int, payload: bytes) -> None:
        """Send one ``VirtualRc`` frame (the radio's stand-in: outside the link faults)."""
        if self.transport is None:
            return
        self._write(encode(VirtualRc(payload), self._next_seq()))
        self.rc_sent_us.append(now_us)

    def _write(self, data: bytes) -> None:
        if self.transport is not None and data:
            self.transport.write(data)
            if self.recorder is not None:
                self.recorder.write_raw(recording.LINK_RX, self.clock.now_us(), data)

    # --- receiving --------------------------------------------------------------------------------

    def receive(self, now_us: int) -> None:
        """Take what the reader thread queued (each chunk with its receive time) and decode it.

        Raises:
            HilError: the board closed the link.
        """
        reader = self._reader
        chunks = reader.drain() if reader is not None else []
        if reader is not None and reader.closed and not chunks:
            raise HilError(f"the board closed the link on {self.port}")
        faults = self.faults
        for t_us, data in chunks:
            if self.recorder is not None:
                self.recorder.write_raw(recording.LINK_TX, t_us, data)
            if faults is not None:
                self._watch_board(data)
                data = faults.link_bytes(t_us - self.t0_us, data, "tx")
            if data:
                self._dispatch(t_us, self.parser.feed(data))
        if faults is not None:  # bytes a link-delay fault held back until now
            held = faults.link_bytes(now_us - self.t0_us, b"", "tx")
            if held:
                self._dispatch(now_us, self.parser.feed(held))

    def _watch_board(self, data: bytes) -> None:
        """What the board sent, before the emulated noise: did it keep sending, what RC did it get?"""
        for frame in self._clean_parser.feed(data):
            with contextlib.suppress(ValueError):
                if frame.cmd_id == Telemetry.CMD_ID:
                    self.board_telemetry_us.append(Telemetry.unpack(frame.payload).time_us)
                elif frame.cmd_id == RawRc.CMD_ID:
                    raw = RawRc.unpack(frame.payload)
                    if raw.frame.is_valid():
                        self.board_rc_us.append(raw.time_us)

    def _dispatch(self, now_us: int, frames: list[LinkFrame]) -> None:
        for frame in frames:
            try:
                msg = decode(frame)
            except ValueError:
                self.decode_errors += 1
                continue
            if isinstance(msg, Telemetry):
                self.telemetry.append(msg)
                if self.recorder is not None:
                    self.recorder.write_json(recording.TELEMETRY, now_us, telemetry_json(msg))
                lag = now_us - msg.time_us
                if self.offset_us is None or lag < self.offset_us:
                    self.offset_us = lag
            elif isinstance(msg, RawRc):
                self.raw_rc.append(msg)
            elif isinstance(msg, Event):
                self.events.append(msg)
            elif isinstance(msg, CommandAck):
                self.acks.append((msg, len(self.telemetry)))
            elif isinstance(msg, ParamValue):
                self.params[msg.name] = msg.value
                self.param_log.append(msg.name)
                self.param_count = msg.count

    def ack(self, seq: int, code: CommandCode) -> tuple[CommandAck, int] | None:
        """The board's answer to our command frame ``seq``, with the telemetry count when it came."""
        for ack, count in reversed(self.acks):
            if ack.request_seq == seq and ack.command == code:
                return ack, count
        return None

    # --- the loop ---------------------------------------------------------------------------------

    def tick(self, now_us: int) -> None:
        """One host period: connection per faults, receive, due RC / heartbeat / commands, flush."""
        self._connection(now_us)
        self.receive(now_us)
        if now_us >= self.next_rc_us:
            payload = self.rc_at(self.next_rc_us)
            if payload is not None:
                self.send_rc(now_us, payload)
            self.next_rc_us = _next_slot(self.next_rc_us, now_us, FRAME_PERIOD_US)
        if now_us >= self.next_hb_us:
            if self.heartbeat_on(now_us):
                self.send(now_us, Heartbeat(now_us, self._hb_count & 0xFFFF_FFFF))
                self._hb_count += 1
            self.next_hb_us = _next_slot(self.next_hb_us, now_us, HEARTBEAT_PERIOD_US)
        while self.commands and self.commands[0][0] <= now_us:
            self.send(now_us, self.commands.pop(0)[1])
        if self.faults is not None:
            data = bytes(self._pending)
            self._pending.clear()
            self._write(self.faults.link_bytes(now_us - self.t0_us, data, "rx"))

    def _connection(self, now_us: int) -> None:
        down = self.faults is not None and self.faults.link_down(now_us - self.t0_us)
        if down and self.transport is not None:
            self.close()
            self._down_since = now_us
        elif not down and self.transport is None:
            try:
                self.transport = _open(self.port)
            except HilError:
                since = self._down_since if self._down_since is not None else now_us
                if now_us - since > _REOPEN_TIMEOUT_US:
                    raise
                return
            self._reader = _Reader(self.transport, self.clock)
            self._down_since = None
            self.reconnects_us.append(now_us)

    def run_until(self, end_us: int, done: Callable[[], bool] | None = None) -> bool:
        """Tick every :data:`LOOP_PERIOD_US` until ``end_us`` or until ``done()``; True if done."""
        clock = self.clock
        start = clock.now_us()
        next_tick = start
        for _ in range(2 * max(0, end_us - start) // LOOP_PERIOD_US + 10):
            now = clock.now_us()
            if now >= end_us:
                return False
            self._note_max("loop_late_max_us", now - next_tick)
            self.tick(now)
            self._note_max("tick_exec_max_us", clock.now_us() - now)
            if done is not None and done():
                return True
            next_tick += LOOP_PERIOD_US
            if now - next_tick >= LOOP_PERIOD_US:  # late: skip the missed ticks, never burst
                next_tick = now + LOOP_PERIOD_US
            clock.sleep_until_us(min(next_tick, end_us))
        return False

    def _note_max(self, key: str, value: int) -> None:
        if self.faults is not None and value > self.counters.get(key, 0):  # only while a scenario runs
            self.counters[key] = value

    def start_scenario(self, t0_us: int, faults: FaultSet) -> None:
        """From ``t0_us`` on, scenario time runs and the link faults apply."""
        self.t0_us = t0_us
        self.faults = faults
        self.next_rc_us = self.next_hb_us = t0_us

    def stop_scenario(self) -> None:
        """No more faults or scripted commands (what the faults held back is dropped)."""
        self.faults = None
        self.commands.clear()
        self._pending.clear()

    def close(self) -> None:
        """Stop the reader and release the port (safe twice)."""
        if self._reader is not None:
            self._reader.stop()
            self._reader = None
        if self.transport is not None:
            self.transport.close()
            self.transport = None


def _next_slot(slot_us: int, now_us: int, period_us: int) -> int:
    """The next slot of the ``slot_us + k * period_us`` grid after ``now_us`` (missed slots skipped)."""
    return slot_us + ((now_us - slot_us) // period_us + 1) * period_us


# --- preparing the board, and leaving it safe -----------------------------------------------------


def _marker(right_lever: int) -> bytes:
    return RcFrame((0, 0, _MARKER_CH2, 0), int(right_lever), int(Lever.DOWN)).pack()


def _ours(msg: Telemetry, right_lever: int) -> bool:
    return msg.rc_channels[2] == _MARKER_CH2 and msg.right_lever == right_lever


def _float(value: float) -> float:
    """A float32 wire value as the decimal it was meant to be (3.3, not 3.2999999523)."""
    return float(f"{value:.7g}")


def _prepare(host: _Host, plan: Plan, originals: list[tuple[str, float]]) -> FirmwareConfig:
    """Bring the board to its boot state with our RC, apply the plan's parameters, re-arm the host.

    Args:
        host: the link.
        plan: the scenario's plan.
        originals: receives a (name, old value) pair for every parameter changed, as it is changed.

    Returns:
        The configuration in force.
    """
    clock = host.clock
    safe, middle = _marker(Lever.DOWN), _marker(Lever.MIDDLE)
    host.rc_at = lambda slot_us: safe
    host.heartbeat_on = lambda now_us: True
    begin = clock.now_us()
    disarm = host.send(begin, Command(CommandCode.DISARM))
    host.send(begin, ParamRequest(PARAM_LIST_ALL))
    last_try = begin
    cleared = False

    def at_gate() -> bool:
        nonlocal disarm, last_try, cleared
        now = clock.now_us()
        latest = host.telemetry[-1] if host.telemetry else None
        if latest is not None and latest.phase == Phase.ESTOP and not cleared:
            host.send(now, Command(CommandCode.CLEAR_ESTOP))
            cleared = True
        answer = host.ack(disarm, CommandCode.DISARM)
        if answer is None:
            if now - last_try > _RESEND_US:
                disarm = host.send(now, Command(CommandCode.DISARM))
                host.send(now, ParamRequest(PARAM_LIST_ALL))
                last_try = now
            return False
        fresh = host.telemetry[answer[1] :]
        return (
            bool(fresh)
            and _ours(fresh[-1], Lever.DOWN)
            and fresh[-1].phase == Phase.GATE
            and host.param_count > 0
            and len(host.params) >= host.param_count
        )

    if not host.run_until(begin + _PREAMBLE_TIMEOUT_US, at_gate):
        raise HilError(_why_not_ready(host))

    _set_params(host, list(_plan_params(plan).items()), originals)

    host.rc_at = lambda slot_us: middle  # the gate must see the lever DOWN again, as after boot
    start = clock.now_us()
    mark = len(host.telemetry)
    if not host.run_until(
        start + _REPLY_TIMEOUT_US,
        lambda: any(_ours(m, Lever.MIDDLE) and m.phase == Phase.GATE for m in host.telemetry[mark:]),
    ):
        raise HilError(f"the board on {host.port} did not take the lever MIDDLE while disarmed")
    arm = host.send(clock.now_us(), Command(CommandCode.ARM))
    if not host.run_until(
        clock.now_us() + _REPLY_TIMEOUT_US, lambda: host.ack(arm, CommandCode.ARM) is not None
    ):
        raise HilError(f"the board on {host.port} did not answer ARM")
    answer = host.ack(arm, CommandCode.ARM)
    if answer is not None and answer[0].result != AckResult.ACCEPTED:
        raise HilError(f"the board on {host.port} refused ARM: {answer[0].text or answer[0].result.name}")
    return _config(plan.firmware, host.params)


def _why_not_ready(host: _Host) -> str:
    port = host.port
    secs = _PREAMBLE_TIMEOUT_US / 1e6
    if not host.telemetry:
        return f"no telemetry from {port} within {secs:g} s: not a SpiRob board link, or no board running"
    latest = host.telemetry[-1]
    if latest.rc_channels[2] != _MARKER_CH2:
        return (
            f"the board on {port} ignores virtual RC from the link (its RC source is a radio?): "
            "scenarios on a port send the radio script over the link"
        )
    if latest.phase != Phase.GATE:
        return f"the board on {port} stays in {latest.phase.name} with the lever DOWN and the host disarmed"
    return f"the board on {port} did not answer DISARM or list its parameters within {secs:g} s"


def _set_param(host: _Host, name: str, value: float) -> bool:
    """Set one parameter; True if the board now holds ``value``.

    Raises:
        HilError: no answer.
    """
    clock = host.clock
    mark = len(host.param_log)
    host.send(clock.now_us(), ParamSet(name, value))
    if not host.run_until(clock.now_us() + _REPLY_TIMEOUT_US, lambda: name in host.param_log[mark:]):
        raise HilError(f"the board on {host.port} did not answer setting {name}")
    return _float(host.params.get(name, math.nan)) == _float(value)


def _set_params(host: _Host, values: Sequence[tuple[str, float]], changed: list[tuple[str, float]]) -> None:
    """Set several parameters, in as many passes as their relations need.

    The board validates each value against the others (``common_max_n <= tension_max_n``, ...), so a
    value refused now may be taken once another has changed. ``changed`` receives (name, old value)
    for each parameter set, as it is set.

    Raises:
        HilError: no answer, or a value the board keeps refusing.
    """
    todo = [(n, v) for n, v in values if _float(host.params.get(n, math.nan)) != _float(v)]
    while todo:  # every pass takes at least one value or stops: at most len(values) passes
        refused: list[tuple[str, float]] = []
        for name, value in todo:
            old = _float(host.params.get(name, math.nan))
            if _set_param(host, name, value):
                changed.append((name, old))
            else:
                refused.append((name, value))
        if len(refused) == len(todo):
            name, value = refused[0]
            got = host.params.get(name, math.nan)
            raise HilError(f"the board on {host.port} refused {name} = {value:g} (keeps {got:g})")
        todo = refused


def _config(plan_config: FirmwareConfig, params: dict[str, float]) -> FirmwareConfig:
    """The plan's configuration with the board's parameter values (calibration is the board's)."""
    changes: dict[str, Any] = {}
    current = plan_config.to_dict()
    for name, value in params.items():
        fname = PARAM_FIELDS.get(name)
        if fname is None:
            continue
        default = current[fname]
        if isinstance(default, bool):
            changes[fname] = value != 0.0
        elif isinstance(default, int):
            changes[fname] = round(value)
        else:
            changes[fname] = _float(value)
    try:
        return plan_config.replaced(**changes)
    except ConfigError as exc:
        raise HilError(f"the board reports an inconsistent configuration: {exc}") from exc


def _finish(host: _Host, originals: list[tuple[str, float]]) -> None:
    """Leave the board as found: SAFE frames (zero current), the changed parameters restored.

    Best effort (the board may be gone): failures are logged and counted, never raised, so they do not
    hide why a run stopped.
    """
    clock = host.clock
    host.stop_scenario()
    safe = _marker(Lever.DOWN)
    host.rc_at = lambda slot_us: safe
    host.heartbeat_on = lambda now_us: True
    try:
        host.run_until(clock.now_us() + _FINISH_SAFE_US)
    except HilError as exc:
        _log.warning("could not leave the board in SAFE: %s", exc)
        host.counters["finish_failed"] = 1
        return
    try:
        _set_params(host, originals[::-1], [])
    except HilError as exc:
        _log.warning("could not restore the board's parameters: %s", exc)
        host.counters["params_not_restored"] = 1


# --- the scenario in real time --------------------------------------------------------------------


def _active(faults: Sequence[Fault], kind: FaultKind, t_us: int) -> bool:
    return any(f.kind is kind and f.active(t_us) for f in faults)


def _radio(host: _Host, plan: Plan, faults: FaultSet, t0_us: int) -> Callable[[int], bytes | None]:
    """What the emulated radio sends at each 14 ms slot (host time), RC faults applied."""
    script = RadioScript(plan.radio)
    kinds = faults.faults

    def at(slot_us: int) -> bytes | None:
        s = slot_us - t0_us
        frame = script.at(s)
        if frame is None:
            return None
        if _active(kinds, FaultKind.RC_GARBAGE, s) and not _active(kinds, FaultKind.RC_SILENCE, s):
            host.counters["rc_garbage_frames"] = host.counters.get("rc_garbage_frames", 0) + 1
            data = faults.rng.integers(0, 256, FRAME_LEN, dtype=np.uint8)
            data[5] &= 0x0F  # both levers 0: never a valid frame, whatever the channels say
            return data.tobytes()
        sent = faults.rc_override(s, frame)
        return sent.pack() if isinstance(sent, RcFrame) else None

    return at


def _record(host: _Host, plan: Plan, config: FirmwareConfig, t0_us: int, duration_us: int) -> PortRun:
    """The run as the checks see it: board times relative to the scenario's start."""
    if host.offset_us is None:
        raise HilError(f"no telemetry from {host.port} during the run")
    board_t0 = t0_us - host.offset_us  # the board's clock when the scenario started

    def rel(t_us: int) -> int:
        return t_us - board_t0

    tel = [m for m in host.telemetry if 0 <= rel(m.time_us) < duration_us]
    tel.sort(key=lambda m: m.time_us)
    n = len(tel)

    def ints(get: Callable[[Telemetry], Any], width: int = 0) -> npt.NDArray[np.int64]:
        shape = (n, width) if width else (n,)
        return np.array([get(m) for m in tel], dtype=np.int64).reshape(shape)

    return PortRun(
        plan=plan,
        config=config,
        duration_us=duration_us,
        t_us=ints(lambda m: rel(m.time_us)),
        current_raw=ints(lambda m: m.commanded_current, 3),
        target_n=np.array([m.tension_target_n for m in tel], dtype=np.float64).reshape(n, 3),
        phase=ints(lambda m: int(m.phase)),
        mode=ints(lambda m: int(m.mode)),
        rc_frames_ok=ints(lambda m: m.rc_frames_ok),
        rc_rejected=ints(lambda m: m.rc_rejected),
        link_crc_errors=ints(lambda m: m.link_crc_errors),
        rc=[(rel(m.time_us), m.frame) for m in host.raw_rc if 0 <= rel(m.time_us) < duration_us],
        events=[(rel(e.time_us), e) for e in host.events],
        sent=[(t - t0_us, m) for t, m in host.sent if t >= t0_us],
        rc_sent_us=[t - t0_us for t in host.rc_sent_us if t >= t0_us],
        reconnects_us=[t - t0_us for t in host.reconnects_us if t >= t0_us],
        decode_errors=host.decode_errors,
        telemetry=tel,
        board_telemetry_us=[rel(t) for t in host.board_telemetry_us],
        board_rc_us=[rel(t) for t in host.board_rc_us],
    )


def _counters(host: _Host, run: PortRun, faults: FaultSet) -> dict[str, int]:
    out: dict[str, int] = {}
    if run.telemetry:
        last = run.telemetry[-1]
        for name in (
            "rc_frames_ok",
            "rc_rejected",
            "dbus_bytes_dropped",
            "link_frames_ok",
            "link_crc_errors",
            "motor_offline_events",
            "can_errors",
            "control_late",
        ):
            out[name] = int(getattr(last, name))
        out["control_late_during_run"] = int(last.control_late - run.telemetry[0].control_late)
    parser = host.parser
    rc_sent = sum(1 for t in run.rc_sent_us if t < run.duration_us)
    out.update(
        {
            "host_frames_sent": sum(1 for t, _ in run.sent if t < run.duration_us) + rc_sent,
            "host_rc_frames_sent": rc_sent,
            "host_telemetry_received": run.n,
            "host_decode_errors": host.decode_errors,
            "host_crc_errors": parser.header_crc_errors + parser.body_crc_errors,
            "host_bytes_skipped": parser.bytes_skipped,
        }
    )
    out.update({f"host_{k}": v for k, v in host.counters.items()})
    out.update({f"injected_{k}": v for k, v in faults.injected.items()})
    return out


def _play(
    host: _Host,
    plan: Plan,
    faults: FaultSet,
    duration_us: int,
    progress: Callable[[int, int], None] | None,
) -> int:
    """Play the scenario from now for its duration plus :data:`SETTLE_US`; returns its start (host time)."""
    clock = host.clock
    t0 = clock.now_us()
    host.start_scenario(t0, faults)
    host.rc_at = _radio(host, plan, faults, t0)
    host.heartbeat_on = lambda now_us: not faults.heartbeat_blocked(now_us - t0)
    host.commands = sorted(((t0 + t, m) for t, m in plan.host), key=lambda item: item[0])
    total_ms = duration_us // 1000
    shown = 0

    def report() -> bool:
        nonlocal shown
        done_ms = min(duration_us, clock.now_us() - t0) // 1000
        if progress is not None and done_ms >= shown + 100:
            shown = done_ms - done_ms % 100
            progress(shown, total_ms)
        return False

    host.run_until(t0 + duration_us + SETTLE_US, report)
    if progress is not None:
        progress(total_ms, total_ms)
    return t0


def run_scenario_on_port(
    name: str,
    port: str,
    *,
    seed: int = 0,
    faults: Sequence[Fault] = (),
    progress: Callable[[int, int], None] | None = None,
    record: str | Path | None = None,
) -> ScenarioResult:
    """Run one scenario against the board on ``port`` in real time and measure its checks.

    The host's part of the scenario (radio script as ``VirtualRc``, heartbeats, commands, faults) is
    played on the host's clock; every check is measured on the board's clock from its telemetry, RC
    echo and events. The run lasts the scenario's duration plus :data:`SETTLE_US`, plus about half a
    second to prepare the board and to leave it in SAFE with its parameters restored.

    Args:
        name: a name from :data:`hil.scenarios.SCENARIOS` that is in :data:`PORT_CHECKS`.
        port: a device path, pty path or pyserial URL (``socket://127.0.0.1:PORT``, ...).
        seed: seed of the run's random choices (link noise, garbage frames, out-of-range channels).
        faults: faults added to the scenario's own (the host-side kinds only).
        progress: called as ``progress(ms_done, ms_total)`` every 100 ms of the scenario.
        record: write an MCAP recording of the run there: the link's bytes both ways and the decoded
            telemetry, on the host's clock (what a host can see of a board; it cannot be replayed).

    Returns:
        The result, with the same shape as a lockstep run's (checks, counters).

    Raises:
        KeyError: unknown scenario name.
        HilError: the scenario or a fault cannot run on a port, the port cannot be opened (missing,
            busy), or the board does not answer as a SpiRob board (one-line message).
    """
    check_port_run(name, faults)
    scenario = SCENARIOS[name]
    plan = scenario.plan()
    plan = dataclasses.replace(plan, faults=(*plan.faults, *faults))
    fault_set = FaultSet(plan.faults, np.random.default_rng(seed))
    duration = scenario.duration_us
    clock = RealTimeClock(fifo=True, fifo_priority=_HOST_FIFO_PRIORITY, spin_us=0)
    originals: list[tuple[str, float]] = []
    # Everything inside: the reader thread inherits the loop's priority, so it is never preempted by
    # ordinary processes while it holds the GIL the loop waits for.
    recorder = None
    if record is not None:
        meta = {
            "kind": recording.KIND_PORT,
            "scenario": name,
            "port": port,
            "seed": str(seed),
            "faults": ";".join(repr(f) for f in plan.faults),
        }
        recorder = Recorder(record, metadata=meta)
    with clock.running():
        try:
            host = _Host(port, clock, recorder)
            try:
                try:
                    config = _prepare(host, plan, originals)
                    t0 = _play(host, plan, fault_set, duration, progress)
                finally:
                    _finish(host, originals)
            finally:
                host.close()
        finally:
            if recorder is not None:
                recorder.close()
    run = _record(host, plan, config, t0, duration)
    checks = [*PORT_CHECKS[name](run), _rc_gap_check(run)]
    return ScenarioResult(name, seed, tuple(checks), duration, _counters(host, run, fault_set))
