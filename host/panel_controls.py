"""The per-tab Control folder: its builder (callbacks only write to the model) and its refresh."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import viser

from host.model import CLI_CLIENT, ControlResult, UiModel
from protocol.messages import CommandCode, Mode, TelemetryFlags

__all__ = ["LEVER_OPTIONS", "STICK_CHANNELS", "ControlHandles", "build_control_panel", "refresh_control"]

STICK_CHANNELS = (
    (3, "Left ↕ curl"),
    (2, "Left ↔"),
    (0, "Right ↔ bend"),
    (1, "Right ↕ bend"),
)
"""Slider order in the panel: (DBUS channel, label). ch3 = left vertical = common tension (curl)."""
LEVER_OPTIONS = ("UP", "MIDDLE", "DOWN")
_ORDER_CONTROL = 0.0  # folder order in the panel: Control (0), Plots (100), Health (200)


@dataclass
class ControlHandles:
    """Per-tab control widgets."""

    client_id: int
    status: Any
    take: Any
    release: Any
    grant: Any
    refuse: Any
    cancel: Any
    sticks: dict[int, Any]
    centre: Any
    right_lever: Any
    left_lever: Any
    levers_md: Any
    arm: Any
    disarm: Any
    estop: Any
    clear_estop: Any
    grasp: Any
    release_grasp: Any
    hold: Any
    direct_mode: Any
    tensions: list[Any]
    holds: list[Any]
    estop_command: Any
    shown: dict[str, Any] = field(default_factory=dict)

    def action_widgets(self) -> list[Any]:
        """Widgets that only the control holder may use."""
        return [
            *self.sticks.values(),
            self.centre,
            self.arm,
            self.disarm,
            self.clear_estop,
            self.grasp,
            self.release_grasp,
            self.hold,
            self.direct_mode,
            *self.tensions,
            *self.holds,
        ]


def build_control_panel(
    client: viser.ClientHandle, model: UiModel, *, tension_max_n: float
) -> ControlHandles:
    """Build one tab's Control folder; every callback writes to ``model`` on behalf of that tab."""
    cid = client.client_id
    gui = client.gui

    def own(event: Any) -> bool:
        # Server-side assignments (client_id None) are echoes of our own updates, not user input.
        return event.client_id is not None and event.client_id == cid

    with gui.add_folder("Control", order=_ORDER_CONTROL):
        status = gui.add_markdown("**Control**: …")
        take = gui.add_button(
            "Take control", color="blue", hint="Ask for control; the holder must hand it over"
        )
        release = gui.add_button("Release control", visible=False)
        grant = gui.add_button("Hand control over", color="orange", visible=False)
        refuse = gui.add_button("Keep control", visible=False)
        cancel = gui.add_button("Cancel request", visible=False)
        estop = gui.add_button("E-STOP  [Space]", color="red", hint="Emergency stop: zero current, latched")
        with gui.add_folder("Sticks"):
            sticks = {
                ch: gui.add_slider(label, min=-660.0, max=660.0, step=1.0, initial_value=0.0, disabled=True)
                for ch, label in STICK_CHANNELS
            }
            centre = gui.add_button("Centre sticks", disabled=True)
        with gui.add_folder("Levers"):
            right_lever = gui.add_button_group("Right lever (mode)", LEVER_OPTIONS)
            left_lever = gui.add_button_group("Left lever", LEVER_OPTIONS)
            levers_md = gui.add_markdown("")
        with gui.add_folder("Commands"):
            arm = gui.add_button("Arm", disabled=True)
            disarm = gui.add_button("Disarm", disabled=True)
            clear_estop = gui.add_button("Clear E-stop", disabled=True)
            grasp = gui.add_button("Grasp", disabled=True)
            release_grasp = gui.add_button("Release", disabled=True)
            hold = gui.add_button("Hold", disabled=True)
        with gui.add_folder("Direct mode", expand_by_default=False):
            direct_mode = gui.add_button("Enter DIRECT mode", disabled=True)
            tensions = [
                gui.add_slider(
                    f"Cable {i + 1} tension [N]",
                    min=0.0,
                    max=tension_max_n,
                    step=0.1,
                    initial_value=0.0,
                    disabled=True,
                )
                for i in range(3)
            ]
            holds = [
                gui.add_checkbox(
                    f"Cable {i + 1} hold length",
                    initial_value=False,
                    disabled=True,
                    hint="Hold this cable at its present length (position loop) instead of a tension",
                )
                for i in range(3)
            ]
    estop_cmd = gui.add_command(
        "E-STOP", description="Emergency stop (zero current, latched)", hotkey="space"
    )

    h = ControlHandles(
        cid,
        status,
        take,
        release,
        grant,
        refuse,
        cancel,
        sticks,
        centre,
        right_lever,
        left_lever,
        levers_md,
        arm,
        disarm,
        estop,
        clear_estop,
        grasp,
        release_grasp,
        hold,
        direct_mode,
        tensions,
        holds,
        estop_cmd,
    )

    @take.on_click
    def _(event: Any) -> None:
        if not own(event):
            return
        result = model.request_control(cid)
        if result is ControlResult.DENIED:
            client.add_notification(
                "Not authorised", "This tab has no access token.", color="red", auto_close_seconds=5
            )
        elif result is ControlResult.PENDING:
            client.add_notification(
                "Control requested", "Waiting for the holder to hand control over.", auto_close_seconds=5
            )

    @release.on_click
    def _(event: Any) -> None:
        if own(event):
            model.release_control(cid)

    @grant.on_click
    def _(event: Any) -> None:
        if own(event):
            model.answer_request(cid, grant=True)

    @refuse.on_click
    def _(event: Any) -> None:
        if own(event):
            model.answer_request(cid, grant=False)

    @cancel.on_click
    def _(event: Any) -> None:
        if own(event):
            model.cancel_request(cid)

    @estop.on_click
    def _(event: Any) -> None:
        if own(event):
            model.estop(cid)

    @estop_cmd.on_trigger
    def _(event: Any) -> None:
        if event.client_id is None or event.client_id == cid:
            model.estop(cid)

    for ch, slider in sticks.items():

        def _stick(event: Any, ch: int = ch) -> None:
            if own(event):
                model.set_stick(cid, ch, float(event.target.value))

        slider.on_update(_stick)

    @centre.on_click
    def _(event: Any) -> None:
        if own(event):
            model.centre_sticks(cid)
            for s in sticks.values():
                handle: Any = s  # viser types the setter oddly (read-only to mypy)
                handle.value = 0.0

    @right_lever.on_click
    def _(event: Any) -> None:
        if own(event):
            model.set_lever(cid, "right", str(event.target.value))

    @left_lever.on_click
    def _(event: Any) -> None:
        if own(event):
            model.set_lever(cid, "left", str(event.target.value))

    def _cmd(button: Any, code: CommandCode, args: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> None:
        def _(event: Any) -> None:
            if own(event):
                model.command(cid, code, args)

        button.on_click(_)

    _cmd(arm, CommandCode.ARM)
    _cmd(disarm, CommandCode.DISARM)
    _cmd(clear_estop, CommandCode.CLEAR_ESTOP)
    _cmd(grasp, CommandCode.GRASP)
    _cmd(release_grasp, CommandCode.RELEASE)
    _cmd(hold, CommandCode.HOLD)
    _cmd(direct_mode, CommandCode.SET_MODE, (float(Mode.DIRECT), 0.0, 0.0))

    for i, slider in enumerate(tensions):

        def _tension(event: Any, i: int = i) -> None:
            if own(event):
                model.set_direct_tension(cid, i, float(event.target.value))

        slider.on_update(_tension)

    for i, box in enumerate(holds):

        def _hold(event: Any, i: int = i) -> None:
            if own(event):
                model.set_length_hold(cid, i, bool(event.target.value))

        box.on_update(_hold)

    return h


def refresh_control(h: ControlHandles, model: UiModel, force: bool = False) -> None:
    """Bring one tab's control widgets in line with the model (sends only what changed unless forced).

    Args:
        h: The tab's handles.
        model: The UI model.
        force: Send every widget state even if it looks unchanged (a new tab).
    """
    m = model
    cid = h.client_id
    holder = m.holder
    pending = m.pending
    mine = holder == cid
    authorised = m.is_authorised(cid)
    sticks, right, left, _ = m.operator_input()
    telemetry = m.telemetry
    flags = int(telemetry.flags) if telemetry is not None else 0
    # What the board holds (it drops every hold on a mode change or failsafe): the toggles follow it.
    held = tuple(bool(flags & (TelemetryFlags.HOLD_1 << i)) for i in range(3))
    if mine:
        who = "**You hold control.**"
    elif holder is None:
        who = "Nobody holds control." + ("" if authorised else " This tab may only watch.")
    elif holder == CLI_CLIENT:
        who = "The command line holds control (--virtual-rc). Watching."
    else:
        who = f"Tab {holder} holds control. Watching."
    if pending is not None and mine:
        who += f"  \nTab {pending} asks for control."
    elif pending == cid:
        who += "  \nRequest sent; waiting for the holder."
    state = {
        "who": who,
        "mine": mine,
        "pending_mine": pending == cid,
        "asked": mine and pending is not None,
        "auth": authorised,
        "levers": (right, left),
        "sticks": None if mine else sticks,
        "held": held,
    }
    if not force and state == h.shown:
        return
    prev = h.shown
    h.shown = state
    h.status.content = who
    h.take.visible = not mine and pending != cid
    h.take.disabled = not authorised
    h.release.visible = mine
    h.grant.visible = mine and pending is not None
    h.refuse.visible = mine and pending is not None
    h.cancel.visible = pending == cid
    h.estop.disabled = not authorised
    for w in h.action_widgets():
        w.disabled = not mine
    if force or prev.get("mine") != mine or (not mine and prev.get("sticks") != sticks):
        # Whoever gets (or loses) control starts from SAFE: show the reset sticks. Watchers see
        # the holder's sticks (their own sliders are disabled).
        for ch, slider in h.sticks.items():
            slider.value = float(sticks[ch])
    if force or prev.get("held") != held:
        for box, on in zip(h.holds, held, strict=True):
            box_handle: Any = box
            box_handle.value = on
    h.levers_md.content = f"Right lever **{right.name}** · left lever **{left.name}**"
