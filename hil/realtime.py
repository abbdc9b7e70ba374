"""Scenarios against a board-link endpoint in real time: ``spirob-hil run NAME... --port PORT``.

:func:`run_scenario_on_port` plays the host's part of a lockstep scenario (:mod:`hil.scenarios`) over a
real port (``/dev/ttyACM0``, a pty path, ``socket://...``, any pyserial URL) against a real C-board or
``spirob-hil board``, and judges the board with the scenario's own checks, the ones a lockstep run uses:
the :class:`~hil.run_record.RunRecord` they read is filled here from what the board reports, its ``Telemetry``
(100 Hz: board time, commanded currents, phase, mode, tension targets, counters), ``RawRc`` (every RC frame
it received, with its board time) and ``Event`` messages. There is no plant to look at (a real board has
none), so the checks that need one are left out, and every time is measured on the board's clock. The
host's end of the link is :class:`hil.port_host.PortHost`, a shell around ``protocol.session.HostSession``.

What the host sends (docs/board-link.md):

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

import dataclasses
import logging
import math
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, Final

import numpy as np

from controller.clock import RealTimeClock
from controller.config import FirmwareConfig
from controller.errors import ConfigError
from controller.params import PARAM_FIELDS, PARAMS
from hil import recording
from hil.errors import HilError
from hil.faults import Fault, FaultKind, FaultSet
from hil.port_host import PortHost
from hil.radio import RadioScript
from hil.recording import Recorder
from hil.run_record import RunRecord, Samples, ScenarioResult
from hil.scenarios import SCENARIOS, Plan, judge, largest_unplanned_gap_us
from protocol.dbus import FRAME_LEN, Lever, RcFrame
from protocol.messages import (
    AckResult,
    CommandCode,
    Phase,
    Telemetry,
)

__all__ = [
    "BOARD_ONLY_FAULTS",
    "LINK_ALLOWANCE_US",
    "SETTLE_US",
    "TELEMETRY_PERIOD_US",
    "TICK_LATENESS_US",
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
_FINISH_SAFE_US = 150_000
_HOST_FIFO_PRIORITY = 30  # below the virtual board's 50: a board on the same machine keeps its deadlines
_MARKER_CH2 = 321  # left horizontal stick: no mode reads it; seeing it in telemetry proves our RC rules


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
    plan = scenario().plan()
    for f in plan.faults:
        if f.kind in BOARD_ONLY_FAULTS:
            return (
                f"scenario {name!r} needs fault {f.kind}, which only a lockstep run can inject "
                "(the board side injects it); run it without --port"
            )
    for f in faults:
        if f.kind in BOARD_ONLY_FAULTS:
            return f"fault {f.kind} can only be injected in a lockstep run (the board side injects it)"
    if scenario.needs_plant or plan.objects or plan.start_packed:
        return f"scenario {name!r} needs the simulated plant (its scene or its checks); run it without --port"
    default = FirmwareConfig().to_dict()
    settable = set(PARAM_FIELDS.values())
    for key, value in plan.firmware.to_dict().items():
        if key not in settable and value != default[key]:
            return f"scenario {name!r} changes {key}, which a board takes only at start-up; use lockstep"
    return None


def port_scenario_names() -> list[str]:
    """The scenarios that can run on a port, in the order of the catalogue."""
    return [n for n in SCENARIOS if _lockstep_only_reason(n, ()) is None]


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


# --- preparing the board, and leaving it safe -----------------------------------------------------


def _marker(right_lever: int) -> bytes:
    return RcFrame((0, 0, _MARKER_CH2, 0), int(right_lever), int(Lever.DOWN)).pack()


def _ours(msg: Telemetry, right_lever: int) -> bool:
    return msg.rc_channels[2] == _MARKER_CH2 and msg.right_lever == right_lever


def _float(value: float) -> float:
    """A float32 wire value as the decimal it was meant to be (3.3, not 3.2999999523)."""
    return float(f"{value:.7g}")


def _prepare(host: PortHost, plan: Plan, originals: list[tuple[str, float]]) -> FirmwareConfig:
    """Bring the board to its boot state with our RC, apply the plan's parameters, re-arm the host.

    Args:
        host: the link.
        plan: the scenario's plan.
        originals: receives a (name, old value) pair for every parameter changed, as it is changed.

    Returns:
        The configuration in force.
    """
    clock, session = host.clock, host.session
    safe, middle = _marker(Lever.DOWN), _marker(Lever.MIDDLE)
    session.rc_source = None
    session.set_rc(safe)
    session.heartbeat_allowed = None
    begin = clock.now_us()
    disarm = session.command(CommandCode.DISARM, now_us=begin)
    session.request_params(begin)
    last_try = begin
    cleared = False
    answered_at = 0  # telemetry received when DISARM's ack was first seen: only later frames count

    def at_gate() -> bool:
        nonlocal disarm, last_try, cleared, answered_at
        now = clock.now_us()
        latest = session.last_telemetry
        if latest is not None and latest.phase == Phase.ESTOP and not cleared:
            session.command(CommandCode.CLEAR_ESTOP, now_us=now)
            cleared = True
        if session.ack(disarm) is None:
            if now - last_try > _RESEND_US:
                disarm = session.command(CommandCode.DISARM, now_us=now)
                session.request_params(now)
                last_try = now
            answered_at = len(host.telemetry)
            return False
        fresh = host.telemetry[answered_at:]
        return (
            bool(fresh)
            and _ours(fresh[-1], Lever.DOWN)
            and fresh[-1].phase == Phase.GATE
            and session.param_count > 0
            and len(session.params) >= session.param_count
        )

    if not host.run_until(begin + _PREAMBLE_TIMEOUT_US, at_gate):
        raise HilError(_why_not_ready(host))

    _set_params(host, list(_plan_params(plan).items()), originals)

    session.set_rc(middle)  # the gate must see the lever DOWN again, as after boot
    start = clock.now_us()
    mark = len(host.telemetry)
    if not host.run_until(
        start + _REPLY_TIMEOUT_US,
        lambda: any(_ours(m, Lever.MIDDLE) and m.phase == Phase.GATE for m in host.telemetry[mark:]),
    ):
        raise HilError(f"the board on {host.port} did not take the lever MIDDLE while disarmed")
    arm = session.command(CommandCode.ARM, now_us=clock.now_us())
    if not host.run_until(clock.now_us() + _REPLY_TIMEOUT_US, lambda: session.ack(arm) is not None):
        raise HilError(f"the board on {host.port} did not answer ARM")
    answer = session.ack(arm)
    if answer is not None and answer.result != AckResult.ACCEPTED:
        raise HilError(f"the board on {host.port} refused ARM: {answer.text or answer.result.name}")
    return _config(plan.firmware, session.params)


def _why_not_ready(host: PortHost) -> str:
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


def _set_param(host: PortHost, name: str, value: float) -> bool:
    """Set one parameter; True if the board now holds ``value``.

    Raises:
        HilError: no answer.
    """
    clock, session = host.clock, host.session
    mark = session.param_mark()
    session.set_param(name, value, clock.now_us())
    if not host.run_until(clock.now_us() + _REPLY_TIMEOUT_US, lambda: name in session.answered_since(mark)):
        raise HilError(f"the board on {host.port} did not answer setting {name}")
    return _float(session.params.get(name, math.nan)) == _float(value)


def _set_params(
    host: PortHost, values: Sequence[tuple[str, float]], changed: list[tuple[str, float]]
) -> None:
    """Set several parameters, in as many passes as their relations need.

    The board validates each value against the others (``common_max_n <= tension_max_n``, ...), so a
    value refused now may be taken once another has changed. ``changed`` receives (name, old value)
    for each parameter set, as it is set.

    Raises:
        HilError: no answer, or a value the board keeps refusing.
    """
    todo = [(n, v) for n, v in values if _float(host.session.params.get(n, math.nan)) != _float(v)]
    while todo:  # every pass takes at least one value or stops: at most len(values) passes
        refused: list[tuple[str, float]] = []
        for name, value in todo:
            old = _float(host.session.params.get(name, math.nan))
            if _set_param(host, name, value):
                changed.append((name, old))
            else:
                refused.append((name, value))
        if len(refused) == len(todo):
            name, value = refused[0]
            got = host.session.params.get(name, math.nan)
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


def _finish(host: PortHost, originals: list[tuple[str, float]]) -> None:
    """Leave the board as found: SAFE frames (zero current), the changed parameters restored.

    Best effort (the board may be gone): failures are logged and counted, never raised, so they do not
    hide why a run stopped.
    """
    clock = host.clock
    host.stop_scenario()
    safe = _marker(Lever.DOWN)
    host.session.rc_source = None
    host.session.set_rc(safe)
    host.session.heartbeat_allowed = None
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


def _radio(host: PortHost, plan: Plan, faults: FaultSet, t0_us: int) -> Callable[[int], bytes | None]:
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


def _record(host: PortHost, plan: Plan, config: FirmwareConfig, t0_us: int, duration_us: int) -> RunRecord:
    """The run as the checks see it: board times relative to the scenario's start."""
    if host.offset_us is None:
        raise HilError(f"no telemetry from {host.port} during the run")
    board_t0 = t0_us - host.offset_us  # the board's clock when the scenario started

    def rel(t_us: int) -> int:
        return t_us - board_t0

    tel = sorted((m for m in host.telemetry if 0 <= rel(m.time_us) < duration_us), key=lambda m: m.time_us)
    return RunRecord(
        config=config,
        duration_us=duration_us,
        samples=Samples.from_telemetry(tel, board_t0),
        resolution_us=config.telemetry_period_us,
        lateness_us=TICK_LATENESS_US,
        link_delay_us=LINK_ALLOWANCE_US,
        samples_through_link=True,
        rc=[(rel(t), frame) for t, frame in host.board_rc if 0 <= rel(t) < duration_us],
        events=[(rel(e.time_us), e) for e in host.board_events],
        telemetry_sent_us=[rel(t) for t in host.board_telemetry_us],
        telemetry_received_us=[rel(m.time_us) for m in tel],
        sent=[(t - t0_us, m) for t, m in host.session.sent if t >= t0_us],
        rc_sent_us=[t - t0_us for t in host.rc_sent_us if t >= t0_us],
        reconnects_us=[t - t0_us for t in host.reconnects_us if t >= t0_us],
        decode_errors=host.session.stream.decode_errors,
    )


def _counters(host: PortHost, run: RunRecord, plan: Plan, faults: FaultSet) -> dict[str, int]:
    out: dict[str, int] = {}
    # The host's own sender, outside the board: its largest unplanned gap tells a stalled host from a
    # stalled board when the board's RC gap check fails.
    send_gap = largest_unplanned_gap_us(run.rc_sent_us, plan, run.duration_us)
    if send_gap is not None:
        out["host_rc_send_gap_max_us"] = send_gap
    if host.telemetry:
        last = host.telemetry[-1]
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
        out["control_late_during_run"] = int(last.control_late - host.telemetry[0].control_late)
    stream = host.session.stream
    rc_sent = sum(1 for t in run.rc_sent_us if t < run.duration_us)
    out.update(
        {
            "host_frames_sent": sum(1 for t, _ in run.sent if t < run.duration_us) + rc_sent,
            "host_rc_frames_sent": rc_sent,
            "host_telemetry_received": run.n,
            "host_decode_errors": stream.decode_errors,
            "host_crc_errors": stream.crc_errors,
            "host_bytes_skipped": stream.bytes_skipped,
        }
    )
    out.update({f"host_{k}": v for k, v in host.counters.items()})
    out.update({f"injected_{k}": v for k, v in faults.injected.items()})
    return out


def _play(
    host: PortHost,
    plan: Plan,
    faults: FaultSet,
    duration_us: int,
    progress: Callable[[int, int], None] | None,
) -> int:
    """Play the scenario from now for its duration plus :data:`SETTLE_US`; returns its start (host time)."""
    clock = host.clock
    t0 = clock.now_us()
    host.start_scenario(t0, faults)
    host.session.rc_source = _radio(host, plan, faults, t0)
    host.session.heartbeat_allowed = lambda now_us: not faults.heartbeat_blocked(now_us - t0)
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
        name: a name from :data:`hil.scenarios.SCENARIOS` that can run on a port (:func:`check_port_run`).
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
    scenario = SCENARIOS[name]()
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
            host = PortHost(port, clock, recorder)
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
    return ScenarioResult(
        name, seed, judge(scenario, run, plan), duration, _counters(host, run, plan, fault_set)
    )
