"""One run record: what a scenario's checks read, filled in lockstep or from a port.

A run is observed through two windows:

- **samples**: the board's state at a fixed rate (commanded currents, tension targets, phase, mode, grasp
  state, counters). A lockstep run samples the firmware itself after every 1 ms tick; a run against a port
  samples the ``Telemetry`` the board sends (100 Hz) and so sees the board a telemetry period late at worst.
- **the board's own messages**, as the board sent them (before any emulated link noise): its events, the RC
  frames it received (``RawRc``, with its receive time), the times of its telemetry frames. The lockstep
  runner reads them off the board's end of the wire; the port runner off the bytes that reached the host.

Beside these, what the host did (the messages it sent, with their times; its RC frames; reconnections),
what reached the host through the link faults (telemetry times, decode errors), and in lockstep only the
plant's true state (:class:`PlantSamples`).

The differences between the two runners are numbers the record carries, never separate check code:
:attr:`RunRecord.resolution_us` (how late a sample may show a change), :attr:`RunRecord.lateness_us` (how
late a real-time board's tick may start) and :attr:`RunRecord.link_delay_us` (how long something the host
sent takes to reach the board's firmware). Every query returns NaN where it has nothing to measure, so a
check on an empty window never passes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from controller.config import FirmwareConfig
from hil.sim.types import PhysicsExtremes
from protocol.dbus import RcFrame
from protocol.messages import Event, EventKind, Message, Telemetry

__all__ = ["Check", "PlantSamples", "RunRecord", "Samples", "ScenarioResult"]

TICK_US = 1000
"""The firmware's control tick (1 kHz): what the lockstep samples resolve."""


@dataclass(frozen=True, slots=True)
class Check:
    """One measured check: ``value <op> bound`` (a NaN value never passes)."""

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
    """What a scenario run measured (picklable): the same shape in lockstep and on a port."""

    name: str
    seed: int
    checks: tuple[Check, ...]
    duration_us: int
    counters: dict[str, int] = field(default_factory=dict)
    extremes: PhysicsExtremes | None = None
    """The plant's largest penetration, tension and limit overshoot over the run (None on a port)."""
    report_lines: tuple[str, ...] = field(default=(), compare=False)
    """With a report: its pictures, one line each, or the one line saying why there are none."""

    @property
    def passed(self) -> bool:
        """Every check holds."""
        return all(c.passed for c in self.checks)

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready form (``extremes`` in SI units, or None on a port)."""
        return {
            "name": self.name,
            "seed": self.seed,
            "passed": self.passed,
            "duration_s": self.duration_us / 1e6,
            "checks": [c.as_dict() for c in self.checks],
            "counters": self.counters,
            "extremes": None if self.extremes is None else self.extremes.as_dict(),
        }


class Samples:
    """The board's state at each sample, in preallocated arrays (``capacity`` samples at most).

    Attributes:
        t_us: board time of each sample, since the run started.
        current_raw: commanded currents (raw C610 units), shape (n, 3).
        target_n: the firmware's tension targets, shape (n, 3).
        phase, mode, grasp: failsafe phase, mode and grasp state.
        rc_frames_ok: valid RC frames the board accepted so far.
        rc_refused: RC frames the board refused so far: rejected as invalid, plus (lockstep) bursts the
            DBUS framer dropped (on a port the link delimits the frames, so there is no framing to fail).
        link_crc_errors: board-link frames the board dropped on a CRC error so far.
    """

    def __init__(self, capacity: int) -> None:
        self.n = 0
        self.t_us = np.zeros(capacity, np.int64)
        self.current_raw = np.zeros((capacity, 3), np.int64)
        self.target_n = np.zeros((capacity, 3))
        self.phase = np.zeros(capacity, np.int64)
        self.mode = np.zeros(capacity, np.int64)
        self.grasp = np.zeros(capacity, np.int64)
        self.rc_frames_ok = np.zeros(capacity, np.int64)
        self.rc_refused = np.zeros(capacity, np.int64)
        self.link_crc_errors = np.zeros(capacity, np.int64)

    def trim(self) -> Samples:
        """Cut every array to the samples taken (call once, when the run is over)."""
        n = self.n
        for name in (
            "t_us",
            "current_raw",
            "target_n",
            "phase",
            "mode",
            "grasp",
            "rc_frames_ok",
            "rc_refused",
            "link_crc_errors",
        ):
            setattr(self, name, getattr(self, name)[:n])
        return self

    @classmethod
    def from_telemetry(cls, telemetry: list[Telemetry], t0_us: int) -> Samples:
        """Samples from telemetry frames (board times made relative to ``t0_us``)."""
        s = cls(len(telemetry))
        for i, m in enumerate(telemetry):
            s.t_us[i] = m.time_us - t0_us
            s.current_raw[i] = m.commanded_current
            s.target_n[i] = m.tension_target_n
            s.phase[i] = int(m.phase)
            s.mode[i] = int(m.mode)
            s.grasp[i] = int(m.grasp_state)
            s.rc_frames_ok[i] = m.rc_frames_ok
            s.rc_refused[i] = m.rc_rejected
            s.link_crc_errors[i] = m.link_crc_errors
        s.n = len(telemetry)
        return s


class PlantSamples:
    """The simulated plant's true state at each lockstep sample (none on a port: a real arm has no probe).

    Attributes:
        tension_n: cable tensions, shape (n, 3).
        tip_m: tip position in the world, shape (n, 3).
        cable_m: cable lengths from spool to tip, shape (n, 3).
        applied_a: the largest |current| any drive delivered, per sample.
    """

    def __init__(self, capacity: int) -> None:
        self.tension_n = np.zeros((capacity, 3))
        self.tip_m = np.zeros((capacity, 3))
        self.cable_m = np.zeros((capacity, 3))
        self.applied_a = np.zeros(capacity)

    def trim(self, n: int) -> PlantSamples:
        """Cut every array to ``n`` samples."""
        self.tension_n = self.tension_n[:n]
        self.tip_m = self.tip_m[:n]
        self.cable_m = self.cable_m[:n]
        self.applied_a = self.applied_a[:n]
        return self


@dataclass
class RunRecord:
    """Everything a check may look at, on the board's clock in µs since the run started.

    Attributes:
        config: the firmware configuration in force.
        duration_us: the run's duration.
        samples: the board's state over time.
        resolution_us: how much later than the board's tick a sample may show a change (0 when every tick
            is sampled; the telemetry period on a port).
        lateness_us: how late a tick that acts on a timeout may start (0 in lockstep; a real-time board's
            allowance on a port).
        link_delay_us: how long something the host sent takes to reach the firmware (lockstep: the wire
            delivers it on the next tick; a port: the board polls once per tick and USB waits for a frame).
        samples_through_link: the samples travel over the board link (a port run), so a link outage hides
            the board; a lockstep run samples the firmware directly.
        plant: the plant's true state (lockstep only).
        extremes: the plant's largest penetration, tension and limit overshoot over the run (lockstep
            only; a real arm has no such probe).
        rc: every RC frame the board reported receiving, as (board time, frame), before link noise.
        events: the board's events, as (board time, event), before link noise.
        telemetry_sent_us: board times of the telemetry frames the board sent, before link noise.
        telemetry_received_us: board times of the telemetry frames that reached the host.
        sent: what the host sent (before link faults), as (board time, message).
        rc_sent_us: board times at which the host sent ``VirtualRc`` frames (port runs).
        reconnects_us: board times at which the host reopened the link after a disconnect.
        decode_errors: intact frames the host could not decode.
        counters: counters by name (board, host, injected faults).
    """

    config: FirmwareConfig
    duration_us: int
    samples: Samples
    resolution_us: int = 0
    lateness_us: int = 0
    link_delay_us: int = TICK_US
    samples_through_link: bool = False
    plant: PlantSamples | None = None
    extremes: PhysicsExtremes | None = None
    rc: list[tuple[int, RcFrame]] = field(default_factory=list)
    events: list[tuple[int, Event]] = field(default_factory=list)
    telemetry_sent_us: list[int] = field(default_factory=list)
    telemetry_received_us: list[int] = field(default_factory=list)
    sent: list[tuple[int, Message]] = field(default_factory=list)
    rc_sent_us: list[int] = field(default_factory=list)
    reconnects_us: list[int] = field(default_factory=list)
    decode_errors: int = 0
    counters: dict[str, int] = field(default_factory=dict)

    # --- the samples ------------------------------------------------------------------------------

    @property
    def n(self) -> int:
        """Number of samples."""
        return int(self.samples.t_us.size)

    @property
    def limit_raw(self) -> int:
        """The firmware's current limit in raw units."""
        return self.config.motor.current_limit_raw

    def window(self, start_us: float, end_us: float | None = None) -> npt.NDArray[np.bool_]:
        """Mask of the samples with ``start_us <= t < end_us`` (empty for a NaN bound)."""
        t = self.samples.t_us
        if math.isnan(start_us) or (end_us is not None and math.isnan(end_us)):
            return np.zeros(t.size, bool)
        mask = t >= start_us
        if end_us is not None:
            mask &= t < end_us
        return mask

    def abs_current(self) -> npt.NDArray[np.int64]:
        """Largest |commanded current| over the three motors, per sample."""
        cur = self.samples.current_raw
        out: npt.NDArray[np.int64] = np.abs(cur).max(axis=1) if cur.size else np.zeros(0, np.int64)
        return out

    def max_current(self, start_us: float, end_us: float | None = None) -> float:
        """Largest |commanded current| on ``start_us <= t < end_us`` (NaN if no sample)."""
        cur = self.abs_current()[self.window(start_us, end_us)]
        return float(cur.max()) if cur.size else math.nan

    def zero_after(self, t_us: float) -> float:
        """Time from ``t_us`` to the first sample at or after it with zero current on every motor (NaN if
        none); it overstates the true time by less than :attr:`resolution_us`."""
        idx = np.flatnonzero(self.window(t_us) & (self.abs_current() == 0))
        return float(self.samples.t_us[idx[0]] - t_us) if idx.size else math.nan

    def count(self, start_us: float, end_us: float | None = None) -> int:
        """Samples on ``start_us <= t < end_us``."""
        return int(np.count_nonzero(self.window(start_us, end_us)))

    def counter_rise(self, counter: npt.NDArray[np.int64], start_us: float, end_us: float) -> float:
        """How much a board counter rose from before ``start_us`` to one resolution after ``end_us``."""
        before = counter[self.window(0, start_us)]
        after = counter[self.window(0, end_us + self.resolution_us)]
        if not before.size or not after.size:
            return math.nan
        return float(after.max() - before.max())

    def mode_changes(self, start_us: float, end_us: float) -> int:
        """Mode changes on ``[start_us, end_us)``: from the samples or the board's MODE events, the more."""
        mode = self.samples.mode[self.window(start_us, end_us)]
        sampled = int(np.count_nonzero(np.diff(mode) != 0))
        reported = sum(1 for t, e in self.events if start_us <= t < end_us and e.kind == EventKind.MODE)
        return max(sampled, reported)

    # --- the board's messages and the host's ------------------------------------------------------

    def last_valid_rc_before(self, t_us: float) -> float:
        """Board time of the last valid RC frame received before ``t_us`` (NaN if none)."""
        times = [t for t, f in self.rc if t < t_us and f.is_valid()]
        return float(max(times)) if times else math.nan

    def first_rc_at_or_after(self, t_us: float, right_lever: int) -> float:
        """Board time of the first valid RC frame at or after ``t_us`` with that right lever (NaN if none)."""
        times = [t for t, f in self.rc if t >= t_us and f.is_valid() and f.right_lever == right_lever]
        return float(min(times)) if times else math.nan

    def event_after(self, t_us: float, kind: EventKind, code: int) -> float:
        """Time from ``t_us`` to the first board event of that kind and code at or after it (NaN if none)."""
        if math.isnan(t_us):
            return math.nan
        times = [t for t, e in self.events if t >= t_us and e.kind == kind and e.code == code]
        return float(min(times) - t_us) if times else math.nan

    def last_sent_before(self, kind: type[Message], t_us: float) -> float:
        """Board time of the last message of that type the host sent before ``t_us`` (NaN if none)."""
        times = [t for t, m in self.sent if isinstance(m, kind) and t < t_us]
        return float(max(times)) if times else math.nan

    def received(self, start_us: float, end_us: float | None = None) -> int:
        """Telemetry frames that reached the host on ``start_us <= t < end_us``."""
        hi = math.inf if end_us is None else end_us
        return sum(1 for t in self.telemetry_received_us if start_us <= t < hi)
