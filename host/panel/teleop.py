"""The browser teleop panel (viser 1.1.x): one builder per area, callbacks that only call the arbiter.

Areas and who sees what (one module each, a builder returning its handles: ``host.panel.controls``,
``host.panel.plots``, ``host.panel.health``; the 3-D scene is ``host.panel.scene``):

- **Control** (built per browser tab, ``client.gui``): who holds control and the hand-over buttons,
  two virtual sticks as four sliders, two three-position levers, arm / disarm, E-STOP (also the Space
  hotkey), grasp / release / hold, and the per-cable tension sliders of DIRECT mode. Controls are
  disabled for tabs that do not hold control; the control arbiter (``host.panel.arbiter``) refuses
  their input anyway (server-side check and clamp of every value).
- **State bar** (per tab, on top): phase, mode and the one next step for the pilot
  (``host.panel.state_bar``), an E-stop banner while latched; Space is E-stop in every field.
- **View** (per tab): camera presets (aligned with the sticks by default, behind the drone, side,
  top, following the tip), also on the keys 1-5.
- **Parameters** (per tab, ``host.panel.params``): the board's parameters with units and bounds,
  set by the control holder and read back by the board.
- **Plots** (shared): uPlot charts of tensions, commanded and measured currents, cable lengths, with
  pause, window length, chart and cable choice (``host.panel.plots``).
- **Recording** (shared, ``host.panel.record``): start and stop a recording mid-run.
- **Events** (shared): the event console (board events, failsafes, acks, commands, board times).
- **Health** (shared): checked numbers with thresholds and colours (and the malformed panel messages
  count), link state, rates, errors, latency, loop statistics, RC / motors, failsafe phase, pose
  source (simulation, shadow plant, none), MAVLink state.

:class:`TeleopPanel` pushes the board's state (``host.panel.board_state``), who holds control and the
notices (``host.panel.notices``) to the browser at fixed rates from one thread (scene at up to 60 Hz
when new poses arrive, plots at 10 Hz, health and control state at 4 Hz): the latest value wins,
nothing queues up behind a slow browser.

Security (docs/host.md): the caller binds 127.0.0.1 unless told otherwise and starts the server through
``host.panel.guard``, whose handshake check refuses a websocket from another origin or without the
token; :func:`harden` replaces ``request_share_url`` with a refusal. The arbiter checks the token of
every tab again before it may act.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
import viser

from host.panel.arbiter import ControlArbiter
from host.panel.board_params import BoardParams
from host.panel.board_state import BoardState, PoseSource
from host.panel.camera import camera_view
from host.panel.console import console_html
from host.panel.controls import ControlHandles, build_control_panel, refresh_control
from host.panel.guard import request_token
from host.panel.health import build_health_panel, health_checks, health_html, health_text
from host.panel.notices import Notices
from host.panel.params import ParamHandles, build_param_panel, refresh_params
from host.panel.plots import CHART_COLUMNS, build_plot_panel, fixed_scales, plot_frame, y_range
from host.panel.record import RecordHandles, RecordingSwitch, build_record_panel, refresh_record
from host.panel.scene import (
    ArmGeometry,
    DronePose,
    SceneObject,
    SceneView,
    build_scene,
    default_hanging_pose,
)
from host.worker import Worker
from protocol.messages import TelemetryFlags

__all__ = ["PanelConfig", "TeleopPanel", "client_url_token", "harden"]

_log = logging.getLogger(__name__)


@dataclass(frozen=True, slots=True)
class PanelConfig:
    """Rates and sizes of the panel.

    Attributes:
        scene_hz: scene update loop rate (an update is sent only when new poses arrived).
        plot_hz: plot refresh rate.
        health_hz: health and control-state refresh rate.
        plot_window_s: seconds shown in the plots at first (the Window slider changes it, up to the
            board state's history).
        plot_points: most points per plotted series.
        shadows: the scene's main light casts shadows (three cascaded shadow maps: on a machine without
            a GPU, where the browser renders in software, most of each frame's cost).
    """

    scene_hz: float = 60.0
    plot_hz: float = 10.0
    health_hz: float = 4.0
    plot_window_s: float = 10.0
    plot_points: int = 400
    shadows: bool = True


def harden(server: viser.ViserServer) -> None:
    """Turn off viser's public share-URL tunnel (any connected client could otherwise request it)."""

    def _refuse(*_args: Any, **_kwargs: Any) -> None:
        _log.warning("share URL requested and refused (disabled in spirob-host)")
        return None

    server.request_share_url = _refuse  # type: ignore[method-assign]


def client_url_token(server: viser.ViserServer, client_id: int) -> str | None:
    """The token a client's websocket request carried (``token`` query parameter or cookie), if any.

    The handshake already refused a request without a valid one (``host.panel.guard``); the arbiter
    checks it again. viser 1.1.1 keeps the raw websocket connection (``websockets``
    ``ServerConnection``) per client id in ``server._websock_server._live_connections``. Private API,
    pinned by ``viser>=1.1,<1.2``; any failure reads as "no token".
    """
    try:
        conn = server._websock_server._live_connections.get(client_id)
        if conn is None or conn.request is None:
            return None
        return request_token(conn.request.path, conn.request.headers)
    except Exception:
        return None


class TeleopPanel:
    """Builds the panel on a viser server and keeps it in step with the board and who holds control.

    Args:
        server: a running viser server (bind it to 127.0.0.1 unless told otherwise).
        board: the board's state (telemetry, poses, history, link health).
        arbiter: who may act; every control calls it.
        notices: the toasts and the event console.
        params: the board's parameters (the editor).
        geometry: arm geometry for drawing; default: the paper's prototype.
        objects: static objects to draw.
        drone_pose: optional provider of the drone pose (MAVLink), in the scene's z-up world frame.
        mavlink_status: optional provider of a one-line MAVLink link state.
        shadow_status: optional provider of a one-line shadow-plant state (``host.shadow``).
        malformed_n: optional provider of the count of malformed panel messages (``host.panel.guard``).
        recorder: optional recording switch (the Recording folder is shown with one).
        config: rates.
    """

    def __init__(
        self,
        server: viser.ViserServer,
        board: BoardState,
        arbiter: ControlArbiter,
        notices: Notices,
        params: BoardParams,
        *,
        geometry: ArmGeometry | None = None,
        objects: Sequence[SceneObject] = (),
        drone_pose: Callable[[], DronePose | None] | None = None,
        mavlink_status: Callable[[], str] | None = None,
        shadow_status: Callable[[], str] | None = None,
        malformed_n: Callable[[], int] | None = None,
        recorder: RecordingSwitch | None = None,
        config: PanelConfig | None = None,
    ) -> None:
        self.server = server
        self.board = board
        self.arbiter = arbiter
        self.notices = notices
        self.params = params
        self.config = config or PanelConfig()
        self.geometry = geometry or ArmGeometry.default()
        self._drone_pose = drone_pose
        self._mavlink_status = mavlink_status
        self._shadow_status = shadow_status
        self._malformed_n = malformed_n
        harden(server)
        server.gui.configure_theme(control_width="large", show_logo=False, show_share_button=False)
        self._framed = False
        self.scene: SceneView = build_scene(server, self.geometry, objects)
        if not self.config.shadows:
            server.scene.configure_default_lights(enabled=True, cast_shadow=False)
        self._frame_camera()
        self.plots = build_plot_panel(server, window_s=self.config.plot_window_s, history_s=board.history_s)
        self.recorder = recorder
        self.record: RecordHandles | None = None
        if recorder is not None:
            self.record = build_record_panel(server, recorder, arbiter, notices)
        with server.gui.add_folder("Events", order=180.0, expand_by_default=False):
            self.console = server.gui.add_html(console_html([]))
        self._console_seq = 0
        self.health = build_health_panel(server)
        self._scales: dict[str, tuple[float, float, float]] = {}
        self._params: dict[int, ParamHandles] = {}
        self._controls: dict[int, ControlHandles] = {}
        self._controls_lock = threading.Lock()
        self._worker = Worker("teleop-panel", self._run)
        self._stop = self._worker.stop_event
        self._last_poses = -1
        self._last_notice = 0
        self._health_cache: tuple[str, str, str, str] = ("", "", "", "")
        self.pose_source = PoseSource.NONE.value
        server.on_client_connect(self._on_connect)
        server.on_client_disconnect(self._on_disconnect)

    # ------------------------------------------------------------------ clients

    def _on_connect(self, client: viser.ClientHandle) -> None:
        cid = client.client_id
        token = client_url_token(self.server, cid)
        self.arbiter.authorise(cid, token)
        handles = build_control_panel(
            client,
            self.arbiter,
            self.board,
            tension_max_n=self.arbiter.limits.tension_max_n,
            set_camera=self.set_camera,
        )
        params = build_param_panel(client, self.params)
        with self._controls_lock:
            self._controls[cid] = handles
            self._params[cid] = params
        refresh_control(handles, self.arbiter, self.board, force=True)
        refresh_params(params, self.params, force=True)
        if not self.params.params:
            self.params.request_params()  # the editor shows the board's values, not the defaults

    def _on_disconnect(self, client: viser.ClientHandle) -> None:
        with self._controls_lock:
            self._controls.pop(client.client_id, None)
            self._params.pop(client.client_id, None)
        self.arbiter.client_left(client.client_id)

    def set_camera(self, client: viser.ClientHandle, preset: str) -> None:
        """Move one tab's camera to a preset (``host.panel.camera.CAMERA_PRESETS``)."""
        sv = self.scene
        position, look_at = camera_view(preset, sv.centre_m, sv.drone, sv.tip_m)
        with client.atomic():
            # Position first, then the look-at point: viser's position setter moves the look-at point
            # by the same offset (it keeps the view direction), so the other order aimed every preset
            # but the one already shown at empty ground or sky.
            client.camera.up_direction = (0.0, 0.0, 1.0)
            client.camera.position = position
            client.camera.look_at = look_at

    def controls(self) -> dict[int, ControlHandles]:
        """Control handles per connected tab (a copy)."""
        with self._controls_lock:
            return dict(self._controls)

    # ------------------------------------------------------------------ loop

    def start(self) -> None:
        """Start the update thread."""
        self._worker.start()

    def stop(self) -> None:
        """Stop the update thread (the caller stops the server); safe twice."""
        self._worker.stop()

    def _run(self) -> None:
        cfg = self.config
        min_scene_s = 1.0 / cfg.scene_hz
        next_plot = next_health = time.monotonic()
        last_scene = 0.0
        poses_event = self.board.poses_event
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

    def _frame_camera(self) -> None:
        """New tabs start in the stick view: stick right = screen right, stick up = away."""
        sv = self.scene
        position, look_at = camera_view("sticks", sv.centre_m, sv.drone, sv.tip_m)
        self.server.initial_camera.look_at = look_at
        self.server.initial_camera.position = position

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
        m = self.board
        source = m.pose_source
        drone = self._drone_override()
        bodies = m.bodies() if source is not PoseSource.NONE else None
        if bodies is not None:
            if m.poses_count == self._last_poses and drone is None:
                return False
            self._last_poses = m.poses_count
            positions, quats, drawn = bodies
            # "simulation (SimPoses)" or "shadow plant (measured currents)": said in the scene and in
            # the health area, so nobody mistakes a model's shape for the measured one.
            self.pose_source = source.value
            arms = m.arms
            if arms > 1:  # an array: every arm from its ArmPoses (docs/board-link.md, 0x010A)
                self.pose_source += f" + ArmPoses: {drawn} of {arms} arms drawn"
            label = f"pose source: {self.pose_source}"
            if drone is not None:
                label += " · drone: MAVLink"
            self.scene.update(positions, quats, drone_override=drone, label=label, arms=drawn)
            if not self._framed:
                self._framed = True
                self._frame_camera()
            return True
        # Hardware or replay without poses: draw the arm hanging, say there is no pose source.
        t = m.telemetry
        none = PoseSource.NONE.value
        if t is not None and TelemetryFlags(t.flags) & TelemetryFlags.SIM:
            self.pose_source = f"{none} (simulation, waiting for SimPoses) — arm drawn hanging"
        elif m.source_label.startswith("replay"):
            self.pose_source = f"{none} (the recording has no poses) — arm drawn hanging"
        elif self._shadow_status is not None:
            # "shadow plant waiting for telemetry", or why it is off (an array board: it models one arm)
            self.pose_source = f"{none} ({self._shadow_status()}) — arm drawn hanging"
        else:
            self.pose_source = f"{none} (hardware, shadow plant off) — arm drawn hanging"
        if self._last_poses == -2 and drone is None:
            return False
        self._last_poses = -2
        pos, quat = default_hanging_pose(self.geometry, drone)
        self.scene.update(pos, quat, label=none, trail=False)
        return True

    def update_plots(self) -> None:
        """Refresh the charts from the board state's history (nothing while paused)."""
        p = self.plots
        if bool(p.pause.value):
            return
        data = self.board.history.snapshot(max_points=None)
        window_s = float(p.window.value)
        x, series = plot_frame(data, window_s, str(p.cables.value), self.config.plot_points)
        with self.server.atomic():
            for chart in CHART_COLUMNS:
                handle = p.chart(chart)
                if not bool(p.show[chart].value):
                    continue
                empty = (0.0, self.arbiter.limits.tension_max_n) if chart == "tensions" else None
                rng = y_range(np.concatenate(series[chart]), chart, empty)
                # A new range rebuilds the chart in the browser (uplot-react): sent only when it changes.
                if self._scales.get(chart) != (*rng, window_s):
                    self._scales[chart] = (*rng, window_s)
                    handle.scales = fixed_scales(*rng, window_s)
                handle.data = (x, *series[chart])

    def update_health(self) -> None:
        """Refresh the health text (only what changed is sent)."""
        self.board.refresh_link_stats()
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
        malformed = 0
        if self._malformed_n is not None:
            malformed = self._malformed_n()
        checks = health_html(health_checks(self.board, malformed))
        texts = (checks, *health_text(self.board, self.pose_source, status, shadow))
        h = self.health
        for handle, old, new in zip(
            (h.checks, h.summary, h.link, h.loop), self._health_cache, texts, strict=True
        ):
            if old != new:
                handle.content = new
        self._health_cache = texts

    def update_controls(self) -> None:
        """Refresh each tab's control state (holder, requests, enabled widgets)."""
        with self._controls_lock:
            params = list(self._params.values())
        for h in self.controls().values():
            try:
                refresh_control(h, self.arbiter, self.board)
                if h.follow_tip:
                    client = self.server.get_clients().get(h.client_id)
                    if client is not None:
                        self.set_camera(client, "tip")
            except Exception:
                _log.debug("control refresh failed for tab %s", h.client_id, exc_info=True)
        for ph in params:
            try:
                refresh_params(ph, self.params)
            except Exception:
                _log.debug("parameter refresh failed for tab %s", ph.client_id, exc_info=True)
        if self.record is not None and self.recorder is not None:
            refresh_record(self.record, self.recorder)
        seq = self.notices.events.seq
        if seq != self._console_seq:
            self._console_seq = seq
            self.console.content = console_html(self.notices.events.entries())

    def push_notices(self) -> None:
        """Show new notices as browser notifications (to everyone or to the one tab concerned)."""
        notices = self.notices.notices_after(self._last_notice)
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
                        # Every toast closes itself (errors stay longer); the event console keeps them.
                        auto_close_seconds=15.0 if n.level == "error" else 6.0,
                    )
                except Exception:
                    _log.debug("notification failed", exc_info=True)
