"""host.panel.arbiter: control ownership, server-side clamps, E-stop, token, the operator's radio pushed
to the link once per change, refusals told to the tab that asked."""

from __future__ import annotations

import math

import pytest

from host.link.source import LinkState
from host.panel.arbiter import CLI_CLIENT, ControlArbiter, ControlResult
from host.panel.notices import Notices
from protocol.dbus import Lever, RcFrame
from protocol.messages import AckResult, Command, CommandAck, CommandCode, Message, Mode, ParamValue


class Link:
    """What the arbiter sends to: messages (with who sent them) and every RC frame pushed."""

    def __init__(self) -> None:
        self.sent: list[Message] = []
        self.origins: list[str] = []
        self.frames: list[RcFrame | None] = []  # None would be silence

    def send(self, msg: Message, *, origin: str = "host") -> bool:
        self.sent.append(msg)
        self.origins.append(origin)
        return True


def make(token: str | None = None) -> tuple[ControlArbiter, Link, Notices]:
    link = Link()
    notices = Notices()
    return ControlArbiter(notices, link.send, link.frames.append, token=token), link, notices


def test_first_client_gets_control_second_must_be_handed_it() -> None:
    m, _, _ = make()
    assert m.request_control(1) is ControlResult.GRANTED
    assert m.request_control(2) is ControlResult.PENDING
    assert m.holder == 1 and m.pending == 2
    # The requester cannot act meanwhile.
    assert not m.set_stick(2, 3, 400)
    assert not m.command(2, CommandCode.ARM)
    assert m.answer_request(1, grant=False) is False
    assert m.holder == 1 and m.pending is None
    m.request_control(2)
    assert not m.answer_request(2, grant=True)  # only the holder answers
    assert m.answer_request(1, grant=True)
    assert m.holder == 2
    assert not m.set_stick(1, 3, 400)


def test_new_holder_starts_safe_and_leaving_releases() -> None:
    m, link, _ = make()
    m.request_control(1)
    assert m.set_lever(1, "right", "MIDDLE")
    assert m.set_stick(1, 3, 500)
    m.request_control(2)
    m.answer_request(1, grant=True)
    frame = m.rc_frame()
    assert frame is not None
    assert frame.right_lever == Lever.DOWN and frame.channels == (0, 0, 0, 0)
    assert link.frames[-1] == frame  # and that is what the link sends
    m.client_left(2)
    assert m.holder is None
    assert m.rc_frame() == IDLE  # nobody holds control: the idle radio, never silence
    assert link.frames[-1] == IDLE


IDLE = RcFrame((0, 0, 0, 0), int(Lever.DOWN), int(Lever.DOWN))
"""What the radio sends with nobody holding control: sticks centred, both levers DOWN."""


def test_the_radio_transmits_the_idle_frame_from_the_start() -> None:
    # A DT7 transmits whether anyone touches it or not: the link gets a frame before anyone takes control.
    m, link, _ = make()
    assert m.holder is None and m.idle
    assert link.frames == [IDLE] and m.rc_frame() == IDLE
    # Nobody holding control moves nothing: a tab without control cannot set the idle radio.
    assert not m.set_lever(1, "right", Lever.MIDDLE) and not m.set_stick(1, 3, 500)
    assert link.frames == [IDLE]
    # The first holder starts from the same SAFE frame (unchanged: not pushed again).
    m.request_control(1)
    assert not m.idle and link.frames == [IDLE]


@pytest.mark.parametrize("how", ["release", "tab closed"])
def test_control_given_up_mid_drive_leaves_the_radio_as_a_dt7_put_down(how: str) -> None:
    # A tab in GRASP with the left lever UP and a stick deflected: the radio it leaves behind keeps the
    # levers where they were (a held object stays held) with every stick centred; the next holder
    # starts from SAFE.
    m, link, _ = make()
    m.request_control(1)
    assert m.set_radio(1, (300, -200, 0, 500), Lever.UP, Lever.UP)
    assert link.frames[-1] == RcFrame((300, -200, 0, 500), int(Lever.UP), int(Lever.UP))
    if how == "release":
        assert m.release_control(1)
    else:
        m.client_left(1)
    put_down = RcFrame((0, 0, 0, 0), int(Lever.UP), int(Lever.UP))
    assert m.idle and link.frames[-1] == put_down and m.rc_frame() == put_down
    assert m.operator_input()[:3] == ((0, 0, 0, 0), Lever.UP, Lever.UP)
    # Nobody holding control moves nothing; the next holder starts from SAFE (levers DOWN).
    assert not m.set_stick(1, 0, 100)
    m.request_control(2)
    assert link.frames[-1] == RcFrame((0, 0, 0, 0), int(Lever.DOWN), int(Lever.DOWN))


def test_the_radio_reaches_the_link_once_per_change() -> None:
    """One sampler: the arbiter pushes a frame when the operator changes it, never on a clock."""
    m, link, _ = make()
    assert link.frames == [RcFrame.neutral()]  # nobody holds control: the idle radio, pushed once
    m.request_control(1)
    assert link.frames == [RcFrame.neutral()]  # the new holder's SAFE frame: the same, not pushed again
    m.set_stick(1, 3, 300)
    m.set_stick(1, 3, 300)  # the same value again: nothing new to send
    m.set_stick(1, 3, 300.2)  # rounds to the same count
    assert link.frames == [RcFrame.neutral(), RcFrame((0, 0, 0, 300), Lever.DOWN, Lever.DOWN)]
    m.set_lever(1, "right", Lever.MIDDLE)
    assert link.frames[-1] == RcFrame((0, 0, 0, 300), Lever.MIDDLE, Lever.DOWN)
    # A whole radio at once (a gamepad) is one frame, not one per field.
    n = len(link.frames)
    assert m.set_radio(1, (10, -20, 30, 40), Lever.UP, Lever.MIDDLE)
    assert link.frames[n:] == [RcFrame((10, -20, 30, 40), Lever.UP, Lever.MIDDLE)]
    assert not m.set_radio(2, (0, 0, 0, 0), Lever.DOWN, Lever.DOWN)  # not the holder
    assert not m.set_radio(1, (0, 0, 0, 0), 0, Lever.DOWN)  # type: ignore[arg-type]  # no such lever
    assert m.centre_sticks(1)
    assert link.frames[-1] == RcFrame((0, 0, 0, 0), Lever.UP, Lever.MIDDLE)
    assert not m.centre_sticks(2)


def test_values_are_clamped_server_side() -> None:
    m, link, _ = make()
    sent = link.sent
    m.request_control(1)
    m.set_stick(1, 0, 10_000)
    m.set_stick(1, 1, -10_000)
    m.set_stick(1, 2, float("nan"))
    frame = m.rc_frame()
    assert frame is not None and frame.channels[:3] == (660, -660, 0)
    assert frame.is_valid()
    assert link.frames[-1] == frame
    assert not m.set_lever(1, "right", "SIDEWAYS")
    with pytest.raises(ValueError):
        m.set_stick(1, 7, 0)
    m.set_direct_tension(1, 0, 1e9)
    m.set_direct_tension(1, 1, -5)
    cmd = sent[-1]
    assert isinstance(cmd, Command) and cmd.code == CommandCode.SET_TENSIONS
    assert cmd.args[0] == m.limits.tension_max_n and cmd.args[1] == 0.0
    assert not m.command(1, CommandCode.SET_MODE, (42.0, 0.0, 0.0))
    assert m.command(1, CommandCode.SET_MODE, (float(Mode.DIRECT), 0.0, 0.0))
    assert m.set_length_hold(1, 2, True)
    cmd = sent[-1]
    assert isinstance(cmd, Command) and cmd.code == CommandCode.HOLD_LENGTHS
    assert math.isnan(cmd.args[0]) and math.isnan(cmd.args[1]) and cmd.args[2] == math.inf
    assert m.set_length_hold(1, 0, False)
    assert sent[-1].args[0] == -math.inf  # type: ignore[attr-defined]
    assert not m.set_length_hold(2, 0, True)  # not the holder
    with pytest.raises(ValueError):
        m.set_length_hold(1, 3, True)
    assert m.command(1, CommandCode.HOLD_LENGTHS, (math.nan, 0.05, -math.inf))
    cmd = sent[-1]
    assert isinstance(cmd, Command) and math.isnan(cmd.args[0]) and cmd.args[1:] == (0.05, -math.inf)
    assert set(link.origins) == {"Tab 1"}  # every command says who sent it (the event console)


def test_estop_is_open_to_every_authorised_client_and_forces_safe() -> None:
    m, link, notices = make()
    sent = link.sent
    m.request_control(1)
    m.set_lever(1, "right", Lever.MIDDLE)
    assert m.estop(2)
    assert isinstance(sent[-1], Command) and sent[-1].code == CommandCode.ESTOP
    assert link.origins[-1] == "Tab 2"
    frame = m.rc_frame()
    assert frame is not None and frame.right_lever == Lever.DOWN
    assert link.frames[-1] == frame
    assert any(n.title == "E-STOP pressed" for n in notices.notices_after(0))


def test_token_gates_everything_but_watching() -> None:
    m, link, _ = make(token="s3cret")
    assert not m.authorise(1, None)
    assert not m.authorise(1, "wrong")
    assert m.request_control(1) is ControlResult.DENIED
    assert not m.estop(1)
    assert not link.sent
    assert m.authorise(1, "s3cret")
    assert m.request_control(1) is ControlResult.GRANTED
    assert m.is_authorised(CLI_CLIENT)


def test_reconnect_resets_levers_and_pushes_the_safe_frame_again() -> None:
    m, link, _ = make()
    m.request_control(1)
    m.set_lever(1, "right", Lever.MIDDLE)
    m.on_link_state(LinkState.CONNECTED)
    m.on_link_state(LinkState.DISCONNECTED)
    n = len(link.frames)
    m.on_link_state(LinkState.CONNECTED)
    frame = m.rc_frame()
    assert frame is not None and frame.right_lever == Lever.DOWN
    # Pushed on every connect, even unchanged: the board client lets the link send it only after this.
    assert link.frames[n:] == [frame]
    m.on_link_state(LinkState.CONNECTED)
    assert link.frames[n:] == [frame, frame]


def test_refused_command_toasts_the_tab_that_sent_it_with_the_boards_reason() -> None:
    m, link, notices = make()
    m.request_control(4)
    assert m.command(4, CommandCode.SET_MODE, (float(Mode.DIRECT), 0.0, 0.0))
    assert isinstance(link.sent[-1], Command)
    seq = notices.notices_after(0)[-1].seq if notices.notices_after(0) else 0
    refusal = CommandAck(CommandCode.SET_MODE, AckResult.REJECTED, 7, "right lever not MIDDLE")
    m.on_board_message(refusal)
    notices.on_board_message(refusal)
    (notice,) = notices.notices_after(seq)
    assert notice.client == 4 and notice.title == "Board refused SET_MODE"
    assert notice.body == "right lever not MIDDLE"
    # An accepted one says nothing; both are in the event console.
    accepted = CommandAck(CommandCode.SET_MODE, AckResult.ACCEPTED, 8)
    m.on_board_message(accepted)
    notices.on_board_message(accepted)
    assert notices.notices_after(notice.seq) == []
    lines = [e.text for e in notices.events.entries() if e.source == "ack"]
    assert lines == ["SET_MODE REJECTED: right lever not MIDDLE", "SET_MODE ACCEPTED"]
    # An answer to a command no tab sent (MAVLink) goes to everyone.
    m.on_board_message(CommandAck(CommandCode.GRASP, AckResult.DENIED, 9, "not in GRASP"))
    assert notices.notices_after(notice.seq)[-1].client is None


def test_a_tab_that_cannot_act_is_told_why() -> None:
    m, _, notices = make()
    m.request_control(1)
    assert not m.command(2, CommandCode.ARM)
    notice = notices.notices_after(0)[-1]
    assert notice.client == 2 and "does not hold control" in notice.body


def test_nothing_goes_out_without_a_board() -> None:
    notices = Notices()
    m = ControlArbiter(notices)  # a replay: no link, no radio
    m.request_control(3)
    assert m.rc_frame() == RcFrame.neutral()
    assert not m.command(3, CommandCode.ARM)
    notice = notices.notices_after(0)[-1]
    assert notice.client == 3 and notice.body == "no board to send it to (replay)"


def test_control_request_toast_names_the_tab() -> None:
    m, _, notices = make()
    m.request_control(11)
    m.request_control(12)
    notice = notices.notices_after(0)[-1]
    assert notice.client == 11 and notice.body.startswith("Tab 12 asks for control")


def test_the_direct_ceiling_follows_the_board() -> None:
    m, _, _ = make()
    m.on_board_message(ParamValue(8, 44, "TENSION_MAX_N", 12.0))
    assert m.limits.tension_max_n == 12.0
