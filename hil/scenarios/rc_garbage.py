"""rc-garbage: noise on the RC input is never acted on, and is counted."""

from __future__ import annotations

from hil.faults import Fault, FaultKind
from hil.run_record import Check, RunRecord
from hil.scenarios.base import MS, Plan, Scenario, arm_then, fault_window, rc_acted_us, rc_zero_checks


class RcGarbage(Scenario):
    """Armed; for 1 s the RC input is noise (framing noise on the DBUS UART in lockstep; frames with both
    levers 0 over a port, whose link delimits frames)."""

    name = "rc-garbage"
    summary = "framing noise on the DBUS UART is never acted on, and is counted"
    duration_us = 3000 * MS

    def plan(self) -> Plan:
        return Plan(radio=arm_then(ch3=400), faults=[Fault(FaultKind.RC_GARBAGE, 1500 * MS, 2500 * MS)])

    def checks(self, run: RunRecord, plan: Plan) -> list[Check]:
        start, end = fault_window(plan, FaultKind.RC_GARBAGE)
        last = run.last_valid_rc_before(end)
        return [
            Check(
                "garbage refused and counted",
                run.counter_rise(run.samples.rc_refused, start, end),
                50,
                ">=",
                "frames",
            ),
            *rc_zero_checks(run, last),
            Check(
                "max |current| while garbage arrives",
                run.max_current(last + rc_acted_us(run), end),
                0,
                "<=",
                "raw",
            ),
            Check("mode changes during the garbage", float(run.mode_changes(start, end)), 1, "<="),
        ]
