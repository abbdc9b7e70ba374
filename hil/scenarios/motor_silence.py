"""motor-silence: one motor silent: all-stop within 10 ms + 1 tick, latched until re-armed through SAFE."""

from __future__ import annotations

from hil.faults import Fault, FaultKind
from hil.run_record import TICK_US, Check, RunRecord
from hil.scenarios.base import MS, REQUIRED, SAFE, Plan, Scenario, current_before, fault_window, rc, rearmed
from protocol.dbus import Lever


class MotorSilence(Scenario):
    """Armed and pulling; motor 2's feedback stops for 200 ms; the pilot re-arms through SAFE at 2.5 s."""

    name = "motor-silence"
    summary = "one motor silent: all-stop within 10 ms + 1 tick, latched until re-armed through SAFE"
    duration_us = 4000 * MS

    def plan(self) -> Plan:
        pull = rc(Lever.MIDDLE, ch3=400)
        return Plan(
            radio=[(0, SAFE), (200 * MS, pull), (2500 * MS, SAFE), (2800 * MS, pull)],
            faults=[Fault(FaultKind.MOTOR_SILENCE, 1500 * MS, 1700 * MS, motor=2)],
        )

    def checks(self, run: RunRecord, plan: Plan) -> list[Check]:
        start, end = fault_window(plan, FaultKind.MOTOR_SILENCE)
        last_fb = start - TICK_US  # the last tick whose feedback reached the board
        acted = REQUIRED.failsafe.motor_timeout_us + TICK_US + run.lateness_us
        rearm = run.first_rc_at_or_after(end, Lever.DOWN)
        return [
            current_before(run, start),
            Check(
                "all-stop after motor 2's last feedback",
                run.zero_after(last_fb),
                acted + run.resolution_us,
                "<=",
                "us",
            ),
            Check(
                "max |current| after feedback returns, before re-arming (latched)",
                run.max_current(last_fb + acted, rearm),
                0,
                "<=",
                "raw",
            ),
            rearmed(run, plan),
        ]
