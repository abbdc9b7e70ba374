"""The grasp's contact detector: arm-object contact from what the board measures (REACH state).

The board sees only its motors: per cable the paid-in speed, length and the tension estimated from the
current (``controller.cables.MotorModel``), and the tension it commands. During the reach the curl
tension ramps down and the coil rolls out toward the object, paying the pack-side cable out:

- **While the ramp runs** a falling tension keeps the free arm paying out faster and faster, so a
  pay-out that falls below ``grasp_contact_slow_ratio`` of the fastest one seen (or below the stall
  speed) for the dwell time is a blocked body: contact.
- **After the ramp has ended** the free arm also slows down on its own (it reaches its unrolled rest),
  so slowing is no evidence; but it slows smoothly, at the rate the drive's friction and the arm's
  stiffness allow, while an arm that hits an object is stopped within a few milliseconds. A
  deceleration of the pay-out above ``grasp_contact_decel_m_per_s2`` (from the low-pass filtered
  speed, so a single frame's noise does not trigger it) while the arm still moves faster than the
  stall speed is contact. This is the late contact (arm moving fast) the stall rule missed.
- **At rest short of the unroll** (after the ramp): an arm that comes to rest against an object after
  the ramp has ended is not moving when it meets it, so no speed rule sees it. But a free arm unrolls
  all the way: its pack-side cable pays out the packed-to-straight length (65 mm on the prototype from
  the 18 N pack). An arm whose pack-side cable has stayed still (below the stall speed) for the dwell
  time after the ramp, having paid out less than ``grasp_contact_rest_m`` since the reach began, has
  met something. The pay-out is the filtered speed integrated (the low-pass keeps the integral).
- **The wrap-side cables** (opposite the pack side) went slack while the arm unrolled; a contact on
  the coil's outer face pushes the arm back and makes them pay out: their pay-out above
  ``grasp_contact_wrap_m_per_s`` while the pack side has slowed (below its peak's slow ratio) is
  contact too.

Every rule needs the pack-side cable to have been seen paying out (a still-settling pack reverses
through zero speed), the grace time to have passed, and the estimated tension to be at least
``grasp_contact_min_tension_n``. One instance per grasp machine, reset at each reach; no allocation.
"""

from __future__ import annotations

from controller.config import FirmwareConfig

__all__ = ["ContactDetector"]


class ContactDetector:
    """Contact from the pack- and wrap-side cables' speeds and tension (see the module notes).

    Attributes:
        peak_payout_m_s: fastest pack-side pay-out seen since :meth:`reset`.
        decel_m_s2: low-pass filtered pack-side pay-out deceleration.
        paid_out_m: pack-side cable paid out since :meth:`reset` (the pay-out speed integrated).
        reason: which rule fired last (``""`` before any): ``"stall"``, ``"decel"``, ``"rest"`` or
            ``"wrap"``.
    """

    def __init__(self, config: FirmwareConfig) -> None:
        """Create the detector (call :meth:`reset` at the start of each reach)."""
        self.peak_payout_m_s = 0.0
        self.decel_m_s2 = 0.0
        self.paid_out_m = 0.0
        self.reason = ""
        self._t0_us = 0
        self._stall_since_us = -1
        self._prev_payout_m_s = 0.0
        self._unrolling_seen = False
        self.configure(config)

    def configure(self, config: FirmwareConfig) -> None:
        """Take new parameters."""
        g = config.grasp
        self._stall_m_s = g.contact_speed_m_per_s
        self._slow_ratio = g.contact_slow_ratio
        self._dwell_us = g.contact_dwell_us
        self._grace_us = g.contact_grace_us
        self._min_tension_n = g.contact_min_tension_n
        self._decel_m_s2 = g.contact_decel_m_per_s2
        self._wrap_m_s = g.contact_wrap_m_per_s
        self._rest_m = g.contact_rest_m
        self._tau_us = float(g.contact_decel_tau_us)

    def reset(self, now_us: int) -> None:
        """Start a reach at ``now_us``."""
        self.peak_payout_m_s = 0.0
        self.decel_m_s2 = 0.0
        self.paid_out_m = 0.0
        self.reason = ""
        self._t0_us = now_us
        self._stall_since_us = -1
        self._prev_payout_m_s = 0.0
        self._unrolling_seen = False

    def update(
        self,
        now_us: int,
        dt_us: int,
        ramping: bool,
        pack_speed_m_s: float,
        pack_tension_n: float,
        wrap_speed_m_s: float,
    ) -> bool:
        """One control tick of the reach; True = contact.

        Args:
            now_us: board time.
            dt_us: time since the previous tick.
            ramping: the reach's tension ramp is still running.
            pack_speed_m_s: share-weighted paid-in speed of the pack-side cables (negative = paying out).
            pack_tension_n: their share-weighted estimated tension.
            wrap_speed_m_s: share-weighted paid-in speed of the wrap-side cables.
        """
        payout = -pack_speed_m_s
        stall = self._stall_m_s
        if payout > stall:
            self._unrolling_seen = True
        peak = self.peak_payout_m_s
        if payout > peak:
            peak = self.peak_payout_m_s = payout
        if dt_us > 0:
            self.paid_out_m += payout * dt_us * 1e-6
            raw = (self._prev_payout_m_s - payout) * 1e6 / dt_us
            self.decel_m_s2 += (raw - self.decel_m_s2) * (dt_us / (self._tau_us + dt_us))
        self._prev_payout_m_s = payout
        armed = (
            self._unrolling_seen
            and now_us - self._t0_us >= self._grace_us
            and pack_tension_n >= self._min_tension_n
        )
        if not armed:
            self._stall_since_us = -1
            return False
        slow_ref = self._slow_ratio * peak
        slowed = payout < (slow_ref if slow_ref > stall else stall)
        if self._decel_m_s2 > 0.0 and payout > stall and self.decel_m_s2 > self._decel_m_s2:
            self.reason = "decel"
            return True
        if self._wrap_m_s > 0.0 and slowed and -wrap_speed_m_s > self._wrap_m_s:
            self.reason = "wrap"
            return True
        # after the ramp: at rest short of the free arm's unroll (0 = rule off)
        resting = not ramping and payout < stall and self.paid_out_m < self._rest_m
        if (ramping and slowed) or resting:
            if self._stall_since_us < 0:
                self._stall_since_us = now_us
            elif now_us - self._stall_since_us >= self._dwell_us:
                self.reason = "stall" if ramping else "rest"
                return True
        else:
            self._stall_since_us = -1
        return False
