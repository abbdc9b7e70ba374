"""The gamepad as the virtual radio: js_event records in, DT7 sticks and levers (DBUS frames) out.

No hardware: the events are ``struct js_event`` records written in the kernel's format, fed to the pure
state and, through a FIFO standing in for ``/dev/input/js0``, to a running host whose board (the fake
board of tests/support/link_peer.py) records the DBUS frames it receives.
"""

from __future__ import annotations

import os
import time
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from host.app import HostApp
from host.gamepad import (
    AXIS_MAX,
    DEFAULT_MAPPING,
    JS_EVENT_AXIS,
    JS_EVENT_BUTTON,
    GamepadMapping,
    GamepadState,
    Input,
    JsEvent,
    JsEventReader,
    format_mapping,
    parse_mapping,
)
from host.options import HostOptions
from host.panel.arbiter import CLI_CLIENT
from protocol.dbus import CH_LIMIT, Lever, RcFrame
from protocol.messages import VirtualRc
from tests.support.link_peer import LinkPeer
from tests.support.realtime_guard import wait_for


def axis(n: int, value: int, t_ms: int = 0, init: bool = False) -> JsEvent:
    return JsEvent(t_ms, value, JS_EVENT_AXIS, n, init)


def button(n: int, value: int, t_ms: int = 0, init: bool = False) -> JsEvent:
    return JsEvent(t_ms, value, JS_EVENT_BUTTON, n, init)


def opening_state() -> list[JsEvent]:
    """What the kernel reports on open for an Xbox pad at rest: 8 axes (triggers at -32767), 11 buttons."""
    axes = [axis(n, -AXIS_MAX if n in (2, 5) else 0, init=True) for n in range(8)]
    return axes + [button(n, 0, init=True) for n in range(11)]


def press(n: int) -> list[JsEvent]:
    return [button(n, 1), button(n, 0)]


def dpad(value: int) -> list[JsEvent]:
    return [axis(7, value), axis(7, 0)]


def stream(events: list[JsEvent]) -> bytes:
    return b"".join(e.pack() for e in events)


# ---------------------------------------------------------------------- records


def test_records_split_across_reads_and_unknown_types_are_counted() -> None:
    data = stream([axis(1, -1000, 5), button(3, 1, 6)])
    junk = JsEvent(7, 0, 0x04, 0).pack()  # no such event type
    reader = JsEventReader()
    events = [e for i in range(0, len(data), 3) for e in reader.feed(data[i : i + 3])]
    events += reader.feed(junk)
    assert events == [axis(1, -1000, 5), button(3, 1, 6)]
    assert reader.bad_n == 1
    init = reader.feed(JsEvent(9, 1, JS_EVENT_BUTTON, 2, init=True).pack())
    assert init == [JsEvent(9, 1, JS_EVENT_BUTTON, 2, True)]


# ---------------------------------------------------------------------- state


def run(events: list[JsEvent], mapping: GamepadMapping = DEFAULT_MAPPING) -> GamepadState:
    state = GamepadState(mapping)
    reader = JsEventReader()
    for e in reader.feed(stream(opening_state() + events)):
        state.apply(e)
    return state


def test_sticks_map_to_the_dt7_channels_with_up_and_right_positive() -> None:
    s = run([axis(3, AXIS_MAX), axis(4, -AXIS_MAX), axis(0, -AXIS_MAX // 2), axis(1, -32768)])
    assert s.sticks[0] == CH_LIMIT  # right stick right
    assert s.sticks[1] == CH_LIMIT  # right stick up (the pad's Y reads down positive)
    assert -CH_LIMIT < s.sticks[2] < -CH_LIMIT // 2 + 60  # half left, rescaled past the deadzone
    assert s.sticks[3] == CH_LIMIT  # -32768 (the s16 minimum) is clamped to full deflection
    resting = run([axis(3, 2000), axis(4, -2500)])  # inside the 8 % deadzone
    assert resting.sticks == [0, 0, 0, 0]


def test_levers_step_one_position_per_press_and_stop_at_the_ends() -> None:
    assert run([]).right_lever == Lever.DOWN and run([]).left_lever == Lever.DOWN
    assert run(dpad(-AXIS_MAX)).right_lever == Lever.MIDDLE
    assert run(dpad(-AXIS_MAX) * 3).right_lever == Lever.UP
    assert run(dpad(-AXIS_MAX) * 2 + dpad(AXIS_MAX)).right_lever == Lever.MIDDLE
    assert run(dpad(AXIS_MAX)).right_lever == Lever.DOWN
    left = run(press(3) + press(3) + press(0))
    assert left.left_lever == Lever.MIDDLE and left.right_lever == Lever.DOWN
    # Holding the D-pad is one press, not one per repeated report.
    assert run([axis(7, -AXIS_MAX), axis(7, -AXIS_MAX + 5), axis(7, 0)]).right_lever == Lever.MIDDLE


def test_a_button_held_while_the_device_opens_is_not_a_press() -> None:
    state = GamepadState()
    state.apply(button(3, 1, init=True))
    state.apply(axis(7, -AXIS_MAX, init=True))
    assert state.left_lever == Lever.DOWN and state.right_lever == Lever.DOWN
    state.apply(button(3, 0))
    state.apply(button(3, 1))
    assert state.left_lever == Lever.MIDDLE


def test_losing_the_device_puts_the_right_lever_down_and_centres_the_sticks() -> None:
    state = run(dpad(-AXIS_MAX) * 2 + press(3) + [axis(1, -AXIS_MAX), axis(3, AXIS_MAX)])
    assert state.right_lever == Lever.UP and state.sticks[3] == CH_LIMIT
    state.lost()
    assert (state.right_lever, state.left_lever, state.sticks) == (Lever.DOWN, Lever.DOWN, [0, 0, 0, 0])
    state.apply(axis(4, 0))  # the axes it remembered are gone too
    assert state.sticks == [0, 0, 0, 0]


def test_control_button_presses_are_counted() -> None:
    assert run(press(7) + press(7)).control_requests == 2


# ---------------------------------------------------------------------- mapping


def test_mapping_overrides_single_entries() -> None:
    m = parse_mapping("ch1=a4, right=b5/b4,control=b6")
    assert m.channels[1] == Input(JS_EVENT_AXIS, 4, False)
    assert m.channels[0] == DEFAULT_MAPPING.channels[0]
    assert m.right_lever == (Input(JS_EVENT_BUTTON, 5), Input(JS_EVENT_BUTTON, 4))
    state = run(press(5) + press(5) + [axis(4, AXIS_MAX)], m)
    assert state.right_lever == Lever.UP and state.sticks[1] == CH_LIMIT
    assert parse_mapping(format_mapping(DEFAULT_MAPPING)) == DEFAULT_MAPPING


@pytest.mark.parametrize(
    ("text", "needle"),
    [
        ("ch4=a1", "unknown key 'ch4'"),
        ("ch0=b1", "a stick channel needs an axis"),
        ("ch0=x1", "an input is aK, -aK (axis K) or bK"),
        ("ch0=a999", "input numbers are 0..255"),
        ("right=b1", "a lever needs UP/DOWN inputs"),
        ("control=a1", "control=a1: a button"),
        ("ch0=a1,ch0=a2", "ch0 given twice"),
        ("ch0", "expected KEY=VALUE"),
    ],
)
def test_bad_mappings_say_what_is_wrong(text: str, needle: str) -> None:
    with pytest.raises(ValueError) as info:
        parse_mapping(text)
    assert needle in str(info.value) and "\n" not in str(info.value)


_axes = st.builds(Input, st.just(JS_EVENT_AXIS), st.integers(0, 255), st.booleans())
_inputs = _axes | st.builds(Input, st.just(JS_EVENT_BUTTON), st.integers(0, 255), st.just(False))


@given(
    st.tuples(_axes, _axes, _axes, _axes),
    st.tuples(_inputs, _inputs),
    st.tuples(_inputs, _inputs),
    st.builds(Input, st.just(JS_EVENT_BUTTON), st.integers(0, 255), st.just(False)),
)
def test_format_then_parse_is_the_identity(
    channels: tuple[Input, Input, Input, Input],
    right: tuple[Input, Input],
    left: tuple[Input, Input],
    control: Input,
) -> None:
    mapping = GamepadMapping(channels, right, left, control)
    assert parse_mapping(format_mapping(mapping)) == mapping


# ---------------------------------------------------------------------- through a running host


def frames(peer: LinkPeer) -> list[RcFrame]:
    return [m.frame for m in peer.messages(VirtualRc) if isinstance(m, VirtualRc)]


def test_pad_events_travel_as_dbus_frames_and_an_unplugged_pad_sends_safe(tmp_path: Path) -> None:
    js = tmp_path / "js0"
    os.mkfifo(js)
    # Held open read-write by the test: the pad's reader sees data and no end of file until it closes.
    writer = os.open(js, os.O_RDWR | os.O_NONBLOCK)
    try:
        with LinkPeer("pty") as peer, HostApp(HostOptions(port=peer.url, ui=False, gamepad=str(js))) as app:
            app.start()
            assert app.arbiter is not None and app.arbiter.has_control(CLI_CLIENT)
            os.write(writer, stream(opening_state()))
            # Right lever to MIDDLE (MANUAL), left stick full up, right stick half right.
            os.write(writer, stream([*dpad(-AXIS_MAX), axis(1, -AXIS_MAX), axis(3, AXIS_MAX // 2)]))

            def driving() -> bool:
                return any(
                    f.right_lever == Lever.MIDDLE and f.channels[3] == CH_LIMIT and 250 < f.channels[0] < 330
                    for f in frames(peer)
                )

            assert wait_for(driving), frames(peer)[-3:]
            seen = len(frames(peer))
            os.close(writer)  # unplugged
            writer = -1
            assert wait_for(lambda: app.gamepad is not None and app.gamepad.losses_n == 1)

            def safe() -> bool:
                after = frames(peer)[seen:]
                return any(f.right_lever == Lever.DOWN and f.channels == (0, 0, 0, 0) for f in after)

            assert wait_for(safe), frames(peer)[-3:]
    finally:
        if writer >= 0:
            os.close(writer)


def test_a_tab_that_asks_gets_control_and_start_asks_for_it_back(tmp_path: Path) -> None:
    from host.gamepad import Gamepad
    from host.panel.arbiter import ControlArbiter
    from host.panel.notices import Notices

    js = tmp_path / "js0"
    os.mkfifo(js)
    writer = os.open(js, os.O_RDWR | os.O_NONBLOCK)
    model = ControlArbiter(Notices())
    pad = Gamepad(str(js), model, CLI_CLIENT)
    try:
        pad.start()
        assert model.holder == CLI_CLIENT
        os.write(writer, stream(opening_state() + dpad(-AXIS_MAX)))
        assert wait_for(lambda: model.operator_input()[1] == Lever.MIDDLE)
        tab = 11
        model.request_control(tab)
        assert wait_for(lambda: model.holder == tab)
        os.write(writer, stream(dpad(-AXIS_MAX)))  # not the holder: the pad's lever moves nothing
        time.sleep(0.3)
        assert model.operator_input()[1] == Lever.DOWN
        os.write(writer, stream(press(7)))  # Start
        assert wait_for(lambda: model.pending == CLI_CLIENT)
        model.answer_request(tab, grant=True)
        os.write(writer, stream(dpad(-AXIS_MAX)))
        # Regained from right lever DOWN (the arbiter restarts the operator): one step is MIDDLE.
        assert wait_for(lambda: model.holder == CLI_CLIENT and model.operator_input()[1] == Lever.MIDDLE)
    finally:
        pad.stop()
        os.close(writer)


def test_a_fifo_reopened_without_a_writer_is_not_back_until_events_flow(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    from host.gamepad import Gamepad
    from host.panel.arbiter import ControlArbiter
    from host.panel.notices import Notices

    js = tmp_path / "js0"
    os.mkfifo(js)
    writer = os.open(js, os.O_RDWR | os.O_NONBLOCK)
    pad = Gamepad(str(js), ControlArbiter(Notices()), CLI_CLIENT, reopen_period_s=0.05)
    try:
        with caplog.at_level("DEBUG", logger="host.gamepad"):
            pad.start()
            os.write(writer, stream(opening_state()))
            os.close(writer)  # the writer goes: lost once
            writer = -1
            assert wait_for(lambda: pad.losses_n == 1)
            time.sleep(0.6)  # reopened (a FIFO opens without a writer), and nothing flows
            back = [r for r in caplog.records if "is back" in r.getMessage()]
            lost = [r for r in caplog.records if "lost" in r.getMessage() and r.levelname == "WARNING"]
            assert not back and pad.backs_n == 0, [r.getMessage() for r in back]
            assert len(lost) == 1 and pad.losses_n == 1
            writer = os.open(js, os.O_RDWR | os.O_NONBLOCK)  # a writer again, events flow
            os.write(writer, stream(opening_state()))
            assert wait_for(lambda: pad.backs_n == 1)
            assert len([r for r in caplog.records if "is back" in r.getMessage()]) == 1
    finally:
        pad.stop()
        if writer >= 0:
            os.close(writer)
