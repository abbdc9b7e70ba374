"""The grasp strategy of seed Note S4 as a state machine producing one curl tension and a direction.

Strategy on (octopus-inspired, Note S4 / Fig. S6B)::

    IDLE --grasp--> (pack to grasp_pack_n) --> REACH --contact--> WRAP --wrap_n reached--> HOLD
      ^                                          |                  |                       |
      |                                          +--timeout--> FAILED                       |
      +--- dwell at 0 N <-- RELEASE <--release-- (REACH, WRAP, HOLD, FAILED) <--------------+

- IDLE: the arm is held packed (coiled) toward the grasp direction with ``grasp_pack_n``. A grasp
  request waits until the pack tension is reached, then starts the reach.
- REACH: the curl tension ramps down to ``grasp_reach_n``: the spiral arm unrolls base-first toward the
  target side, paying the object-side cable out. Contact = after that cable has been seen paying out
  (faster than ``grasp_contact_speed_m_per_s``), it stalls (|speed| below that for
  ``grasp_contact_dwell_us``) while its tension holds (estimate >= ``grasp_contact_min_tension_n``)
  *and the ramp is still running*: in free space a falling tension keeps the cable paying out, so a
  stall then means the body is blocked. Requiring the pay-out first ignores the speed passing through
  zero when a still-settling pack reverses; stalls in the first ``grasp_contact_grace_us`` are ignored
  too. No contact within ``grasp_reach_timeout_us``: FAILED.
- WRAP: the object-side tension ramps up to ``grasp_wrap_n``, so the arm curls around the object.
- HOLD: the tension is kept. RELEASE: it ramps to 0 (uncurl), stays there ``grasp_release_dwell_us``,
  then IDLE re-packs.

Strategy off (Fig. S6A, for comparison): IDLE holds the arm straight (0 N); a grasp ramps the tension
from straight up to ``grasp_wrap_n`` (WRAP, the arm curls from the tip), then HOLD; release as above.

Triggers: left lever UP / DOWN edges in GRASP mode, host ``GRASP`` / ``RELEASE`` / ``HOLD`` commands
(MAVLink DO_GRIPPER through the host).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from controller.config import MOTOR_COUNT, FirmwareConfig
from controller.events import EventQueue
from controller.mapping import bend_shares
from protocol.messages import AckResult, EventKind, GraspState

__all__ = ["GraspMachine"]


class GraspMachine:
    """Grasp state machine; :meth:`step` runs once per control tick while the mode is GRASP.

    Attributes:
        state: current ``GraspState``.
        curl_n: curl (bending) tension toward :attr:`direction_rad`, before shaping and slew.
        direction_rad: grasp direction (same convention as the right stick, see ``controller.mapping``).
        pending: a grasp was requested and waits for the arm to be packed.
    """

    def __init__(self, config: FirmwareConfig, events: EventQueue) -> None:
        """Create the machine in IDLE."""
        self._events = events
        self.state = GraspState.IDLE
        self.curl_n = 0.0
        self.pending = False
        self._shares = [0.0] * MOTOR_COUNT
        self._t_state_us = 0
        self._stall_since_us = -1
        self._zero_since_us = -1
        self._unrolling_seen = False
        self.configure(config)
        self.direction_rad = self._default_dir_rad
        self._set_direction(self.direction_rad)

    def configure(self, config: FirmwareConfig) -> None:
        """Take new grasp parameters."""
        c = config
        self.strategy_on = c.grasp_strategy_on
        self._angles_rad = tuple(math.radians(a) for a in c.cable_angles_deg)
        self._default_dir_rad = math.radians(c.grasp_direction_deg)
        self._pack_n = c.grasp_pack_n
        self._reach_n = c.grasp_reach_n
        self._wrap_n = c.grasp_wrap_n
        self._reach_rate = c.grasp_reach_rate_n_per_s / 1e6
        self._wrap_rate = c.grasp_wrap_rate_n_per_s / 1e6
        self._release_rate = c.grasp_release_rate_n_per_s / 1e6
        self._stall_m_s = c.grasp_contact_speed_m_per_s
        self._dwell_us = c.grasp_contact_dwell_us
        self._grace_us = c.grasp_contact_grace_us
        self._min_tension_n = c.grasp_contact_min_tension_n
        self._timeout_us = c.grasp_reach_timeout_us
        self._release_dwell_us = c.grasp_release_dwell_us

    @property
    def idle_curl_n(self) -> float:
        """Curl held in IDLE: packed with the strategy on, straight (0 N) with it off."""
        return self._pack_n if self.strategy_on else 0.0

    def _set_direction(self, direction_rad: float) -> None:
        self.direction_rad = direction_rad
        shares = bend_shares(direction_rad, self._angles_rad)
        for i in range(MOTOR_COUNT):
            self._shares[i] = shares[i]

    def _enter(self, now_us: int, state: GraspState, why: str) -> None:
        self.state = state
        self._t_state_us = now_us
        self._stall_since_us = -1
        self._zero_since_us = -1
        self._unrolling_seen = False
        self._events.push(now_us, EventKind.GRASP, int(state), self.curl_n, f"grasp {state.name}: {why}")

    # --- requests ---------------------------------------------------------------------------------

    def reset(self, now_us: int, curl_n: float = 0.0) -> None:
        """Back to IDLE without a pending grasp (leaving GRASP mode), starting from ``curl_n``."""
        self.pending = False
        self.curl_n = curl_n
        if self.state != GraspState.IDLE:
            self._enter(now_us, GraspState.IDLE, "reset")

    def request_grasp(self, now_us: int, direction_rad: float | None = None) -> AckResult:
        """Start a grasp toward ``direction_rad`` (None = the configured default).

        Accepted in IDLE, FAILED and RELEASE (the arm re-packs first); refused while one runs.
        """
        if self.state in (GraspState.REACH, GraspState.WRAP, GraspState.HOLD):
            return AckResult.REJECTED
        if direction_rad is not None and not math.isfinite(direction_rad):
            return AckResult.DENIED
        self._set_direction(self._default_dir_rad if direction_rad is None else direction_rad)
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
            cable_speed_m_s: per-cable filtered paid-in speed (``MotorModel.cable_speed_m_s``).
            tension_est_n: per-cable estimated tension (``MotorModel.tension_est_n``).
        """
        state = self.state
        curl = self.curl_n
        if state == GraspState.IDLE:
            target = self.idle_curl_n
            if curl < target:
                curl = min(target, curl + self._wrap_rate * dt_us)
            elif curl > target:
                curl = max(target, curl - self._release_rate * dt_us)
            self.curl_n = curl
            if self.pending and curl == target:
                self.pending = False
                if self.strategy_on:
                    self._enter(now_us, GraspState.REACH, "packed, unrolling toward the target")
                else:
                    self._enter(now_us, GraspState.WRAP, "strategy off: plain tension ramp")
        elif state == GraspState.REACH:
            ramping = curl > self._reach_n
            if ramping:
                curl = max(self._reach_n, curl - self._reach_rate * dt_us)
                self.curl_n = curl
            elapsed = now_us - self._t_state_us
            speed, tension = self._object_side(cable_speed_m_s, tension_est_n)
            if speed < -self._stall_m_s:
                self._unrolling_seen = True
            stalled = -self._stall_m_s < speed < self._stall_m_s and tension >= self._min_tension_n
            if ramping and self._unrolling_seen and elapsed >= self._grace_us and stalled:
                if self._stall_since_us < 0:
                    self._stall_since_us = now_us
                elif now_us - self._stall_since_us >= self._dwell_us:
                    self._enter(now_us, GraspState.WRAP, "contact: cable stalled under tension")
            else:
                self._stall_since_us = -1
            if self.state == GraspState.REACH and elapsed >= self._timeout_us:
                self._enter(now_us, GraspState.FAILED, "no contact before the reach timeout")
        elif state == GraspState.WRAP:
            curl = min(self._wrap_n, curl + self._wrap_rate * dt_us)
            self.curl_n = curl
            if curl >= self._wrap_n:
                self._enter(now_us, GraspState.HOLD, "wrap tension reached")
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

    def _object_side(self, speed_m_s: Sequence[float], tension_n: Sequence[float]) -> tuple[float, float]:
        """Share-weighted paid-in speed and estimated tension of the object-side cables."""
        s = self._shares
        total = s[0] + s[1] + s[2]  # >= 1 for three cables at 120°
        v = (s[0] * speed_m_s[0] + s[1] * speed_m_s[1] + s[2] * speed_m_s[2]) / total
        t = (s[0] * tension_n[0] + s[1] * tension_n[1] + s[2] * tension_n[2]) / total
        return v, t
