"""The per-tab Control folder: its builder (callbacks only call the control arbiter) and its refresh."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import viser

from host.panel.arbiter import CLI_CLIENT, ControlArbiter, ControlResult
from host.panel.board_state import BoardState
from host.panel.camera import CAMERA_PRESETS
from host.panel.state_bar import KEY_HOOK_HTML, pilot_state, state_bar_html
from protocol.dbus import Lever
from protocol.messages import ArmBlocker, CommandCode, Mode, Phase, TelemetryFlags

__all__ = [
    "LEVER_OPTIONS",
    "STICK_CHANNELS",
    "ControlHandles",
    "build_control_panel",
    "lever_options",
    "refresh_control",
]

STICK_CHANNELS = (
    (1, "Right ↕ bend away / toward"),
    (0, "Right ↔ bend right / left"),
    (3, "Left ↕ tighten all cables"),
)
"""Slider order in the panel: (DBUS channel, label), named after what MANUAL does with them
(``controller.cables.CableMapper.manual``): the right stick pulls the cables on its side, so the arm
bends toward +x (right) and +y (away, in the default view); left stick up adds the same tension to every
cable (down does nothing). The left stick's ↔ (ch2) is not used by the board: no slider."""
LEVER_OPTIONS = ("UP", "MIDDLE", "DOWN")
SELECTED = "● "
"""Prefix of the lever button in the position this tab sends."""
CAMERA_LABELS = {
    "sticks": ("Stick view", "1"),
    "behind": ("Behind the drone", "2"),
    "side": ("Side", "3"),
    "top": ("Top", "4"),
    "tip": ("Follow the tip", "5"),
}
"""Preset -> (button label, hotkey). Digits and C only: viser's camera owns WASD, Q/E and the arrows."""
_ORDER_STATE = -10.0  # the state bar first, then Control (0), Plots (100), Health (200)
_ORDER_CONTROL = 0.0
_ORDER_VIEW = 50.0


def lever_options(selected: Lever) -> tuple[str, ...]:
    """The lever's buttons with the selected one marked (``● DOWN``)."""
    return tuple(SELECTED + o if o == selected.name else o for o in LEVER_OPTIONS)


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
    state_bar: Any
    camera: list[Any]
    commands: list[Any]
    follow_tip: bool = False
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
    client: viser.ClientHandle,
    arbiter: ControlArbiter,
    board: BoardState,
    *,
    tension_max_n: float,
    set_camera: Callable[[viser.ClientHandle, str], None] | None = None,
) -> ControlHandles:
    """Build one tab's state bar, Control folder and View folder.

    Every callback calls ``arbiter`` on behalf of that tab (or moves this tab's own camera).

    Args:
        client: the tab.
        arbiter: who may act, and the way to the board.
        board: the board's state (the state bar's first text).
        tension_max_n: the DIRECT sliders' ceiling.
        set_camera: moves a tab's camera to a preset (``host.panel.camera.CAMERA_PRESETS``).
    """
    cid = client.client_id
    gui = client.gui
    first = pilot_state(None, board.link_state, mine=False, holder_known=False)
    state_bar = gui.add_html(state_bar_html(first), order=_ORDER_STATE)
    gui.add_html(KEY_HOOK_HTML, order=_ORDER_STATE + 1)

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
            centre = gui.add_button("Centre sticks  [C]", disabled=True)
            gui.add_markdown(
                "Right stick: the arm bends that way (up = toward the drone's nose, right = your right). "
                "Left ↕ up: every cable tighter. Left ↔: not used by the board."
            )
        with gui.add_folder("Levers"):
            right_lever = gui.add_button_group(
                "Right lever", lever_options(Lever.DOWN), hint="DOWN = SAFE, MIDDLE = drive, UP = grasp"
            )
            left_lever = gui.add_button_group(
                "Left lever", lever_options(Lever.DOWN), hint="In GRASP: UP = grasp, DOWN = release"
            )
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
    with gui.add_folder("View", order=_ORDER_VIEW, expand_by_default=False):
        camera = [gui.add_button(f"{CAMERA_LABELS[p][0]}  [{CAMERA_LABELS[p][1]}]") for p in CAMERA_PRESETS]
        gui.add_markdown("Camera keys: WASD / Q E / arrows (viser's); 1-5 presets; C centres the sticks.")
    estop_cmd = gui.add_command(
        "E-STOP", description="Emergency stop (zero current, latched)", hotkey="space"
    )
    commands = [
        gui.add_command(label, description="Camera preset", hotkey=key)  # type: ignore[arg-type]
        for label, key in (CAMERA_LABELS[p] for p in CAMERA_PRESETS)
    ]
    centre_cmd = gui.add_command("Centre sticks", description="All sticks to the centre", hotkey="C")

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
        state_bar,
        camera,
        [*commands, centre_cmd],
    )

    def _view(preset: str) -> None:
        h.follow_tip = preset == "tip"
        if set_camera is not None:
            set_camera(client, preset)

    for preset, button, command in zip(CAMERA_PRESETS, camera, commands, strict=True):

        def _on_view(_event: Any, preset: str = preset) -> None:
            _view(preset)

        button.on_click(_on_view)
        command.on_trigger(_on_view)

    @take.on_click
    def _(event: Any) -> None:
        if not own(event):
            return
        result = arbiter.request_control(cid)
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
            arbiter.release_control(cid)

    @grant.on_click
    def _(event: Any) -> None:
        if own(event):
            arbiter.answer_request(cid, grant=True)

    @refuse.on_click
    def _(event: Any) -> None:
        if own(event):
            arbiter.answer_request(cid, grant=False)

    @cancel.on_click
    def _(event: Any) -> None:
        if own(event):
            arbiter.cancel_request(cid)

    @estop.on_click
    def _(event: Any) -> None:
        if own(event):
            arbiter.estop(cid)

    @estop_cmd.on_trigger
    def _(event: Any) -> None:
        if event.client_id is None or event.client_id == cid:
            arbiter.estop(cid)

    for ch, slider in sticks.items():

        def _stick(event: Any, ch: int = ch) -> None:
            if own(event):
                arbiter.set_stick(cid, ch, float(event.target.value))

        slider.on_update(_stick)

    def _centre(event: Any) -> None:
        if event.client_id is not None and event.client_id == cid and arbiter.has_control(cid):
            arbiter.centre_sticks(cid)
            for s in sticks.values():
                handle: Any = s  # viser types the setter oddly (read-only to mypy)
                handle.value = 0.0

    centre.on_click(_centre)
    centre_cmd.on_trigger(_centre)

    def _lever(event: Any, which: str) -> None:
        if not own(event):
            return
        # viser's button groups cannot be disabled: a watcher's click is refused here, and said.
        if not arbiter.set_lever(cid, which, str(event.target.value).removeprefix(SELECTED)):
            client.add_notification(
                "Lever not moved",
                "Take control first: only the holder's levers reach the board.",
                color="yellow",
                auto_close_seconds=5.0,
            )

    right_lever.on_click(lambda event: _lever(event, "right"))
    left_lever.on_click(lambda event: _lever(event, "left"))

    def _cmd(button: Any, code: CommandCode, args: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> None:
        def _(event: Any) -> None:
            if own(event):
                arbiter.command(cid, code, args)

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
                arbiter.set_direct_tension(cid, i, float(event.target.value))

        slider.on_update(_tension)

    for i, box in enumerate(holds):

        def _hold(event: Any, i: int = i) -> None:
            if own(event):
                arbiter.set_length_hold(cid, i, bool(event.target.value))

        box.on_update(_hold)

    return h


def refresh_control(
    h: ControlHandles, arbiter: ControlArbiter, board: BoardState, force: bool = False
) -> None:
    """Bring one tab's control widgets in line with the arbiter and the board (sends only what changed
    unless forced).

    Args:
        h: The tab's handles.
        arbiter: who holds control, the operator's radio.
        board: the board's state.
        force: Send every widget state even if it looks unchanged (a new tab).
    """
    cid = h.client_id
    holder = arbiter.holder
    pending = arbiter.pending
    mine = holder == cid
    authorised = arbiter.is_authorised(cid)
    sticks, right, left, _ = arbiter.operator_input()
    telemetry = board.telemetry
    bar = state_bar_html(pilot_state(telemetry, board.link_state, mine=mine, holder_known=holder is not None))
    if force or bar != h.shown.get("bar"):
        h.state_bar.content = bar
    flags = int(telemetry.flags) if telemetry is not None else 0
    # Arm does something only while the board is not armed and no E-stop is latched (it refuses then).
    arm_useful = not flags & TelemetryFlags.ARMED and not (
        telemetry is not None
        and (telemetry.phase == Phase.ESTOP or telemetry.arm_blocker == ArmBlocker.ESTOP_LATCHED)
    )
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
        "bar": bar,
        "arm_useful": arm_useful,
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
    h.arm.disabled = not (mine and arm_useful)
    if force or prev.get("mine") != mine or (not mine and prev.get("sticks") != sticks):
        # Whoever gets (or loses) control starts from SAFE: show the reset sticks. Watchers see
        # the holder's sticks (their own sliders are disabled).
        for ch, slider in h.sticks.items():
            slider.value = float(sticks[ch])
    if force or prev.get("levers") != (right, left):
        h.right_lever.options = lever_options(right)
        h.left_lever.options = lever_options(left)
    if force or prev.get("held") != held:
        for box, on in zip(h.holds, held, strict=True):
            box_handle: Any = box
            box_handle.value = on
    seen = ""
    if telemetry is not None and telemetry.right_lever in (1, 2, 3):
        seen = f" · the board sees right **{Lever(telemetry.right_lever).name}**"
    if holder is None:
        h.levers_md.content = (
            f"Idle radio (nobody holds control): sticks centred, right lever **{right.name}** · left lever "
            f"**{left.name}**{seen}"
        )
    else:
        h.levers_md.content = f"Sent: right lever **{right.name}** · left lever **{left.name}**{seen}"
