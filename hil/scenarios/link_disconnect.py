"""link-disconnect: the link unplugged for 1 s: zero current after the host timeout, resumes after re-arm."""

from __future__ import annotations

import math

import numpy as np

from hil.faults import FaultKind
from hil.run_record import Check, RunRecord
from hil.scenarios.base import (
    MS,
    Plan,
    Scenario,
    current_before,
    fault_window,
    host_cut_and_latched,
    host_gone_plan,
    rearmed,
)
from protocol.dbus import Lever
from protocol.messages import Heartbeat, Phase


class LinkDisconnect(Scenario):
    """Host required, armed and pulling; the board link is unplugged for 1 s."""

    name = "link-disconnect"
    summary = "board link unplugged for 1 s: zero current after the host timeout, resumes after re-arm"
    duration_us = 5000 * MS

    def plan(self) -> Plan:
        return host_gone_plan(FaultKind.LINK_DISCONNECT)

    def checks(self, run: RunRecord, plan: Plan) -> list[Check]:
        start, end = fault_window(plan, FaultKind.LINK_DISCONNECT)
        rearm = run.first_rc_at_or_after(end, Lever.DOWN)
        checks = [current_before(run, start)]
        if run.samples_through_link:
            # Nothing crosses an unplugged link, so the board cannot be watched while it is down: what it
            # reports once the link is back must still be latched.
            back = next((t for t in run.reconnects_us if t >= start), math.nan)
            latched = run.window(back, rearm)
            checks += [
                Check(
                    "max |current| after reconnecting, before re-arming (latched)",
                    run.max_current(back, rearm),
                    0,
                    "<=",
                    "raw",
                ),
                Check(
                    "samples reporting OK after reconnecting, before re-arming",
                    float(np.count_nonzero(run.samples.phase[latched] == Phase.OK))
                    if latched.any()
                    else math.nan,
                    0,
                    "<=",
                    "samples",
                ),
            ]
        else:
            checks += host_cut_and_latched(run, run.last_sent_before(Heartbeat, start), rearm)
        checks += [
            rearmed(run, plan),
            Check(
                "telemetry frames after reconnecting",
                float(run.received(end + 100 * MS)),
                100,
                ">=",
                "frames",
            ),
        ]
        return checks
