"""spirob-host --params (host.param_push, host.options): a parameter file's values sent to the board as
ParamSets at every link-up, SAFE-only ones while disarmed, against the firmware's own parameter rule
(``controller.commands.Params``)."""

from __future__ import annotations

from pathlib import Path

import pytest

from controller.commands import Params
from controller.config import FirmwareConfig
from controller.events import EventQueue
from controller.param_file import write_param_file
from controller.params import PARAMS
from host.errors import HostError
from host.link.source import LinkState
from host.options import HostOptions, build_parser
from host.param_push import ParamPush, wire_values
from protocol.dbus import Lever
from protocol.messages import (
    Message,
    Mode,
    ParamSet,
    ParamValue,
    Phase,
    Telemetry,
    TelemetryFlags,
)

FILE_VALUES = {
    "grasp_strategy_on": False,
    "grasp_wrap_n": 11.5,
    "grasp_contact_dwell_us": 80_000,
    "payin_limit_m_per_s": 0.06,  # SAFE only
}


def _telemetry(armed: bool) -> Telemetry:
    return Telemetry(
        time_us=0,
        mode=Mode.MANUAL if armed else Mode.SAFE,
        phase=Phase.OK,
        flags=(TelemetryFlags.ARMED if armed else TelemetryFlags(0)) | TelemetryFlags.RC_OK,
        motors_online=0b111,
        rc_channels=(0, 0, 0, 0),
        right_lever=Lever.MIDDLE if armed else Lever.DOWN,
        left_lever=Lever.DOWN,
        motor_angle=(1, 2, 3),
        motor_speed_rpm=(0, 0, 0),
        motor_current=(0, 0, 0),
        commanded_current=(0, 0, 0),
        tension_target_n=(1.0, 1.0, 1.0),
        tension_est_n=(1.0, 1.0, 1.0),
        cable_length_m=(0.0, 0.0, 0.0),
        control_late=0,
        control_exec_p99_us=10,
        control_exec_max_us=20,
        control_lateness_max_us=5,
        rc_frames_ok=1,
        link_frames_ok=1,
    )


class _Board:
    """The firmware's parameter store behind a fake link: answers a ParamSet as the board does."""

    def __init__(self) -> None:
        self.events = EventQueue(64)
        self.armed = True
        self.link_up = True
        self.params = Params(FirmwareConfig(), self.events, lambda _cfg: None, lambda: not self.armed)
        self.sent: list[ParamSet] = []
        self.replies: list[Message] = []

    def send(self, msg: Message) -> bool:
        if not self.link_up:
            return False
        assert isinstance(msg, ParamSet)
        self.sent.append(msg)
        value = self.params.set(0, msg.name, msg.value)
        self.replies.append(ParamValue(PARAMS.index(msg.name), len(PARAMS), msg.name, value))
        self.replies += [ev for ev in self.events.pop_all() if ev.text.startswith("rejected")]
        return True


def _deliver(board: _Board, push: ParamPush) -> None:
    replies, board.replies = board.replies, []
    for msg in replies:
        push.on_board_message(msg)


def test_values_go_at_link_up_and_safe_only_ones_wait_for_disarm(tmp_path: Path) -> None:
    path = write_param_file(tmp_path / "p.toml", FILE_VALUES)
    values = wire_values(path)
    assert values == {
        "GRASP_STRATEGY": 0.0,
        "GRASP_WRAP_N": 11.5,
        "GRASP_DWELL_US": 80000.0,
        "PAYIN_MAX_M_S": 0.06,
    }
    board = _Board()
    lines: list[tuple[str, str]] = []
    push = ParamPush(values, board.send, lambda level, text: lines.append((level, text)))
    push.on_board_message(_telemetry(armed=False))
    assert board.sent == []  # the link is not up yet
    push.on_link_state(LinkState.CONNECTED)
    push.on_board_message(_telemetry(armed=True))
    _deliver(board, push)
    assert [m.name for m in board.sent] == ["GRASP_STRATEGY", "GRASP_WRAP_N", "GRASP_DWELL_US"]
    assert not push.done and not push.status["PAYIN_MAX_M_S"].sent
    board.armed = False
    push.on_board_message(_telemetry(armed=False))
    _deliver(board, push)
    assert [m.name for m in board.sent][-1] == "PAYIN_MAX_M_S"
    assert push.done and all(s.taken for s in push.status.values())
    cfg = board.params.config
    assert cfg.grasp.strategy_on is False and cfg.grasp.wrap_n == 11.5 and cfg.grasp.contact_dwell_us == 80000
    assert cfg.motor.payin_limit_m_per_s == pytest.approx(0.06)
    assert lines and "took 4 of 4" in lines[-1][1]
    push.on_board_message(_telemetry(armed=False))
    assert len(board.sent) == 4  # nothing twice per link-up
    push.on_link_state(LinkState.DISCONNECTED)
    push.on_link_state(LinkState.CONNECTED)
    push.on_board_message(_telemetry(armed=False))
    assert len(board.sent) == 8  # again after a new link-up


def test_a_refusal_is_reported_with_the_boards_reason() -> None:
    board = _Board()
    board.armed = False
    lines: list[tuple[str, str]] = []
    # The file's check is the static range; the board's run-time range (the M2006's figure) is tighter.
    push = ParamPush({"TORQUE_K_NM_A": 0.05}, board.send, lambda level, text: lines.append((level, text)))
    push.on_link_state(LinkState.CONNECTED)
    push.on_board_message(_telemetry(armed=False))
    _deliver(board, push)
    st = push.status["TORQUE_K_NM_A"]
    assert st.refused is not None and "0.1..0.5" in st.refused and not st.taken and push.done
    assert any(level == "warning" and "refused TORQUE_K_NM_A" in text for level, text in lines)


def test_a_send_that_fails_is_tried_at_the_next_link_up() -> None:
    board = _Board()
    board.link_up = False
    push = ParamPush({"GRASP_WRAP_N": 9.0}, board.send)
    push.on_link_state(LinkState.CONNECTED)
    push.on_board_message(_telemetry(armed=True))
    assert not push.status["GRASP_WRAP_N"].sent
    board.link_up = True
    push.on_board_message(_telemetry(armed=True))
    _deliver(board, push)
    assert push.status["GRASP_WRAP_N"].taken


def test_host_options_read_the_file_and_refuse_bad_ones(tmp_path: Path) -> None:
    good = write_param_file(tmp_path / "good.toml", FILE_VALUES)
    opts = HostOptions.from_args(build_parser().parse_args(["--headless", "--params", str(good)]))
    assert dict(opts.params) == wire_values(good)
    for text, message in (
        ("grasp_wrap_n = 50.0\n", "grasp_wrap_n: must be 0..tension_max_n"),
        ("nonsense = 1\n", "unknown key 'nonsense'"),
        ("control_period_us = 2000\n", "control_period_us is a start-up setting"),
    ):
        bad = tmp_path / "bad.toml"
        bad.write_text(text)
        with pytest.raises(HostError, match=message.replace("(", r"\(")):
            HostOptions.from_args(build_parser().parse_args(["--headless", "--params", str(bad)]))
    rec = tmp_path / "r.mcap"
    rec.write_bytes(b"")
    with pytest.raises(HostError, match="--params needs a board"):
        HostOptions.from_args(build_parser().parse_args(["--replay", str(rec), "--params", str(good)]))
