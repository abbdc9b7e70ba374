"""What every scenario is made of: a plan, an episode, and checks written once for lockstep and port runs.

A scenario is an :class:`~hil.environment.Episode` with a :meth:`Scenario.plan` (the radio script, the host's
commands, the faults, the firmware settings, the objects in the scene) and :meth:`Scenario.checks`, which
turn a :class:`~hil.run_record.RunRecord` into measured :class:`~hil.run_record.Check` values. The same checks
judge a lockstep run and a run against a port: every window is taken from the plan (fault windows, radio
steps), every timing bound is the firmware's own timeout plus what the record says about its resolution,
a real-time board's lateness and the link's delay. Checks that need the simulated plant only run where a
plant was sampled.

Timing facts the checks rely on: a control tick every 1 ms; the radio sends a frame every 14 ms; RC is
lost 30 ms after the last valid frame, a motor 10 ms after its last feedback, the host 500 ms after its
last heartbeat (the firmware configuration's defaults). "Zero current within X" is measured from the last
input that kept the board alive to the first sample with zero current on every motor; the bound is X plus
one tick, plus the record's allowances.
"""

from __future__ import annotations

import itertools
import math
from abc import ABC, abstractmethod
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import ClassVar, Final

from controller.config import FailsafeConfig, FirmwareConfig
from hil.environment import Episode
from hil.faults import Fault, FaultKind
from hil.run_record import TICK_US, Check, RunRecord
from hil.sim.config import ObjectConfig
from hil.sim.drone_motion import DroneMotion
from protocol.dbus import Lever, RcFrame
from protocol.messages import Command, EventKind, Phase

__all__ = ["MANUAL", "MS", "SAFE", "Plan", "S", "Scenario", "fault_window", "rc"]

MS: Final = 1000
S: Final = 1_000_000
AFTER_REARM_US: Final = 200 * MS
"""Current must flow again this long after the stick pull resumes (the slew limiter ramps it up)."""
FLOAT32_TOLERANCE_N: Final = 1e-4
"""Tensions travel as float32 in telemetry: values this close are the same set-point."""
RC_GAP_CHECK: Final = "largest unplanned gap between the RC frames the board received"
"""Name prefix of every run's validity check (see :func:`rc_gap_check`)."""

REQUIRED: Final = FirmwareConfig()
"""The requirements the checks hold a board to: the default firmware's timeouts, which are the field
figures (RC lost after 30 ms and a motor offline after 10 ms without data: DJI's detect task). A board
under test configured slower must fail, so bounds never come from the run's own configuration."""

_RC_CUTS = (FaultKind.RC_SILENCE, FaultKind.RC_GARBAGE, FaultKind.RC_OUT_OF_RANGE, FaultKind.LINK_DISCONNECT)


def rc(
    right: int = Lever.DOWN, left: int = Lever.DOWN, *, ch0: int = 0, ch1: int = 0, ch3: int = 0
) -> RcFrame:
    """A radio frame: levers and the sticks the scenarios use (ch2, left horizontal, is unused)."""
    return RcFrame((ch0, ch1, 0, ch3), int(right), int(left))


SAFE: Final = rc()
MANUAL: Final = rc(Lever.MIDDLE)


def arm_then(t_manual_us: int = 200 * MS, **sticks: int) -> list[tuple[int, RcFrame]]:
    """DOWN from the start (passes the start-up gate), then MIDDLE with the given sticks."""
    return [(0, SAFE), (t_manual_us, rc(Lever.MIDDLE, **sticks))]


@dataclass(frozen=True)
class Plan:
    """How a scenario runs: the radio, the host, the faults, the board's configuration, the scene, and the
    drone's scripted motion (lockstep only: the plant's acceleration)."""

    radio: Sequence[tuple[int, RcFrame]]
    faults: Sequence[Fault] = ()
    host: Sequence[tuple[int, Command]] = ()
    heartbeats: bool = True
    firmware: FirmwareConfig = field(default_factory=FirmwareConfig)
    objects: tuple[ObjectConfig, ...] = ()
    start_packed: bool = False
    drone: DroneMotion | None = None


class Scenario(Episode, ABC):
    """A named scenario: what it plans, what it checks, and (optionally) what it does around each tick.

    One instance serves one run (its hooks may keep state). Class attributes describe it in the catalogue.
    """

    name: ClassVar[str]
    summary: ClassVar[str]
    duration_us: int
    """How long it runs (a class attribute; a scenario with options may set its own)."""
    needs_plant: ClassVar[bool] = False
    """Its plan or its checks need the simulated plant (objects, a packed start): lockstep only."""

    @abstractmethod
    def plan(self) -> Plan:
        """The run's inputs."""

    @abstractmethod
    def checks(self, run: RunRecord, plan: Plan) -> list[Check]:
        """The measured checks of a finished run."""

    def recording_metadata(self) -> dict[str, str]:
        """What a recording of the run says about it beyond the board (none by default)."""
        return {}


# --- windows from the plan ------------------------------------------------------------------------


def fault_window(plan: Plan, kind: FaultKind) -> tuple[int, int]:
    """The window of the plan's first fault of that kind (an open end reads as the end of time).

    Raises:
        ValueError: the plan has no such fault (a catalogue change its checks do not know).
    """
    for f in plan.faults:
        if f.kind is kind:
            return f.start_us, f.end_us if f.end_us is not None else 1 << 62
    raise ValueError(f"the plan has no {kind} fault")


def rearm_pull_us(plan: Plan) -> int:
    """When the stick pull resumes after re-arming (the radio script's last step)."""
    return plan.radio[-1][0]


# --- checks shared by several scenarios -----------------------------------------------------------


def rc_acted_us(run: RunRecord) -> int:
    """Latest time after the last valid RC frame by which the board must have cut the current."""
    return REQUIRED.failsafe.rc_timeout_us + TICK_US + run.lateness_us


def rc_zero_checks(run: RunRecord, last_rc_us: float) -> list[Check]:
    """Zero current, and RC_LOST reported, within the RC timeout of the last valid frame."""
    return [
        Check(
            "zero current after the last valid frame",
            run.zero_after(last_rc_us),
            rc_acted_us(run) + run.resolution_us,
            "<=",
            "us",
        ),
        Check(
            "RC_LOST reported after the last valid frame (board event)",
            run.event_after(last_rc_us, EventKind.PHASE, Phase.RC_LOST),
            rc_acted_us(run),
            "<=",
            "us",
        ),
    ]


def current_before(run: RunRecord, start_us: int) -> Check:
    """Current flowed in the half second before a fault."""
    return Check("|current| before the loss", run.max_current(start_us - 500 * MS, start_us), 1, ">=", "raw")


def rearmed(run: RunRecord, plan: Plan, name: str = "|current| after re-arming through SAFE") -> Check:
    """Current flows again after the pilot re-armed through SAFE and pulled again."""
    return Check(name, run.max_current(rearm_pull_us(plan) + AFTER_REARM_US), 1, ">=", "raw")


def largest_unplanned_gap_us(times_us: Sequence[int], plan: Plan, duration_us: int) -> int | None:
    """The largest interval between consecutive RC instants in ``[0, duration_us)`` that no planned RC cut
    of ``plan`` explains (None: no instant in the run)."""
    cuts = [
        (f.start_us, f.end_us if f.end_us is not None else 1 << 62) for f in plan.faults if f.kind in _RC_CUTS
    ]
    seen = [t for t in times_us if 0 <= t < duration_us]
    if not seen:
        return None
    gaps = [b - a for a, b in itertools.pairwise(seen) if not any(a < e and b > s for s, e in cuts)]
    return max(gaps, default=0)


def rc_gap_check(run: RunRecord, plan: Plan) -> Check:
    """The run's own validity: the RC stream reached the board without a gap the scenario did not plan.

    A gap longer than the RC timeout makes the board declare RC lost (and latch it), rightly: then the
    host or the link stalled (on a port, a pty's delivery waits for a normal-priority kernel worker), and
    the run says nothing about the checks that follow. Measured on the board's own receive times
    (``RawRc``); from the host's send times when the board reports none, with the link's delay taken off.
    """
    board_times = [t for t, f in run.rc if f.is_valid()]
    gap = largest_unplanned_gap_us(board_times or run.rc_sent_us, plan, run.duration_us)
    bound = (
        REQUIRED.failsafe.rc_timeout_us
        if board_times
        else REQUIRED.failsafe.rc_timeout_us - run.link_delay_us
    )
    return Check(
        f"{RC_GAP_CHECK} (longer: the host or the link stalled; the run is void)",
        math.nan if gap is None else float(gap),
        bound,
        "<=",
        "us",
    )


# --- the host gone (host-loss, link-disconnect) ------------------------------------------------------


def host_gone_plan(kind: FaultKind) -> Plan:
    """Host required, armed and pulling; ``kind`` (the host or its link gone) from 1.5 s to 2.5 s; re-armed
    through SAFE at 3.2 s."""
    pull = rc(Lever.MIDDLE, ch3=400)
    return Plan(
        radio=[(0, SAFE), (200 * MS, pull), (3200 * MS, SAFE), (3500 * MS, pull)],
        faults=[Fault(kind, 1500 * MS, 2500 * MS)],
        firmware=FirmwareConfig(failsafe=FailsafeConfig(host_required=True)),
    )


def host_acted_us(run: RunRecord) -> int:
    """Latest time after the last heartbeat the host sent by which the board must have cut the current."""
    return REQUIRED.failsafe.host_timeout_us + TICK_US + run.link_delay_us + run.lateness_us


def host_cut_and_latched(run: RunRecord, last_hb: float, rearm: float) -> list[Check]:
    """Zero current within the host timeout of the last heartbeat, and none until re-armed."""
    acted = host_acted_us(run)
    return [
        Check(
            "zero current after the last heartbeat",
            run.zero_after(last_hb),
            acted + run.resolution_us,
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
    ]
