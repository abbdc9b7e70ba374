"""host.panel.board_params: a parameter set checked, sent through the arbiter and read back."""

from __future__ import annotations

from host.panel.arbiter import ControlArbiter
from host.panel.board_params import BoardParams
from host.panel.notices import Notices
from protocol.messages import PARAM_LIST_ALL, Event, EventKind, Message, ParamRequest, ParamSet, ParamValue


def test_param_set_is_checked_sent_and_confirmed_by_the_board() -> None:
    sent: list[tuple[Message, str]] = []

    def send(msg: Message, *, origin: str = "host") -> bool:
        sent.append((msg, origin))
        return True

    arbiter = ControlArbiter(Notices(), send)
    m = BoardParams(arbiter)
    assert m.set_param(1, "PRETENSION_N", 1.0) == "this tab does not hold control"
    assert not m.has_control(1)
    arbiter.request_control(1)
    assert m.has_control(1)
    assert m.set_param(1, "NOPE", 1.0) == "unknown parameter 'NOPE'"
    assert m.set_param(1, "CURRENT_LIMIT_A", 50.0) == "current_limit_a: must be in (0, 10] A (C610)"
    assert not any(isinstance(x, ParamSet) for x, _ in sent)
    assert m.set_param(1, "PRETENSION_N", 0.75) is None
    assert sent[-1] == (ParamSet("PRETENSION_N", 0.75), "Tab 1")
    assert m.param_status["PRETENSION_N"].confirmed is None
    m.on_board_message(ParamValue(5, 44, "PRETENSION_N", 0.75))
    status = m.param_status["PRETENSION_N"]
    assert status.confirmed == 0.75 and status.accepted
    assert m.params["PRETENSION_N"] == 0.75 and m.params_count == 44
    # The board keeps another value (a safety parameter outside SAFE): read back and its reason.
    assert m.set_param(1, "CURRENT_LIMIT_A", 2.0) is None
    m.on_board_message(Event(10, EventKind.PARAM, 4, 2.0, "rejected: only in SAFE"))
    m.on_board_message(ParamValue(4, 44, "CURRENT_LIMIT_A", 3.0))
    status = m.param_status["CURRENT_LIMIT_A"]
    assert status.confirmed == 3.0 and not status.accepted and status.note == "rejected: only in SAFE"
    assert m.request_params()
    assert sent[-1][0] == ParamRequest(PARAM_LIST_ALL)


def test_a_set_that_cannot_go_out_is_forgotten() -> None:
    arbiter = ControlArbiter(Notices(), lambda msg, *, origin="host": False)
    m = BoardParams(arbiter)
    arbiter.request_control(1)
    assert m.set_param(1, "PRETENSION_N", 0.75) == "the board link is down"
    assert "PRETENSION_N" not in m.param_status
    assert not m.request_params()
