"""rc-out-of-range: frames with a channel beyond +-660 are rejected, counted and never acted on."""

from __future__ import annotations

import math

from hil.faults import Fault, FaultKind
from hil.run_record import Check, RunRecord
from hil.scenarios.base import MS, Plan, Scenario, arm_then, fault_window, rc_zero_checks


class RcOutOfRange(Scenario):
    """Armed; for 1 s every frame has a channel beyond ±660."""

    name = "rc-out-of-range"
    summary = "frames with channels beyond +-660 are rejected, counted and never acted on"
    duration_us = 3000 * MS

    def plan(self) -> Plan:
        return Plan(radio=arm_then(ch3=400), faults=[Fault(FaultKind.RC_OUT_OF_RANGE, 1500 * MS, 2500 * MS)])

    def checks(self, run: RunRecord, plan: Plan) -> list[Check]:
        start, end = fault_window(plan, FaultKind.RC_OUT_OF_RANGE)
        target = run.samples.target_n
        before = run.window(start - 500 * MS, start)
        during = run.window(start, end)
        rise = (
            float(target[during].max() - target[before].max()) if during.any() and before.any() else math.nan
        )
        return [
            Check(
                "out-of-range frames rejected and counted",
                run.counter_rise(run.samples.rc_refused, start, end),
                60,
                ">=",
                "frames",
            ),
            Check(
                "largest target tension while they arrive (never above the last valid command)",
                rise,
                0.0,
                "<=",
                "N",
            ),
            *rc_zero_checks(run, run.last_valid_rc_before(end)),
        ]
