"""host.excite: ``--excite`` waits for the right lever MIDDLE, asks for DIRECT, plays the profile's tensions
at the times it says, stops at once on the lever DOWN, a failsafe phase, the board leaving DIRECT or the
link going down; and, end to end against the real virtual board, the recording is one a fit can use."""

from __future__ import annotations

import math
import re
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from hil.identify.excitation import Profile, Segment, profile
from hil.identify.motor_data import EXCITATION_TOPIC
from host.excite import (
    EXCITATION_SCHEMA,
    BoardClock,
    Excitation,
    ExcitationDriver,
    ExciteConfig,
    ExciteState,
    ExciteStep,
    operator_lines,
)
from host.link.source import LinkState
from host.panel.notices import Notices
from protocol.dbus import Lever
from protocol.messages import AckResult, Command, CommandAck, CommandCode, Message, Mode, Phase, Telemetry
from tests.support.realtime_guard import skip_if_others_were_busy, wait_for

TINY = Profile(
    "tiny",
    (Segment("rest", 0.0, 0.1), Segment("ramp", 0.1, 0.4, (0,)), Segment("rest", 0.4, 0.5)),
)
"""Half a second: the driver's thread plays it in a test."""

TRANSIT_US = 2_000
"""The simulated link's delay from the board to the host."""


def tel(
    board_us: int, mode: Mode = Mode.MANUAL, phase: Phase = Phase.OK, lever: int = Lever.MIDDLE
) -> Telemetry:
    return Telemetry(time_us=board_us, mode=mode, phase=phase, right_lever=int(lever))


@dataclass
class Sim:
    """An :class:`Excitation` in simulated time: the board's clock runs ``offset_us`` behind the host's,
    telemetry every 10 ms, a poll every 20 ms."""

    ex: Excitation
    offset_us: int = 1_000_000
    now_us: int = 0
    sent: list[tuple[int, Command]] = field(default_factory=list)
    lines: list[tuple[str, str]] = field(default_factory=list)
    started: list[dict[str, Any]] = field(default_factory=list)

    def take(self, step: ExciteStep) -> ExciteStep:
        self.sent += [(self.now_us, c) for c in step.commands]
        self.lines += step.lines
        if step.started is not None:
            self.started.append(step.started)
        return step

    def run(self, seconds: float, board: Callable[[int], Telemetry | None]) -> None:
        """Advance ``seconds``: ``board(board_us)`` gives each telemetry message (None: none)."""
        end = self.now_us + round(seconds * 1e6)
        while self.now_us < end:
            self.now_us += 10_000
            t = board(self.now_us - self.offset_us - TRANSIT_US)
            if t is not None:
                self.ex.on_telemetry(t, self.now_us)
            if self.now_us % 20_000 == 0:
                self.take(self.ex.poll(self.now_us))

    def codes(self) -> list[CommandCode]:
        return [c.code for _, c in self.sent]


def ready(mode: Mode = Mode.MANUAL) -> Callable[[int], Telemetry]:
    return lambda b: tel(b, mode)


def started_sim(p: Profile = TINY, config: ExciteConfig | None = None) -> Sim:
    """A simulation in which the board went from DOWN to MIDDLE and entered DIRECT: the profile plays."""
    s = Sim(Excitation(p, config))
    s.run(0.1, lambda b: tel(b, Mode.SAFE, lever=Lever.DOWN))
    s.run(0.04, ready())
    assert s.codes() == [CommandCode.SET_TENSIONS, CommandCode.SET_MODE]
    assert s.sent[1][1].args[0] == Mode.DIRECT and s.ex.state is ExciteState.ASKING
    s.run(0.04, ready(Mode.DIRECT))
    assert s.ex.state is ExciteState.RUNNING and len(s.started) == 1
    return s


# ---------------------------------------------------------------------- waiting for the enable


def test_it_waits_for_the_lever_middle_and_says_what_to_do() -> None:
    s = Sim(Excitation(profile("quick")))
    s.run(2.0, lambda b: None)  # no telemetry yet: nothing sent, nothing to say
    s.run(2.0, lambda b: tel(b, Mode.SAFE, Phase.GATE, lever=0))
    s.run(2.0, lambda b: tel(b, Mode.SAFE, lever=Lever.DOWN))
    s.run(2.0, lambda b: tel(b, Mode.GRASP, lever=Lever.UP))
    assert s.sent == [] and s.ex.state is ExciteState.WAITING
    said = [text for _, text in s.lines]
    assert said == [
        "excitation quick: right lever DOWN (the start-up gate), then MIDDLE to start the excitation",
        "excitation quick: right lever MIDDLE starts the excitation (DOWN stops it)",  # DOWN, then UP
    ]
    s.run(0.04, ready())
    assert s.codes() == [CommandCode.SET_TENSIONS, CommandCode.SET_MODE]
    first, mode = s.sent[0][1], s.sent[1][1]
    assert first.args == pytest.approx(profile("quick").tensions_n(0.0))  # DIRECT starts at the rest
    assert mode.args == (float(Mode.DIRECT), 0.0, 0.0)


def test_a_lever_already_middle_must_go_down_and_back() -> None:
    s = Sim(Excitation(TINY))
    s.run(3.0, ready())
    assert s.sent == []
    assert s.lines == [
        (
            "info",
            "excitation tiny: the right lever is already MIDDLE: put it DOWN, then MIDDLE, to start the "
            "excitation",
        )
    ]
    s.run(0.1, lambda b: tel(b, Mode.SAFE, lever=Lever.DOWN))
    s.run(0.04, ready())
    assert s.codes() == [CommandCode.SET_TENSIONS, CommandCode.SET_MODE]


def test_a_radio_on_its_way_to_middle_gets_no_line() -> None:
    s = Sim(Excitation(TINY))
    s.run(0.3, lambda b: tel(b, Mode.SAFE, Phase.GATE, lever=0))
    s.run(0.3, lambda b: tel(b, Mode.SAFE, lever=Lever.DOWN))
    s.run(0.04, ready())
    assert s.lines == [] and s.ex.state is ExciteState.ASKING


@pytest.mark.parametrize(
    ("phase", "needle"),
    [
        (Phase.RC_LOST, "no RC (RC_LOST)"),
        (Phase.HOST_LOST, "HOST_LOST"),
        (Phase.MOTOR_FAULT, "motor fault latched"),
        (Phase.ESTOP, "E-stop latched: clear it"),
    ],
)
def test_a_failsafe_while_waiting_is_explained(phase: Phase, needle: str) -> None:
    s = Sim(Excitation(TINY))
    s.run(2.0, lambda b: tel(b, Mode.SAFE, phase))
    assert s.sent == [] and len(s.lines) == 1 and needle in s.lines[0][1]


# ---------------------------------------------------------------------- playing the profile


def test_it_sends_the_profiles_tensions_at_the_right_times() -> None:
    p = profile("quick")
    s = started_sim(p)
    start_host_us = s.sent[2][0]  # the first command of the profile
    s.run(p.duration_s + 0.2, ready(Mode.DIRECT))
    assert s.ex.outcome is not None and s.ex.outcome.completed and s.ex.state is ExciteState.COMPLETED
    profile_cmds = s.sent[2:-2]
    # 50 Hz: one command per 20 ms poll, each the profile's tensions at its own instant
    assert len(profile_cmds) == pytest.approx(p.duration_s * 50, abs=2)
    for host_us, cmd in profile_cmds:
        assert cmd.code == CommandCode.SET_TENSIONS
        assert cmd.args == pytest.approx(p.tensions_n((host_us - start_host_us) / 1e6))
    # At the end: the rest, then the board is handed back to the sticks; then nothing more.
    end = s.sent[-2:]
    assert end[0][1].args == pytest.approx(p.tensions_n(p.duration_s))
    assert end[1][1] == Command(CommandCode.SET_MODE, (float(Mode.MANUAL), 0.0, 0.0))
    assert s.lines[-1] == ("info", "excitation quick completed: 14.5 s played; DIRECT handed back (MANUAL)")
    n = len(s.sent)
    s.run(1.0, ready(Mode.MANUAL))
    assert len(s.sent) == n


def test_the_start_is_recorded_in_board_time() -> None:
    s = started_sim()
    start_host_us = s.sent[2][0]
    got = s.started[0]
    # The board's clock when the profile began (the simulated transit: 2 ms, the estimate's error).
    assert got["start_us"] == start_host_us - s.offset_us - TRANSIT_US
    assert Profile.from_description(got) == TINY
    assert got["command_rate_hz"] == 50.0
    assert set(got) <= set(EXCITATION_SCHEMA["properties"]) and set(EXCITATION_SCHEMA["required"]) <= set(got)
    assert s.lines[-1] == ("info", "excitation tiny started: 0.5 s, 3 segments (right lever DOWN stops it)")


def test_progress_lines_say_percent_segment_and_what_is_left() -> None:
    p = profile("quick")
    s = started_sim(p)
    s.run(6.1, ready(Mode.DIRECT))
    progress = [text for level, text in s.lines if level == "progress"]
    assert len(progress) == 3  # every 2 s
    assert progress[-1] == "excitation quick: 41 % · segment 4/7 steps (cable 2) · 8.5 s left"


# ---------------------------------------------------------------------- stopping


@pytest.mark.parametrize(
    ("board", "why"),
    [
        (lambda b: tel(b, Mode.SAFE, lever=Lever.DOWN), "right lever DOWN (SAFE)"),
        (lambda b: tel(b, Mode.SAFE, Phase.RC_LOST), "failsafe phase RC_LOST"),
        (lambda b: tel(b, Mode.SAFE, Phase.HOST_LOST), "failsafe phase HOST_LOST"),
        (lambda b: tel(b, Mode.SAFE, Phase.MOTOR_FAULT), "failsafe phase MOTOR_FAULT"),
        (lambda b: tel(b, Mode.SAFE, Phase.ESTOP, lever=Lever.DOWN), "right lever DOWN (SAFE)"),
        (lambda b: tel(b, Mode.SAFE, Phase.ESTOP), "failsafe phase ESTOP"),
        (lambda b: tel(b, Mode.MANUAL), "the board left DIRECT (mode MANUAL)"),
        (lambda b: tel(b, Mode.GRASP, lever=Lever.UP), "the board left DIRECT (mode GRASP)"),
    ],
)
def test_it_stops_at_once_on_the_lever_down_a_failsafe_or_leaving_direct(
    board: Callable[[int], Telemetry], why: str
) -> None:
    s = started_sim(profile("quick"))
    s.run(3.0, ready(Mode.DIRECT))
    n = len(s.sent)
    s.run(0.01, board)  # one telemetry message
    s.run(0.02, ready(Mode.DIRECT))  # the next poll: the stop, even though the board looks fine again
    assert len(s.sent) == n, "a command after the stop"
    assert s.ex.state is ExciteState.STOPPED and s.ex.outcome is not None and not s.ex.outcome.completed
    level, text = s.lines[-1]
    assert level == "error"
    assert text == f"excitation quick stopped after 3.0 of 14.5 s (segment 2/7 ramp (cable 1)): {why}"
    s.run(2.0, ready(Mode.DIRECT))
    assert len(s.sent) == n


def test_a_lost_link_stops_it_without_a_word_to_the_board() -> None:
    s = started_sim()
    s.ex.on_link_state(LinkState.DISCONNECTED)
    n = len(s.sent)
    s.run(0.02, ready(Mode.DIRECT))
    assert len(s.sent) == n and s.ex.state is ExciteState.STOPPED
    assert s.lines[-1][1].endswith(": the board link went down")


def test_silent_telemetry_stops_it_and_hands_direct_back() -> None:
    s = started_sim(profile("quick"))
    s.run(1.2, lambda b: None)
    assert s.ex.state is ExciteState.STOPPED
    assert s.sent[-1][1] == Command(CommandCode.SET_MODE, (float(Mode.MANUAL), 0.0, 0.0))
    assert s.lines[-1][1].endswith(": no telemetry for 1 s")


def test_the_end_of_the_run_stops_it() -> None:
    s = started_sim(profile("quick"))
    s.run(1.0, ready(Mode.DIRECT))
    s.take(s.ex.finish("--duration ran out before the profile ended", s.now_us))
    assert s.ex.state is ExciteState.STOPPED
    assert s.sent[-1][1].code == CommandCode.SET_MODE  # the board still held DIRECT: handed back
    assert s.lines[-1][1].endswith("--duration ran out before the profile ended")
    assert s.ex.finish("again", s.now_us).lines == []  # once


# ---------------------------------------------------------------------- not starting


def _asking() -> Sim:
    s = Sim(Excitation(TINY, ExciteConfig(direct_wait_s=2.0)))
    s.run(0.1, lambda b: tel(b, Mode.SAFE, lever=Lever.DOWN))
    s.run(0.04, ready())
    assert s.ex.state is ExciteState.ASKING
    return s


def test_a_refused_direct_is_one_line_with_the_boards_reason() -> None:
    s = _asking()
    s.ex.on_mode_ack(
        CommandAck(CommandCode.SET_MODE, AckResult.REJECTED, 7, "DIRECT needs the host heartbeat")
    )
    s.run(0.02, ready())
    assert s.ex.state is ExciteState.FAILED
    assert s.lines[-1] == (
        "error",
        "excitation tiny did not start: the board refused DIRECT: DIRECT needs the host heartbeat",
    )
    assert s.sent[-1][1].args[0] == Mode.MANUAL  # the request withdrawn
    assert not any(c.code == CommandCode.SET_TENSIONS for _, c in s.sent[2:])


def test_no_direct_within_the_wait_fails() -> None:
    s = _asking()
    s.run(1.9, ready())
    assert s.ex.state is ExciteState.ASKING
    s.run(0.2, ready())
    assert s.ex.state is ExciteState.FAILED
    assert (
        s.lines[-1][1]
        == "excitation tiny did not start: the board did not enter DIRECT within 2 s of the request"
    )


def test_the_lever_down_while_asking_ends_it() -> None:
    s = _asking()
    s.run(0.02, lambda b: tel(b, Mode.SAFE, lever=Lever.DOWN))
    assert s.ex.state is ExciteState.FAILED and s.lines[-1][1].endswith("right lever DOWN (SAFE)")


def test_no_telemetry_or_no_enable_within_the_waits_fails() -> None:
    s = Sim(Excitation(TINY, ExciteConfig(telemetry_wait_s=3.0)))
    s.run(3.1, lambda b: None)
    assert s.ex.state is ExciteState.FAILED
    assert s.lines[-1][1] == "excitation tiny did not start: no telemetry from the board within 3 s"
    s = Sim(Excitation(TINY, ExciteConfig(enable_wait_s=5.0)))
    s.run(5.1, lambda b: tel(b, Mode.SAFE, lever=Lever.DOWN))
    assert s.ex.state is ExciteState.FAILED and s.sent == []
    assert s.lines[-1][1] == (
        "excitation tiny did not start: the board did not reach DIRECT within 5 s "
        "(right lever MIDDLE starts the excitation (DOWN stops it))"
    )


def test_the_board_clock_takes_the_least_delayed_stamp_and_restarts() -> None:
    c = BoardClock(window=4)
    assert c.board_us(100) is None
    for board_us, host_us in ((0, 1_500), (10_000, 11_200), (20_000, 25_000)):
        c.on_telemetry(board_us, host_us)
    assert c.board_us(30_000) == 30_000 - 1_200
    c.on_telemetry(500, 40_000)  # the board restarted
    assert c.board_us(41_000) == 1_500
    with pytest.raises(ValueError, match="command_rate_hz"):
        ExciteConfig(command_rate_hz=0.0)


# ---------------------------------------------------------------------- the driver's thread


class ToyBoard:
    """Telemetry at 100 Hz to a driver and the firmware's rule for ``SET_MODE``; records commands."""

    def __init__(self) -> None:
        self.lever = Lever.DOWN
        self.phase = Phase.OK
        self.mode = Mode.SAFE
        self.commands: list[Command] = []
        self.listeners: list[Callable[[Message], None]] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._t0 = time.monotonic()

    def send(self, msg: Message, on_ack: Callable[[CommandAck | None], None] | None) -> bool:
        assert isinstance(msg, Command)
        self.commands.append(msg)
        if msg.code == CommandCode.SET_MODE:
            if msg.args[0] == Mode.DIRECT and not (self.lever == Lever.MIDDLE and self.phase is Phase.OK):
                result, text = AckResult.REJECTED, "DIRECT needs phase OK and the right lever MIDDLE"
            else:
                result, text = AckResult.ACCEPTED, ""
                self.mode = Mode(int(msg.args[0]))
            if on_ack is not None:
                on_ack(CommandAck(msg.code, result, 0, text))
        return True

    def _run(self) -> None:
        while not self._stop.wait(0.01):
            if self.lever != Lever.MIDDLE or self.phase is not Phase.OK:
                self.mode = (
                    Mode.SAFE if self.lever == Lever.DOWN or self.phase is not Phase.OK else Mode.GRASP
                )
            elif self.mode is Mode.SAFE:
                self.mode = Mode.MANUAL
            t = tel(round((time.monotonic() - self._t0) * 1e6), self.mode, self.phase, self.lever)
            for fn in self.listeners:
                fn(t)

    def __enter__(self) -> ToyBoard:
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join(2.0)


class ListRecorder:
    def __init__(self) -> None:
        self.json: list[tuple[str, dict[str, Any]]] = []
        self.events: list[tuple[str, bool]] = []

    def write_json(self, topic: str, obj: Any, schema: Any) -> None:
        assert schema is EXCITATION_SCHEMA
        self.json.append((topic, dict(obj)))

    def write_event(self, text: str, *, warning: bool = False) -> None:
        self.events.append((text, warning))


@pytest.fixture
def toy() -> Iterator[ToyBoard]:
    with ToyBoard() as b:
        yield b


def _driver(toy: ToyBoard, rec: ListRecorder, said: list[tuple[str, str]]) -> ExcitationDriver:
    d = ExcitationDriver(TINY, toy.send, lambda level, text: said.append((level, text)), [rec])
    toy.listeners.append(d.on_board_message)
    d.start()
    return d


def test_the_driver_plays_a_profile_on_a_board_and_records_its_start(toy: ToyBoard) -> None:
    rec = ListRecorder()
    said: list[tuple[str, str]] = []
    d = _driver(toy, rec, said)
    try:
        assert wait_for(
            lambda: d.excitation.state is ExciteState.WAITING and d.excitation.clock.board_us(0) is not None
        )
        toy.lever = Lever.MIDDLE
        assert wait_for(d.done.is_set, 10.0), said
    finally:
        outcome = d.stop()
    assert outcome is not None and outcome.completed, said
    assert [topic for topic, _ in rec.json] == [EXCITATION_TOPIC]
    assert rec.json[0][1]["name"] == "tiny" and isinstance(rec.json[0][1]["start_us"], int)
    assert rec.events[0][0].startswith("excitation tiny started at board time")
    assert rec.events[-1] == ("excitation tiny completed: 0.5 s played; DIRECT handed back (MANUAL)", False)
    codes = [c.code for c in toy.commands]
    assert codes[:2] == [CommandCode.SET_TENSIONS, CommandCode.SET_MODE]
    assert codes[-1] == CommandCode.SET_MODE and toy.mode is Mode.MANUAL
    assert codes.count(CommandCode.SET_TENSIONS) >= 5


def test_the_driver_stops_when_the_lever_goes_down(toy: ToyBoard) -> None:
    rec = ListRecorder()
    said: list[tuple[str, str]] = []
    slow = Profile("slow", (Segment("ramp", 0.0, 30.0, (0, 1, 2)),))
    d = ExcitationDriver(slow, toy.send, lambda level, text: said.append((level, text)), [rec])
    toy.listeners.append(d.on_board_message)
    d.start()
    try:
        assert wait_for(lambda: d.excitation.clock.board_us(0) is not None)
        toy.lever = Lever.MIDDLE
        assert wait_for(lambda: d.excitation.state is ExciteState.RUNNING, 10.0), said
        toy.lever = Lever.DOWN
        assert wait_for(d.done.is_set, 10.0), said
        n = len(toy.commands)
        time.sleep(0.1)
        assert len(toy.commands) == n  # nothing after the stop
    finally:
        outcome = d.stop()
    assert outcome is not None and outcome.state is ExciteState.STOPPED
    assert said[-1][0] == "error" and said[-1][1].endswith(": right lever DOWN (SAFE)")
    assert rec.events[-1][1] is True  # a warning in the recording's events


def test_the_driver_ends_a_run_that_is_stopped_from_outside(toy: ToyBoard) -> None:
    rec = ListRecorder()
    said: list[tuple[str, str]] = []
    d = _driver(toy, rec, said)
    outcome = d.stop("the run was interrupted before the profile ended")
    assert outcome is not None and outcome.state is ExciteState.FAILED and d.done.is_set()
    assert said[-1] == (
        "error",
        "excitation tiny did not start: the run was interrupted before the profile ended",
    )
    assert d.stop() is outcome  # safe twice


def test_operator_lines_go_to_the_command_line_and_the_panel(capsys: pytest.CaptureFixture[str]) -> None:
    notices = Notices()
    say = operator_lines(notices)
    say("progress", "excitation quick: 41 %")
    say("info", "excitation quick started")
    say("error", "excitation quick stopped: right lever DOWN (SAFE)")
    out, err = capsys.readouterr()
    assert out.splitlines() == [
        "spirob-host: excitation quick: 41 %",
        "spirob-host: excitation quick started",
    ]
    assert err.splitlines() == ["spirob-host: error: excitation quick stopped: right lever DOWN (SAFE)"]
    assert [e.text for e in notices.events.entries()] == [
        "excitation quick started",
        "excitation quick stopped: right lever DOWN (SAFE)",
    ]
    assert [n.level for n in notices.notices_after(0)] == ["info", "error"]


# ---------------------------------------------------------------------- end to end, the real virtual board


def _slewed(tensions_n: np.ndarray, dt_s: float) -> np.ndarray:
    """The firmware's slew limiter (and pretension floor) over a target sampled every ``dt_s``."""
    from controller.config import FirmwareConfig

    m = FirmwareConfig().mapping
    out = np.empty_like(tensions_n)
    cur = np.full(tensions_n.shape[1], m.pretension_n)
    step = m.slew_n_per_s * dt_s
    for i, target in enumerate(tensions_n):
        cur = np.maximum(m.pretension_n, cur + np.clip(target - cur, -step, step))
        out[i] = cur
    return out


def _link_view(path: Path) -> tuple[np.ndarray, np.ndarray, int, int]:
    """What the host sent and saw: each ``SET_TENSIONS`` (host µs when written, tensions), the host clock
    minus the board's (the least delayed telemetry) and the first telemetry's board time."""
    from hil import recording
    from protocol.stream import MessageStream

    sent_us, sent_n = [], []
    stream = MessageStream()
    for rec in recording.read_records(path, {recording.LINK_RX}):  # host -> board
        for _, msg in stream.feed(rec.data):
            if isinstance(msg, Command) and msg.code == CommandCode.SET_TENSIONS:
                sent_us.append(rec.time_us)
                sent_n.append(msg.args)
    offsets, first = [], []
    stream = MessageStream()
    for rec in recording.read_records(path, {recording.LINK_TX}):  # board -> host
        for _, msg in stream.feed(rec.data):
            if isinstance(msg, Telemetry):
                offsets.append(rec.time_us - msg.time_us)
                first = first or [msg.time_us]
    return np.array(sent_us), np.array(sent_n), min(offsets), first[0]


@pytest.mark.realtime
def test_excite_records_what_a_fit_reads(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from controller.config import FirmwareConfig
    from hil.identify.motor_data import load_motor_data
    from host.cli import main
    from tests.support.foxglove_check import check_recording

    path = tmp_path / "excite.mcap"
    argv = ["--headless", "--virtual-rc", "manual", "--excite", "quick", "--record", str(path)]
    since = time.monotonic()
    status = main([*argv, "--duration", "90"])
    out, err = capsys.readouterr()
    gaps = re.search(r"RC gaps over 30 ms: (\d+)", out)
    if status != 0 and gaps is not None and int(gaps.group(1)) > 0:
        skip_if_others_were_busy(
            since, f"the virtual radio's frames were {gaps.group(1)} times over 30 ms apart: {err.strip()}"
        )
    assert status == 0, out + err
    assert "excitation quick started" in out and "excitation quick completed" in out
    assert re.search(r"excitation quick: \d+ % · segment \d/7 \w+", out)

    checked = check_recording(path)  # the /excitation message passes its own schema
    assert len(checked.messages[EXCITATION_TOPIC]) == 1
    data = load_motor_data(path)
    p = data.profile
    assert data.source == "telemetry" and p is not None and p.name == "quick"
    assert data.profile_start_s is not None and 0.0 < data.profile_start_s < data.duration_s
    # The run ends with the excitation.
    assert data.profile_start_s + p.duration_s == pytest.approx(data.duration_s, abs=1.0)

    # The host's commands are the profile's tensions at the instants they went out, counted from the
    # recorded start (board time): the start is where the fit will look for it. (A command carries the
    # value of the instant the host computed it, a few ms before the link wrote it; a starved host
    # sends fewer commands, never wrong ones.)
    sent_us, sent_n, offset_us, first_us = _link_view(path)
    start_us = first_us + round(data.profile_start_s * 1e6)
    sent_s = (sent_us - offset_us - start_us) / 1e6
    playing = (sent_s >= 0.0) & (sent_s < p.duration_s)
    assert playing.sum() > p.duration_s * 25  # 50 Hz, or at least half of it on a busy machine
    for t_s, tensions in zip(sent_s[playing], sent_n[playing], strict=True):
        candidates = np.array([p.tensions_n(x) for x in np.arange(t_s - 0.1, t_s + 0.005, 0.00025)])
        assert np.abs(candidates - tensions).max(axis=1).min() < 0.03, (t_s, tensions)

    # The board turns them into currents through its slew and motor model: current = tension x spool
    # radius / torque constant (the pay-in governor may cut a cable reeling in near 0.1 m/s, never raise
    # it). What the board may command at t: the slewed commands between t - 20 ms and t + 5 ms.
    fw = FirmwareConfig()
    amps_per_n = fw.motor.spool_radius_m / fw.motor.torque_constant_nm_per_a
    dt_s = 0.001
    grid = np.arange(sent_s[0], sent_s[-1] + 0.5, dt_s)
    held = sent_n[np.clip(np.searchsorted(sent_s, grid, side="right") - 1, 0, None)]
    slewed = _slewed(held, dt_s)
    t = data.t_s - data.profile_start_s
    inside = (t > sent_s[1]) & (t < sent_s[-2])
    windows = [
        slewed[max(0, int((tk - 0.02 - grid[0]) / dt_s)) : int((tk + 0.005 - grid[0]) / dt_s) + 1]
        for tk in t[inside]
    ]
    lo = np.array([w.min(axis=0) for w in windows])
    hi = np.array([w.max(axis=0) for w in windows])
    cmd_n = data.current_cmd_a[inside] / amps_per_n
    governed = data.speed_m_s[inside] > 0.8 * fw.motor.payin_limit_m_per_s
    within = ((cmd_n >= lo - 0.05) | governed) & (cmd_n <= hi + 0.05)
    assert within.mean() > 0.995, f"{within.mean():.4f} of the samples follow the commands"
    assert governed.mean() < 0.05
    # And so, the profile: the currents against the profile itself, slewed.
    profile_n = _slewed(np.array([p.tensions_n(x) for x in np.arange(0.0, p.duration_s, dt_s)]), dt_s)
    on_profile = (t > 0.0) & (t < p.duration_s)
    expected_a = profile_n[(t[on_profile] / dt_s).astype(int)] * amps_per_n
    assert np.corrcoef(data.current_cmd_a[on_profile].ravel(), expected_a.ravel())[0, 1] > 0.98

    # The cables moved: the ramp on cable 1 winds it in by centimetres, every cable moves in the multisine.
    travel_mm = (data.length_m.max(axis=0) - data.length_m.min(axis=0)) * 1000.0
    assert travel_mm[0] > 20.0 and all(travel_mm > 5.0), travel_mm
    assert not math.isnan(data.period_s)


@pytest.mark.realtime
def test_the_pilot_stops_it_on_the_virtual_board_and_the_run_fails() -> None:
    from host.app import HostApp
    from host.options import HostOptions
    from host.panel.arbiter import CLI_CLIENT

    sent: list[tuple[bool, Message]] = []  # (the excitation had ended, what was sent)
    since = time.monotonic()
    with HostApp(HostOptions(ui=False, virtual_rc=Lever.MIDDLE, excite="standard")) as app:
        app.start()
        assert app.client is not None and app.excite is not None and app.arbiter is not None
        driver, arbiter = app.excite, app.arbiter
        app.client.add_sent_listener(lambda msg, origin: sent.append((driver.excitation.done, msg)))

        def pilot() -> None:
            if wait_for(lambda: driver.excitation.state is ExciteState.RUNNING, 30.0):
                time.sleep(1.0)
                arbiter.set_lever(CLI_CLIENT, "right", Lever.DOWN)

        threading.Thread(target=pilot, daemon=True).start()
        status = app.run(60.0)
        outcome = driver.outcome
    if outcome is not None and "RC_LOST" in outcome.text:
        skip_if_others_were_busy(since, f"the board lost the virtual radio: {outcome.text}")
    assert status == 1
    assert outcome is not None and outcome.state is ExciteState.STOPPED, outcome
    assert outcome.text.startswith("excitation standard stopped after")
    assert outcome.text.endswith(": right lever DOWN (SAFE)")
    tensions = [
        ended for ended, msg in sent if isinstance(msg, Command) and msg.code == CommandCode.SET_TENSIONS
    ]
    assert len(tensions) > 20 and not any(tensions)  # none once it had stopped
    assert not any(ended for ended, msg in sent if isinstance(msg, Command))  # nor anything else
