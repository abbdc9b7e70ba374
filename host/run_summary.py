"""What a `spirob-host` run went through, for the line printed when a failsafe latches and the summary at
exit: time in each mode and phase (board time), failsafes, faults, and the virtual radio's gaps."""

from __future__ import annotations

import logging
import threading
from dataclasses import dataclass, field

from protocol.messages import ArmsTelemetry, Event, EventKind, Message, Mode, Phase, Telemetry

__all__ = ["FAILSAFE_PHASES", "RunSummary", "SummaryReport"]

_log = logging.getLogger("spirob-host")

FAILSAFE_PHASES = frozenset({Phase.RC_LOST, Phase.MOTOR_FAULT, Phase.HOST_LOST, Phase.ESTOP})
"""Phases that hold zero current until the operator re-arms through SAFE (latched)."""

_GAP_LIMIT_US = 1_000_000
"""A telemetry gap longer than this is not counted as time in a mode (the board restarted or the link was
down: nothing is known of that time)."""


@dataclass(frozen=True)
class SummaryReport:
    """A snapshot of :class:`RunSummary`.

    Attributes:
        telemetry_n: telemetry messages seen.
        board_s: board time covered by them.
        mode_s: seconds of board time in each mode.
        phase_s: seconds of board time in each phase.
        failsafes: every entry into a failsafe phase: (board time s, phase name).
        faults: every fault event: (board time s, text).
        last_mode: the mode of the last telemetry (None before any).
        last_phase: its phase.
        rc_gaps_n: virtual RC frames sent more than the board's 30 ms RC timeout apart (None: not known,
            e.g. a replay).
        rc_max_gap_ms: the longest interval between two of them.
    """

    telemetry_n: int
    board_s: float
    mode_s: dict[str, float] = field(default_factory=dict)
    phase_s: dict[str, float] = field(default_factory=dict)
    failsafes: tuple[tuple[float, str], ...] = ()
    faults: tuple[tuple[float, str], ...] = ()
    last_mode: Mode | None = None
    last_phase: Phase | None = None
    rc_gaps_n: int | None = None
    rc_max_gap_ms: float | None = None
    layout: tuple[int, int] | None = None

    @property
    def ended_latched(self) -> bool:
        """The run ended in a failsafe phase."""
        return self.last_phase in FAILSAFE_PHASES

    def failure(self) -> str | None:
        """Why a scripted run failed (ended latched, a fault, or no telemetry at all); None if it did not."""
        if self.telemetry_n == 0:
            return "no telemetry from the board"
        if self.ended_latched:
            assert self.last_phase is not None
            return f"the run ended latched in {self.last_phase.name}"
        if self.faults:
            return f"{len(self.faults)} fault(s), the first: {self.faults[0][1]}"
        return None

    def lines(self) -> list[str]:
        """The summary, a few lines for people."""
        if self.telemetry_n == 0:
            return ["summary: no telemetry received"]

        def shares(times: dict[str, float]) -> str:
            return " · ".join(f"{k} {v:.1f} s" for k, v in times.items() if v > 0) or "-"

        rc = "RC gaps over 30 ms: not known"
        if self.rc_gaps_n is not None:
            rc = f"RC gaps over 30 ms: {self.rc_gaps_n}"
            if self.rc_max_gap_ms is not None:
                rc += f" (longest {self.rc_max_gap_ms:.1f} ms)"
        failsafes = ", ".join(f"{p} at {t:.2f} s" for t, p in self.failsafes) or "none"
        faults = ", ".join(f"{text} at {t:.2f} s" for t, text in self.faults) or "none"
        last_mode = self.last_mode.name if self.last_mode is not None else "-"
        last_phase = self.last_phase.name if self.last_phase is not None else "-"
        board = (
            []
            if self.layout is None
            else [f"  board: an array of {self.layout[0]} arms x {self.layout[1]} cable(s)"]
        )
        return [
            f"summary: {self.board_s:.1f} s of board time, {self.telemetry_n} telemetry messages",
            *board,
            f"  mode:  {shares(self.mode_s)}",
            f"  phase: {shares(self.phase_s)}",
            f"  {rc}; failsafes: {failsafes}; faults: {faults}",
            f"  ended in mode {last_mode}, phase {last_phase}"
            + (" (latched: re-arm through SAFE)" if self.ended_latched else ""),
        ]


class RunSummary:
    """A board-link listener that accounts for a run (thread-safe; constant work per message).

    Time in a mode or phase is board time between consecutive telemetry messages, credited to the
    earlier one's state. Entering a failsafe phase logs one warning line at once.
    """

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._mode_us = {m: 0 for m in Mode}
        self._phase_us = {p: 0 for p in Phase}
        self._last: Telemetry | None = None
        self._n = 0
        self._board_us = 0
        self._failsafes: list[tuple[float, str]] = []
        self._faults: list[tuple[float, str]] = []
        self._layout: tuple[int, int] | None = None

    def on_board_message(self, msg: Message) -> None:
        """Listener: telemetry, an array's layout and fault events."""
        if isinstance(msg, Telemetry):
            self._on_telemetry(msg)
        elif isinstance(msg, ArmsTelemetry):
            layout = (msg.arms, msg.cables_per_arm)
            with self._lock:
                new = layout != self._layout
                self._layout = layout
            if new:  # once per layout: the board is an array (docs/board-link.md, 0x0109)
                _log.info(
                    "the board is an array of %d arms x %d cable(s), %d motors (ArmsTelemetry)",
                    msg.arms,
                    msg.cables_per_arm,
                    len(msg.motor_angle),
                )
        elif isinstance(msg, Event) and msg.kind == EventKind.FAULT:
            text = msg.text or f"fault code {msg.code}"
            with self._lock:
                self._faults.append((msg.time_us / 1e6, text))
            _log.warning("fault at board time %.2f s: %s", msg.time_us / 1e6, text)

    def _on_telemetry(self, t: Telemetry) -> None:
        with self._lock:
            prev = self._last
            self._last = t
            self._n += 1
            entered = t.phase in FAILSAFE_PHASES and (prev is None or prev.phase != t.phase)
            if prev is not None:
                dt = t.time_us - prev.time_us
                if 0 < dt <= _GAP_LIMIT_US:
                    self._mode_us[prev.mode] += dt
                    self._phase_us[prev.phase] += dt
                    self._board_us += dt
            if entered:
                self._failsafes.append((t.time_us / 1e6, t.phase.name))
        if entered:
            _log.warning(
                "failsafe latched at board time %.2f s: %s, zero current until re-armed through SAFE",
                t.time_us / 1e6,
                t.phase.name,
            )

    def report(self, rc_gaps_n: int | None = None, rc_max_gap_us: int | None = None) -> SummaryReport:
        """A snapshot, with the virtual radio's gap statistics from the link (None: not known)."""
        with self._lock:
            last = self._last
            return SummaryReport(
                telemetry_n=self._n,
                board_s=self._board_us / 1e6,
                mode_s={m.name: us / 1e6 for m, us in self._mode_us.items()},
                phase_s={p.name: us / 1e6 for p, us in self._phase_us.items()},
                failsafes=tuple(self._failsafes),
                faults=tuple(self._faults),
                last_mode=None if last is None else last.mode,
                last_phase=None if last is None else last.phase,
                rc_gaps_n=rc_gaps_n,
                rc_max_gap_ms=None if rc_max_gap_us is None else rc_max_gap_us / 1000,
                layout=self._layout,
            )
