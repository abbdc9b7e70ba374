"""host.panel.state_bar: the state bar's colour and next step in each phase and mode."""

from __future__ import annotations

import pytest

from host.link.source import LinkState
from host.panel.state_bar import KEY_HOOK_HTML, pilot_state, state_bar_html
from protocol.dbus import Lever
from protocol.messages import ArmBlocker, Mode, Phase, Telemetry, TelemetryFlags

OK = LinkState.CONNECTED


def tel(
    phase: Phase, mode: Mode = Mode.SAFE, blocker: ArmBlocker = ArmBlocker.NONE, lever: int = 2
) -> Telemetry:
    flags = TelemetryFlags.ARMED if blocker == ArmBlocker.NONE and phase == Phase.OK else TelemetryFlags.NONE
    return Telemetry(1_000_000, mode=mode, phase=phase, flags=flags, right_lever=lever, arm_blocker=blocker)


@pytest.mark.parametrize(
    ("t", "colour", "step"),
    [
        (tel(Phase.RC_LOST, blocker=ArmBlocker.RC_INVALID, lever=0), "orange", "waiting for valid RC"),
        (
            tel(Phase.GATE, blocker=ArmBlocker.LEVER_NOT_DOWN, lever=int(Lever.MIDDLE)),
            "orange",
            "move the right lever DOWN, then MIDDLE to drive",
        ),
        (tel(Phase.OK), "blue", "move the right lever to MIDDLE to drive"),
        (tel(Phase.OK, blocker=ArmBlocker.DISARMED), "blue", "press Arm"),
        (tel(Phase.OK, Mode.MANUAL, lever=int(Lever.MIDDLE)), "green", "driving: right stick bends"),
        (tel(Phase.OK, Mode.GRASP, lever=int(Lever.UP)), "green", "left lever UP grasps"),
        (tel(Phase.HOST_LOST, blocker=ArmBlocker.HOST_MISSING), "orange", "no host heartbeat"),
        (tel(Phase.MOTOR_FAULT, blocker=ArmBlocker.MOTOR_FAULT), "red", "a motor is silent"),
        (
            tel(Phase.ESTOP, blocker=ArmBlocker.ESTOP_LATCHED),
            "red",
            "E-stop latched: clear it (Clear E-stop), then re-arm through SAFE",
        ),
    ],
)
def test_state_for_the_holder(t: Telemetry, colour: str, step: str) -> None:
    s = pilot_state(t, OK, mine=True, holder_known=True)
    assert s.colour == colour
    assert step in s.next_step
    assert s.headline.startswith(t.phase.name) and t.mode.name in s.headline
    assert s.estop == (t.phase == Phase.ESTOP)


def test_watchers_are_told_to_take_control_and_estop_shows_a_banner() -> None:
    t = tel(Phase.RC_LOST, blocker=ArmBlocker.RC_INVALID, lever=0)
    assert "Take control" in pilot_state(t, OK, mine=False, holder_known=False).next_step
    assert "watching" in pilot_state(t, OK, mine=False, holder_known=True).next_step
    assert pilot_state(None, OK, mine=True, holder_known=True).colour == "grey"
    assert pilot_state(t, LinkState.DISCONNECTED, mine=True, holder_known=True).colour == "red"
    latched = pilot_state(
        tel(Phase.ESTOP, blocker=ArmBlocker.ESTOP_LATCHED), OK, mine=False, holder_known=True
    )
    html = state_bar_html(latched)
    assert "E-STOP LATCHED" in html and 'data-colour="red"' in html
    assert "E-STOP LATCHED" not in state_bar_html(
        pilot_state(tel(Phase.OK), OK, mine=True, holder_known=True)
    )
    assert "<script" not in KEY_HOOK_HTML and "'keydown'" in KEY_HOOK_HTML and ",true)" in KEY_HOOK_HTML
