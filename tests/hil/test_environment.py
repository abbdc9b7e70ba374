"""hil.environment: the one lockstep loop calls an episode's hooks in order and keeps the run record."""

from __future__ import annotations

import pytest

from hil.board import BoardConfig
from hil.environment import Environment, Episode
from hil.radio import RadioScript
from protocol.dbus import Lever, RcFrame
from protocol.messages import Mode, Phase


class _Spy(Episode):
    def __init__(self) -> None:
        self.calls: list[tuple[str, int]] = []

    def initialize(self, env: Environment) -> None:
        self.calls.append(("initialize", env.now_us))

    def before_tick(self, env: Environment) -> None:
        self.calls.append(("before", env.now_us))

    def after_tick(self, env: Environment) -> None:
        self.calls.append(("after", env.now_us))


def _radio() -> RadioScript:
    return RadioScript([(0, RcFrame.neutral()), (100_000, RcFrame((0, 0, 0, 400), Lever.MIDDLE, Lever.DOWN))])


def test_hooks_run_around_every_tick_in_order() -> None:
    spy = _Spy()
    with Environment(BoardConfig(), episode=spy, radio=_radio()) as env:
        assert env.run(3000) == 3
    assert spy.calls == [
        ("initialize", 0),
        ("before", 0),
        ("after", 1000),
        ("before", 1000),
        ("after", 2000),
        ("before", 2000),
        ("after", 3000),
    ]


def test_run_stops_when_asked_and_the_record_samples_every_tick() -> None:
    with Environment(BoardConfig(), radio=_radio(), record_ticks=400) as env:
        ticks = env.run(400_000, until=lambda: env.board.firmware.mode == Mode.MANUAL)
        run = env.record(env.now_us)
    assert 100 < ticks < 200  # MANUAL a few ticks after the MIDDLE frame at 100 ms
    assert run.n == ticks and run.plant is not None and run.plant.tip_m.shape == (ticks, 3)
    assert list(run.samples.t_us[:3]) == [1000, 2000, 3000]
    assert run.samples.phase[-1] == Phase.OK and run.samples.mode[-1] == Mode.MANUAL
    assert run.rc and all(f.is_valid() for _, f in run.rc)  # the board's own RawRc, before any fault
    assert run.telemetry_sent_us and run.telemetry_received_us == run.telemetry_sent_us  # no link fault
    assert run.sent  # the host's heartbeats


def test_a_record_needs_room_and_must_be_asked_for() -> None:
    with Environment(BoardConfig(), radio=_radio()) as env:
        env.run(2000)
        with pytest.raises(RuntimeError, match="record_ticks"):
            env.record(2000)
    with Environment(BoardConfig(), radio=_radio(), record_ticks=1) as env:
        env.step()
        with pytest.raises(IndexError):
            env.step()
