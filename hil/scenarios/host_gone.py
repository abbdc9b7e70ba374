"""host-loss and link-disconnect: the host's heartbeats stop, or the link goes away, for a second."""

from __future__ import annotations

import math

import numpy as np

from controller.config import FailsafeConfig, FirmwareConfig
from protocol.dbus import Lever
from protocol.messages import EventKind, Heartbeat, Phase

from ..faults import Fault, FaultKind
from ..record import TICK_US, Check, RunRecord
from .base import MS, REQUIRED, SAFE, Plan, Scenario, current_before, fault_window, rc, rearmed


def _plan(kind: FaultKind) -> Plan:
    pull = rc(Lever.MIDDLE, ch3=400)
    return Plan(
        radio=[(0, SAFE), (200 * MS, pull), (3200 * MS, SAFE), (3500 * MS, pull)],
        faults=[Fault(kind, 1500 * MS, 2500 * MS)],
        firmware=FirmwareConfig(failsafe=FailsafeConfig(host_required=True)),
    )


def _host_acted_us(run: RunRecord) -> int:
    """Latest time after the last heartbeat the host sent by which the board must have cut the current."""
    return REQUIRED.failsafe.host_timeout_us + TICK_US + run.link_delay_us + run.lateness_us


def _cut_and_latched(run: RunRecord, last_hb: float, rearm: float) -> list[Check]:
    acted = _host_acted_us(run)
    return [
        Check(
            "zero current after the last heartbeat",
            run.zero_after(last_hb),
            acted + run.resolution_us,
            "<=",
            "us",
        ),
        Check(
            "max |current| from the timeout to re-arming (latched)",
            run.max_current(last_hb + acted, rearm),
            0,
            "<=",
            "raw",
        ),
    ]


class HostLoss(Scenario):
    """Host required, armed and pulling; the heartbeats stop for 1 s (the link stays up)."""

    name = "host-loss"
    summary = "host heartbeats stop (link up): zero current after the host timeout, telemetry keeps flowing"
    duration_us = 5000 * MS

    def plan(self) -> Plan:
        return _plan(FaultKind.HOST_LOSS)

    def checks(self, run: RunRecord, plan: Plan) -> list[Check]:
        start, end = fault_window(plan, FaultKind.HOST_LOSS)
        last_hb = run.last_sent_before(Heartbeat, start)
        rearm = run.first_rc_at_or_after(end, Lever.DOWN)
        lost = np.count_nonzero(run.samples.phase[run.window(start, end)] == Phase.HOST_LOST)
        return [
            current_before(run, start),
            *_cut_and_latched(run, last_hb, rearm),
            Check(
                "HOST_LOST reported after the last heartbeat (board event)",
                run.event_after(last_hb, EventKind.PHASE, Phase.HOST_LOST),
                _host_acted_us(run),
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


class LinkDisconnect(Scenario):
    """Host required, armed and pulling; the board link is unplugged for 1 s."""

    name = "link-disconnect"
    summary = "board link unplugged for 1 s: zero current after the host timeout, resumes after re-arm"
    duration_us = 5000 * MS

    def plan(self) -> Plan:
        return _plan(FaultKind.LINK_DISCONNECT)

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
            checks += _cut_and_latched(run, run.last_sent_before(Heartbeat, start), rearm)
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
