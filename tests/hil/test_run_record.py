"""hil.run_record: the one run record's queries measure nothing on an empty window (NaN never passes)."""

from __future__ import annotations

import math

import numpy as np

from controller.config import FirmwareConfig
from hil.report import results_table
from hil.run_record import Check, RunRecord, Samples, ScenarioResult
from hil.sim.types import PhysicsExtremes
from protocol.dbus import Lever, RcFrame
from protocol.messages import Event, EventKind, Heartbeat, Phase


def _record(t_us: list[int], current: list[int]) -> RunRecord:
    s = Samples(len(t_us))
    s.n = len(t_us)
    s.t_us[:] = t_us
    s.current_raw[:] = np.asarray(current)[:, None]
    return RunRecord(config=FirmwareConfig(), duration_us=100_000, samples=s.trim())


def test_queries_on_an_empty_window_are_nan_and_fail_every_check() -> None:
    run = _record([0, 10_000, 20_000], [5, 5, 0])
    assert math.isnan(run.max_current(50_000, 60_000))
    assert math.isnan(run.max_current(math.nan))
    assert math.isnan(run.zero_after(30_000))
    assert math.isnan(run.last_valid_rc_before(10_000))
    assert math.isnan(run.first_rc_at_or_after(0, Lever.DOWN))
    assert math.isnan(run.event_after(0, EventKind.PHASE, Phase.RC_LOST))
    assert math.isnan(run.last_sent_before(Heartbeat, 10_000))
    assert math.isnan(run.counter_rise(run.samples.rc_refused, 0, 10_000))  # nothing before t = 0
    for op in ("<=", ">=", "=="):
        assert not Check("x", run.max_current(50_000, 60_000), 0, op).passed


def test_queries_measure_what_the_samples_and_messages_say() -> None:
    run = _record([0, 10_000, 20_000, 30_000], [5, 7, 0, 0])
    assert run.max_current(0, 20_000) == 7
    assert run.zero_after(5_000) == 15_000
    assert run.count(10_000) == 3
    down, middle = RcFrame.neutral(), RcFrame((0, 0, 0, 0), Lever.MIDDLE, Lever.DOWN)
    invalid = RcFrame((700, 0, 0, 0), Lever.MIDDLE, Lever.DOWN)
    run.rc = [(1_000, down), (15_000, middle), (18_000, invalid)]
    assert run.last_valid_rc_before(20_000) == 15_000  # the out-of-range frame does not count
    assert run.first_rc_at_or_after(2_000, Lever.MIDDLE) == 15_000
    run.events = [(12_000, Event(12_000, EventKind.PHASE, int(Phase.RC_LOST)))]
    assert run.event_after(10_000, EventKind.PHASE, Phase.RC_LOST) == 2_000
    run.sent = [(0, Heartbeat(0, 0)), (9_000, Heartbeat(9_000, 1))]
    assert run.last_sent_before(Heartbeat, 9_000) == 0
    run.telemetry_received_us = [0, 10_000, 20_000]
    assert run.received(5_000) == 2 and run.received(0, 10_000) == 1


def test_a_scenario_result_carries_the_plant_extremes_into_json_and_the_table() -> None:
    from rich.console import Console

    extremes = PhysicsExtremes(0.0004, 0.08, 61.5, math.radians(1.25))
    check = Check("x", 1.0, 2.0, "<=")
    lockstep = ScenarioResult("grasp", 0, (check,), 1000, extremes=extremes)
    port = ScenarioResult("grasp", 0, (check,), 1000)
    assert lockstep.as_dict()["extremes"] == extremes.as_dict()
    assert port.as_dict()["extremes"] is None
    console = Console(width=200, record=True)
    console.print(results_table([lockstep, port]))
    text = console.export_text()
    assert "61.5 N" in text and "1.25°" in text and "0.40 mm (8 % of its radius)" in text
    assert text.count("largest cable tension") == 1  # the port run has no plant to report
