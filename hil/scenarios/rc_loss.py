"""rc-loss: zero current within 30 ms of the last valid frame; recovery only after re-arming."""

from __future__ import annotations

from hil.faults import Fault, FaultKind
from hil.run_record import Check, RunRecord
from hil.scenarios.base import (
    MS,
    SAFE,
    Plan,
    Scenario,
    current_before,
    fault_window,
    rc,
    rc_acted_us,
    rc_zero_checks,
    rearmed,
)
from protocol.dbus import Lever


class RcLoss(Scenario):
    """Armed and pulling; the radio goes silent for 1 s and comes back with the lever still in MANUAL; the
    pilot re-arms through SAFE at 3 s."""

    name = "rc-loss"
    summary = "zero current within 30 ms of the last valid frame; recovery only after re-arming"
    duration_us = 4000 * MS

    def plan(self) -> Plan:
        pull = rc(Lever.MIDDLE, ch0=300, ch3=400)
        return Plan(
            radio=[(0, SAFE), (200 * MS, pull), (3000 * MS, SAFE), (3300 * MS, pull)],
            faults=[Fault(FaultKind.RC_SILENCE, 1500 * MS, 2500 * MS)],
        )

    def checks(self, run: RunRecord, plan: Plan) -> list[Check]:
        start, end = fault_window(plan, FaultKind.RC_SILENCE)
        last = run.last_valid_rc_before(end)  # no valid frame arrives during the silence
        rearm = run.first_rc_at_or_after(end, Lever.DOWN)
        return [
            current_before(run, start),
            *rc_zero_checks(run, last),
            Check(
                "max |current| from 30 ms after the loss to re-arming",
                run.max_current(last + rc_acted_us(run), rearm),
                0,
                "<=",
                "raw",
            ),
            rearmed(run, plan, "|current| after re-arming"),
        ]
