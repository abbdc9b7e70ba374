"""The state bar at the top of each tab: what the board is doing and the one next step for the pilot.

:func:`pilot_state` derives it from the latest ``Telemetry`` (phase, mode, ``arm_blocker``, the levers
the board saw) and who holds control; :func:`state_bar_html` draws it. The same module holds the tab's
keyboard hook (:data:`KEY_HOOK_HTML`): viser's hotkeys (Mantine ``useHotkeys``) ignore keys typed
into an input, so Space would not stop the arm while a number box has focus; a capture-phase listener
on the window sees Space first, everywhere, and presses the tab's E-STOP button.
"""

from __future__ import annotations

import html
from dataclasses import dataclass

from host.link.source import LinkState
from protocol.dbus import Lever
from protocol.messages import ArmBlocker, GraspState, Mode, Phase, Telemetry, TelemetryFlags

__all__ = ["KEY_HOOK_HTML", "PilotState", "pilot_state", "state_bar_html"]

_COLOURS = {
    "grey": ("#5c5f66", "#f1f3f5"),
    "blue": ("#1c7ed6", "#e7f5ff"),
    "green": ("#2b8a3e", "#ebfbee"),
    "orange": ("#e8590c", "#fff4e6"),
    "red": ("#c92a2a", "#fff5f5"),
}
"""Colour name -> (border / text, background)."""


@dataclass(frozen=True, slots=True)
class PilotState:
    """What the state bar says.

    Attributes:
        colour: ``grey`` (no board / watching), ``blue`` (safe, ready), ``green`` (driving),
            ``orange`` (failsafe that clears itself), ``red`` (latched stop).
        headline: phase, mode and arming in a few words.
        next_step: the one thing the pilot has to do next.
        estop: an E-stop is latched (the tab shows the banner).
    """

    colour: str
    headline: str
    next_step: str
    estop: bool = False


def _lever(value: int) -> str:
    return Lever(value).name if value in (1, 2, 3) else "-"


_RE_ARM = {
    Phase.RC_LOST: "RC is back",
    Phase.HOST_LOST: "the host heartbeat is back",
    Phase.MOTOR_FAULT: "every motor answers again",
}
"""Latched phases whose cause is gone (the board's ``arm_blocker`` moved on to the lever): what came back."""


def pilot_state(
    telemetry: Telemetry | None,
    link_state: LinkState,
    *,
    mine: bool,
    holder_known: bool,
) -> PilotState:
    """The state bar's content for one tab.

    Every word comes from the board: its phase, mode, ``ARMED`` and ``RC_OK`` flags, the levers of the
    last frame it accepted, its grasp state and above all its ``arm_blocker`` (what holds its arming gate
    shut, in the firmware's own order: E-stop, motor, RC, host heartbeat, DISARM, right lever). The phase
    says what happened; the blocker says what is still missing: a latched ``RC_LOST`` whose radio is back
    is blocked by the right lever, not by the RC. Who holds control decides whose step it is: a tab that
    does not hold control is told to take it (or that someone else drives); the radio keeps transmitting
    while nobody holds control, so that is not an RC loss.

    Args:
        telemetry: the latest telemetry (None before the first).
        link_state: the board link's state.
        mine: this tab holds control (its sliders and levers are the radio).
        holder_known: somebody (a tab or the command line) holds control.

    Returns:
        The colour, the headline and the next step.
    """
    if link_state is LinkState.DISCONNECTED:
        return PilotState("red", "Board disconnected", "wait: the host reconnects (zero current)")
    if telemetry is None:
        return PilotState("grey", "Connecting to the board…", "wait for the first telemetry")
    t = telemetry
    flags = TelemetryFlags(t.flags)
    armed = bool(flags & TelemetryFlags.ARMED)
    head = f"{t.phase.name} · {t.mode.name} · {'ARMED' if armed else 'not armed'}"
    head += f" · right lever {_lever(t.right_lever)}"
    blocker = t.arm_blocker
    take = "press Take control: this tab then becomes the radio"
    if t.phase == Phase.ESTOP or blocker == ArmBlocker.ESTOP_LATCHED:
        step = "E-stop latched: clear it (Clear E-stop), then re-arm through SAFE (right lever DOWN)"
        if not mine:
            step = "E-stop latched: take control, clear it (Clear E-stop), then re-arm through SAFE"
        return PilotState("red", head, step, estop=True)
    if blocker == ArmBlocker.MOTOR_FAULT:
        return PilotState("red", head, "a motor is silent (zero current): check its power and CAN")
    if not mine:
        if holder_known:
            return PilotState("grey", head, "watching: another tab or the command line drives")
        if blocker == ArmBlocker.RC_INVALID:
            return PilotState("orange", head, f"no RC reaches the board (zero current); {take}")
        return PilotState("grey", head, take)
    if blocker == ArmBlocker.RC_INVALID:
        return PilotState(
            "orange", head, "no valid RC reaches the board (zero current): see Health (link, RC late)"
        )
    if blocker == ArmBlocker.HOST_MISSING:
        return PilotState("orange", head, "no host heartbeat (zero current): wait for the link")
    if blocker == ArmBlocker.DISARMED:
        return PilotState("blue", head, "press Arm (the host disarmed the board)")
    if blocker == ArmBlocker.LEVER_NOT_DOWN:
        came_back = _RE_ARM.get(t.phase)
        if came_back is not None:
            return PilotState(
                "orange", head, f"{came_back}: move the right lever DOWN to re-arm (zero current)"
            )
        return PilotState("orange", head, "move the right lever DOWN to arm, then MIDDLE to drive")
    if not armed:  # nothing blocks the gate any more: it opens on the board's next tick
        return PilotState("blue", head, "arming: the gate opens on the board's next tick")
    if t.mode == Mode.SAFE:
        return PilotState("blue", head, "move the right lever to MIDDLE to drive (UP: grasp)")
    if t.mode == Mode.MANUAL:
        return PilotState(
            "green",
            head,
            "driving: right stick bends, left ↕ up tightens all cables; right lever DOWN stops",
        )
    if t.mode == Mode.GRASP:
        return _grasp_state(t, head)
    return PilotState(
        "green", head, "DIRECT: cable tensions from the Direct mode sliders; right lever DOWN stops"
    )


def _grasp_state(t: Telemetry, head: str) -> PilotState:
    """GRASP mode's next step from the grasp state and the left lever the board saw: only a lever's
    *change* acts (``controller.modes``: an edge to UP grasps, an edge to DOWN releases)."""
    known = t.grasp_state in GraspState._value2member_map_
    grasp = GraspState(t.grasp_state) if known else None
    head = f"{head} · grasp {grasp.name if grasp is not None else '?'}"
    left_down = t.left_lever == Lever.DOWN
    release = "press Release (or left lever UP, then DOWN)" if left_down else "left lever DOWN releases"
    if grasp in (GraspState.IDLE, None):
        if t.left_lever == Lever.UP:  # requested (packing first), or GRASP was entered with it UP
            step = "left lever UP: the grasp reaches once the arm is packed (if not: lever DOWN, then UP)"
        else:
            step = "left lever UP grasps (or press Grasp)"
    elif grasp in (GraspState.REACH, GraspState.WRAP):
        step = f"grasping ({grasp.name}): wait; {release}"
    elif grasp == GraspState.HOLD:
        step = f"holding the object: {release}"
    elif grasp == GraspState.RELEASE:
        step = "releasing: wait until IDLE"
    elif left_down:  # FAILED: an edge to UP grasps again
        step = "the grasp failed (no contact): left lever UP tries again"
    else:
        step = "the grasp failed (no contact): left lever DOWN releases, then UP tries again"
    return PilotState("green", head, f"{step}; right lever DOWN stops")


def state_bar_html(state: PilotState) -> str:
    """The bar as HTML (the E-stop banner on top while latched)."""
    fg, bg = _COLOURS.get(state.colour, _COLOURS["grey"])
    banner = ""
    if state.estop:
        banner = (
            '<div data-testid="estop-banner" style="background:#c92a2a;color:#fff;font-weight:700;'
            'padding:4px 8px;border-radius:4px;margin-bottom:4px;text-align:center">'
            "E-STOP LATCHED: zero current</div>"
        )
    return (
        f'{banner}<div data-testid="state-bar" data-colour="{state.colour}" '
        f'style="border-left:6px solid {fg};background:{bg};padding:4px 8px;border-radius:4px;"'
        'font-size:0.85em">'
        f'<div style="color:{fg};font-weight:700">{html.escape(state.headline)}</div>'
        f'<div data-testid="next-step">Next: {html.escape(state.next_step)}</div></div>'
    )


KEY_HOOK_HTML = (
    '<img alt="" style="display:none" src="data:image/gif;base64,invalid" onerror="'
    "if(!window.__spirobSpace){window.__spirobSpace=true;"
    "window.addEventListener('keydown',function(e){"
    "if(e.code!=='Space'&&e.key!==' ')return;"
    "var b=Array.from(document.querySelectorAll('button')).find(function(x){"
    "return x.textContent.trim().indexOf('E-STOP')===0;});"
    "if(!b)return;e.preventDefault();e.stopPropagation();if(!e.repeat)b.click();},true);}"
    '">'
)
"""Injected once per tab with ``add_html``: viser renders it with ``innerHTML``, which does not run a
``<script>``, but does run an image's ``onerror``. The listener runs in the capture phase, before any
input or viser's hotkeys see the key, and stops it there (one E-stop per press, none on key repeat)."""
