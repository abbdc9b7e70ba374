"""host.panel.notices and host.panel.console: failsafe notices, the event console, commands sent."""

from __future__ import annotations

import pytest

from host.link.source import LinkState
from host.panel.console import EventConsole, console_html
from host.panel.notices import Notices
from protocol.messages import Command, CommandCode, Event, EventKind, ParamSet, Phase, Telemetry


def test_phase_notices_and_faults() -> None:
    n = Notices()
    for i in range(5):
        n.on_board_message(Telemetry(time_us=i * 10_000, phase=Phase.OK, commanded_current=(1000, 0, 0)))
    n.on_board_message(Telemetry(time_us=60_000, phase=Phase.RC_LOST))
    n.on_board_message(Event(61_000, EventKind.FAULT, 2, 0.0, "motor 2 silent"))
    titles = [x.title for x in n.notices_after(0)]
    assert titles == ["RC lost", "Fault"]


def test_link_loss_and_return_are_said() -> None:
    n = Notices()
    n.on_link_state(LinkState.CONNECTED)
    n.on_link_state(LinkState.DISCONNECTED)
    n.on_link_state(LinkState.CONNECTED)
    titles = [x.title for x in n.notices_after(0)]
    assert titles == ["Board disconnected", "Board reconnected"]


def test_event_console_is_bounded_and_keeps_board_times() -> None:
    c = EventConsole(3)
    for i in range(5):
        c.add(i * 1_000_000, "board", "info", f"e{i}")
    assert [e.text for e in c.entries()] == ["e2", "e3", "e4"] and c.seq == 5
    assert c.entries()[-1].line().split() == ["4.000", "s", "board", "e4"]
    text = console_html(c.entries(), max_lines=2)
    assert text.index("e4") < text.index("e3") and "e2" not in text
    with pytest.raises(ValueError):
        EventConsole(0)
    n = Notices()
    n.on_board_message(Event(2_500_000, EventKind.FAULT, 2, 0.0, "motor 2 silent"))
    (entry,) = n.events.entries()
    assert entry.board_time_us == 2_500_000 and entry.level == "error" and "motor 2 silent" in entry.text


def test_commands_sent_are_logged_with_who_sent_them() -> None:
    n = Notices()
    n.on_board_message(Telemetry(3_000_000))
    # BoardClient's sent listener: the drone link's commands, and a tab's, each with its origin.
    n.on_sent(Command(CommandCode.GRASP), "MAVLink")
    n.on_sent(ParamSet("SLEW_N_S", 40.0), "MAVLink")
    n.on_sent(Command(CommandCode.SET_TENSIONS, (1.0, 0.0, 2.5)), "Tab 3")
    n.on_sent(Command(CommandCode.ESTOP), "host")
    lines = [(e.source, e.text, e.board_time_us, e.level) for e in n.events.entries()]
    assert lines == [
        ("MAVLink", "GRASP", 3_000_000, "info"),
        ("MAVLink", "set SLEW_N_S = 40", 3_000_000, "info"),
        ("Tab 3", "SET_TENSIONS (1, 2.5)", 3_000_000, "info"),
        ("host", "ESTOP", 3_000_000, "error"),
    ]
