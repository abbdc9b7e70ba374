"""Mode selection and the tension targets of each mode (Betaflight's ``fc/rc_modes.c`` counterpart).

The failsafe phase and the right lever own the mode; the host may only choose between MANUAL and
DIRECT while the lever is MIDDLE (``SET_MODE``):

- phase not ``OK`` (or no valid frame yet): SAFE, zero current.
- right lever DOWN: SAFE. UP: GRASP (the grasp state machine, driven by the left lever or host commands).
- right lever MIDDLE: MANUAL (sticks), or DIRECT (host tensions) while the host asked for it and its
  heartbeat is fresh; DIRECT ends when the heartbeat is lost.

The DIRECT request and tensions are reset (tensions to the pretension) on every SAFE (disarm, RC loss,
every failsafe), on heartbeat loss and, through the command server, on link loss.

Every mode change drops every length-hold (``controller.lengthhold``); with ``grasp_hold_length`` the
grasp's HOLD state holds its pulling cables' length until it ends.

Runs on the control tick: :meth:`ModeSelector.select` once per tick, :meth:`ModeSelector.grasp_targets`
once per tick in GRASP. Neither allocates unless the mode or the grasp state changes.
"""

from __future__ import annotations

from typing import Protocol

from controller.cables import CableMapper, MotorModel
from controller.config import FirmwareConfig
from controller.events import EventQueue
from controller.failsafe import Failsafe
from controller.grasp import GraspMachine, grasp_refusal
from controller.lengthhold import LengthHold
from protocol.dbus import Lever, RcFrame
from protocol.messages import EventKind, GraspState, Mode, Phase

__all__ = ["GRASP_STICK_MIN", "GraspListener", "ModeSelector"]

GRASP_STICK_MIN = 0.5
"""Right stick deflection (of full scale) that picks the grasp direction."""
_PULLING_SHARE = 1e-6  # a cable with a larger bending share pulls (the others sit at the pretension)

# Enum members the control tick compares by identity (no class attribute lookup per tick).
_SAFE, _MANUAL, _DIRECT, _GRASP = Mode.SAFE, Mode.MANUAL, Mode.DIRECT, Mode.GRASP
_HOLD = GraspState.HOLD
_PHASE_OK = Phase.OK
_LEVER_MIDDLE, _LEVER_UP = Lever.MIDDLE, Lever.UP


class GraspListener(Protocol):
    """Told when the grasp state changes or GRASP mode is left (the command server's pending acks)."""

    def grasp_progress(self, state: GraspState) -> None:
        """The grasp state machine moved to ``state``."""

    def grasp_left(self, why: str) -> None:
        """GRASP mode was left (``why``: the radio's reason, :func:`~controller.grasp.grasp_refusal`):
        whatever the host awaits from the grasp has failed."""


class ModeSelector:
    """The operating mode, the host's DIRECT request and tensions, and the grasp lever edges.

    Attributes:
        mode: the mode of the last control tick.
        direct_requested: the host asked for DIRECT (cleared when the lever leaves MIDDLE or the
            heartbeat is lost).
        direct_tensions_n: the host's tensions for DIRECT (clamped by ``SET_TENSIONS``), one per cable
            of an arm: every arm of an array takes them.
    """

    def __init__(
        self,
        config: FirmwareConfig,
        failsafe: Failsafe,
        grasp: GraspMachine,
        mapper: CableMapper,
        motors: MotorModel,
        hold: LengthHold,
        events: EventQueue,
        listener: GraspListener,
    ) -> None:
        """Start in SAFE, DIRECT tensions at the pretension."""
        self._hold = hold
        self._failsafe = failsafe
        self._grasp = grasp
        self._mapper = mapper
        self._motors = motors
        self._events = events
        self._listener = listener
        self.mode = Mode.SAFE
        self.direct_requested = False
        self._pretension_n = config.mapping.pretension_n
        self.direct_tensions_n = [self._pretension_n] * config.cables_per_arm
        self._cables = config.cables_per_arm
        self._arms = config.arm_count
        self._prev_left_lever = 0
        self._prev_grasp_state = GraspState.IDLE

    def configure(self, config: FirmwareConfig) -> None:
        """Take a new pretension (what :meth:`reset_direct` sets the DIRECT tensions to)."""
        self._pretension_n = config.mapping.pretension_n

    def reset_direct(self) -> None:
        """Forget the host's DIRECT request and tensions (every SAFE, heartbeat loss and link loss).

        A host that re-arms and selects DIRECT then starts from the pretension, never from the tensions
        a previous session (or another host) left behind.
        """
        self.direct_requested = False
        tensions = self.direct_tensions_n
        for i in range(len(tensions)):
            tensions[i] = self._pretension_n

    def select(self, now_us: int, phase: Phase, rc: RcFrame | None) -> Mode:
        """The mode for this tick from the phase and the last valid frame ``rc`` (logs a change)."""
        if phase is not _PHASE_OK or rc is None:
            mode = _SAFE
        else:
            lever = rc.right_lever
            if lever == _LEVER_MIDDLE:
                if self.direct_requested and not self._failsafe.host_ok:
                    self.reset_direct()
                    self._events.push(now_us, EventKind.INFO, 0, 0.0, "DIRECT ended: no host heartbeat")
                mode = _DIRECT if self.direct_requested else _MANUAL
            elif lever == _LEVER_UP:
                mode = _GRASP
            else:
                mode = _SAFE
        if mode is not self.mode:
            self._changed(now_us, self.mode, mode, rc, phase)
        return mode

    def _changed(self, now_us: int, old: Mode, new: Mode, rc: RcFrame | None, phase: Phase) -> None:
        self.mode = new
        # A hold belongs to the mode it was set in; SAFE (every failsafe) and any other change drop it.
        self._hold.release_all()
        if new == Mode.SAFE:  # every disarm, failsafe and E-stop: the next DIRECT starts from rest
            self.reset_direct()
        elif new != Mode.DIRECT and new != Mode.MANUAL:
            self.direct_requested = False  # DIRECT only while the lever stays MIDDLE
        if old == Mode.GRASP:
            self._grasp.reset(now_us)
            self._listener.grasp_left(grasp_refusal(phase, phase is _PHASE_OK, new) or f"mode {new.name}")
        if new == Mode.GRASP:
            self._grasp.reset(now_us)
            self._prev_left_lever = rc.left_lever if rc else 0
            self._prev_grasp_state = self._grasp.state
        self._events.push(now_us, EventKind.MODE, int(new), 0.0, f"mode {new.name}")

    def grasp_targets(self, now_us: int, dt_us: int, rc: RcFrame) -> list[float]:
        """GRASP's tension targets: left lever edges request grasp (UP) / release (DOWN), then one step."""
        grasp = self._grasp
        left = rc.left_lever
        if left != self._prev_left_lever:
            self._prev_left_lever = left
            if left == Lever.UP:
                grasp.request_grasp(now_us, self._mapper.stick_direction(rc.channels, GRASP_STICK_MIN))
            elif left == Lever.DOWN:
                grasp.request_release(now_us)
        motors = self._motors
        curl = grasp.step(now_us, dt_us, motors.cable_speed_m_s, motors.tension_est_n)
        state = grasp.state
        if state != self._prev_grasp_state:
            if self._prev_grasp_state is _HOLD:
                self._hold.release_grasp()
            self._prev_grasp_state = state
            if state is _HOLD and grasp.hold_length:
                self._hold_pulling_cables()
            self._listener.grasp_progress(state)
        return self._mapper.curl(curl, grasp.direction_rad)

    def _hold_pulling_cables(self) -> None:
        """``grasp_hold_length``: HOLD freezes the length of the cables that pull the wrap (on every arm)."""
        hold = self._hold
        cables = self._cables
        for i, share in enumerate(self._grasp.pull_shares()):
            if share > _PULLING_SHARE:
                for arm in range(self._arms):
                    hold.engage(arm * cables + i, by_grasp=True)
