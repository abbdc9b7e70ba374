"""The `spirob-host` application: the composition root. It builds the parts and connects them.

A board source (the live link, :class:`~host.link.client.BoardClient`, or a recording played back,
:class:`~host.link.replay.ReplaySource`) fans every board message out to its listeners: the panel's
board state, notices, control arbiter and parameters, the run summary, and for a live link the
recorders, the shadow plant and the drone link. The arbiter pushes the operator's radio to the link and
sends commands; the drone link sends its own, with their answers routed back by the client. Data never
passes through this module.
"""

from __future__ import annotations

import contextlib
import dataclasses
import io
import logging
import socket
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from controller.cli_kit import EXIT_FAILURE, EXIT_OK, EXIT_USAGE, error_line
from controller.transport import is_loopback_host
from host.errors import HostError
from host.excite import ExcitationDriver, ExciteConfig, operator_lines
from host.link.client import BoardClient, load_scaled_s
from host.link.process import BoardLinkError
from host.link.recording import LinkRecording
from host.link.replay import ReplaySource
from host.link.source import BoardSource
from host.options import (
    PROG,
    HostOptions,
    check_signing_timestamp_writable,
    check_ui_port_free,
    signing_timestamp_path,
)
from host.panel.arbiter import CLI_CLIENT, ControlArbiter
from host.panel.board_params import BoardParams
from host.panel.board_state import BoardState
from host.panel.guard import PanelGuard, start_guarded_server
from host.panel.notices import Notices
from host.panel.record import RecordingSwitch
from host.panel.scene import ArmGeometry, DronePose, SceneObject, ned_to_scene, scene_objects
from host.plant_model import resolve_preset, shadow_plant_factory, virtual_board_config
from host.run_summary import RunSummary, SummaryReport
from host.shadow import ShadowPlant
from host.virtual_rc import ScriptDriver, ScriptState, VirtualRcDriver

__all__ = ["HostApp"]

_log = logging.getLogger("spirob-host")


class HostApp:
    """One `spirob-host` run: board (or replay), listeners, panel, drone link. Usable in-process.

    Call :meth:`start` (raises :class:`HostError` with a one-line reason), then :meth:`run` or drive it
    yourself, then :meth:`close` (safe twice; also a context manager). The panel's parts
    (:attr:`board_state`, :attr:`arbiter`, :attr:`notices`, :attr:`board_params`) exist from
    :meth:`start` on.
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
        self.notices = Notices()
        """The panel's notices and event console."""
        self.board_state: BoardState | None = None
        """The board as the panel sees it (telemetry, poses, history, link health)."""
        self.arbiter: ControlArbiter | None = None
        """Who holds control; the operator's radio and commands."""
        self.board_params: BoardParams | None = None
        """The board's parameters and the fate of each set."""
        self.source: BoardSource | None = None
        """Where board messages come from: :attr:`client` or :attr:`replay`."""
        self.client: BoardClient | None = None
        self.replay: ReplaySource | None = None
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
        self.virtual_rc: VirtualRcDriver | None = None
        self.script: ScriptDriver | None = None
        """``--virtual-rc-script``: the radio script played on the board."""
        self.param_push: Any = None
        """``--params``: the parameter file's values sent at every link-up (``host.param_push``)."""
        self.excite: ExcitationDriver | None = None
        """``--excite``: the excitation played on the board."""
        self.preset: Any = None
        """``--preset``'s ``hil.sim.presets.Preset`` (None: the default model)."""
        self.design: Any = None
        """The arm's ``SpiralDesign`` when the host knows it (the virtual board's, or ``--preset``'s)."""
        self.summary = RunSummary()
        """Modes, phases, failsafes and faults of the run (the summary at exit)."""
        self.report: SummaryReport | None = None
        """The summary, taken when :meth:`run` returns."""
        self.url = ""
        self.board_url = ""
        self.objects: list[SceneObject] = []

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
        client: BoardClient | None = None
        self.preset = resolve_preset(o.preset)
        if o.replay is None:
            self.board_url = o.port if o.port is not None else self._start_virtual_board()
            client = self.client = BoardClient(self.board_url)
            source: BoardSource = client
            label = "virtual board" if o.port is None else f"board {o.port}"
        else:
            source = self.replay = ReplaySource(o.replay, o.replay_speed)
            label = f"replay {o.replay}"
        self.source = source
        notices = self.notices
        board = self.board_state = BoardState(label, client.stats if client is not None else None)
        arbiter = self.arbiter = ControlArbiter(
            notices,
            client.send if client is not None else None,
            client.set_rc if client is not None else None,
            token=o.token,
        )
        params = self.board_params = BoardParams(arbiter)
        for listener in (board, notices, arbiter, params, self.summary):
            source.add_listener(listener.on_board_message)
        for state_listener in (board, notices, arbiter):
            source.add_state_listener(state_listener.on_link_state)
        if o.params:
            from host.param_push import ParamPush

            push = self.param_push = ParamPush(
                dict(o.params), arbiter.forward, lambda level, text: notices.log("host", level, text)
            )
            source.add_listener(push.on_board_message)
            source.add_state_listener(push.on_link_state)
        if client is not None:
            self._wire_link(client)
            try:
                client.start()
            except BoardLinkError as exc:
                raise HostError(f"board link: {exc}") from exc
        elif o.foxglove_port is not None and o.replay is not None:
            from hil.recording import read_metadata  # type: ignore[import-not-found,unused-ignore]

            self._start_foxglove(read_metadata(o.replay))
        if o.ui:
            self._start_ui()
        if self.replay is not None:
            self.replay.start()  # after the panel: it sees the recording from its start
        if o.excite is not None and client is not None:
            self._start_excite(client, o.excite)  # before the radio moves: it must see the lever's way
        if o.virtual_rc is not None:
            self.virtual_rc = VirtualRcDriver(arbiter, board, o.virtual_rc)
            self.virtual_rc.start()
        if o.virtual_rc_script is not None and client is not None:
            self.script = ScriptDriver(
                arbiter, o.virtual_rc_script, self._say("script"), timeout_scale=load_scaled_s(1.0)
            )
            client.add_listener(self.script.on_board_message)
            self.script.start()
        if o.gamepad is not None:
            self._start_gamepad(o.gamepad)

    def _wire_link(self, client: BoardClient) -> None:
        """The live link's own listeners: commands sent to the console, shadow plant, recorders, drone."""
        o = self.options
        assert self.board_state is not None
        client.add_sent_listener(self.notices.on_sent)  # every command, with who sent it
        if o.port is not None and o.shadow:
            # A board that sends no SimPoses (hardware) gets its shape from a local plant driven by
            # the measured currents; it switches itself off when SimPoses arrive.
            self.shadow = ShadowPlant(
                self.board_state.on_shadow_poses, plant_factory=shadow_plant_factory(self.preset)
            )
            if self.preset is not None:
                self.design = self.preset.spiral()
            client.add_listener(self.shadow.on_board_message)
            self.shadow.start()
        meta = {"source": "spirob-host", "port": self.board_url}
        if self.board is not None:  # the virtual board's design and firmware parameters
            meta.update(self.board_config.describe())
        if o.preset is not None:
            meta["preset"] = o.preset
        if o.record is not None:
            tlog = o.record.with_suffix(".tlog") if o.mavlink is not None else None
            self.recording = LinkRecording(o.record, meta, tlog=tlog)
            client.add_tap(self.recording.tap)
            client.add_listener(self.recording.on_board_message)
            client.add_state_listener(self.recording.on_link_state)
        # Always on the link (it forwards nothing until the panel starts a recording).
        self.recorder = RecordingSwitch(
            (o.record.parent if o.record is not None else Path("recordings")).resolve(),
            {"source": "spirob-host (panel)", "port": self.board_url},
        )
        client.add_tap(self.recorder.tap)
        client.add_listener(self.recorder.on_board_message)
        if o.foxglove_port is not None:
            self._start_foxglove(meta)
        if o.mavlink is not None:
            self._start_drone_link(client)

    def _start_virtual_board(self) -> str:
        try:
            from hil.board import VirtualBoardProcess  # type: ignore[import-not-found,unused-ignore]
        except ImportError as exc:
            raise HostError(
                f"the virtual board is not available ({exc}); pass --port to use a real board"
            ) from exc
        from hil.errors import HilError  # type: ignore[import-not-found,unused-ignore]

        config = virtual_board_config(self.board_config, self.preset, self.options.objects, self.options.arms)
        self.board_config = config
        self.design = config.design
        self.board = VirtualBoardProcess(config, listen="socket://127.0.0.1:0")
        try:
            url = str(self.board.start(timeout_s=load_scaled_s(30.0)))
        except HilError as exc:
            raise HostError(f"virtual board: {exc}") from exc
        # The objects of the plant we asked for (free objects drawn where they start).
        self.objects.extend(scene_objects(config.plant.model.objects))
        return url

    def _start_excite(self, client: BoardClient, name: str) -> None:
        from hil.identify.excitation import profile  # type: ignore[import-not-found,unused-ignore]

        def send(msg: Any, on_ack: Any) -> bool:
            return client.send(msg, origin="excite", on_ack=on_ack)

        config = ExciteConfig(direct_wait_s=load_scaled_s(2.0), telemetry_wait_s=load_scaled_s(10.0))
        recorders = [r for r in (self.recording, self.recorder) if r is not None]
        self.excite = ExcitationDriver(
            profile(name), send, operator_lines(self.notices), recorders, config=config
        )
        client.add_listener(self.excite.on_board_message)
        client.add_state_listener(self.excite.on_link_state)
        self.excite.start()

    def _say(self, source: str) -> Callable[[str, str], None]:
        """Lines for the operator from ``source``: ``info`` to stdout, ``error`` as one line on stderr;
        both also in the panel's event console."""
        notices = self.notices

        def say(level: str, text: str) -> None:
            if level == "error":
                error_line(PROG, text)
            else:
                print(f"{PROG}: {text}", flush=True)
            notices.log(source, level, text)

        return say

    def _start_gamepad(self, path: str) -> None:
        from host.gamepad import Gamepad

        assert self.arbiter is not None
        pad = Gamepad(path, self.arbiter, CLI_CLIENT, self.options.gamepad_map)
        try:
            pad.start()
        except OSError as exc:
            raise HostError(f"--gamepad {path}: {exc.strerror or exc}") from exc
        self.gamepad = pad

    def _start_foxglove(self, metadata: dict[str, str]) -> None:
        from host.foxglove_live import FoxgloveLive

        assert self.options.foxglove_port is not None
        live = FoxgloveLive(self.options.foxglove_port, metadata, self.options.foxglove_origins)
        live.start()
        self.foxglove = live
        assert self.source is not None
        self.source.add_listener(live.on_board_message)
        self.source.add_state_listener(live.on_link_state)

    def _start_drone_link(self, client: BoardClient) -> None:
        o = self.options
        assert o.mavlink is not None
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
                cfg = dataclasses.replace(cfg, tlog_path=o.record.with_suffix(".tlog"))
            link = drone_link.DroneLink(cfg, send_to_board=client.send)
            link.start()
        except (drone_config.DroneLinkError, ValueError, OSError) as exc:
            raise HostError(f"--mavlink: {exc}") from exc
        self.drone_link = link
        client.add_listener(link.on_board_message)

    def _start_ui(self) -> None:
        from host.panel.teleop import TeleopPanel

        o = self.options
        # viser prints its own banner (with a URL lacking the token): ours replaces it.
        self.guard = guard = PanelGuard(o.token, loopback=is_loopback_host(o.ui_host))
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
        assert self.board_state is not None and self.arbiter is not None and self.board_params is not None
        self.panel = TeleopPanel(
            server,
            self.board_state,
            self.arbiter,
            self.notices,
            self.board_params,
            objects=self.objects,
            geometry=ArmGeometry.from_design(self.design) if self.design is not None else None,
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
        return "off" if link is None else str(link.state().describe())

    def run(self, duration_s: float | None = None, stop: threading.Event | None = None) -> int:
        """Serve until ``duration_s`` passes, ``stop`` is set, or (headless) a replay ends; then take the
        run's summary (:attr:`report`).

        Returns:
            The exit status: 2 if the ``--replay`` file was refused (``replay.error``), 1 if a
            ``--virtual-rc`` or ``--virtual-rc-script`` run ended latched in a failsafe, saw a fault or no
            telemetry at all (:meth:`SummaryReport.failure`), a radio script did not reach its every step
            or an ``--excite`` profile did not play to its end (the run ends with either), else 0.
        """
        stop = stop or threading.Event()
        end = None if duration_s is None else time.monotonic() + duration_s
        next_status = time.monotonic() + 10.0
        while not stop.is_set():
            now = time.monotonic()
            if end is not None and now >= end:
                break
            if self.replay is not None and self.replay.error is not None:
                break  # a recording refused by the bounded reader ends the run, panel or not
            if self.replay is not None and not self.options.ui and self.replay.done.is_set():
                break
            if self.excite is not None and self.excite.done.is_set():
                break  # the run ends with its excitation
            if self.script is not None and self.script.done.is_set():
                break  # and with its radio script
            if now >= next_status:
                next_status = now + 10.0
                _log.info("%s", self.status_line())
            wait = 0.1 if end is None else max(0.0, min(0.1, end - now))
            stop.wait(wait)
        excite_failed = False
        if self.excite is not None:
            why = "the run was interrupted" if stop.is_set() else "--duration ran out"
            outcome = self.excite.stop(f"{why} before the profile ended")
            excite_failed = outcome is None or not outcome.completed
        script_failed = False
        if self.script is not None:
            why = "the run was interrupted" if stop.is_set() else "--duration ran out"
            script_failed = self.script.stop(f"{why} before the script ended") is not ScriptState.DONE
        self.report = self.take_report()
        if self.replay is not None and self.replay.error is not None:
            return EXIT_USAGE
        scripted = self.options.virtual_rc is not None or self.script is not None
        if scripted and self.report.failure() is not None:
            return EXIT_FAILURE
        return EXIT_FAILURE if excite_failed or script_failed else EXIT_OK

    def take_report(self) -> SummaryReport:
        """The run's summary so far, with the virtual radio's gaps from the link (when there is one)."""
        if self.client is None:
            return self.summary.report()
        stats = self.client.stats()
        return self.summary.report(stats.rc_gaps_over_timeout, stats.rc_max_gap_us)

    def status_line(self) -> str:
        """One line of progress: link state, telemetry count, mode and phase."""
        b = self.board_state
        if b is None:
            return "not started"
        t = b.telemetry
        state = b.link_state.value
        if t is None:
            return f"{b.source_label}: {state}, no telemetry yet"
        return (
            f"{b.source_label}: {state} · telemetry {b.telemetry_count} · "
            f"mode {t.mode.name} · phase {t.phase.name}"
        )

    # ------------------------------------------------------------------ stop

    def close(self) -> None:
        """Stop everything in reverse order; safe twice."""
        if self.excite is not None:  # first: its last word to the board needs the link
            self.excite.stop("the host closed before the profile ended")
        if self.virtual_rc is not None:
            self.virtual_rc.stop()
            self.virtual_rc = None
        if self.script is not None:
            self.script.stop("the host closed before the script ended")
        if self.replay is not None:
            self.replay.stop()
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
