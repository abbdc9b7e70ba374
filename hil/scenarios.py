"""Scenarios: scripted runs of the virtual board in lockstep, each with measured checks.

A scenario is data: a radio script, a host script, faults, a duration, and a check function that turns
the run's probe into :class:`Check` values (measured value, bound, pass/fail), all in simulated time.
:func:`run_scenario` is a pure function of (scenario name, design, seed, extra faults): picklable inputs,
picklable :class:`ScenarioResult` out, no global state, so campaigns can fan out over a process pool or
a distributed engine unchanged.

Timing conventions the checks rely on (DESIGN.md sections 2-3): a control tick every 1 ms; the radio
sends a frame every 14 ms; RC is lost 30 ms after the last valid frame; a motor is offline 10 ms after
its last feedback; the host is lost 500 ms after its last heartbeat. "Zero current within X" is measured
from the last input that kept the board alive to the first tick whose command to the ESCs is zero, and
the bound is X plus one tick.
"""

from __future__ import annotations

import dataclasses
import enum
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from controller.config import CONTROL_PERIOD_US, FailsafeConfig, FirmwareConfig, MappingConfig
from controller.rc import DbusSerialSource
from protocol.dbus import Lever, RcFrame
from protocol.messages import Command, CommandCode, Mode, Phase, Telemetry

from . import recording
from .board import BoardConfig, VirtualBoard
from .faults import Fault, FaultKind
from .harness import Probe, ScriptedHost
from .mjcf import ObjectConfig
from .plant import PlantConfig
from .radio import RadioScript
from .recording import Recorder
from .spiral import SpiralDesign

TICK_US = CONTROL_PERIOD_US
MS = 1000
S = 1_000_000


def rc(
    right: int = Lever.DOWN, left: int = Lever.DOWN, *, ch0: int = 0, ch1: int = 0, ch3: int = 0
) -> RcFrame:
    """A radio frame: levers and the sticks the scenarios use (ch2, left horizontal, is unused)."""
    return RcFrame((ch0, ch1, 0, ch3), int(right), int(left))


SAFE = rc()
MANUAL = rc(Lever.MIDDLE)


@dataclass(frozen=True, slots=True)
class Check:
    """One measured check: ``value <op> bound``."""

    name: str
    value: float
    bound: float
    op: str
    unit: str = ""

    @property
    def passed(self) -> bool:
        """The check holds (a NaN value never passes)."""
        v, b = self.value, self.bound
        if math.isnan(v):
            return False
        return {"<=": v <= b, ">=": v >= b, "==": v == b}[self.op]

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        return {
            "name": self.name,
            "value": self.value,
            "bound": self.bound,
            "op": self.op,
            "unit": self.unit,
            "passed": self.passed,
        }


@dataclass(frozen=True)
class ScenarioResult:
    """What a scenario run measured (picklable)."""

    name: str
    seed: int
    checks: tuple[Check, ...]
    duration_us: int
    counters: dict[str, int] = field(default_factory=dict)

    @property
    def passed(self) -> bool:
        """Every check holds."""
        return all(c.passed for c in self.checks)

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        return {
            "name": self.name,
            "seed": self.seed,
            "passed": self.passed,
            "duration_s": self.duration_us / S,
            "checks": [c.as_dict() for c in self.checks],
            "counters": self.counters,
        }


@dataclass
class Run:
    """Everything a check function may look at after the run."""

    board: VirtualBoard
    host: ScriptedHost
    probe: Probe
    extra: dict[str, Any] = field(default_factory=dict)

    @property
    def config(self) -> FirmwareConfig:
        """The firmware configuration the run used."""
        return self.board.config.firmware

    @property
    def limit_raw(self) -> int:
        """The firmware's current limit in raw units."""
        return self.config.motor.current_limit_raw

    def max_current(self, start_us: int, end_us: int | None = None) -> float:
        """Largest |current| sent to any ESC on ``start_us <= t < end_us`` (0 for an empty window)."""
        mask = self.probe.window(start_us, end_us)
        cur = self.probe.abs_current()[mask]
        return float(cur.max()) if cur.size else 0.0

    def zero_after(self, t_us: int) -> float:
        """Time from ``t_us`` to the first tick at or after it with zero current on every motor [us]."""
        mask = self.probe.window(t_us) & (self.probe.abs_current() == 0)
        first = self.probe.first_time(mask)
        return math.nan if first is None else float(first - t_us)


Setup = Callable[[], "Plan"]


@dataclass(frozen=True)
class Plan:
    """How a scenario runs: the radio, the host, the faults, the board's configuration."""

    radio: Sequence[tuple[int, RcFrame]]
    faults: Sequence[Fault] = ()
    host: Sequence[tuple[int, Command]] = ()
    heartbeats: bool = True
    firmware: FirmwareConfig = field(default_factory=FirmwareConfig)
    objects: tuple[ObjectConfig, ...] = ()
    start_packed: bool = False
    on_tick: Callable[[Run], None] | None = None


@dataclass(frozen=True)
class Scenario:
    """A named scenario: a one-line summary, how long it runs, its plan and its checks."""

    name: str
    summary: str
    duration_us: int
    plan: Callable[[], Plan]
    check: Callable[[Run], list[Check]]


# --- helpers for the checks -----------------------------------------------------------------------


def _last_rc_before(run: Run, t_us: int) -> int:
    """Board time at which the last valid RC frame before ``t_us`` was accepted."""
    return _last_increment_before(run.extra["rc_ok"], run.probe, t_us)


def _last_increment_before(counter: np.ndarray[Any, Any], probe: Probe, t_us: int) -> int:
    n = probe.n
    t = probe.t_us[:n]
    inc = np.flatnonzero((np.diff(counter[:n], prepend=counter[0]) > 0) & (t < t_us))
    return int(t[inc[-1]]) if inc.size else 0


def _arm(t_manual: int = 200 * MS, **sticks: int) -> list[tuple[int, RcFrame]]:
    """DOWN from the start (passes the gate), then MIDDLE with the given sticks."""
    return [(0, SAFE), (t_manual, rc(Lever.MIDDLE, **sticks))]


# --- the scenarios --------------------------------------------------------------------------------


def _startup_gate_plan() -> Plan:
    # The pilot tries to drive before arming: valid frames, lever MIDDLE, stick up; then arms.
    return Plan(
        radio=[
            (100 * MS, MANUAL),
            (150 * MS, rc(Lever.MIDDLE, ch3=600)),
            (600 * MS, SAFE),
            (800 * MS, rc(Lever.MIDDLE, ch3=600)),
        ]
    )


def _startup_gate_check(run: Run) -> list[Check]:
    return [
        Check("max |current| before the lever was seen DOWN", run.max_current(0, 600 * MS), 0, "<=", "raw"),
        Check(
            "phase OK before the lever was seen DOWN",
            float(np.any(run.probe.phase[run.probe.window(0, 600 * MS)] == Phase.OK)),
            0,
            "==",
        ),
        Check("max |current| once armed (stick up)", run.max_current(1000 * MS), 1, ">=", "raw"),
    ]


_TELEOP_STEPS = (
    # start, end, sticks, expected tip direction in the xy plane (radians) or None
    (500 * MS, 1500 * MS, {"ch0": 600}, 0.0),
    (2500 * MS, 3500 * MS, {"ch0": -600}, math.pi),
    (4500 * MS, 5500 * MS, {"ch1": 600}, math.pi / 2),
)


def _manual_teleop_plan() -> Plan:
    radio: list[tuple[int, RcFrame]] = [(0, SAFE), (200 * MS, MANUAL)]
    for start, end, sticks, _ in _TELEOP_STEPS:
        radio += [(start, rc(Lever.MIDDLE, **sticks)), (end, MANUAL)]
    radio += [(6500 * MS, rc(Lever.MIDDLE, ch3=660)), (7500 * MS, MANUAL)]
    return Plan(radio=radio)


def _manual_teleop_check(run: Run) -> list[Check]:
    p = run.probe
    checks: list[Check] = []
    for start, end, sticks, direction in _TELEOP_STEPS:
        i0 = int(np.flatnonzero(p.window(start))[0])
        i1 = int(np.flatnonzero(p.window(end))[0])
        d = p.tip_m[i1, :2] - p.tip_m[i0, :2]
        moved = float(np.hypot(*d))
        err = abs(math.remainder(math.atan2(d[1], d[0]) - direction, 2 * math.pi))
        label = ", ".join(f"{k}={v:+d}" for k, v in sticks.items())
        checks.append(Check(f"tip moved with {label}", moved * 1000, 10, ">=", "mm"))
        checks.append(Check(f"tip direction error with {label}", math.degrees(err), 45, "<=", "deg"))
    curl = p.window(7000 * MS, 7500 * MS)
    checks.append(
        Check("least cable tension with the curl stick up", float(p.tension_n[curl].min()), 2.0, ">=", "N")
    )
    checks.append(
        Check(
            "largest target tension",
            float(p.target_n[: p.n].max()),
            run.config.mapping.tension_max_n,
            "<=",
            "N",
        )
    )
    checks.append(Check("largest |current|", run.max_current(0), run.limit_raw, "<=", "raw"))
    return checks


def _rc_loss_plan() -> Plan:
    # Armed and pulling; the radio goes silent for 1 s and comes back with the lever still in MANUAL;
    # the pilot re-arms through SAFE at 3 s.
    pull = rc(Lever.MIDDLE, ch0=300, ch3=400)
    return Plan(
        radio=[(0, SAFE), (200 * MS, pull), (3000 * MS, SAFE), (3300 * MS, pull)],
        faults=[Fault(FaultKind.RC_SILENCE, 1500 * MS, 2500 * MS)],
    )


def _rc_loss_check(run: Run) -> list[Check]:
    last = _last_rc_before(run, 2500 * MS)  # no valid frame arrives during the silence
    return [
        Check("|current| before the loss", run.max_current(1000 * MS, 1500 * MS), 1, ">=", "raw"),
        Check("zero current after the last valid frame", run.zero_after(last), 30 * MS + TICK_US, "<=", "us"),
        Check(
            "max |current| from 30 ms after the loss to re-arming",
            run.max_current(last + 30 * MS + TICK_US, 3000 * MS),
            0,
            "<=",
            "raw",
        ),
        Check("|current| after re-arming", run.max_current(3500 * MS), 1, ">=", "raw"),
    ]


def _rc_bad_frames_plan(kind: FaultKind) -> Callable[[], Plan]:
    def plan() -> Plan:
        return Plan(
            radio=_arm(ch3=400),
            faults=[Fault(kind, 1500 * MS, 2500 * MS)],
        )

    return plan


def _rc_garbage_check(run: Run) -> list[Check]:
    last = _last_rc_before(run, 2500 * MS)
    rc_source = run.board.rc
    assert isinstance(rc_source, DbusSerialSource)  # scenarios always use the radio
    framer = rc_source.framer
    return [
        Check("bursts dropped by the framer", float(framer.frames_dropped), 50, ">=", "bursts"),
        Check("zero current after the last valid frame", run.zero_after(last), 30 * MS + TICK_US, "<=", "us"),
        Check(
            "max |current| while garbage arrives",
            run.max_current(last + 30 * MS + TICK_US, 2500 * MS),
            0,
            "<=",
            "raw",
        ),
        Check(
            "mode changes during the garbage",
            float(np.count_nonzero(np.diff(run.probe.mode[run.probe.window(1500 * MS, 2500 * MS)]) != 0)),
            1,
            "<=",
        ),
    ]


def _rc_out_of_range_check(run: Run) -> list[Check]:
    p = run.probe
    before = p.window(1000 * MS, 1500 * MS)
    during = p.window(1500 * MS, 2500 * MS)
    rejected = float(p.rc_rejected[during].max() - p.rc_rejected[before].max())
    last = _last_rc_before(run, 2500 * MS)
    return [
        Check("out-of-range frames rejected and counted", rejected, 60, ">=", "frames"),
        Check(
            "largest target tension while they arrive (never above the last valid command)",
            float(p.target_n[during].max() - p.target_n[before].max()),
            0.0,
            "<=",
            "N",
        ),
        Check("zero current after the last valid frame", run.zero_after(last), 30 * MS + TICK_US, "<=", "us"),
    ]


def _motor_silence_plan() -> Plan:
    pull = rc(Lever.MIDDLE, ch3=400)
    return Plan(
        radio=[(0, SAFE), (200 * MS, pull), (2500 * MS, SAFE), (2800 * MS, pull)],
        faults=[Fault(FaultKind.MOTOR_SILENCE, 1500 * MS, 1700 * MS, motor=2)],
    )


def _motor_silence_check(run: Run) -> list[Check]:
    last_fb = 1500 * MS - TICK_US  # the last tick whose feedback reached the board
    return [
        Check("|current| before the silence", run.max_current(1000 * MS, 1500 * MS), 1, ">=", "raw"),
        Check(
            "all-stop after motor 2's last feedback", run.zero_after(last_fb), 10 * MS + TICK_US, "<=", "us"
        ),
        Check(
            "max |current| after feedback returns, before re-arming (latched)",
            run.max_current(1500 * MS + 10 * MS + TICK_US, 2500 * MS),
            0,
            "<=",
            "raw",
        ),
        Check("|current| after re-arming through SAFE", run.max_current(3200 * MS), 1, ">=", "raw"),
    ]


def _link_noise_plan() -> Plan:
    values = [(2.0, 3.0, 4.0), (5.0, 1.5, 2.5), (3.5, 3.5, 1.0), (1.0, 6.0, 2.0)]
    host: list[tuple[int, Command]] = []
    for k, t in enumerate(range(500 * MS, 5000 * MS, 100 * MS)):
        if k % 5 == 0:
            host.append((t, Command(CommandCode.SET_MODE, (float(Mode.DIRECT), 0.0, 0.0))))
        host.append((t + 50 * MS, Command(CommandCode.SET_TENSIONS, values[k % len(values)])))
    return Plan(
        radio=_arm(),
        faults=[
            Fault(FaultKind.LINK_BYTE_LOSS, 0, rate=0.005),
            Fault(FaultKind.LINK_BIT_FLIP, 0, rate=0.005),
        ],
        host=host,
        firmware=FirmwareConfig(failsafe=FailsafeConfig(host_required=True)),
        on_tick=_track_direct_tensions,
    )


def _track_direct_tensions(run: Run) -> None:
    fw = run.board.firmware
    if fw.mode == Mode.DIRECT:
        run.extra.setdefault("direct", set()).add(tuple(round(x, 6) for x in fw.direct_tensions_n))


def _link_noise_check(run: Run) -> list[Check]:
    sent = {
        tuple(round(x, 6) for x in cmd.args)
        for _, cmd in run.host.sent
        if isinstance(cmd, Command) and cmd.code == CommandCode.SET_TENSIONS
    }
    sent.add(tuple([round(run.config.mapping.pretension_n, 6)] * 3))
    applied: set[tuple[float, ...]] = run.extra.get("direct", set())
    telem_t = np.array([m.time_us for m in run.host.telemetry], dtype=np.int64)
    per_window = [
        int(np.count_nonzero((telem_t >= t) & (telem_t < t + 500 * MS)))
        for t in range(0, 5000 * MS, 500 * MS)
    ]
    link = run.board.firmware.link
    crc_errors = link.crc_errors if link is not None else 0
    return [
        Check("direct-mode tension sets applied", float(len(applied)), 2, ">=", "sets"),
        Check("applied tension sets that the host never sent", float(len(applied - sent)), 0, "<=", "sets"),
        Check("corrupted frames the board dropped (counted)", float(crc_errors), 1, ">=", "frames"),
        Check("fewest telemetry frames in any 0.5 s", float(min(per_window)), 5, ">=", "frames"),
        Check("host decode errors on delivered frames", float(run.host.decode_errors), 0, "<=", "frames"),
    ]


def _host_gone_plan(kind: FaultKind) -> Callable[[], Plan]:
    def plan() -> Plan:
        pull = rc(Lever.MIDDLE, ch3=400)
        return Plan(
            radio=[(0, SAFE), (200 * MS, pull), (3200 * MS, SAFE), (3500 * MS, pull)],
            faults=[Fault(kind, 1500 * MS, 2500 * MS)],
            firmware=FirmwareConfig(failsafe=FailsafeConfig(host_required=True)),
        )

    return plan


def _last_heartbeat_before(run: Run, t_us: int) -> int:
    times = [t for t, msg in run.host.sent if type(msg).__name__ == "Heartbeat" and t < t_us]
    return times[-1] if times else 0


def _host_gone_check(run: Run, *, telemetry_during: bool) -> list[Check]:
    timeout = run.config.failsafe.host_timeout_us
    last_hb = _last_heartbeat_before(run, 1500 * MS) + TICK_US  # the wire delivers it on the next tick
    telem = [m for m in run.host.telemetry if 1500 * MS <= m.time_us < 2500 * MS]
    checks = [
        Check("|current| before the loss", run.max_current(1000 * MS, 1500 * MS), 1, ">=", "raw"),
        Check(
            "zero current after the last heartbeat", run.zero_after(last_hb), timeout + TICK_US, "<=", "us"
        ),
        Check(
            "max |current| from the timeout to re-arming (latched)",
            run.max_current(last_hb + timeout + TICK_US, 3200 * MS),
            0,
            "<=",
            "raw",
        ),
        Check("|current| after re-arming through SAFE", run.max_current(3700 * MS), 1, ">=", "raw"),
    ]
    if telemetry_during:
        lost = [m for m in telem if m.phase == Phase.HOST_LOST]
        checks.append(
            Check("telemetry frames while heartbeats are missing", float(len(telem)), 80, ">=", "frames")
        )
        checks.append(Check("telemetry frames reporting HOST_LOST", float(len(lost)), 1, ">=", "frames"))
    else:
        after = [m for m in run.host.telemetry if m.time_us >= 2600 * MS]
        checks.append(Check("telemetry frames after reconnecting", float(len(after)), 100, ">=", "frames"))
    return checks


def _overcurrent_plan() -> Plan:
    # A configuration that asks for more tension than the motors may carry: 150 N on a 10 mm spool at
    # 0.18 N·m/A is 8.3 A, far above the 3 A limit.
    cfg = FirmwareConfig(mapping=MappingConfig(common_max_n=150.0, tension_max_n=200.0, slew_n_per_s=1000.0))
    return Plan(radio=_arm(ch3=660), firmware=cfg)


def _overcurrent_check(run: Run) -> list[Check]:
    cfg = run.config
    asked = cfg.mapping.common_max_n * cfg.motor.spool_radius_m / cfg.motor.torque_constant_nm_per_a * 1000
    applied_a = run.extra.get("applied_a_max", math.nan)
    return [
        Check("current the mapping asks for", asked, run.limit_raw, ">=", "raw"),
        Check("largest |current| sent", run.max_current(0), run.limit_raw, "<=", "raw"),
        Check("the clamp engaged (largest |current| sent)", run.max_current(0), run.limit_raw, ">=", "raw"),
        Check("largest current a drive delivered", applied_a, cfg.motor.current_limit_a + 1e-9, "<=", "A"),
    ]


def _track_applied(run: Run) -> None:
    a = float(np.abs(run.board.plant.applied_currents_a()).max())
    run.extra["applied_a_max"] = max(a, run.extra.get("applied_a_max", 0.0))


# --- grasp: the strategy of Note S4 in the closed loop ------------------------------------------------

_CAN = ObjectConfig("can", radius_m=0.010, length_m=0.06, pos_m=(0.6, 0.0, 0.4), mass_kg=0.020)
_CAN_AT = (0.04, 0.0, 0.87)  # 40 mm beside the arm's axis, 110 mm under its base (the mount is at z = 0.98)
_GRASP_REQUEST_US = 2000 * MS
_GRASP_HELD_US = 1000 * MS  # how long the can must stay after its support is removed


def _grasp_plan() -> Plan:
    # GRASP mode at 0.2 s packs the hanging arm (IDLE); the left lever asks for the grasp at 2 s.
    return Plan(
        radio=[(0, SAFE), (200 * MS, rc(Lever.UP)), (_GRASP_REQUEST_US, rc(Lever.UP, Lever.UP))],
        objects=(_CAN,),
        on_tick=_grasp_stage,
    )


def _grasp_stage(run: Run) -> None:
    """The can waits on its stand out of reach; when the grasp starts it is put beside the packed arm (as
    the drone would bring the arm to it), still on its stand; the stand goes when the firmware reports
    HOLD. Records what the checks need."""
    from protocol.messages import GraspState  # kept local: this block is the grasp scenario's own

    plant = run.board.plant
    state = run.board.firmware.grasp_state
    now = run.board.now_us
    x = run.extra
    name = _CAN.name
    if "placed_us" not in x:
        if not plant.object_held(name):
            plant.hold_object(name)
        if state in (GraspState.REACH, GraspState.WRAP):
            plant.hold_object(name, _CAN_AT)
            x["placed_us"] = now
        return
    if "hold_us" not in x:
        if state == GraspState.HOLD:
            x["hold_us"] = now
            x["units_at_hold"] = len({c.unit for c in plant.contacts() if c.other == name})
            plant.release_object(name)
            x["z_release"] = x["z_low"] = float(plant.object_pose(name).pos_m[2])
        return
    if now <= x["hold_us"] + _GRASP_HELD_US:
        x["z_low"] = min(x["z_low"], float(plant.object_pose(name).pos_m[2]))
        x["units_after"] = len({c.unit for c in plant.contacts() if c.other == name})


def _grasp_check(run: Run) -> list[Check]:
    x = run.extra
    hold_us = x.get("hold_us")
    after = hold_us is not None and run.board.now_us >= hold_us + _GRASP_HELD_US
    return [
        Check(
            "time from the grasp request to HOLD",
            math.nan if hold_us is None else (hold_us - _GRASP_REQUEST_US) / S,
            4.0,
            "<=",
            "s",
        ),
        Check("arm units touching the can at HOLD", float(x.get("units_at_hold", 0)), 4, ">=", "units"),
        Check(
            "arm units touching the can 1 s after its support was removed",
            float(x.get("units_after", 0)) if after else math.nan,
            4,
            ">=",
            "units",
        ),
        Check(
            "largest drop of the can in the 1 s after its support was removed",
            (x["z_release"] - x["z_low"]) * 1000 if after else math.nan,
            40.0,  # the can swings with the settling wrap (~25 mm); a dropped can falls metres
            "<=",
            "mm",
        ),
        Check("largest |current| sent", run.max_current(0), run.limit_raw, "<=", "raw"),
    ]


SCENARIOS: dict[str, Scenario] = {
    s.name: s
    for s in (
        Scenario(
            "startup-gate",
            "no current before valid RC has shown the right lever DOWN; current once armed",
            1500 * MS,
            _startup_gate_plan,
            _startup_gate_check,
        ),
        Scenario(
            "manual-teleop",
            "each stick bends the arm the right way; tensions and currents stay within limits",
            8000 * MS,
            _manual_teleop_plan,
            _manual_teleop_check,
        ),
        Scenario(
            "rc-loss",
            "zero current within 30 ms of the last valid frame; recovery only after re-arming",
            4000 * MS,
            _rc_loss_plan,
            _rc_loss_check,
        ),
        Scenario(
            "rc-garbage",
            "framing noise on the DBUS UART is never acted on, and is counted",
            3000 * MS,
            _rc_bad_frames_plan(FaultKind.RC_GARBAGE),
            _rc_garbage_check,
        ),
        Scenario(
            "rc-out-of-range",
            "frames with channels beyond +-660 are rejected, counted and never acted on",
            3000 * MS,
            _rc_bad_frames_plan(FaultKind.RC_OUT_OF_RANGE),
            _rc_out_of_range_check,
        ),
        Scenario(
            "motor-silence",
            "one motor silent: all-stop within 10 ms + 1 tick, latched until re-armed through SAFE",
            4000 * MS,
            _motor_silence_plan,
            _motor_silence_check,
        ),
        Scenario(
            "link-noise",
            "1% byte errors on the board link: no corrupted command applied, telemetry keeps flowing",
            5000 * MS,
            _link_noise_plan,
            _link_noise_check,
        ),
        Scenario(
            "link-disconnect",
            "board link unplugged for 1 s: zero current after the host timeout, resumes after re-arm",
            5000 * MS,
            _host_gone_plan(FaultKind.LINK_DISCONNECT),
            lambda run: _host_gone_check(run, telemetry_during=False),
        ),
        Scenario(
            "host-loss",
            "host heartbeats stop (link up): zero current after the host timeout, telemetry keeps flowing",
            5000 * MS,
            _host_gone_plan(FaultKind.HOST_LOSS),
            lambda run: _host_gone_check(run, telemetry_during=True),
        ),
        Scenario(
            "overcurrent",
            "a mapping that asks for 8 A is clamped to the 3 A limit on the wire and at the drives",
            1500 * MS,
            lambda: dataclasses.replace(_overcurrent_plan(), on_tick=_track_applied),
            _overcurrent_check,
        ),
        Scenario(
            "grasp",
            "the strategy (pack, reach, contact, wrap) grasps a 20 g can beside the arm and holds it",
            7000 * MS,
            _grasp_plan,
            _grasp_check,
        ),
    )
}


def scenario_names() -> list[str]:
    """Every scenario, in the order of the catalogue."""
    return list(SCENARIOS)


def run_scenario(
    name: str,
    *,
    seed: int = 0,
    design: SpiralDesign | None = None,
    faults: Sequence[Fault] = (),
    record: str | Path | None = None,
    progress: Callable[[int, int], None] | None = None,
    report_dir: str | Path | None = None,
) -> ScenarioResult:
    """Run one scenario in lockstep and measure its checks.

    Args:
        name: a name from :data:`SCENARIOS`.
        seed: seed of every random choice in the run.
        design: the arm (default: the paper's 3-cable prototype).
        faults: faults added to the scenario's own.
        record: write an MCAP recording of every byte in and out of the board.
        progress: called as ``progress(ticks_done, ticks_total)`` every 100 ticks.
        report_dir: write a PNG of the run's signals there (``NAME.png``).

    Raises:
        KeyError: unknown scenario name.
    """
    scenario = SCENARIOS[name]
    plan = scenario.plan()
    plant = PlantConfig()
    if plan.objects:
        plant = dataclasses.replace(plant, model=plant.model.with_objects(*plan.objects))
    config = BoardConfig(
        design=design if design is not None else SpiralDesign.paper_prototype(),
        plant=plant,
        firmware=plan.firmware,
        rc="radio",
        seed=seed,
        start_packed=plan.start_packed,
    )
    recorder = None
    if record is not None:
        meta = {"scenario": name, **config.describe()}
        meta["faults"] = ";".join(repr(f) for f in (*plan.faults, *faults))
        recorder = Recorder(record, metadata=meta)
    try:
        board = VirtualBoard(
            config, faults=(*plan.faults, *faults), radio_script=RadioScript(plan.radio), recorder=recorder
        )
        assert board.wire is not None  # lockstep boards always have a wire
        host = ScriptedHost(board.wire.host, board.faults, heartbeats=plan.heartbeats)
        for t, msg in plan.host:
            host.at(t, msg)
        ticks = scenario.duration_us // board.period_us
        probe = Probe(ticks)
        run = Run(board, host, probe)
        rc_ok = np.zeros(ticks, np.int64)
        run.extra["rc_ok"] = rc_ok
        seen_telemetry = 0
        for i in range(ticks):
            host.before_tick(board.now_us)
            board.tick()
            host.after_tick(board.now_us)
            probe.sample(board)
            rc_ok[i] = board.firmware.rc_frames_ok
            if plan.on_tick is not None:
                plan.on_tick(run)
            if recorder is not None and len(host.telemetry) > seen_telemetry:
                for telemetry in host.telemetry[seen_telemetry:]:
                    recorder.write_json(recording.TELEMETRY, telemetry.time_us, telemetry_json(telemetry))
                seen_telemetry = len(host.telemetry)
            if progress is not None and (i + 1) % 100 == 0:
                progress(i + 1, ticks)
        checks = scenario.check(run)
        if report_dir is not None:
            from .report import plot_run  # matplotlib only when a report is asked for

            plot_run(probe, report_dir, name)
        counters = dict(board.firmware.counters)
        counters.update({f"injected_{k}": v for k, v in board.faults.injected.items()})
        board.close()
    finally:
        if recorder is not None:
            recorder.close()
    return ScenarioResult(name, seed, tuple(checks), scenario.duration_us, counters)


def telemetry_json(msg: Telemetry) -> dict[str, Any]:
    """A telemetry message as plain JSON numbers (enums as their values, so plotting tools plot them)."""
    out: dict[str, Any] = {}
    for f in dataclasses.fields(msg):
        v = getattr(msg, f.name)
        if isinstance(v, enum.Enum):
            out[f.name] = int(v.value)
        elif isinstance(v, tuple):
            out[f.name] = list(v)
        else:
            out[f.name] = v
    return out
