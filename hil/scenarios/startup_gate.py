"""startup-gate: no current before valid RC has shown the right lever DOWN; current once armed."""

from __future__ import annotations

import numpy as np

from hil.run_record import Check, RunRecord
from hil.scenarios.base import AFTER_REARM_US, MANUAL, MS, SAFE, Plan, Scenario, rc
from protocol.dbus import Lever
from protocol.messages import Phase


class StartupGate(Scenario):
    """The pilot tries to drive before arming (valid frames, lever MIDDLE, stick up); then arms."""

    name = "startup-gate"
    summary = "no current before valid RC has shown the right lever DOWN; current once armed"
    duration_us = 1500 * MS

    def plan(self) -> Plan:
        return Plan(
            radio=[
                (100 * MS, MANUAL),
                (150 * MS, rc(Lever.MIDDLE, ch3=600)),
                (600 * MS, SAFE),
                (800 * MS, rc(Lever.MIDDLE, ch3=600)),
            ]
        )

    def checks(self, run: RunRecord, plan: Plan) -> list[Check]:
        # "Before the lever was seen DOWN": up to the board time of the first DOWN frame it received.
        down = run.first_rc_at_or_after(0, Lever.DOWN)
        armed_from = max((t for t, f in plan.radio if f.right_lever == Lever.MIDDLE), default=0)
        before = run.window(0, down)
        return [
            Check("max |current| before the lever was seen DOWN", run.max_current(0, down), 0, "<=", "raw"),
            Check(
                "phase OK before the lever was seen DOWN",
                float(np.any(run.samples.phase[before] == Phase.OK)) if before.any() else float("nan"),
                0,
                "==",
            ),
            Check(
                "max |current| once armed (stick up)",
                run.max_current(armed_from + AFTER_REARM_US),
                1,
                ">=",
                "raw",
            ),
        ]
