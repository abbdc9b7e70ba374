"""A unit-test stand-in for the board behind the drone link: answers like the firmware would.

It keeps a small parameter table, publishes ``Telemetry`` at 100 Hz from its own thread, runs a
grasp state machine a few ticks per phase, and answers ``Command`` / ``ParamRequest`` / ``ParamSet``
with ``CommandAck`` / ``ParamValue`` (a rejected value is answered with the value in force, as the
firmware does). Tests flip its mode, phase and arming, and choose how the next grasp ends.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from dataclasses import dataclass, field

from protocol import messages as bm

PARAMS: dict[str, float] = {
    "pretension_n": 0.5,
    "tension_max_n": 20.0,
    "current_limit_a": 3.0,
    "spool_radius_m": 0.010,
    "grasp_wrap_n": 10.0,
}


@dataclass
class FakeBoard:
    """Firmware-like fake. ``attach`` it to a sink (``DroneLink.on_board_message``), then ``start``.

    Attributes:
        mode: Operating mode shown in telemetry.
        phase: Failsafe phase shown in telemetry.
        armed: ARMED flag.
        grasp_state: Grasp state machine.
        outcome: How the next grasp ends: "hold", "fail" or "stall" (never finishes).
        ticks_per_phase: Telemetry ticks spent in REACH, WRAP and RELEASE.
        answer_param_set: False = ignore ``ParamSet`` (a board that never confirms).
        defer_param_set: True = take ``ParamSet`` values but confirm them only on
            :meth:`confirm_param_sets` (a slow board).
        received: Every message the link sent to the board, in order.
    """

    mode: bm.Mode = bm.Mode.GRASP
    phase: bm.Phase = bm.Phase.OK
    armed: bool = True
    grasp_state: bm.GraspState = bm.GraspState.IDLE
    outcome: str = "hold"
    ticks_per_phase: int = 5
    answer_param_set: bool = True
    defer_param_set: bool = False
    period_s: float = 0.01
    params: dict[str, float] = field(default_factory=lambda: dict(PARAMS))
    received: list[bm.Message] = field(default_factory=list)
    _sink: Callable[[bm.Message], None] | None = None
    _lock: threading.Lock = field(default_factory=threading.Lock)
    _stop: threading.Event = field(default_factory=threading.Event)
    _thread: threading.Thread | None = None
    _ticks_left: int = 0
    _time_us: int = 0
    _deferred: list[str] = field(default_factory=list)

    # ---- wiring -----------------------------------------------------------------------------------

    def attach(self, sink: Callable[[bm.Message], None]) -> None:
        """Where board -> host messages go."""
        self._sink = sink

    def start(self) -> None:
        """Start publishing telemetry."""
        self._thread = threading.Thread(target=self._run, name="fake-board", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        """Stop the telemetry thread (safe twice)."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5.0)
            self._thread = None

    def set(self, **state: object) -> None:
        """Change mode / phase / armed / grasp_state / outcome atomically."""
        with self._lock:
            for k, v in state.items():
                setattr(self, k, v)
            if "grasp_state" in state:
                self._ticks_left = self.ticks_per_phase

    def confirm_param_sets(self) -> None:
        """Confirm the deferred ``ParamSet`` values now (``defer_param_set``)."""
        with self._lock:
            replies = [self._pv(name) for name in self._deferred]
            self._deferred.clear()
        for r in replies:
            self._emit(r)

    def commands(self) -> list[bm.Command]:
        """The ``Command`` messages received so far."""
        with self._lock:
            return [m for m in self.received if isinstance(m, bm.Command)]

    # ---- host -> board ------------------------------------------------------------------------

    def __call__(self, msg: bm.Message) -> None:
        """``send_to_board``: handle one host -> board message."""
        with self._lock:
            self.received.append(msg)
            replies = self._handle(msg)
        for r in replies:
            self._emit(r)

    def _handle(self, msg: bm.Message) -> list[bm.Message]:
        if isinstance(msg, bm.ParamRequest):
            names = list(self.params)
            if msg.index == bm.PARAM_LIST_ALL:
                return [self._pv(n) for n in names]
            if msg.index >= 0:
                return [self._pv(names[msg.index])] if msg.index < len(names) else []
            return [self._pv(msg.name)] if msg.name in self.params else []
        if isinstance(msg, bm.ParamSet):
            if msg.name not in self.params or not self.answer_param_set:
                return []
            if msg.value >= 0.0:  # the firmware validates; a rejected value is answered with the old one
                self.params[msg.name] = msg.value
            if self.defer_param_set:
                self._deferred.append(msg.name)
                return []
            return [self._pv(msg.name)]
        if isinstance(msg, bm.Command):
            return [self._command(msg)]
        return []

    def _pv(self, name: str) -> bm.ParamValue:
        names = list(self.params)
        return bm.ParamValue(names.index(name), len(names), name, self.params[name])

    def _command(self, cmd: bm.Command) -> bm.CommandAck:
        code = cmd.code
        if code in (bm.CommandCode.GRASP, bm.CommandCode.RELEASE, bm.CommandCode.HOLD):
            if not (self.armed and self.phase == bm.Phase.OK and self.mode == bm.Mode.GRASP):
                return bm.CommandAck(code, bm.AckResult.DENIED, 0, "not in GRASP")
            if self.grasp_state in (bm.GraspState.REACH, bm.GraspState.WRAP, bm.GraspState.RELEASE):
                return bm.CommandAck(code, bm.AckResult.REJECTED, 0, "busy")
            if code == bm.CommandCode.GRASP:
                self.grasp_state = bm.GraspState.REACH
            elif code == bm.CommandCode.RELEASE:
                self.grasp_state = bm.GraspState.RELEASE
            else:
                self.grasp_state = bm.GraspState.HOLD
            self._ticks_left = self.ticks_per_phase
            return bm.CommandAck(code, bm.AckResult.ACCEPTED, 0)
        return bm.CommandAck(int(code), bm.AckResult.UNSUPPORTED, 0)

    # ---- board -> host ------------------------------------------------------------------------

    def _emit(self, msg: bm.Message) -> None:
        if self._sink is not None:
            self._sink(msg)

    def emit_event(self, kind: bm.EventKind, code: int, text: str) -> None:
        """Send an ``Event`` now."""
        self._emit(bm.Event(self._time_us, kind, code, 0.0, text))

    def _step_grasp(self) -> None:
        s = self.grasp_state
        if s not in (bm.GraspState.REACH, bm.GraspState.WRAP, bm.GraspState.RELEASE):
            return
        if self.phase != bm.Phase.OK or self.mode != bm.Mode.GRASP:
            self.grasp_state = bm.GraspState.FAILED if s != bm.GraspState.RELEASE else bm.GraspState.IDLE
            return
        if s == bm.GraspState.REACH and self.outcome == "stall":
            return
        self._ticks_left -= 1
        if self._ticks_left > 0:
            return
        self._ticks_left = self.ticks_per_phase
        if s == bm.GraspState.REACH:
            self.grasp_state = bm.GraspState.FAILED if self.outcome == "fail" else bm.GraspState.WRAP
        elif s == bm.GraspState.WRAP:
            self.grasp_state = bm.GraspState.HOLD
        else:
            self.grasp_state = bm.GraspState.IDLE

    def _telemetry(self) -> bm.Telemetry:
        flags = bm.TelemetryFlags.RC_OK | (bm.TelemetryFlags.ARMED if self.armed else bm.TelemetryFlags.NONE)
        return bm.Telemetry(
            time_us=self._time_us,
            mode=self.mode,
            phase=self.phase,
            grasp_state=self.grasp_state,
            flags=flags,
            motors_online=0b111,
            motor_current=(500, 1000, 1500),
            commanded_current=(500, 1000, 1500),
            tension_target_n=(1.0, 2.0, 3.0),
            tension_est_n=(1.5, 2.5, 3.5),
            cable_length_m=(0.0, 0.0, 0.0),
        )

    def _run(self) -> None:
        while not self._stop.wait(self.period_s):
            with self._lock:
                self._time_us += int(self.period_s * 1e6)
                self._step_grasp()
                tel = self._telemetry()
            self._emit(tel)
