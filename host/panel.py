"""The browser teleop panel (viser 1.1.x): one builder per area, callbacks that only write to the model.

Areas and who sees what:

- **Control** (built per browser tab, ``client.gui``): who holds control and the hand-over buttons,
  the access-token field (when a token is required), two virtual sticks as four sliders, two
  three-position levers, arm / disarm, E-STOP (also the Space hotkey), grasp / release / hold, and the
  per-cable tension sliders of DIRECT mode. Controls are disabled for tabs that do not hold control;
  the model refuses their input anyway (server-side check and clamp of every value).
- **Plots** (shared): uPlot charts of tensions, commanded and measured currents, cable lengths.
- **Health** (shared): link state, rates, errors, latency, loop statistics (late count, execution and
  lateness p99), RC / motors, failsafe phase, pose source (simulation, shadow plant, none), MAVLink
  state.

:class:`TeleopPanel` pushes the model to the browser at fixed rates from one thread (scene at up to
60 Hz when new poses arrive, plots at 10 Hz, health and control state at 4 Hz): the latest value wins,
nothing queues up behind a slow browser.

Security (docs/host.md): the caller binds 127.0.0.1 unless told
otherwise; :func:`harden` replaces ``request_share_url`` with a refusal. With a token, a tab is
authorised when its websocket URL carries ``?token=...`` (the URL printed at start does that through
viser's ``websocket`` page parameter) or when the token is typed into the panel; an unauthorised tab
can watch but not act.
"""

from __future__ import annotations

import logging
import threading
import time
import urllib.parse
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np
import viser

from host.model import CLI_CLIENT, ControlResult, PoseSource, UiModel
from host.scene import ArmGeometry, DronePose, SceneObject, SceneView, build_scene, default_hanging_pose
from protocol.dbus import Lever
from protocol.messages import CommandCode, GraspState, Mode, Phase, TelemetryFlags

__all__ = [
    "ControlHandles",
    "HealthHandles",
    "PanelConfig",
    "PlotHandles",
    "TeleopPanel",
    "build_control_panel",
    "build_health_panel",
    "build_plot_panel",
    "client_url_token",
    "harden",
]

_log = logging.getLogger(__name__)

STICK_CHANNELS = (
    (3, "Left ↕ curl"),
    (2, "Left ↔"),
    (0, "Right ↔ bend"),
    (1, "Right ↕ bend"),
)
"""Slider order in the panel: (DBUS channel, label). ch3 = left vertical = common tension (curl)."""
LEVER_OPTIONS = ("UP", "MIDDLE", "DOWN")
_ORDER_CONTROL = 0.0
_ORDER_PLOTS = 100.0
_ORDER_HEALTH = 200.0
_CABLE_STROKES = ("#dc3c3c", "#3caa3c", "#e6a01e")


@dataclass(frozen=True, slots=True)
class PanelConfig:
    """Rates and sizes of the panel.

    Attributes:
        scene_hz: scene update loop rate (an update is sent only when new poses arrived).
        plot_hz: plot refresh rate.
        health_hz: health and control-state refresh rate.
        plot_window_s: seconds shown in the plots.
        plot_points: most points per plotted series.
    """

    scene_hz: float = 60.0
    plot_hz: float = 10.0
    health_hz: float = 4.0
    plot_window_s: float = 10.0
    plot_points: int = 400


def harden(server: viser.ViserServer) -> None:
    """Turn off viser's public share-URL tunnel (any connected client could otherwise request it)."""

    def _refuse(*_args: Any, **_kwargs: Any) -> None:
        _log.warning("share URL requested and refused (disabled in spirob-host)")
        return None

    server.request_share_url = _refuse  # type: ignore[method-assign]


def client_url_token(server: viser.ViserServer, client_id: int) -> str | None:
    """The ``token`` query parameter of a client's websocket URL, if any.

    viser 1.1.1 keeps the raw websocket connection (``websockets`` ``ServerConnection``) per client id in
    ``server._websock_server._live_connections``; its ``request.path`` is the path and query the browser
    opened. Private API, pinned by ``viser>=1.1,<1.2``; any failure reads as "no token".
    """
    try:
        conn = server._websock_server._live_connections.get(client_id)
        if conn is None or conn.request is None:
            return None
        query = urllib.parse.urlsplit(conn.request.path).query
        values = urllib.parse.parse_qs(query).get("token")
        return values[0] if values else None
    except Exception:
        return None


# ---------------------------------------------------------------------- builders


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
    token_text: Any | None
    token_button: Any | None
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
        token_text = token_button = None
        if model.token is not None:
            token_text = gui.add_text(
                "Access token", initial_value="", hint="printed by spirob-host at start"
            )
            token_button = gui.add_button("Unlock")
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
        token_text,
        token_button,
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
        estop_cmd,
    )

    @take.on_click
    def _(event: Any) -> None:
        if not own(event):
            return
        result = model.request_control(cid)
        if result is ControlResult.DENIED:
            client.add_notification(
                "Not authorised", "Enter the access token first.", color="red", auto_close_seconds=5
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

    if token_button is not None and token_text is not None:
        text_handle = token_text

        @token_button.on_click
        def _(event: Any) -> None:
            if not own(event):
                return
            if model.authorise(cid, str(text_handle.value).strip()):
                client.add_notification("Unlocked", "This tab may now take control.", auto_close_seconds=4)
            else:
                client.add_notification("Wrong token", "Access refused.", color="red", auto_close_seconds=5)

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

    return h


@dataclass
class PlotHandles:
    """The shared uPlot charts."""

    tensions: Any
    currents: Any
    lengths: Any


def _series(label: str, stroke: str, dash: bool = False) -> dict[str, Any]:
    s: dict[str, Any] = {"label": label, "stroke": stroke, "width": 1.5}
    if dash:
        s["dash"] = [5, 4]
    return s


def _add_plot(server: viser.ViserServer, title: str, series: tuple[dict[str, Any], ...]) -> Any:
    """One uPlot with an empty sample per series and an auto-scaled relative-time x axis."""
    return server.gui.add_uplot(
        data=tuple(np.zeros(1) for _ in series),
        series=series,  # type: ignore[arg-type]
        title=title,
        scales={"x": {"time": False, "auto": True}, "y": {"auto": True}},
        aspect=1.6,
    )


def build_plot_panel(server: viser.ViserServer) -> PlotHandles:
    """Build the shared Plots folder (x axis: seconds relative to the newest sample)."""
    x: dict[str, Any] = {"label": "t [s]"}
    cables = tuple(enumerate(_CABLE_STROKES))
    with server.gui.add_folder("Plots", order=_ORDER_PLOTS):
        tensions = _add_plot(
            server,
            "Cable tension [N]",
            (
                x,
                *(_series(f"T{i + 1} target", c, dash=True) for i, c in cables),
                *(_series(f"T{i + 1} est", c) for i, c in cables),
            ),
        )
        currents = _add_plot(
            server,
            "Motor current [A]",
            (
                x,
                *(_series(f"I{i + 1} cmd", c, dash=True) for i, c in cables),
                *(_series(f"I{i + 1} meas", c) for i, c in cables),
            ),
        )
        lengths = _add_plot(server, "Cable paid in [mm]", (x, *(_series(f"L{i + 1}", c) for i, c in cables)))
    return PlotHandles(tensions, currents, lengths)


@dataclass
class HealthHandles:
    """The shared Health folder."""

    summary: Any
    link: Any
    loop: Any


def build_health_panel(server: viser.ViserServer) -> HealthHandles:
    """Build the shared Health folder."""
    with server.gui.add_folder("Health", order=_ORDER_HEALTH):
        summary = server.gui.add_markdown("**Board**: connecting…")
        link = server.gui.add_markdown("")
        loop = server.gui.add_markdown("")
    return HealthHandles(summary, link, loop)


# ---------------------------------------------------------------------- formatting


def _fmt_rate(rates: dict[str, float] | Any, name: str) -> str:
    return f"{rates.get(name, 0.0):.0f}"


def health_text(
    model: UiModel, pose_source: str, mavlink_status: str | None, shadow_status: str | None = None
) -> tuple[str, str, str]:
    """Markdown of the three health blocks (summary, link, loop)."""
    t = model.telemetry
    stats = model.link_stats
    state = model.link_state.value
    if t is None:
        summary = (
            f"**Board** ({model.source_label}): {state} · no telemetry yet  \n**Pose source**: {pose_source}"
        )
    else:
        flags = TelemetryFlags(t.flags)
        motors = " ".join(f"M{i + 1} {'on' if t.motors_online >> i & 1 else '**OFF**'}" for i in range(3))
        rc = "ok" if flags & TelemetryFlags.RC_OK else "**lost**"
        phase = t.phase.name if t.phase == Phase.OK else f"**{t.phase.name}**"
        summary = (
            f"**Board** ({model.source_label}): {state} · **Mode** {t.mode.name} · **Phase** {phase} · "
            f"{'ARMED' if flags & TelemetryFlags.ARMED else 'disarmed'}  \n"
            f"**RC** {rc} (R {Lever(t.right_lever).name if t.right_lever in (1, 2, 3) else '-'}, "
            f"L {Lever(t.left_lever).name if t.left_lever in (1, 2, 3) else '-'}) · {motors}  \n"
            f"**Grasp** {GraspState(t.grasp_state).name} · **Host** "
            f"{'ok' if flags & TelemetryFlags.HOST_OK else 'silent'}"
            f"{' (required)' if flags & TelemetryFlags.HOST_REQUIRED else ''}  \n"
            f"**Pose source**: {pose_source}"
        )
    if shadow_status is not None:
        summary += f"  \n**Shadow**: {shadow_status}"
    if mavlink_status is not None:
        summary += f"  \n**MAVLink**: {mavlink_status}"
    if stats is None:
        link = "**Link**: no statistics"
    else:
        lat = "-" if stats.latency_us is None else f"{stats.latency_us / 1000:.1f} ms"
        link = (
            f"**Link** `{stats.url}`: telemetry {_fmt_rate(stats.rx_rate_hz, 'Telemetry')} Hz · poses "
            f"{_fmt_rate(stats.rx_rate_hz, 'SimPoses')} Hz · errors {stats.errors} · "
            f"skipped {stats.parser.get('bytes_skipped', 0)} B · reconnects {stats.reconnects} · "
            f"latency {lat} · RC late {stats.rc_late} · tx dropped {stats.tx_dropped}"
        )
    if t is None:
        loop = ""
    else:
        loop = (
            f"**Loop**: late {t.control_late} · exec p99 {t.control_exec_p99_us} µs · "
            f"max {t.control_exec_max_us} µs · lateness p99 {t.control_lateness_p99_us} µs · "
            f"max {t.control_lateness_max_us} µs  \n"
            f"**Counters**: RC ok {t.rc_frames_ok} · RC rejected {t.rc_rejected} · DBUS dropped "
            f"{t.dbus_bytes_dropped} B · link CRC {t.link_crc_errors} · motor offline "
            f"{t.motor_offline_events} · CAN errors {t.can_errors}"
        )
        status = model.status
        if status is not None:
            rows = " · ".join(
                f"{s.name} late {s.late}/{s.runs}, p99 {s.exec_p99_us} µs" for s in status.tasks[:6]
            )
            loop += f"  \n**Tasks** ({status.firmware_version}, {status.clock_kind.name}): {rows}"
    return summary, link, loop


# ---------------------------------------------------------------------- the panel


class TeleopPanel:
    """Builds the panel on a viser server and keeps it in step with a :class:`UiModel`.

    Args:
        server: a running viser server (bind it to 127.0.0.1 unless told otherwise).
        model: the UI model.
        geometry: arm geometry for drawing; default: the paper's prototype.
        objects: static objects to draw.
        drone_pose: optional provider of the drone pose (MAVLink), in the scene's z-up world frame.
        mavlink_status: optional provider of a one-line MAVLink link state.
        shadow_status: optional provider of a one-line shadow-plant state (``host.shadow``).
        config: rates.
    """

    def __init__(
        self,
        server: viser.ViserServer,
        model: UiModel,
        *,
        geometry: ArmGeometry | None = None,
        objects: Sequence[SceneObject] = (),
        drone_pose: Callable[[], DronePose | None] | None = None,
        mavlink_status: Callable[[], str] | None = None,
        shadow_status: Callable[[], str] | None = None,
        config: PanelConfig | None = None,
    ) -> None:
        self.server = server
        self.model = model
        self.config = config or PanelConfig()
        self.geometry = geometry or ArmGeometry.default()
        self._drone_pose = drone_pose
        self._mavlink_status = mavlink_status
        self._shadow_status = shadow_status
        harden(server)
        server.gui.configure_theme(control_width="large", show_logo=False, show_share_button=False)
        self._framed = False
        self._frame_camera(np.array([0.0, 0.0, 1.08]))
        self.scene: SceneView = build_scene(server, self.geometry, objects)
        self.plots = build_plot_panel(server)
        self.health = build_health_panel(server)
        self._controls: dict[int, ControlHandles] = {}
        self._controls_lock = threading.Lock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._last_poses = -1
        self._last_notice = 0
        self._health_cache: tuple[str, str, str] = ("", "", "")
        self.pose_source = PoseSource.NONE.value
        server.on_client_connect(self._on_connect)
        server.on_client_disconnect(self._on_disconnect)

    # ------------------------------------------------------------------ clients

    def _on_connect(self, client: viser.ClientHandle) -> None:
        cid = client.client_id
        token = client_url_token(self.server, cid)
        authorised = self.model.authorise(cid, token)
        handles = build_control_panel(client, self.model, tension_max_n=self.model.limits.tension_max_n)
        if handles.token_text is not None and authorised:
            handles.token_text.visible = False
            if handles.token_button is not None:
                handles.token_button.visible = False
        with self._controls_lock:
            self._controls[cid] = handles
        self._refresh_control(handles, force=True)

    def _on_disconnect(self, client: viser.ClientHandle) -> None:
        with self._controls_lock:
            self._controls.pop(client.client_id, None)
        self.model.client_left(client.client_id)

    def controls(self) -> dict[int, ControlHandles]:
        """Control handles per connected tab (a copy)."""
        with self._controls_lock:
            return dict(self._controls)

    def _refresh_control(self, h: ControlHandles, force: bool = False) -> None:
        m = self.model
        cid = h.client_id
        holder = m.holder
        pending = m.pending
        mine = holder == cid
        authorised = m.is_authorised(cid)
        sticks, right, left, _ = m.operator_input()
        if mine:
            who = "**You hold control.**"
        elif holder is None:
            who = "Nobody holds control." + ("" if authorised else " Enter the access token to act.")
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
        if h.token_text is not None and authorised:
            h.token_text.visible = False
            if h.token_button is not None:
                h.token_button.visible = False
        h.estop.disabled = not authorised
        for w in h.action_widgets():
            w.disabled = not mine
        if force or prev.get("mine") != mine or (not mine and prev.get("sticks") != sticks):
            # Whoever gets (or loses) control starts from SAFE: show the reset sticks. Watchers see
            # the holder's sticks (their own sliders are disabled).
            for ch, slider in h.sticks.items():
                slider.value = float(sticks[ch])
        h.levers_md.content = f"Right lever **{right.name}** · left lever **{left.name}**"

    # ------------------------------------------------------------------ loop

    def start(self) -> None:
        """Start the update thread."""
        if self._thread is None:
            self._stop.clear()
            self._thread = threading.Thread(target=self._run, name="teleop-panel", daemon=True)
            self._thread.start()

    def stop(self) -> None:
        """Stop the update thread (the caller stops the server); safe twice."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=3.0)
            self._thread = None

    def _run(self) -> None:
        cfg = self.config
        min_scene_s = 1.0 / cfg.scene_hz
        next_plot = next_health = time.monotonic()
        last_scene = 0.0
        poses_event = self.model.poses_event
        while not self._stop.is_set():
            # Wake when new poses arrive (not on a fixed tick: under CPU contention a fixed sleep after
            # a late wake-up halves the rate), at most scene_hz, and for the slower periodic refreshes.
            timeout = max(0.0, min(next_plot, next_health, last_scene + 0.5) - time.monotonic())
            poses_event.wait(min(timeout, 0.1))
            t0 = time.monotonic()
            if t0 - last_scene < min_scene_s:
                self._stop.wait(min_scene_s - (t0 - last_scene))
                t0 = time.monotonic()
            try:
                if poses_event.is_set() or t0 - last_scene >= 0.5:
                    poses_event.clear()
                    last_scene = t0
                    self.update_scene()
                if t0 >= next_plot:
                    next_plot = t0 + 1.0 / cfg.plot_hz
                    self.update_plots()
                if t0 >= next_health:
                    next_health = t0 + 1.0 / cfg.health_hz
                    self.update_health()
                    self.update_controls()
                    self.push_notices()
            except Exception:
                if self._stop.is_set():
                    break
                _log.exception("panel update failed")

    def _frame_camera(self, centre: Any) -> None:
        """Point new tabs' camera at the arm: slightly below the drone, from the side."""
        c = np.asarray(centre, dtype=np.float64)
        self.server.initial_camera.look_at = (float(c[0]), float(c[1]), float(c[2]))
        self.server.initial_camera.position = (float(c[0]) + 0.38, float(c[1]) - 0.52, float(c[2]) + 0.12)

    def _drone_override(self) -> DronePose | None:
        if self._drone_pose is None:
            return None
        try:
            return self._drone_pose()
        except Exception:
            _log.exception("drone pose provider failed")
            return None

    def update_scene(self) -> bool:
        """Send a scene update if new poses arrived (or the drone moved); returns True if one was sent."""
        m = self.model
        poses = m.poses
        source = m.pose_source
        drone = self._drone_override()
        if poses is not None and len(poses.positions_m) >= 2 and source is not PoseSource.NONE:
            if m.poses_count == self._last_poses and drone is None:
                return False
            self._last_poses = m.poses_count
            # "simulation (SimPoses)" or "shadow plant (measured currents)": said in the scene and in
            # the health area, so nobody mistakes a model's shape for the measured one.
            self.pose_source = source.value
            if not self._framed:
                self._framed = True
                self._frame_camera(np.mean(np.asarray(poses.positions_m), axis=0))
            label = f"pose source: {source.value}"
            if drone is not None:
                label += " · drone: MAVLink"
            self.scene.update(
                np.asarray(poses.positions_m),
                np.asarray(poses.quats_wxyz),
                drone_override=drone,
                label=label,
            )
            return True
        # Hardware or replay without poses: draw the arm hanging, say there is no pose source.
        t = m.telemetry
        none = PoseSource.NONE.value
        if t is not None and TelemetryFlags(t.flags) & TelemetryFlags.SIM:
            self.pose_source = f"{none} (simulation, waiting for SimPoses) — arm drawn hanging"
        elif m.source_label.startswith("replay"):
            self.pose_source = f"{none} (the recording has no poses) — arm drawn hanging"
        elif self._shadow_status is not None:
            self.pose_source = f"{none} yet (shadow plant waiting for telemetry) — arm drawn hanging"
        else:
            self.pose_source = f"{none} (hardware, shadow plant off) — arm drawn hanging"
        if self._last_poses == -2 and drone is None:
            return False
        self._last_poses = -2
        pos, quat = default_hanging_pose(self.geometry, drone)
        self.scene.update(pos, quat, label=none, trail=False)
        return True

    def update_plots(self) -> None:
        """Refresh the three charts from the model's history."""
        data = self.model.history.snapshot(max_points=None)
        if len(data) == 0:
            return
        t_end = data[-1, 0]
        data = data[data[:, 0] >= t_end - self.config.plot_window_s]
        if len(data) > self.config.plot_points:
            step = int(np.ceil(len(data) / self.config.plot_points))
            data = data[::-1][::step][::-1]
        x = data[:, 0] - t_end
        cols = [data[:, i] for i in range(1, data.shape[1])]
        with self.server.atomic():
            self.plots.tensions.data = (x, *cols[0:6])
            self.plots.currents.data = (x, *cols[6:12])
            self.plots.lengths.data = (x, *cols[12:15])

    def update_health(self) -> None:
        """Refresh the health text (only what changed is sent)."""
        self.model.refresh_link_stats()
        status = None
        if self._mavlink_status is not None:
            try:
                status = self._mavlink_status()
            except Exception:
                status = "error reading MAVLink state"
        shadow = None
        if self._shadow_status is not None:
            try:
                shadow = self._shadow_status()
            except Exception:
                shadow = "error reading the shadow plant's state"
        texts = health_text(self.model, self.pose_source, status, shadow)
        for handle, old, new in zip(
            (self.health.summary, self.health.link, self.health.loop), self._health_cache, texts, strict=True
        ):
            if old != new:
                handle.content = new
        self._health_cache = texts

    def update_controls(self) -> None:
        """Refresh each tab's control state (holder, requests, enabled widgets)."""
        for h in self.controls().values():
            try:
                self._refresh_control(h)
            except Exception:
                _log.debug("control refresh failed for tab %s", h.client_id, exc_info=True)

    def push_notices(self) -> None:
        """Show new notices as browser notifications (to everyone or to the one tab concerned)."""
        notices = self.model.notices_after(self._last_notice)
        if not notices:
            return
        self._last_notice = notices[-1].seq
        clients = self.server.get_clients()
        colors: dict[str, Literal["blue", "yellow", "red"]] = {
            "info": "blue",
            "warning": "yellow",
            "error": "red",
        }
        for n in notices:
            targets = (
                clients.values() if n.client is None else [c for k, c in clients.items() if k == n.client]
            )
            for c in targets:
                try:
                    c.add_notification(
                        n.title,
                        n.body,
                        color=colors.get(n.level, "blue"),
                        auto_close_seconds=None if n.level == "error" else 6.0,
                    )
                except Exception:
                    _log.debug("notification failed", exc_info=True)
