"""`spirob-host`: the board link, the browser teleop panel, recording, replay and the drone link.

With no arguments it starts the virtual board (``hil.board``, in its own process) and serves the panel
on http://127.0.0.1:8080. ``--port`` connects to a real board (``/dev/ttyACM0``) or any pyserial URL
instead. Start-up errors (wrong port, busy port, UI port taken, bad flags) print one line and exit 2;
a board that vanishes mid-run is retried until it comes back, with the panel showing "disconnected".

Exit status: 0 normal end (``--duration`` elapsed, Ctrl-C, replay finished headless), 1 runtime failure,
2 start-up or usage error.
"""

from __future__ import annotations

import argparse
import contextlib
import errno
import io
import ipaddress
import logging
import math
import os
import socket
import sys
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from controller.cli_kit import (
    EXIT_FAILURE,
    EXIT_OK,
    EXIT_USAGE,
    Parser,
    error_line,
    parse_or_exit,
    port_number,
    positive_duration,
    stop_on_signals,
)
from host.board_client import BoardClient, BoardLinkError, LinkState
from host.model import CLI_CLIENT, UiModel, new_token
from host.scene import DronePose, SceneObject, scene_objects
from host.shadow import ShadowPlant
from protocol.dbus import Lever
from protocol.errors import DecodeError
from protocol.link import LinkParser
from protocol.messages import Message, Telemetry, decode

__all__ = ["HostApp", "HostError", "HostOptions", "build_parser", "main"]

_log = logging.getLogger("spirob-host")

PROG = "spirob-host"

VIRTUAL_RC_LEVERS = {"safe": Lever.DOWN, "manual": Lever.MIDDLE, "grasp": Lever.UP}
"""``--virtual-rc`` choices: the right lever position each one ends in (DOWN first, always)."""


class HostError(Exception):
    """A start-up failure with a one-line reason (printed, exit status 2)."""


# ---------------------------------------------------------------------- argument parsing


def _mav_id(text: str) -> int:
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not an id: {text!r}") from None
    if not 1 <= v <= 255:
        raise argparse.ArgumentTypeError(f"MAVLink ids are 1..255: {text!r}")
    return v


def build_parser() -> argparse.ArgumentParser:
    """The `spirob-host` argument parser (kept apart from :func:`main` so tests call it with argv)."""
    p = Parser(
        prog=PROG,
        description="SpiRob teleop host: board link, browser panel (viser), recording, MAVLink drone link.",
        epilog="With no --port, the virtual board (MuJoCo plant + firmware emulator) is started.",
    )
    src = p.add_argument_group("board")
    src.add_argument(
        "--port",
        metavar="URL",
        help="board link: a device (/dev/ttyACM0), a pty path or any pyserial URL (socket://HOST:PORT, "
        "loop://, spy://...). Default: start the virtual board.",
    )
    src.add_argument(
        "--virtual-rc",
        choices=sorted(VIRTUAL_RC_LEVERS),
        help="drive the virtual radio from the command line: right lever DOWN first (start-up gate), "
        "then SAFE / MANUAL / GRASP; a browser tab can ask for control and gets it",
    )
    src.add_argument(
        "--no-shadow",
        action="store_true",
        help="with --port: do not run the shadow plant (the arm's shape from the measured motor currents "
        "of a board that sends no poses)",
    )
    ui = p.add_argument_group("panel")
    ui.add_argument("--ui-host", default="127.0.0.1", help="address the panel binds (default 127.0.0.1)")
    ui.add_argument("--ui-port", type=port_number, default=8080, help="panel port (default 8080; 0 = any)")
    ui.add_argument("--headless", action="store_true", help="no panel")
    ui.add_argument(
        "--token",
        help="access token for a non-loopback --ui-host (default: a fresh random one, printed at start)",
    )
    run = p.add_argument_group("run")
    run.add_argument("--duration", type=positive_duration, metavar="S", help="exit after S seconds")
    run.add_argument("--record", type=Path, metavar="FILE", help="record the board link to an MCAP file")
    run.add_argument(
        "--replay", type=Path, metavar="FILE", help="replay a recording (no board) through the same listeners"
    )
    run.add_argument("--replay-speed", type=positive_duration, default=1.0, help="replay speed factor")
    mav = p.add_argument_group("drone link (MAVLink)")
    mav.add_argument(
        "--mavlink", metavar="URL", help="pymavlink connection string, e.g. udpout:127.0.0.1:14550"
    )
    mav.add_argument("--mav-sysid", type=_mav_id, default=1, help="the drone's system id (default 1)")
    mav.add_argument("--mav-compid", type=_mav_id, default=25, help="the arm's component id (default 25)")
    mav.add_argument("--mav-signing-key", type=Path, metavar="FILE", help="MAVLink 2 signing key file")
    mav.add_argument(
        "--mav-signing-timestamp",
        type=Path,
        metavar="FILE",
        help="where the signing timestamp persists across restarts (default: <key file>.timestamp)",
    )
    p.add_argument(
        "--log-level",
        default="warning",
        choices=["debug", "info", "warning", "error"],
        help="logging level (default warning)",
    )
    return p


@dataclass(frozen=True, slots=True)
class HostOptions:
    """Validated options of one `spirob-host` run (what :func:`build_parser` produced, checked).

    Attributes:
        port: board link URL; None = start the virtual board.
        ui: serve the panel.
        ui_host: panel bind address.
        ui_port: panel port (0 = any free port).
        token: access token (None on loopback).
        duration_s: stop after this long (None = until interrupted).
        record: MCAP file to write.
        replay: MCAP file to replay instead of a board.
        replay_speed: replay speed factor.
        virtual_rc: right lever the command line drives the virtual radio to (None = it does not).
        mavlink: MAVLink connection string.
        mav_sysid: drone system id.
        mav_compid: our component id.
        mav_signing_key: signing key file.
        mav_signing_timestamp: file persisting the signing timestamp (None with a key:
            ``<key file>.timestamp``).
        shadow: with ``port``, run the shadow plant when the board sends no poses.
    """

    port: str | None = None
    ui: bool = True
    ui_host: str = "127.0.0.1"
    ui_port: int = 8080
    token: str | None = None
    duration_s: float | None = None
    record: Path | None = None
    replay: Path | None = None
    replay_speed: float = 1.0
    virtual_rc: Lever | None = None
    mavlink: str | None = None
    mav_sysid: int = 1
    mav_compid: int = 25
    mav_signing_key: Path | None = None
    mav_signing_timestamp: Path | None = None
    shadow: bool = True

    @classmethod
    def from_args(cls, ns: argparse.Namespace) -> HostOptions:
        """Check the combination of flags.

        Raises:
            HostError: flags that cannot go together, or a missing file.
        """
        if ns.replay is not None:
            if ns.port is not None:
                raise HostError("--replay and --port cannot be combined (a replay has no board)")
            if ns.record is not None:
                raise HostError("--replay and --record cannot be combined")
            if ns.virtual_rc is not None:
                raise HostError("--virtual-rc needs a board; it cannot be used with --replay")
            if not ns.replay.is_file():
                raise HostError(f"no such recording: {ns.replay}")
            from hil.recording import is_mcap

            if not is_mcap(ns.replay):
                raise HostError(f"{ns.replay} is not an MCAP recording")
        if ns.record is not None and not ns.record.parent.exists():
            raise HostError(f"cannot record to {ns.record}: directory {ns.record.parent} does not exist")
        if ns.mav_signing_key is not None and ns.mavlink is None:
            raise HostError("--mav-signing-key needs --mavlink")
        if ns.mav_signing_key is not None and not ns.mav_signing_key.is_file():
            raise HostError(f"no such signing key file: {ns.mav_signing_key}")
        if ns.mav_signing_timestamp is not None and ns.mav_signing_key is None:
            raise HostError("--mav-signing-timestamp needs --mav-signing-key")
        token = ns.token  # an explicit token is honoured on loopback too
        if not ns.headless and not is_loopback(ns.ui_host):
            token = token or new_token()
        return cls(
            port=ns.port,
            ui=not ns.headless,
            ui_host=ns.ui_host,
            ui_port=ns.ui_port,
            token=token,
            duration_s=ns.duration,
            record=ns.record,
            replay=ns.replay,
            replay_speed=ns.replay_speed,
            virtual_rc=VIRTUAL_RC_LEVERS[ns.virtual_rc] if ns.virtual_rc else None,
            mavlink=ns.mavlink,
            mav_sysid=ns.mav_sysid,
            mav_compid=ns.mav_compid,
            mav_signing_key=ns.mav_signing_key,
            mav_signing_timestamp=ns.mav_signing_timestamp,
            shadow=not ns.no_shadow,
        )


def signing_timestamp_path(options: HostOptions) -> Path | None:
    """Where the MAVLink signing timestamp persists (None without a signing key).

    ``--mav-signing-timestamp`` if given, else ``<key file>.timestamp``, the default of
    ``host.drone_link.DroneLinkConfig.with_signing_key_file``; passed explicitly so the check at start
    and the drone link agree on one file.
    """
    if options.mav_signing_key is None:
        return None
    if options.mav_signing_timestamp is not None:
        return options.mav_signing_timestamp
    key = options.mav_signing_key
    return key.with_name(key.name + ".timestamp")


def check_signing_timestamp_writable(path: Path) -> None:
    """Fail early if the signing timestamp cannot be persisted (issue 7: it must survive restarts).

    The drone link only counts a failed save as an I/O error, so without this check a read-only key
    directory would silently restart the timestamp from the wall clock every run.

    Raises:
        HostError: the file or its directory is not writable.
    """
    target = path if path.exists() else path.parent
    if path.exists() and not path.is_file():
        raise HostError(f"signing timestamp {path} is not a regular file")
    if not target.exists():
        raise HostError(f"cannot persist the signing timestamp to {path}: {path.parent} does not exist")
    # The save writes <path>.tmp beside it and renames: the directory must be writable too.
    if not os.access(path.parent, os.W_OK) or (path.exists() and not os.access(path, os.W_OK)):
        raise HostError(
            f"cannot persist the signing timestamp to {path}: not writable "
            "(choose another place with --mav-signing-timestamp)"
        )


def is_loopback(host: str) -> bool:
    """True for ``localhost`` and loopback addresses (127.0.0.0/8, ::1)."""
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def check_ui_port_free(host: str, port: int) -> None:
    """Fail early, with one line, if the panel's port is taken (viser would silently hop to the next).

    Raises:
        HostError: the port is in use or the address cannot be bound.
    """
    if port == 0:
        return
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    with socket.socket(family, socket.SOCK_STREAM) as s:
        # Same option as the server will use: a port in TIME_WAIT is free, a listening one is not.
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            s.bind((host, port))
        except OSError as exc:
            if exc.errno == errno.EADDRINUSE:
                raise HostError(
                    f"UI port {port} on {host} is already in use (choose another with --ui-port)"
                ) from exc
            raise HostError(f"cannot bind the panel to {host}:{port}: {exc.strerror or exc}") from exc


# ---------------------------------------------------------------------- recording and replay


class LinkRecording:
    """Records the board link from the host's side into MCAP (``hil.recording``): a listener and a tap.

    Raw bytes go to the same topics the virtual board uses (``/board/link_tx`` = board -> host,
    ``/board/link_rx`` = host -> board), so ``--replay`` and ``spirob-hil`` read either kind of file.
    Decoded telemetry goes to ``/telemetry`` as JSON for plotting tools. Times are host µs (monotonic).
    """

    def __init__(self, path: Path, metadata: dict[str, str]) -> None:
        """Create the file.

        Raises:
            HostError: the file cannot be created.
        """
        from hil import recording

        self._rec_mod = recording
        try:
            self._rec = recording.Recorder(path, metadata=metadata)
        except OSError as exc:
            raise HostError(f"cannot record to {path}: {exc.strerror or exc}") from exc
        self._lock = threading.Lock()
        self.path = path

    def tap(self, direction: str, data: bytes, t_us: int) -> None:
        """Byte tap of :class:`BoardClient`."""
        topic = self._rec_mod.LINK_TX if direction == "rx" else self._rec_mod.LINK_RX
        with self._lock, contextlib.suppress(ValueError):
            self._rec.write_raw(topic, t_us, data)

    def on_board_message(self, msg: Message) -> None:
        """Listener: decoded telemetry as JSON."""
        if not isinstance(msg, Telemetry):
            return
        obj = {
            "time_us": msg.time_us,
            "mode": msg.mode.name,
            "phase": msg.phase.name,
            "grasp_state": msg.grasp_state.name,
            "flags": int(msg.flags),
            "tension_target_n": list(msg.tension_target_n),
            "tension_est_n": list(msg.tension_est_n),
            "commanded_current": list(msg.commanded_current),
            "motor_current": list(msg.motor_current),
            "cable_length_m": list(msg.cable_length_m),
        }
        with self._lock, contextlib.suppress(ValueError):
            self._rec.write_json(self._rec_mod.TELEMETRY, time.monotonic_ns() // 1000, obj)

    def close(self) -> None:
        """Finish the file (safe twice)."""
        with self._lock:
            self._rec.close()


def replay_messages(path: Path) -> list[tuple[int, Message]]:
    """Decode every board -> host message of a recording with its time (µs), in order."""
    from hil import recording

    parser = LinkParser()
    out: list[tuple[int, Message]] = []
    for rec in recording.read_records(path, {recording.LINK_TX}):
        for frame in parser.feed(rec.data):
            try:
                out.append((rec.time_us, decode(frame)))
            except DecodeError:
                continue
    return out


# ---------------------------------------------------------------------- the application


class HostApp:
    """One `spirob-host` run: board (or replay), listeners, panel, drone link. Usable in-process.

    Call :meth:`start` (raises :class:`HostError` with a one-line reason), then :meth:`run` or drive it
    yourself, then :meth:`close` (safe twice; also a context manager).
    """

    def __init__(self, options: HostOptions, *, panel_config: Any = None, board_config: Any = None) -> None:
        """Prepare a run (nothing starts until :meth:`start`).

        Args:
            options: the run's options.
            panel_config: ``host.panel.PanelConfig`` (rates); default rates when None.
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
        self.panel: Any = None
        self.recording: LinkRecording | None = None
        self.shadow: ShadowPlant | None = None
        self.drone_link: Any = None
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
            self.client.add_state_listener(self.model.on_link_state)
            if o.port is not None and o.shadow:
                # A board that sends no SimPoses (hardware) gets its shape from a local plant driven by
                # the measured currents; it switches itself off when SimPoses arrive.
                self.shadow = ShadowPlant(self.model.on_shadow_poses)
                self.client.add_listener(self.shadow.on_board_message)
                self.shadow.start()
            if o.record is not None:
                self.recording = LinkRecording(o.record, {"source": "spirob-host", "port": self.board_url})
                self.client.add_tap(self.recording.tap)
                self.client.add_listener(self.recording.on_board_message)
            if o.mavlink is not None:
                self._start_drone_link()
            try:
                self.client.start()
            except BoardLinkError as exc:
                raise HostError(f"board link: {exc}") from exc
        else:
            self.model.source_label = f"replay {o.replay}"
            self.model.link_state = LinkState.CONNECTED
        if o.ui:
            self._start_ui()
        if o.replay is not None:
            self._spawn(self._replay_loop, "replay")
        if o.virtual_rc is not None:
            self._spawn(self._virtual_rc_loop, "virtual-rc")

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
        self.board = VirtualBoardProcess(config, listen="socket://127.0.0.1:0")
        try:
            url = str(self.board.start(timeout_s=30.0))
        except HilError as exc:
            raise HostError(f"virtual board: {exc}") from exc
        # The objects of the plant we asked for (free objects drawn where they start).
        self.objects.extend(scene_objects(config.plant.model.objects))
        return url

    def _start_drone_link(self) -> None:
        o = self.options
        assert o.mavlink is not None and self.client is not None
        from host import drone_link

        try:
            cfg = drone_link.DroneLinkConfig(url=o.mavlink, sysid=o.mav_sysid, compid=o.mav_compid)
            ts_path = signing_timestamp_path(o)
            if o.mav_signing_key is not None and ts_path is not None:
                check_signing_timestamp_writable(ts_path)
                cfg = cfg.with_signing_key_file(o.mav_signing_key, timestamp_path=ts_path)
            if o.record is not None:
                cfg = _replace(cfg, tlog_path=o.record.with_suffix(".tlog"))
            client = self.client

            def to_board(msg: Message) -> None:
                client.send(msg)

            link = drone_link.DroneLink(cfg, send_to_board=to_board)
            link.start()
        except (drone_link.DroneLinkError, ValueError, OSError) as exc:
            raise HostError(f"--mavlink: {exc}") from exc
        self.drone_link = link
        self.client.add_listener(link.on_board_message)

    def _start_ui(self) -> None:
        import viser

        from host.panel import TeleopPanel

        o = self.options
        # viser prints its own banner (with a URL lacking the token): ours replaces it.
        with contextlib.redirect_stdout(io.StringIO()):
            server = viser.ViserServer(host=o.ui_host, port=o.ui_port, label="SpiRob teleop", verbose=False)
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
            config=self.panel_config,
        )
        self.panel.start()
        host = o.ui_host if ":" not in o.ui_host else f"[{o.ui_host}]"
        if host in ("0.0.0.0", "[::]"):
            host = socket.gethostname()
        port = server.get_port()
        self.url = f"http://{host}:{port}/"
        if o.token is not None:
            self.url += f"?websocket=ws://{host}:{port}/?token={o.token}"

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
        if messages:
            _log.info("replay finished: %d messages", len(messages))
        else:
            _log.warning(
                "%s holds no board-link messages (/board/link_tx): nothing to replay", self.options.replay
            )
        self.replay_done.set()

    def run(self, duration_s: float | None = None, stop: threading.Event | None = None) -> int:
        """Serve until ``duration_s`` passes, ``stop`` is set, or (headless) a replay ends.

        Returns:
            The exit status.
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
        return EXIT_OK

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
        if self.panel is not None:
            self.panel.stop()
            self.panel = None
        if self.server is not None:
            with contextlib.suppress(Exception), contextlib.redirect_stdout(io.StringIO()):
                self.server.stop()
            self.server = None
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
        if self.board is not None:
            with contextlib.suppress(Exception):
                self.board.stop()
            self.board = None


def _replace(obj: Any, **changes: Any) -> Any:
    import dataclasses

    return dataclasses.replace(obj, **changes)


def ned_to_scene(position: Any, attitude: Any) -> DronePose:
    """MAVLink LOCAL_POSITION_NED / ATTITUDE (NED world, FRD body) -> the scene's z-up (ENU, FLU) pose."""
    import numpy as np

    if position is not None:
        pos = (float(position.y_m), float(position.x_m), -float(position.z_m))
    else:
        from host.scene import DRONE_HEIGHT_M

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


# ---------------------------------------------------------------------- main


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of `spirob-host`; returns the exit status (0 ok, 1 runtime failure, 2 start-up error)."""
    ns = parse_or_exit(build_parser(), argv, hint=" (see --help)")
    # Shorter GIL hand-offs keep the panel's push loop and the link dispatcher responsive while the
    # viser server and numpy work run in other threads (default 5 ms).
    sys.setswitchinterval(0.001)
    logging.basicConfig(
        level=getattr(logging, ns.log_level.upper()), format="%(levelname)s %(name)s: %(message)s"
    )
    try:
        options = HostOptions.from_args(ns)
    except HostError as exc:
        error_line(PROG, str(exc))
        return EXIT_USAGE

    # Ctrl-C and SIGTERM are the normal end of a session: the run loop returns, everything closes in order.
    with stop_on_signals() as stop:
        app = HostApp(options)
        try:
            try:
                app.start()
            except HostError as exc:
                error_line(PROG, str(exc))
                return EXIT_USAGE
            source = f"replay {options.replay}" if options.replay else app.board_url
            print(f"{PROG}: board link {source}", flush=True)
            if app.url:
                print(f"{PROG}: panel at {app.url}", flush=True)
                if options.token is not None:
                    print(f"{PROG}: access token {options.token}", flush=True)
            if options.record is not None:
                print(f"{PROG}: recording to {options.record}", flush=True)
            return app.run(options.duration_s, stop)
        except KeyboardInterrupt:  # Ctrl-C outside the main thread's handler: a normal end too
            return EXIT_OK
        except Exception as exc:  # never a traceback for the user; the log has it at debug level
            _log.debug("fatal", exc_info=True)
            error_line(PROG, str(exc))
            return EXIT_FAILURE
        finally:
            app.close()


if __name__ == "__main__":
    sys.exit(main())
