"""The failsafe phase machine (explicit phases driven by events, like Betaflight's ``failsafe.c``).

Inputs are events with board time — a valid RC frame, a motor feedback frame, a host heartbeat, host
commands — and :meth:`Failsafe.update`, called by the control task at the start of every tick, applies
the timeouts. Output may flow only in phase ``OK``; every other phase means zero current on this tick.

Phases (``protocol.messages.Phase``) and transitions:

- ``GATE`` (start-up, after DISARM, after CLEAR_ESTOP): leaves for ``OK`` when RC is valid and fresh,
  the right lever is DOWN (SAFE), all motors answer, the host heartbeat is fresh if required, and the
  host has not disarmed the board (ARM clears that). Like an arming switch.
- ``OK`` -> ``MOTOR_FAULT`` when any motor (of 1-8) is silent longer than ``motor_timeout_us`` (DJI: 10 ms).
  Latched: leaves only when every motor answers again *and* the right lever is seen DOWN (re-armed
  through SAFE).
- ``OK`` -> ``RC_LOST`` after ``rc_timeout_us`` (DJI: 30 ms) without a valid frame. Latched: leaves
  only when valid frames return *and* show the right lever DOWN (re-armed through SAFE), so an arm never
  jumps back to the stick positions of a radio that comes back into range.
- ``OK`` -> ``HOST_LOST`` when the host is required and its heartbeat is older than
  ``host_timeout_us``. Latched the same way: heartbeats back *and* the right lever seen DOWN.
- any -> ``ESTOP`` on the ESTOP command. Latched: CLEAR_ESTOP moves to ``GATE``, which needs the
  right lever DOWN again.

:meth:`Failsafe.update` is a switch on the phase, each case owning its exits. A fault latched when an
E-stop or DISARM takes over holds again once they are gone (GATE shows it). Priority when several
hold: ESTOP > MOTOR_FAULT > RC_LOST > HOST_LOST. :meth:`Failsafe.arm_blocker` names what holds the
gate. Invalid RC frames never reach this module (the control task rejects and counts them).
"""

from __future__ import annotations

from collections.abc import Iterable

from controller.config import FirmwareConfig
from controller.events import EventQueue
from protocol.dbus import Lever
from protocol.messages import ArmBlocker, EventKind, Phase

__all__ = ["Failsafe"]

# Members as module constants: the tick compares them by identity without a class lookup each time.
_GATE, _OK, _ESTOP = Phase.GATE, Phase.OK, Phase.ESTOP
_RC_LOST, _HOST_LOST, _MOTOR_FAULT = Phase.RC_LOST, Phase.HOST_LOST, Phase.MOTOR_FAULT
_DOWN = Lever.DOWN

_PHASE_TEXT = {
    Phase.GATE: "gate: waiting for valid RC with the right lever DOWN",
    Phase.OK: "ok: armed",
    Phase.RC_LOST: "RC lost: zero current",
    Phase.MOTOR_FAULT: "motor fault: all stop, re-arm through SAFE",
    Phase.HOST_LOST: "host heartbeat lost: zero current",
    Phase.ESTOP: "E-stop: latched",
}


class Failsafe:
    """Failsafe phase machine for the board's motors (1-8), one RC link and an optional host.

    Attributes:
        phase: current phase.
        estop_latched: an E-stop is in force (until CLEAR_ESTOP).
        host_disarmed: the host sent DISARM (until ARM).
        host_required: the host heartbeat is required.
        motors_online: bit i set = motor i+1 answered within ``motor_timeout_us`` (updated every tick).
        motor_offline_events: times a motor went from online to silent.
        rc_ok: a valid RC frame within ``rc_timeout_us`` (as of the last update).
        host_ok: a heartbeat within ``host_timeout_us`` (as of the last update).
    """

    def __init__(self, config: FirmwareConfig, events: EventQueue) -> None:
        """Start in ``GATE`` with nothing seen."""
        self._events = events
        self.phase = Phase.GATE
        self.estop_latched = False
        self.host_disarmed = False
        self._latched: Phase | None = None  # MOTOR_FAULT, RC_LOST or HOST_LOST until re-armed through SAFE
        self.motors_online = 0
        self.motor_offline_events = 0
        self.rc_ok = False
        self.host_ok = False
        self._rc_seen = False
        self._last_rc_us = 0
        self._right_lever = 0
        self._hb_seen = False
        self._last_hb_us = 0
        n = config.motor_count  # a start-up setting: configure() never changes it
        self._motor_count = n
        self._fb_seen = [False] * n
        self._last_fb_us = [0] * n
        self._all_motors = (1 << n) - 1
        self.configure(config)

    def configure(self, config: FirmwareConfig) -> None:
        """Take new timeouts and the host requirement."""
        c = config.failsafe
        self._rc_timeout_us = c.rc_timeout_us
        self._motor_timeout_us = c.motor_timeout_us
        self._host_timeout_us = c.host_timeout_us
        self.host_required = c.host_required

    @property
    def armed(self) -> bool:
        """Current may flow: phase ``OK`` (gate passed, no latched fault, nothing lost)."""
        return self.phase == Phase.OK

    # --- events -----------------------------------------------------------------------------------

    def on_rc_frame(self, now_us: int, right_lever: int) -> None:
        """A *valid* RC frame arrived (invalid frames must not be passed here)."""
        self._rc_seen = True
        self._last_rc_us = now_us
        self._right_lever = right_lever

    def on_motor_frames(self, now_us: int, frames: Iterable[tuple[int, object]]) -> None:
        """The motors in ``frames`` answered (``(motor 1..n, frame)`` pairs from ``read_feedback``)."""
        seen = self._fb_seen
        last = self._last_fb_us
        for motor, _ in frames:
            seen[motor - 1] = True
            last[motor - 1] = now_us

    def on_heartbeat(self, now_us: int) -> None:
        """The host's heartbeat arrived."""
        self._hb_seen = True
        self._last_hb_us = now_us

    def estop(self, now_us: int) -> None:
        """E-stop: zero current now, latched until :meth:`clear_estop` and a pass through SAFE."""
        self.estop_latched = True
        self._set(now_us, Phase.ESTOP)

    def clear_estop(self, now_us: int) -> bool:
        """Release the E-stop latch (the gate then needs the right lever DOWN). False if none was set."""
        if not self.estop_latched:
            return False
        self.estop_latched = False
        self._set(now_us, Phase.GATE)
        return True

    def disarm(self, now_us: int) -> None:
        """Host DISARM: back to the gate until ARM (and the right lever DOWN)."""
        self.host_disarmed = True
        if self.phase is not _ESTOP and self._latched is not _MOTOR_FAULT:
            self._set(now_us, Phase.GATE)

    def arm(self) -> bool:
        """Host ARM: allow the gate to pass again. False (refused) while an E-stop is latched."""
        if self.estop_latched:
            return False
        self.host_disarmed = False
        return True

    # --- the tick ---------------------------------------------------------------------------------

    def update(self, now_us: int) -> Phase:
        """Apply the timeouts at ``now_us`` and return the phase for this tick.

        Runs every control tick: a switch on the phase, each case deciding its own exits, with a single
        phase change at the end.
        """
        rc_ok = self._rc_seen and now_us - self._last_rc_us <= self._rc_timeout_us
        self.rc_ok = rc_ok
        host_ok = self._hb_seen and now_us - self._last_hb_us <= self._host_timeout_us
        self.host_ok = host_ok
        mask = 0
        timeout = self._motor_timeout_us
        seen = self._fb_seen
        last = self._last_fb_us
        for i in range(self._motor_count):
            if seen[i] and now_us - last[i] <= timeout:
                mask |= 1 << i
        if mask != self.motors_online:
            self._motors_changed(now_us, self.motors_online, mask)
        motors_ok = mask == self._all_motors
        lever_down = rc_ok and self._right_lever == _DOWN
        host_fine = host_ok or not self.host_required

        phase = self.phase
        if phase is _GATE and self._latched is not None:
            phase = self._latched  # a fault latched before an E-stop or DISARM holds again
        match phase:
            case Phase.OK:
                if not motors_ok:
                    phase = self._latched = _MOTOR_FAULT
                elif not rc_ok:
                    phase = self._latched = _RC_LOST
                elif not host_fine:
                    phase = self._latched = _HOST_LOST
            case Phase.GATE:
                phase = self._gate(rc_ok, lever_down, motors_ok, host_fine)
            case Phase.MOTOR_FAULT:  # every motor back, and re-armed through SAFE
                if motors_ok and lever_down:
                    self._latched = None
                    phase = self._gate(rc_ok, lever_down, motors_ok, host_fine)
            case Phase.RC_LOST:  # valid frames back, showing the lever DOWN
                if rc_ok and lever_down:
                    self._latched = None
                    phase = self._gate(rc_ok, lever_down, motors_ok, host_fine)
            case Phase.HOST_LOST:  # heartbeats back (or no longer required), and the lever DOWN
                if host_fine and lever_down:
                    self._latched = None
                    phase = self._gate(rc_ok, lever_down, motors_ok, host_fine)
            case Phase.ESTOP:  # left only by CLEAR_ESTOP (:meth:`clear_estop`), to GATE
                pass
        return self._set(now_us, phase)

    def _gate(self, rc_ok: bool, lever_down: bool, motors_ok: bool, host_fine: bool) -> Phase:
        """The arming gate: ``OK`` when every condition holds, else ``GATE``."""
        if rc_ok and lever_down and motors_ok and host_fine and not self.host_disarmed:
            return _OK
        return _GATE

    def arm_blocker(self) -> ArmBlocker:
        """What holds the arming gate shut as of the last :meth:`update` (``NONE`` in phase ``OK``).

        The first of: E-stop latched, a motor silent, RC invalid, host heartbeat missing (when
        required), host DISARM, right lever not seen DOWN. Not called by the control tick: the telemetry
        builder asks for it.
        """
        if self.phase is _OK:
            return ArmBlocker.NONE
        if self.estop_latched:
            return ArmBlocker.ESTOP_LATCHED
        if self.motors_online != self._all_motors:
            return ArmBlocker.MOTOR_FAULT
        if not self.rc_ok:
            return ArmBlocker.RC_INVALID
        if self.host_required and not self.host_ok:
            return ArmBlocker.HOST_MISSING
        if self.host_disarmed:
            return ArmBlocker.DISARMED
        if self._right_lever != _DOWN:
            return ArmBlocker.LEVER_NOT_DOWN
        return ArmBlocker.NONE  # every condition holds: the gate opens on the next tick

    def _set(self, now_us: int, phase: Phase) -> Phase:
        if phase is not self.phase:
            self.phase = phase
            self._events.push(now_us, EventKind.PHASE, int(phase), 0.0, _PHASE_TEXT[phase])
        return phase

    def _motors_changed(self, now_us: int, old: int, new: int) -> None:
        self.motors_online = new
        for i in range(self._motor_count):
            bit = 1 << i
            if old & bit and not new & bit:
                self.motor_offline_events += 1
                self._events.push(now_us, EventKind.FAULT, i + 1, 0.0, f"motor {i + 1} offline")
            elif new & bit and not old & bit:
                self._events.push(now_us, EventKind.INFO, i + 1, 1.0, f"motor {i + 1} online")
