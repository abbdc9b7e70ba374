"""The scripted fake board of the host tests: a toy firmware that speaks board-link messages.

One fake, two shells. :class:`FakeBoard` is the toy firmware: host -> board messages in
(:meth:`~FakeBoard.handle`), replies and telemetry out (:meth:`~FakeBoard.tick`, :meth:`~FakeBoard.poses`),
time given, no I/O. Run in-process (:meth:`~FakeBoard.attach` a sink, :meth:`~FakeBoard.start` its
100 Hz thread) it is the board behind the drone link; ``tests/support/link_peer.py`` puts the same
object behind a real pty or TCP socket for the host's link client, the CLI and the panel.

What it does, so host tests can see cause and effect:

- parameters: every run-time parameter of the firmware's table (``controller.params``) by wire name,
  with its default, in index order; a ``ParamSet`` is checked with the firmware's own rule
  (``FirmwareConfig.with_param``, against the other values; the SAFE-only rule is not modelled) and
  answered with the value in force, as the firmware does;
- commands: ``ESTOP`` latches, ``GRASP`` / ``RELEASE`` / ``HOLD`` run a grasp a few telemetry ticks per
  phase when armed in GRASP (tests choose how it ends), anything else is accepted;
- radio: before any ``VirtualRc`` frame, tests set mode, phase and arming; once frames arrive, the
  firmware's gate rules decide them (a valid frame with the right lever DOWN passes the gate, the right
  lever picks SAFE / MANUAL / GRASP, 30 ms without a valid frame is RC_LOST) and in MANUAL the left stick
  sets the common tension from the ``PRETENSION_N`` and ``COMMON_MAX_N`` parameters.

This is a unit-test fake only: the real virtual board is ``hil.board``.
"""

from __future__ import annotations

import math
import threading
from collections.abc import Callable
from dataclasses import dataclass, field

from controller.config import FirmwareConfig
from controller.errors import ConfigError
from controller.params import WIRE_ROWS, default
from protocol import messages as bm
from protocol.dbus import Lever, RcFrame

_POWER_UP: dict[str, float] = {name: float(row.default) for name, row in WIRE_ROWS.items()}
"""The fake's parameters at power-up: the firmware's run-time parameters and defaults, in index order."""

RC_TIMEOUT_US: int = default("failsafe.rc_timeout_us")
UNITS = 21
"""Units of the arm drawn by :meth:`FakeBoard.poses`."""

_MODE_OF_LEVER = {Lever.DOWN: bm.Mode.SAFE, Lever.MIDDLE: bm.Mode.MANUAL, Lever.UP: bm.Mode.GRASP}
_MOVING = (bm.GraspState.REACH, bm.GraspState.WRAP, bm.GraspState.RELEASE)


@dataclass
class FakeBoard:
    """Firmware-like fake. In-process: ``attach`` it to a sink (``DroneLink.on_board_message``), ``start``.

    Attributes:
        mode: Operating mode shown in telemetry.
        phase: Failsafe phase shown in telemetry.
        armed: ARMED flag.
        grasp_state: Grasp state machine.
        outcome: How the next grasp ends: "hold", "fail" or "stall" (never finishes).
        ticks_per_phase: Telemetry ticks spent in REACH, WRAP and RELEASE.
        answer_param_set: False = ignore ``ParamSet`` (a board that never confirms).
        answer_param_list: False = ignore a ``ParamRequest`` for all (a board slow to list).
        defer_param_set: True = take ``ParamSet`` values but confirm them only on
            :meth:`confirm_param_sets` (a slow board).
        tension_n: Cable tensions shown in telemetry (targets and estimates; the radio sets them).
        current_raw: Motor currents shown in telemetry (C610 raw, 1000 per amp).
        sim: A simulated board: the SIM flag, and poses to draw (:meth:`poses`).
        period_s: Telemetry period of the in-process thread.
        params: Parameter values by wire name, in index order.
        received: Every message the host sent to the board, in order.
        rc: The last valid radio frame (None until one arrives).
        lock: Held while a message is handled or a tick runs.
    """

    mode: bm.Mode = bm.Mode.GRASP
    phase: bm.Phase = bm.Phase.OK
    armed: bool = True
    grasp_state: bm.GraspState = bm.GraspState.IDLE
    outcome: str = "hold"
    ticks_per_phase: int = 5
    answer_param_set: bool = True
    answer_param_list: bool = True
    defer_param_set: bool = False
    tension_n: tuple[float, float, float] = (1.5, 2.5, 3.5)
    current_raw: tuple[int, int, int] = (500, 1000, 1500)
    sim: bool = False
    period_s: float = 0.01
    params: dict[str, float] = field(default_factory=lambda: dict(_POWER_UP))
    received: list[bm.Message] = field(default_factory=list)
    rc: RcFrame | None = None
    lock: threading.Lock = field(default_factory=threading.Lock)
    _sink: Callable[[bm.Message], None] | None = None
    _stop: threading.Event = field(default_factory=threading.Event)
    _thread: threading.Thread | None = None
    _ticks_left: int = 0
    _time_us: int = 0
    _rc_time_us: int = 0
    _deferred: list[str] = field(default_factory=list)

    # ---- the in-process shell ---------------------------------------------------------------------

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

    def __call__(self, msg: bm.Message) -> None:
        """``send_to_board``: handle one host -> board message, replies to the sink."""
        for r in self.handle(msg):
            self._emit(r)

    def _emit(self, msg: bm.Message) -> None:
        if self._sink is not None:
            self._sink(msg)

    def _run(self) -> None:
        while not self._stop.wait(self.period_s):
            self._emit(self.tick(self._time_us + int(self.period_s * 1e6)))

    # ---- tests steer it ---------------------------------------------------------------------------

    def set(self, **state: object) -> None:
        """Change mode / phase / armed / grasp_state / outcome atomically."""
        with self.lock:
            for k, v in state.items():
                setattr(self, k, v)
            if "grasp_state" in state:
                self._ticks_left = self.ticks_per_phase

    def confirm_param_sets(self) -> None:
        """Confirm the deferred ``ParamSet`` values now (``defer_param_set``)."""
        with self.lock:
            replies = [self._pv(name) for name in self._deferred]
            self._deferred.clear()
        for r in replies:
            self._emit(r)

    def commands(self) -> list[bm.Command]:
        """The ``Command`` messages received so far."""
        with self.lock:
            return [m for m in self.received if isinstance(m, bm.Command)]

    def emit_event(self, kind: bm.EventKind, code: int, text: str) -> None:
        """Send an ``Event`` now."""
        self._emit(bm.Event(self._time_us, kind, code, 0.0, text))

    # ---- host -> board ----------------------------------------------------------------------------

    def handle(self, msg: bm.Message, seq: int = 0, now_us: int | None = None) -> list[bm.Message]:
        """Handle one host -> board message; return the replies.

        Args:
            msg: The message.
            seq: Its frame's sequence number (a ``CommandAck`` carries it).
            now_us: When it arrived (board time); default: the last tick's time.
        """
        with self.lock:
            self.received.append(msg)
            return self._handle(msg, seq, self._time_us if now_us is None else now_us)

    def _handle(self, msg: bm.Message, seq: int, now_us: int) -> list[bm.Message]:
        if isinstance(msg, bm.VirtualRc):
            if msg.frame.is_valid():
                self.rc, self._rc_time_us = msg.frame, now_us
            return []
        if isinstance(msg, bm.ParamRequest):
            names = list(self.params)
            if msg.index == bm.PARAM_LIST_ALL:
                return [self._pv(n) for n in names] if self.answer_param_list else []
            if msg.index >= 0:
                return [self._pv(names[msg.index])] if msg.index < len(names) else []
            return [self._pv(msg.name)] if msg.name in self.params else []
        if isinstance(msg, bm.ParamSet):
            if msg.name not in self.params or not self.answer_param_set:
                return []
            if self._takes(msg.name, msg.value):  # a refused value is answered with the one in force
                self.params[msg.name] = msg.value
            if self.defer_param_set:
                self._deferred.append(msg.name)
                return []
            return [self._pv(msg.name)]
        if isinstance(msg, bm.Command):
            return [self._command(msg, seq)]
        return []

    def _takes(self, name: str, value: float) -> bool:
        """The firmware's rule for a ``ParamSet``, against the fake's other values."""
        others = {n: v for n, v in self.params.items() if n != name}
        try:
            FirmwareConfig().with_board_values(others).with_param(name, value)
        except ConfigError:
            return False
        return True

    def _pv(self, name: str) -> bm.ParamValue:
        names = list(self.params)
        return bm.ParamValue(names.index(name), len(names), name, self.params[name])

    def _command(self, cmd: bm.Command, seq: int) -> bm.CommandAck:
        code = cmd.code
        if code == bm.CommandCode.ESTOP:
            self.phase, self.mode, self.armed = bm.Phase.ESTOP, bm.Mode.SAFE, False
            return bm.CommandAck(code, bm.AckResult.ACCEPTED, seq, "ok")
        if code in (bm.CommandCode.GRASP, bm.CommandCode.RELEASE, bm.CommandCode.HOLD):
            if not (self.armed and self.phase == bm.Phase.OK and self.mode == bm.Mode.GRASP):
                return bm.CommandAck(code, bm.AckResult.DENIED, seq, "not in GRASP")
            if self.grasp_state in _MOVING:
                return bm.CommandAck(code, bm.AckResult.REJECTED, seq, "busy")
            if code == bm.CommandCode.GRASP:
                self.grasp_state = bm.GraspState.REACH
            elif code == bm.CommandCode.RELEASE:
                self.grasp_state = bm.GraspState.RELEASE
            else:
                self.grasp_state = bm.GraspState.HOLD
            self._ticks_left = self.ticks_per_phase
            return bm.CommandAck(code, bm.AckResult.ACCEPTED, seq)
        return bm.CommandAck(code, bm.AckResult.ACCEPTED, seq, "ok")

    # ---- board -> host ----------------------------------------------------------------------------

    def tick(self, now_us: int) -> bm.Telemetry:
        """One telemetry period at board time ``now_us``: the radio's rules, a grasp step, the telemetry."""
        with self.lock:
            self._time_us = now_us
            self._radio(now_us)
            self._step_grasp()
            return self._telemetry()

    def poses(self) -> bm.SimPoses:
        """Body poses of a simulated arm bending with the tension (drone first, then ``UNITS`` units)."""
        with self.lock:
            bend = 0.02 * sum(self.tension_n) / len(self.tension_n)
            now_us = self._time_us
        pos = [(0.0, 0.0, 1.2)]
        quat = [(1.0, 0.0, 0.0, 0.0)]
        x, z = 0.0, 1.17
        for i in range(UNITS):
            ang = bend * i
            pos.append((x, 0.0, z))
            quat.append((math.cos(ang / 2), 0.0, math.sin(ang / 2), 0.0))
            step = 0.015 * 1.075 ** (-i)
            x += step * math.sin(ang)
            z -= step * math.cos(ang)
        return bm.SimPoses(now_us, tuple(pos), tuple(quat))

    def _radio(self, now_us: int) -> None:
        """The firmware's gate and levers, once the radio has spoken (before, tests set the state)."""
        rc = self.rc
        if rc is None:
            return
        if self.phase == bm.Phase.ESTOP:
            self.mode = bm.Mode.SAFE
        elif now_us - self._rc_time_us > RC_TIMEOUT_US:
            if self.phase != bm.Phase.GATE:
                self.phase = bm.Phase.RC_LOST
        elif self.phase in (bm.Phase.GATE, bm.Phase.RC_LOST):
            if rc.right_lever == Lever.DOWN:
                self.phase = bm.Phase.OK
        elif self.phase == bm.Phase.OK:
            self.mode = _MODE_OF_LEVER[Lever(rc.right_lever)]
        self.armed = self.phase == bm.Phase.OK
        tension = 0.0
        if self.phase == bm.Phase.OK and self.mode == bm.Mode.MANUAL:
            p = self.params
            tension = p["PRETENSION_N"] + max(0, rc.channels[3]) / 660 * p["COMMON_MAX_N"]
        raw = round(tension * self.params["SPOOL_RADIUS_M"] / self.params["TORQUE_K_NM_A"] * 1000)
        self.tension_n = (tension, tension, tension)
        self.current_raw = (raw, raw, raw)

    def _step_grasp(self) -> None:
        s = self.grasp_state
        if s not in _MOVING:
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
        flags = bm.TelemetryFlags.NONE
        if self.sim:
            flags |= bm.TelemetryFlags.SIM
        if self.armed:
            flags |= bm.TelemetryFlags.ARMED
        if self.phase == bm.Phase.OK:
            flags |= bm.TelemetryFlags.RC_OK
        rc = self.rc
        t = self.tension_n
        return bm.Telemetry(
            time_us=self._time_us,
            mode=self.mode,
            phase=self.phase,
            grasp_state=self.grasp_state,
            flags=flags,
            motors_online=0b111,
            rc_channels=rc.channels if rc else (0, 0, 0, 0),
            right_lever=rc.right_lever if rc else 0,
            left_lever=rc.left_lever if rc else 0,
            commanded_current=self.current_raw,
            motor_current=self.current_raw,
            tension_target_n=t,
            tension_est_n=t,
            cable_length_m=(0.001 * t[0], 0.001 * t[1], 0.001 * t[2]),
        )
