"""The run summary: time per mode and phase in board time, failsafe warnings, faults, the exit status of a
``--virtual-rc`` run."""

from __future__ import annotations

import logging
import time

import pytest

from host.app import HostApp
from host.cli import main
from host.options import HostOptions
from host.panel.arbiter import CLI_CLIENT
from host.run_summary import RunSummary
from protocol.dbus import Lever
from protocol.messages import ArmsTelemetry, Event, EventKind, Mode, Phase, Telemetry
from tests.support.link_peer import LinkPeer
from tests.support.realtime_guard import skip_if_others_were_busy, wait_for


def feed(summary: RunSummary, script: list[tuple[int, Mode, Phase]], step_us: int = 10_000) -> None:
    """Telemetry every ``step_us`` of board time: ``(until_us, mode, phase)`` segments."""
    t = 0
    for until_us, mode, phase in script:
        while t < until_us:
            summary.on_board_message(Telemetry(time_us=t, mode=mode, phase=phase))
            t += step_us


def test_time_in_each_mode_and_phase_is_board_time(caplog: pytest.LogCaptureFixture) -> None:
    s = RunSummary()
    with caplog.at_level(logging.WARNING, logger="spirob-host"):
        feed(
            s,
            [
                (500_000, Mode.SAFE, Phase.GATE),
                (2_500_000, Mode.MANUAL, Phase.OK),
                (3_000_000, Mode.SAFE, Phase.RC_LOST),
            ],
        )
    r = s.report(rc_gaps_n=2, rc_max_gap_us=41_500)
    assert r.telemetry_n == 300
    assert r.mode_s["MANUAL"] == pytest.approx(2.0) and r.mode_s["SAFE"] == pytest.approx(0.99)
    assert r.phase_s["GATE"] == pytest.approx(0.5) and r.phase_s["RC_LOST"] == pytest.approx(0.49)
    assert r.failsafes == ((2.5, "RC_LOST"),)
    # One warning line when the failsafe latched, not one per telemetry message.
    warnings = [rec.getMessage() for rec in caplog.records if "failsafe latched" in rec.getMessage()]
    assert warnings == [
        "failsafe latched at board time 2.50 s: RC_LOST, zero current until re-armed through SAFE"
    ]
    assert r.ended_latched and r.failure() == "the run ended latched in RC_LOST"
    text = "\n".join(r.lines())
    assert "mode:  SAFE 1.0 s · MANUAL 2.0 s" in text
    assert "RC gaps over 30 ms: 2 (longest 41.5 ms)" in text and "RC_LOST at 2.50 s" in text


def test_a_fault_fails_the_run_and_a_gap_in_telemetry_is_not_counted() -> None:
    s = RunSummary()
    s.on_board_message(Telemetry(time_us=0, mode=Mode.MANUAL, phase=Phase.OK))
    s.on_board_message(Telemetry(time_us=10_000, mode=Mode.MANUAL, phase=Phase.OK))
    s.on_board_message(Telemetry(time_us=5_000_000, mode=Mode.MANUAL, phase=Phase.OK))  # link was down
    r = s.report()
    assert r.board_s == pytest.approx(0.01) and r.failure() is None
    s.on_board_message(Event(5_000_000, EventKind.FAULT, 2, 0.0, "motor 2 silent"))
    assert s.report().failure() == "1 fault(s), the first: motor 2 silent"
    assert RunSummary().report().failure() == "no telemetry from the board"


def test_an_arrays_layout_is_logged_once_and_summarised(caplog: pytest.LogCaptureFixture) -> None:
    """A board that sends ArmsTelemetry is an array: the host says its layout once, and in the summary;
    a board that never does (a 3-motor board, or one that predates 0x0109) is read as one arm."""
    s = RunSummary()
    s.on_board_message(Telemetry(time_us=0, mode=Mode.MANUAL, phase=Phase.OK))
    assert not any("board:" in line for line in s.report().lines())
    z = (0,) * 8
    arms = ArmsTelemetry(0, 8, 1, z, z, z, z, (0.0,) * 8, (0.0,) * 8, (0.0,) * 8, (False,) * 8)
    with caplog.at_level(logging.INFO, logger="spirob-host"):
        for _ in range(3):
            s.on_board_message(arms)
    said = [r.getMessage() for r in caplog.records if "array" in r.getMessage()]
    assert said == ["the board is an array of 8 arms x 1 cable(s), 8 motors (ArmsTelemetry)"]
    assert "  board: an array of 8 arms x 1 cable(s)" in s.report().lines()


def test_a_virtual_rc_run_that_ends_latched_exits_1(capsys: pytest.CaptureFixture[str]) -> None:
    with LinkPeer("pty") as peer:
        peer.phase = Phase.ESTOP  # latched before the run starts: it can only end latched
        assert main(["--port", peer.url, "--headless", "--duration", "1", "--virtual-rc", "manual"]) == 1
    captured = capsys.readouterr()
    errors = [line for line in captured.err.splitlines() if "error" in line]
    assert errors == ["spirob-host: error: --virtual-rc run failed: the run ended latched in ESTOP"]
    assert "Traceback" not in captured.err
    assert "ended in mode SAFE, phase ESTOP (latched: re-arm through SAFE)" in captured.out


@pytest.mark.realtime
def test_a_clean_virtual_rc_run_exits_0_with_a_summary(capsys: pytest.CaptureFixture[str]) -> None:
    """The host's virtual RC keeps the board's RC alive; on a machine others starve, its frames can be late
    enough for the board's RC_LOST (seen once with two fits running on both cores): that run is skipped as
    starved, never passed, and on an idle machine it fails."""
    since = time.monotonic()
    with LinkPeer("pty") as peer:
        code = main(["--port", peer.url, "--headless", "--duration", "1.5", "--virtual-rc", "manual"])
    out = capsys.readouterr().out
    if code != 0 and "failsafes: RC_LOST" in out:
        skip_if_others_were_busy(since, "the virtual RC's frames came too late: RC_LOST")
    assert code == 0, out
    assert "spirob-host: summary:" in out and "MANUAL" in out and "failsafes: none; faults: none" in out


def test_an_estop_during_a_virtual_rc_run_fails_it() -> None:
    with (
        LinkPeer("pty") as peer,
        HostApp(HostOptions(port=peer.url, ui=False, virtual_rc=Lever.MIDDLE)) as app,
    ):
        app.start()
        m, arbiter = app.board_state, app.arbiter
        assert m is not None and arbiter is not None
        assert wait_for(lambda: m.telemetry is not None and m.telemetry.mode == Mode.MANUAL)
        assert arbiter.estop(CLI_CLIENT)
        assert wait_for(lambda: m.telemetry is not None and m.telemetry.phase == Phase.ESTOP)
        assert app.run(0.1) == 1
        assert app.report is not None and app.report.failsafes[-1][1] == "ESTOP"
