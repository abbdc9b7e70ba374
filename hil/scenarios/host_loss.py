"""host-loss: host heartbeats stop (link up): zero current after the host timeout, telemetry keeps flowing."""

from __future__ import annotations

import numpy as np

from hil.faults import FaultKind
from hil.run_record import Check, RunRecord
from hil.scenarios.base import (
    MS,
    Plan,
    Scenario,
    current_before,
    fault_window,
    host_acted_us,
    host_cut_and_latched,
    host_gone_plan,
    rearmed,
)
from protocol.dbus import Lever
from protocol.messages import EventKind, Heartbeat, Phase


class HostLoss(Scenario):
    """Host required, armed and pulling; the heartbeats stop for 1 s (the link stays up)."""

    name = "host-loss"
    summary = "host heartbeats stop (link up): zero current after the host timeout, telemetry keeps flowing"
    duration_us = 5000 * MS

    def plan(self) -> Plan:
        return host_gone_plan(FaultKind.HOST_LOSS)

    def checks(self, run: RunRecord, plan: Plan) -> list[Check]:
        start, end = fault_window(plan, FaultKind.HOST_LOSS)
        last_hb = run.last_sent_before(Heartbeat, start)
        rearm = run.first_rc_at_or_after(end, Lever.DOWN)
        lost = np.count_nonzero(run.samples.phase[run.window(start, end)] == Phase.HOST_LOST)
        return [
            current_before(run, start),
            *host_cut_and_latched(run, last_hb, rearm),
            Check(
                "HOST_LOST reported after the last heartbeat (board event)",
                run.event_after(last_hb, EventKind.PHASE, Phase.HOST_LOST),
                host_acted_us(run),
                "<=",
                "us",
            ),
            rearmed(run, plan),
            Check(
                "telemetry frames while heartbeats are missing",
                float(run.received(start, end)),
                80,
                ">=",
                "frames",
            ),
            Check("samples reporting HOST_LOST", float(lost), 1, ">=", "samples"),
        ]
