"""The `spirob-host` application: board (or replay), listeners, panel and drone link in one process."""

from __future__ import annotations

import contextlib
import io
import logging
import math
import socket
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from controller.cli_kit import EXIT_FAILURE, EXIT_OK
from host.errors import HostError
from host.link.client import BoardClient, LinkState, load_scaled_s
from host.link.process import BoardLinkError
from host.link.recording import LinkRecording, replay_messages
from host.object_spec import ObjectSpec, plant_objects
from host.options import (
    HostOptions,
    check_signing_timestamp_writable,
    check_ui_port_free,
    is_loopback,
    signing_timestamp_path,
)
from host.panel.guard import PanelGuard, start_guarded_server
from host.panel.model import CLI_CLIENT, UiModel
from host.panel.record import RecordingSwitch
from host.panel.scene import DronePose, SceneObject, scene_objects
from host.run_summary import RunSummary, SummaryReport
from host.shadow import ShadowPlant
from protocol.dbus import Lever
from protocol.messages import Message

__all__ = ["HostApp", "ned_to_scene"]

_log = logging.getLogger("spirob-host")


class HostApp:
    """One `spirob-host` run: board (or replay), listeners, panel, drone link. Usable in-process.

    Call :meth:`start` (raises :class:`HostError` with a one-line reason), then :meth:`run` or drive it
    yourself, then :meth:`close` (safe twice; also a context manager).
    """

    def __init__(self, options: HostOptions, *, panel_config: Any = None, board_config: Any = None) -> None:
        """Prepare a run (nothing starts until :meth:`start`).

        Args:
            options: the run's options.
            panel_config: ``host.panel.teleop.PanelConfig`` (rates); default rates when None.
            board_config: ``hil.board.BoardConfig`` of the virtual board started without ``--port``
                (default: the prototype arm, RC over the link); its objects are drawn in the scene.
        """
        self.options = options
        self.panel_config = panel_config
        self.board_config = board_config
        self.model = UiModel(token=options.token)
        self.client: BoardClient | None = None
        self.board: Any = None
        self.server: Any = None
        self.guard: PanelGuard | None = None
        self.panel: Any = None
        self.recording: LinkRecording | None = None
        self.foxglove: Any = None
        self.shadow: ShadowPlant | None = None
        self.recorder: RecordingSwitch | None = None
        """Recordings started from the panel (None in replay)."""
        self.drone_link: Any = None
        self.gamepad: Any = None
        self.summary = RunSummary()
        """Modes, phases, failsafes and faults of the run (the summary at exit)."""
        self.report: SummaryReport | None = None
        """The summary, taken when :meth:`run` returns."""
        self.url = ""
        self.board_url = ""
        self.objects: list[SceneObject] = []
        self.replay_done = threading.Event()
        self._stop = threading.Event()
        self._threads: list[threading.Thread] = []

    def __enter__(self) -> HostApp:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ------------------------------------------------------------------ start

    def start(self) -> None:
        """Start everything; on failure everything already started is stopped again.

        Raises:
            HostError: one-line reason.
        """
        try:
            self._start()
        except BaseException:
            self.close()
            raise

    def _start(self) -> None:
        o = self.options
        if o.ui:
            check_ui_port_free(o.ui_host, o.ui_port)
        if o.replay is None:
            self.board_url = o.port if o.port is not None else self._start_virtual_board()
            self.client = BoardClient(self.board_url, rc_source=self.model.virtual_rc_frame)
            self.model._send = self.client.send
            self.model.link_stats_fn = self.client.stats
            self.model.source_label = "virtual board" if o.port is None else f"board {o.port}"
            self.client.add_listener(self.model.on_board_message)
            self.client.add_listener(self.summary.on_board_message)
            self.client.add_state_listener(self.model.on_link_state)
            if o.port is not None and o.shadow:
                # A board that sends no SimPoses (hardware) gets its shape from a local plant driven by
                # the measured currents; it switches itself off when SimPoses arrive.
                self.shadow = ShadowPlant(self.model.on_shadow_poses)
                self.client.add_listener(self.shadow.on_board_message)
                self.shadow.start()
            meta = {"source": "spirob-host", "port": self.board_url}
            if self.board is not None:  # the virtual board's design and firmware parameters
                meta.update(self.board_config.describe())
            if o.record is not None:
                tlog = o.record.with_suffix(".tlog") if o.mavlink is not None else None
                self.recording = LinkRecording(o.record, meta, tlog=tlog)
                self.client.add_tap(self.recording.tap)
                self.client.add_listener(self.recording.on_board_message)
                self.client.add_state_listener(self.recording.on_link_state)
            # Always on the link (it forwards nothing until the panel starts a recording).
            self.recorder = RecordingSwitch(
                (o.record.parent if o.record is not None else Path("recordings")).resolve(),
                {"source": "spirob-host (panel)", "port": self.board_url},
            )
            self.client.add_tap(self.recorder.tap)
            self.client.add_listener(self.recorder.on_board_message)
            if o.foxglove_port is not None:
                self._start_foxglove(meta)
            if o.mavlink is not None:
                self._start_drone_link()
            try:
                self.client.start()
            except BoardLinkError as exc:
                raise HostError(f"board link: {exc}") from exc
        else:
            self.model.source_label = f"replay {o.replay}"
            self.model.link_state = LinkState.CONNECTED
            if o.foxglove_port is not None:
                from hil.recording import read_metadata  # type: ignore[import-not-found,unused-ignore]

                self._start_foxglove(read_metadata(o.replay))
        if o.ui:
            self._start_ui()
        if o.replay is not None:
            self._spawn(self._replay_loop, "replay")
        if o.virtual_rc is not None:
            self._spawn(self._virtual_rc_loop, "virtual-rc")
        if o.gamepad is not None:
            self._start_gamepad(o.gamepad)

    def _spawn(self, target: Callable[[], None], name: str) -> None:
        t = threading.Thread(target=target, name=name, daemon=True)
        self._threads.append(t)
        t.start()

    def _start_virtual_board(self) -> str:
        try:
            from hil.board import VirtualBoardProcess  # type: ignore[import-not-found,unused-ignore]
        except ImportError as exc:
            raise HostError(
                f"the virtual board is not available ({exc}); pass --port to use a real board"
            ) from exc
        from hil.board import BoardConfig  # type: ignore[import-not-found,unused-ignore]
        from hil.errors import HilError  # type: ignore[import-not-found,unused-ignore]

        config = self.board_config if self.board_config is not None else BoardConfig(rc="link")
        if self.options.objects:
            config = _with_objects(config, self.options.objects)
        self.board_config = config
        self.board = VirtualBoardProcess(config, listen="socket://127.0.0.1:0")
        try:
            url = str(self.board.start(timeout_s=load_scaled_s(30.0)))
        except HilError as exc:
            raise HostError(f"virtual board: {exc}") from exc
        # The objects of the plant we asked for (free objects drawn where they start).
        self.objects.extend(scene_objects(config.plant.model.objects))
        return url

    def _start_gamepad(self, path: str) -> None:
        from host.gamepad import Gamepad

        pad = Gamepad(path, self.model, CLI_CLIENT, self.options.gamepad_map)
        try:
            pad.start()
        except OSError as exc:
            raise HostError(f"--gamepad {path}: {exc.strerror or exc}") from exc
        self.gamepad = pad

    def _start_foxglove(self, metadata: dict[str, str]) -> None:
        from host.foxglove_live import FoxgloveLive

        assert self.options.foxglove_port is not None
        live = FoxgloveLive(self.options.foxglove_port, metadata)
        live.start()
        self.foxglove = live
        if self.client is not None:
            self.client.add_listener(live.on_board_message)
            self.client.add_state_listener(live.on_link_state)

    def _start_drone_link(self) -> None:
        o = self.options
        assert o.mavlink is not None and self.client is not None
        from host.drone import config as drone_config
        from host.drone import link as drone_link

        try:
            cfg = drone_config.DroneLinkConfig(
                url=o.mavlink, sysid=o.mav_sysid, compid=o.mav_compid, servo_follow=o.follow_servo
            )
            ts_path = signing_timestamp_path(o)
            if o.mav_signing_key is not None and ts_path is not None:
                check_signing_timestamp_writable(ts_path)
                cfg = cfg.with_signing_key_file(o.mav_signing_key, timestamp_path=ts_path)
            if o.record is not None:
                cfg = _replace(cfg, tlog_path=o.record.with_suffix(".tlog"))
            client = self.client

            model = self.model

            def to_board(msg: Message) -> None:
                model.on_host_command(msg, "MAVLink")  # the panel's event console lists them
                client.send(msg)

            link = drone_link.DroneLink(cfg, send_to_board=to_board)
            link.start()
        except (drone_config.DroneLinkError, ValueError, OSError) as exc:
            raise HostError(f"--mavlink: {exc}") from exc
        self.drone_link = link
        self.client.add_listener(link.on_board_message)

    def _start_ui(self) -> None:
        from host.panel.teleop import TeleopPanel

        o = self.options
        # viser prints its own banner (with a URL lacking the token): ours replaces it.
        self.guard = guard = PanelGuard(o.token, loopback=is_loopback(o.ui_host))
        with contextlib.redirect_stdout(io.StringIO()):
            server = start_guarded_server(
                self.guard, host=o.ui_host, port=o.ui_port, label="SpiRob teleop", verbose=False
            )
        self.server = server
        if o.ui_port != 0 and server.get_port() != o.ui_port:
            # viser moved to another port: somebody took ours between the check and the bind.
            raise HostError(
                f"UI port {o.ui_port} on {o.ui_host} is already in use (choose another with --ui-port)"
            )
        self.panel = TeleopPanel(
            server,
            self.model,
            objects=self.objects,
            drone_pose=self._drone_pose if self.drone_link is not None else None,
            mavlink_status=self._mavlink_status if self.drone_link is not None else None,
            shadow_status=self._shadow_status if self.shadow is not None else None,
            malformed_n=lambda: guard.stats.malformed_messages_n,
            recorder=self.recorder,
            config=self.panel_config,
        )
        self.panel.start()
        host = o.ui_host if ":" not in o.ui_host else f"[{o.ui_host}]"
        if host in ("0.0.0.0", "[::]"):
            host = socket.gethostname()
        port = server.get_port()
        self.url = f"http://{host}:{port}/"
        if o.token is not None:
            self.url += f"?token={o.token}"

    # ------------------------------------------------------------------ drone link adapters

    def _drone_pose(self) -> DronePose | None:
        link = self.drone_link
        if link is None:
            return None
        pose = link.drone_pose
        if pose.position is None and pose.attitude is None:
            return None
        return ned_to_scene(pose.position, pose.attitude)

    def _shadow_status(self) -> str:
        shadow = self.shadow
        return "shadow plant off" if shadow is None else shadow.stats().describe()

    def _mavlink_status(self) -> str:
        link = self.drone_link
        if link is None:
            return "off"
        st = link.state()
        alive = [p for p in st.peers if p.alive]
        last = ""
        if st.last_command is not None:
            last = f" · last command {st.last_command.command} → result {st.last_command.result}"
        return (
            f"`{st.url}` {'running' if st.running else '**stopped**'} · sys {st.sysid} comp {st.compid} · "
            f"peers {len(alive)}/{len(st.peers)} · rx {st.rx_rate_hz:.0f}/s tx {st.tx_rate_hz:.0f}/s · "
            f"signing {'on' if st.signing else 'off'}{last}"
        )

    # ------------------------------------------------------------------ loops

    def _virtual_rc_loop(self) -> None:
        lever = self.options.virtual_rc
        assert lever is not None
        m = self.model
        m.request_control(CLI_CLIENT)
        m.set_lever(CLI_CLIENT, "right", Lever.DOWN)
        m.set_lever(CLI_CLIENT, "left", Lever.DOWN)
        # DOWN first: wait until the board reports it (or 1 s), then the requested lever.
        deadline = time.monotonic() + 1.0
        while not self._stop.is_set() and time.monotonic() < deadline:
            t = m.telemetry
            if t is not None and t.right_lever == Lever.DOWN and t.rc_frames_ok > 0:
                break
            self._stop.wait(0.02)
        self._stop.wait(0.1)
        if not self._stop.is_set():
            m.set_lever(CLI_CLIENT, "right", lever)
        while not self._stop.wait(0.1):
            # The command line hands control to a browser tab that asks for it.
            if m.holder == CLI_CLIENT and m.pending is not None:
                _log.info("handing control to browser tab %s", m.pending)
                m.answer_request(CLI_CLIENT, grant=True)

    def _replay_loop(self) -> None:
        assert self.options.replay is not None
        try:
            messages = replay_messages(self.options.replay)
        except Exception as exc:
            _log.error("cannot read %s: %s", self.options.replay, exc)
            self.replay_done.set()
            return
        speed = self.options.replay_speed
        if messages:
            t0_rec = messages[0][0]
            t0 = time.monotonic()
            for t_us, msg in messages:
                due = t0 + (t_us - t0_rec) / 1e6 / speed
                delay = due - time.monotonic()
                if delay > 0 and self._stop.wait(delay):
                    break
                self.model.on_board_message(msg)
                self.summary.on_board_message(msg)
                if self.foxglove is not None:
                    self.foxglove.on_board_message(msg)
        if messages:
            _log.info("replay finished: %d messages", len(messages))
        else:
            _log.warning(
                "%s holds no board-link messages (/board/link_tx): nothing to replay", self.options.replay
            )
        self.replay_done.set()

    def run(self, duration_s: float | None = None, stop: threading.Event | None = None) -> int:
        """Serve until ``duration_s`` passes, ``stop`` is set, or (headless) a replay ends; then take the
        run's summary (:attr:`report`).

        Returns:
            The exit status: 1 if a ``--virtual-rc`` run ended latched in a failsafe, saw a fault or no
            telemetry at all (:meth:`SummaryReport.failure`), else 0.
        """
        stop = stop or threading.Event()
        end = None if duration_s is None else time.monotonic() + duration_s
        next_status = time.monotonic() + 10.0
        while not stop.is_set():
            now = time.monotonic()
            if end is not None and now >= end:
                break
            if self.options.replay is not None and not self.options.ui and self.replay_done.is_set():
                break
            if now >= next_status:
                next_status = now + 10.0
                _log.info("%s", self.status_line())
            wait = 0.1 if end is None else max(0.0, min(0.1, end - now))
            stop.wait(wait)
        self.report = self.take_report()
        if self.options.virtual_rc is not None and self.report.failure() is not None:
            return EXIT_FAILURE
        return EXIT_OK

    def take_report(self) -> SummaryReport:
        """The run's summary so far, with the virtual radio's gaps from the link (when there is one)."""
        if self.client is None:
            return self.summary.report()
        stats = self.client.stats()
        return self.summary.report(stats.rc_gaps_over_timeout, stats.rc_max_gap_us)

    def status_line(self) -> str:
        """One line of progress: link state, telemetry count, mode and phase."""
        t = self.model.telemetry
        state = self.model.link_state.value
        if t is None:
            return f"{self.model.source_label}: {state}, no telemetry yet"
        return (
            f"{self.model.source_label}: {state} · telemetry {self.model.telemetry_count} · "
            f"mode {t.mode.name} · phase {t.phase.name}"
        )

    # ------------------------------------------------------------------ stop

    def close(self) -> None:
        """Stop everything in reverse order; safe twice."""
        self._stop.set()
        for t in self._threads:
            t.join(timeout=3.0)
        self._threads = []
        if self.gamepad is not None:
            self.gamepad.stop()
            self.gamepad = None
        if self.panel is not None:
            self.panel.stop()
            self.panel = None
        if self.server is not None:
            with contextlib.suppress(Exception), contextlib.redirect_stdout(io.StringIO()):
                self.server.stop()
            self.server = None
        if self.guard is not None:
            self.guard.detach()
        if self.drone_link is not None:
            with contextlib.suppress(Exception):
                self.drone_link.close()
            self.drone_link = None
        if self.client is not None:
            self.client.stop()
            self.client = None
        if self.shadow is not None:
            self.shadow.stop()
            self.shadow = None
        if self.recording is not None:
            self.recording.close()
            self.recording = None
        if self.recorder is not None:
            self.recorder.stop()
            self.recorder = None
        if self.foxglove is not None:
            self.foxglove.close()
            self.foxglove = None
        if self.board is not None:
            with contextlib.suppress(Exception):
                self.board.stop()
            self.board = None


def _replace(obj: Any, **changes: Any) -> Any:
    import dataclasses

    return dataclasses.replace(obj, **changes)


def _with_objects(config: Any, specs: tuple[ObjectSpec, ...]) -> Any:
    """``config`` (a ``hil.board.BoardConfig``) with the ``--object`` objects added to its plant."""
    model = config.plant.model
    model = model.with_objects(*plant_objects(specs, model))
    return _replace(config, plant=_replace(config.plant, model=model))


def ned_to_scene(position: Any, attitude: Any) -> DronePose:
    """MAVLink LOCAL_POSITION_NED / ATTITUDE (NED world, FRD body) -> the scene's z-up (ENU, FLU) pose."""
    import numpy as np

    if position is not None:
        pos = (float(position.y_m), float(position.x_m), -float(position.z_m))
    else:
        from host.panel.scene import DRONE_HEIGHT_M

        pos = (0.0, 0.0, DRONE_HEIGHT_M)
    if attitude is None:
        return DronePose(pos)
    cr, sr = math.cos(attitude.roll_rad), math.sin(attitude.roll_rad)
    cp, sp = math.cos(attitude.pitch_rad), math.sin(attitude.pitch_rad)
    cy, sy = math.cos(attitude.yaw_rad), math.sin(attitude.yaw_rad)
    r_ned_frd = np.array(
        [
            [cp * cy, sr * sp * cy - cr * sy, cr * sp * cy + sr * sy],
            [cp * sy, sr * sp * sy + cr * cy, cr * sp * sy - sr * cy],
            [-sp, sr * cp, cr * cp],
        ]
    )
    t_enu_ned = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
    t_frd_flu = np.diag([1.0, -1.0, -1.0])
    r = t_enu_ned @ r_ned_frd @ t_frd_flu
    return DronePose(pos, _matrix_to_wxyz(r))


def _matrix_to_wxyz(r: Any) -> tuple[float, float, float, float]:
    tr = float(r[0, 0] + r[1, 1] + r[2, 2])
    if tr > 0:
        s = math.sqrt(tr + 1.0) * 2
        q = (0.25 * s, (r[2, 1] - r[1, 2]) / s, (r[0, 2] - r[2, 0]) / s, (r[1, 0] - r[0, 1]) / s)
    elif r[0, 0] > r[1, 1] and r[0, 0] > r[2, 2]:
        s = math.sqrt(1.0 + r[0, 0] - r[1, 1] - r[2, 2]) * 2
        q = ((r[2, 1] - r[1, 2]) / s, 0.25 * s, (r[0, 1] + r[1, 0]) / s, (r[0, 2] + r[2, 0]) / s)
    elif r[1, 1] > r[2, 2]:
        s = math.sqrt(1.0 + r[1, 1] - r[0, 0] - r[2, 2]) * 2
        q = ((r[0, 2] - r[2, 0]) / s, (r[0, 1] + r[1, 0]) / s, 0.25 * s, (r[1, 2] + r[2, 1]) / s)
    else:
        s = math.sqrt(1.0 + r[2, 2] - r[0, 0] - r[1, 1]) * 2
        q = ((r[1, 0] - r[0, 1]) / s, (r[0, 2] + r[2, 0]) / s, (r[1, 2] + r[2, 1]) / s, 0.25 * s)
    return (float(q[0]), float(q[1]), float(q[2]), float(q[3]))
