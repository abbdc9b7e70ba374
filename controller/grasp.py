"""The grasp strategy of the paper's Note S4 as a state machine producing one curl tension and a direction.

Strategy on (octopus-inspired, Note S4 / Fig. S6B)::

    IDLE --grasp--> (pack to grasp_pack_n) --> REACH --contact--> WRAP --wrap_n reached--> HOLD
      ^                                          |                  |                       |
      |                                          +--timeout--> FAILED                       |
      +--- dwell at 0 N <-- RELEASE <--release-- (REACH, WRAP, HOLD, FAILED) <--------------+

The grasp *target* :attr:`GraspMachine.target_rad` is the side of the arm the object is on (same
convention as the right stick, ``controller.cables``). :attr:`GraspMachine.direction_rad` is the
direction the present curl tension bends the arm toward.

- IDLE: the arm is held packed (coiled) toward the target with ``grasp_pack_n``, reached at
  ``grasp_pack_rate_n_per_s``. A grasp request waits until the pack tension is reached and the arm has
  settled (pack-side cable slower than ``grasp_contact_speed_m_per_s`` for ``grasp_contact_dwell_us``),
  then reaches.
- REACH: the curl tension ramps down to ``grasp_reach_n`` at ``grasp_reach_rate_n_per_s``: the spiral
  unrolls base-first (a joint's closing tension scales with its size², so the base opens first) and the
  coil rolls out toward the target, paying the pack-side cable out. Contact is the body being blocked:
  while the ramp still runs (in free space a falling tension keeps the cable paying out faster and
  faster), the pack-side cable's pay-out speed falls below ``grasp_contact_slow_ratio`` of the fastest
  pay-out seen in this reach, or below ``grasp_contact_speed_m_per_s``, for ``grasp_contact_dwell_us``,
  with the estimated tension at least ``grasp_contact_min_tension_n``. The cable must first have been
  seen paying out faster than ``grasp_contact_speed_m_per_s`` (a still-settling pack reverses through
  zero speed), and stalls in the first ``grasp_contact_grace_us`` are ignored. No contact within
  ``grasp_reach_timeout_us``: FAILED.
- WRAP: the coil meets the object with its outer face (the side opposite the pack cable), so the
  wrap tension goes to the cables on that face (direction = target + 180°): the still-curled distal
  part uncurls along the object's surface and bends around it ("uncurling the arms along the surface
  to wrap around", Note S4), while the pack-side cable drops to the pretension. Those cables went slack
  while the arm unrolled (a pretension below the drive's friction cannot reel them in), so the wrap
  first takes the slack up: ``grasp_takeup_n``, cut back whenever they reel in faster than
  ``grasp_takeup_speed_m_per_s`` (a fast spool would snap the cable taut), until they have been still
  for ``grasp_contact_dwell_us``; then the tension ramps to ``grasp_wrap_n``.
- HOLD (entered once the wrap tension is reached and the pulling cables have been still for
  ``grasp_contact_dwell_us``: the arm has closed on the object): the tension is kept. With
  ``grasp_hold_min_payin_m`` / ``grasp_hold_max_payin_m`` the cables' pay-in since the wrap began must
  also say the wrap closed around something (not stalled open, not an empty curl), else the grasp is
  FAILED with the figure (its tension kept); with
  ``grasp_hold_length`` the pulling cables' length is held instead (``controller.lengthhold``, engaged
  by the mode selector), so a grasped load does not sag.
- RELEASE: the tension ramps to 0 (uncurl), stays there ``grasp_release_dwell_us``, then IDLE re-packs
  toward the target.

Strategy off (Fig. S6A, for comparison): IDLE holds the arm straight (0 N); a grasp ramps the tension
toward the target from straight up to ``grasp_wrap_n`` (WRAP: the arm curls from the tip), then HOLD;
release as above.

An array (several arms on one board, ``controller.config``) is one gripper: one machine, one curl that
every arm takes (``controller.cables``); it senses with each cable's mean over the arms (the speed and
tension of cable j averaged over every arm's cable j), so contact is the array's arms, on average, being
blocked. With one arm the signals are the cables' own.

Triggers: left lever UP / DOWN edges in GRASP mode, host ``GRASP`` / ``RELEASE`` / ``HOLD`` commands
(MAVLink DO_GRIPPER through the host). The radio stays the master of the host's commands:
:func:`grasp_refusal` is the one rule that says when the radio lets them act (the board's command server
answers with it, and says it again when GRASP mode is left under a command; a host may ask it of the
latest telemetry to refuse at once).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

from controller.cables import bend_shares
from controller.config import FirmwareConfig
from controller.contact import ContactDetector
from controller.events import EventQueue
from protocol.messages import AckResult, EventKind, GraspState, Mode, Phase

__all__ = ["GraspMachine", "grasp_refusal"]


def _name(enum: type[Phase] | type[Mode], value: int) -> str:
    try:
        return enum(value).name
    except ValueError:
        return str(value)


def grasp_refusal(phase: int, armed: bool, mode: int) -> str | None:
    """Why the radio does not let the host command the grasp now (GRASP, RELEASE, HOLD), or None.

    The radio is the master enable: current may flow (failsafe phase OK, armed) and its right lever is
    UP (GRASP mode). The board decides with this rule (``controller.commands``: a refused command is
    answered REJECTED with this text); a host may apply it to the latest ``Telemetry`` (``phase``,
    ``TelemetryFlags.ARMED``, ``mode``) for an answer before the command travels.

    Args:
        phase: the failsafe ``Phase`` (an unknown value reads as not OK).
        armed: current may flow.
        mode: the operating ``Mode``.

    Returns:
        A short reason (at most 40 characters), or None when the grasp may be commanded.
    """
    if phase == Phase.GATE:
        return "start-up gate (lever DOWN first)"
    if phase != Phase.OK:
        return f"failsafe {_name(Phase, phase)}"
    if not armed:
        return "arm not armed"
    if mode != Mode.GRASP:
        return f"mode {_name(Mode, mode)}, lever not UP"
    return None


class GraspMachine:
    """Grasp state machine; :meth:`step` runs once per control tick while the mode is GRASP.

    Attributes:
        state: current ``GraspState``.
        curl_n: curl (bending) tension toward :attr:`direction_rad`, before shaping and slew.
        target_rad: the side of the arm the object is on (same convention as the right stick, see
            ``controller.cables``).
        direction_rad: direction :attr:`curl_n` bends the arm toward: the target while packing and
            reaching (and for the strategy off), the opposite side while wrapping and holding with the
            strategy on.
        pending: a grasp was requested and waits for the arm to be packed.
        detector: the firmware's contact detector (``controller.contact``), consulted in REACH.
        contact_override: None (default), or a true-contact oracle ``(now_us) -> bool`` set by a test
            harness or an experiment: REACH then goes to WRAP on the first tick it returns True and the
            detector is not consulted.
        hold_length: ``grasp_hold_length`` (HOLD holds the pulling cables' length).
        wrap_payin_m: cable the pulling cables have paid in since the wrap began (their filtered
            speed, share-weighted, integrated from the wrap's first tick, take-up included): the evidence
            HOLD is judged on.
    """

    def __init__(self, config: FirmwareConfig, events: EventQueue) -> None:
        """Create the machine in IDLE."""
        self._events = events
        self.state = GraspState.IDLE
        self.curl_n = 0.0
        self.pending = False
        self.contact_override: Callable[[int], bool] | None = None
        self.detector = ContactDetector(config)
        cables = config.cables_per_arm
        self._cables = cables
        self._arms = config.arm_count
        self._shares = [0.0] * cables
        self._wrap_shares = [0.0] * cables
        self._mean_speed = [0.0] * cables  # per cable of an arm, averaged over the arms (arrays only)
        self._mean_tension = [0.0] * cables
        self._taut = True
        self._t_state_us = 0
        self._stall_since_us = -1
        self._zero_since_us = -1
        self.wrap_payin_m = 0.0
        self.configure(config)
        self.target_rad = self._default_dir_rad
        self.direction_rad = self._default_dir_rad
        self._set_target(self.target_rad)

    def configure(self, config: FirmwareConfig) -> None:
        """Take new grasp parameters."""
        g = config.grasp
        self.strategy_on = g.strategy_on
        self._angles_rad = tuple(math.radians(a) for a in config.mapping.cable_angles_deg)
        self._default_dir_rad = math.radians(g.direction_deg)
        self._pack_n = g.pack_n
        self._pack_rate = g.pack_rate_n_per_s / 1e6
        self._reach_n = g.reach_n
        self._wrap_n = g.wrap_n
        self._takeup_n = g.takeup_n
        self._takeup_m_s = g.takeup_speed_m_per_s
        self._reach_rate = g.reach_rate_n_per_s / 1e6
        self._wrap_rate = g.wrap_rate_n_per_s / 1e6
        self._release_rate = g.release_rate_n_per_s / 1e6
        self._stall_m_s = g.contact_speed_m_per_s
        self._dwell_us = g.contact_dwell_us
        self._timeout_us = g.reach_timeout_us
        self._release_dwell_us = g.release_dwell_us
        self.hold_length = g.hold_length
        self._hold_min_m = g.hold_min_payin_m
        self._hold_max_m = g.hold_max_payin_m
        self.detector.configure(config)

    @property
    def idle_curl_n(self) -> float:
        """Curl held in IDLE: packed with the strategy on, straight (0 N) with it off."""
        return self._pack_n if self.strategy_on else 0.0

    def _in_plane(self, target_rad: float) -> float:
        """A two-cable arm bends in its plane: a target there, toward the nearer of its two cables."""
        if self._cables != 2:
            return target_rad
        a0 = self._angles_rad[0]
        return a0 if math.cos(target_rad - a0) >= 0.0 else math.remainder(a0 + math.pi, 2.0 * math.pi)

    def _set_target(self, target_rad: float) -> None:
        target_rad = self._in_plane(target_rad)
        self.target_rad = target_rad
        self.direction_rad = target_rad
        shares = bend_shares(target_rad, self._angles_rad)
        opposite = bend_shares(target_rad + math.pi, self._angles_rad)
        for i in range(self._cables):
            self._shares[i] = shares[i]
            self._wrap_shares[i] = opposite[i]

    def _enter(self, now_us: int, state: GraspState, why: str) -> None:
        self.state = state
        self._t_state_us = now_us
        self._stall_since_us = -1
        self._zero_since_us = -1
        if state == GraspState.REACH:
            self.detector.reset(now_us)
        elif state == GraspState.WRAP:
            self.wrap_payin_m = 0.0
        elif state == GraspState.IDLE:
            self.direction_rad = self.target_rad
        self._events.push(now_us, EventKind.GRASP, int(state), self.curl_n, f"grasp {state.name}: {why}")

    # --- requests ---------------------------------------------------------------------------------

    def reset(self, now_us: int, curl_n: float = 0.0) -> None:
        """Back to IDLE without a pending grasp (leaving GRASP mode), starting from ``curl_n``."""
        self.pending = False
        self.curl_n = curl_n
        self.direction_rad = self.target_rad
        if self.state != GraspState.IDLE:
            self._enter(now_us, GraspState.IDLE, "reset")

    def request_grasp(self, now_us: int, direction_rad: float | None = None) -> AckResult:
        """Start a grasp of an object on the ``direction_rad`` side (None = the configured default).

        Accepted in IDLE, FAILED and RELEASE (the arm re-packs first); refused while one runs.
        """
        if self.state in (GraspState.REACH, GraspState.WRAP, GraspState.HOLD):
            return AckResult.REJECTED
        if direction_rad is not None and not math.isfinite(direction_rad):
            return AckResult.DENIED
        target = self._in_plane(self._default_dir_rad if direction_rad is None else direction_rad)
        if self.curl_n > 0.0 and target != self.direction_rad:
            # Curled toward another side: start the new pack from 0 N (the slew limiter smooths it).
            self.curl_n = 0.0
        self._set_target(target)
        self.pending = True
        if self.state != GraspState.IDLE:
            self._enter(now_us, GraspState.IDLE, "re-pack before grasping")
        return AckResult.ACCEPTED

    def request_release(self, now_us: int) -> AckResult:
        """Uncurl. Cancels a pending grasp in IDLE; a no-op while already releasing."""
        self.pending = False
        if self.state in (GraspState.REACH, GraspState.WRAP, GraspState.HOLD, GraspState.FAILED):
            self._enter(now_us, GraspState.RELEASE, "release requested")
        return AckResult.ACCEPTED

    def request_hold(self, now_us: int) -> AckResult:
        """Freeze the tension during REACH or WRAP (HOLD). Refused in IDLE, RELEASE and FAILED."""
        if self.state == GraspState.HOLD:
            return AckResult.ACCEPTED
        if self.state in (GraspState.REACH, GraspState.WRAP):
            self._enter(now_us, GraspState.HOLD, "hold requested")
            return AckResult.ACCEPTED
        return AckResult.REJECTED

    # --- the tick ---------------------------------------------------------------------------------

    def step(
        self, now_us: int, dt_us: int, cable_speed_m_s: Sequence[float], tension_est_n: Sequence[float]
    ) -> float:
        """Advance one control tick; return the curl tension (N) toward :attr:`direction_rad`.

        Args:
            now_us: board time.
            dt_us: time since the previous tick.
            cable_speed_m_s: per-motor filtered paid-in speed (``MotorModel.cable_speed_m_s``).
            tension_est_n: per-motor estimated tension (``MotorModel.tension_est_n``).
        """
        if self._arms > 1:
            cable_speed_m_s = self._arm_mean(cable_speed_m_s, self._mean_speed)
            tension_est_n = self._arm_mean(tension_est_n, self._mean_tension)
        state = self.state
        curl = self.curl_n
        if state == GraspState.IDLE:
            target = self.idle_curl_n
            if curl < target:
                curl = min(target, curl + self._pack_rate * dt_us)
            elif curl > target:
                curl = max(target, curl - self._release_rate * dt_us)
            self.curl_n = curl
            if (
                self.pending
                and curl == target
                and (not self.strategy_on or self._settled(now_us, cable_speed_m_s))
            ):
                self.pending = False
                if self.strategy_on:
                    self._enter(now_us, GraspState.REACH, "packed, unrolling toward the target")
                else:
                    self._taut = True
                    self._enter(now_us, GraspState.WRAP, "strategy off: plain tension ramp")
        elif state == GraspState.REACH:
            self._reach(now_us, dt_us, cable_speed_m_s, tension_est_n)
        elif state == GraspState.WRAP:
            payin = self._pull_side_speed(cable_speed_m_s)
            self.wrap_payin_m += payin * dt_us * 1e-6
            if not self._taut:
                self._take_up(now_us, payin)
            else:
                curl = min(self._wrap_n, curl + self._wrap_rate * dt_us)
                self.curl_n = curl
                if curl >= self._wrap_n and self._still(now_us, payin):
                    self._closed(now_us)
        elif state == GraspState.RELEASE:
            curl = max(0.0, curl - self._release_rate * dt_us)
            self.curl_n = curl
            if curl <= 0.0:
                if self._zero_since_us < 0:
                    self._zero_since_us = now_us
                if now_us - self._zero_since_us >= self._release_dwell_us:
                    self._enter(now_us, GraspState.IDLE, "released")
        # HOLD and FAILED keep the tension.
        return self.curl_n

    def _closed(self, now_us: int) -> None:
        """The pulling cables came to rest at the wrap tension: HOLD if their pay-in says the wrap closed
        around something (``grasp_hold_min_payin_m`` / ``grasp_hold_max_payin_m``), else FAILED."""
        paid = self.wrap_payin_m
        lo, hi = self._hold_min_m, self._hold_max_m
        if lo > 0.0 and paid < lo:
            why = f"wrap stalled open: {paid * 1e3:.1f} mm paid in < {lo * 1e3:.1f}"
            self._enter(now_us, GraspState.FAILED, why)
        elif hi > 0.0 and paid > hi:
            why = f"empty curl: {paid * 1e3:.1f} mm paid in > {hi * 1e3:.1f}"
            self._enter(now_us, GraspState.FAILED, why)
        elif lo > 0.0 or hi > 0.0:
            self._enter(
                now_us, GraspState.HOLD, f"wrapped: at wrap tension, still, {paid * 1e3:.1f} mm paid in"
            )
        else:  # the rules off: the words every recording before them carries
            self._enter(now_us, GraspState.HOLD, "wrapped: wrap tension reached, cable still")

    def _arm_mean(self, per_motor: Sequence[float], out: list[float]) -> list[float]:
        """Each cable's value averaged over the arms (motor m = cable (m-1) % C of arm (m-1) // C)."""
        c = self._cables
        arms = self._arms
        for j in range(c):
            total = 0.0
            for a in range(arms):
                total += per_motor[a * c + j]
            out[j] = total / arms
        return out

    def _settled(self, now_us: int, cable_speed_m_s: Sequence[float]) -> bool:
        """The pack-side cable has been still (slower than the stall speed) for the contact dwell time.

        A reach that starts while the arm still moves would take the end of that motion for contact.
        """
        speed, _ = self._pack_side(cable_speed_m_s, cable_speed_m_s)
        return self._still(now_us, speed)

    def _reach(
        self, now_us: int, dt_us: int, cable_speed_m_s: Sequence[float], tension_est_n: Sequence[float]
    ) -> None:
        curl = self.curl_n
        ramping = curl > self._reach_n
        if ramping:
            curl = max(self._reach_n, curl - self._reach_rate * dt_us)
            self.curl_n = curl
        elapsed = now_us - self._t_state_us
        oracle = self.contact_override
        if oracle is not None:
            if oracle(now_us):
                self._contact(now_us, "contact (true-contact oracle)")
        else:
            speed, tension = self._pack_side(cable_speed_m_s, tension_est_n)
            s = self._wrap_shares
            wrap = _dot(s, cable_speed_m_s) / sum(s)
            if self.detector.update(now_us, dt_us, ramping, speed, tension, wrap):
                self._contact(now_us, f"contact ({self.detector.reason})")
        if self.state == GraspState.REACH and elapsed >= self._timeout_us:
            self._enter(now_us, GraspState.FAILED, "no contact before the reach timeout")

    def _contact(self, now_us: int, why: str) -> None:
        """Contact: wrap with the cables on the coil's outer face (the face that met the object)."""
        self.curl_n = 0.0
        self.direction_rad = math.remainder(self.target_rad + math.pi, 2.0 * math.pi)
        self._enter(now_us, GraspState.WRAP, why)
        self._taut = self._takeup_n <= 0.0

    def _take_up(self, now_us: int, payin: float) -> None:
        """Reel the wrap-side cables' slack in at a bounded speed (``payin``: their paid-in speed); taut
        once they stay still."""
        self.curl_n = self._takeup_n if payin < self._takeup_m_s else 0.0
        if self._still(now_us, payin):
            self._taut = True
            self._stall_since_us = -1

    def _still(self, now_us: int, speed_m_s: float) -> bool:
        """``speed_m_s`` has stayed within ± the stall speed for the dwell time (call every tick)."""
        if -self._stall_m_s < speed_m_s < self._stall_m_s:
            if self._stall_since_us < 0:
                self._stall_since_us = now_us
            return now_us - self._stall_since_us >= self._dwell_us
        self._stall_since_us = -1
        return False

    def _pull_side_speed(self, speed_m_s: Sequence[float]) -> float:
        """Share-weighted paid-in speed of the cables that pull toward :attr:`direction_rad`."""
        s = self._wrap_shares if self.direction_rad != self.target_rad else self._shares
        return _dot(s, speed_m_s) / sum(s)

    def pull_shares(self) -> Sequence[float]:
        """Per-cable bending shares of the present curl (which cables pull toward :attr:`direction_rad`)."""
        return self._wrap_shares if self.direction_rad != self.target_rad else self._shares

    def _pack_side(self, speed_m_s: Sequence[float], tension_n: Sequence[float]) -> tuple[float, float]:
        """Share-weighted paid-in speed and estimated tension of the pack-side (target-side) cables."""
        s = self._shares
        total = sum(s)  # >= 1 for three cables at 120° and two at 180°; 1 for one cable
        return _dot(s, speed_m_s) / total, _dot(s, tension_n) / total


def _dot(shares: Sequence[float], values: Sequence[float]) -> float:
    """``shares[0]*values[0] + shares[1]*values[1] + ...`` over the cables of one arm, left to right."""
    acc = shares[0] * values[0]
    for i in range(1, len(shares)):
        acc += shares[i] * values[i]
    return acc
