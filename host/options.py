"""`spirob-host`'s argument parser and its validated options (kept apart from the app and ``main``).

Also the start-up checks that only read the options: the signing timestamp file, loopback
addresses and a free panel port.
"""

from __future__ import annotations

import argparse
import errno
import os
import socket
import stat
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Final

from controller.cli_kit import Parser, port_number, positive_duration
from controller.transport import is_loopback_host
from host.errors import HostError
from host.gamepad import DEFAULT_MAPPING, GamepadMapping, format_mapping, parse_mapping
from host.object_spec import DEFAULT_OBJECT, ObjectSpec, describe_object, parse_object
from host.panel.arbiter import new_token
from host.plant_model import ARMS_MAX
from host.virtual_rc import RadioScript, ScriptError
from protocol.dbus import Lever

if TYPE_CHECKING:
    from host.drone.servo import ServoFollowConfig

__all__ = [
    "FOXGLOVE_PORT",
    "PROG",
    "VIRTUAL_RC_LEVERS",
    "HostOptions",
    "build_parser",
    "check_board_url",
    "check_mavlink_url",
    "check_signing_timestamp_writable",
    "check_ui_port_free",
    "signing_timestamp_path",
]

PROG = "spirob-host"

VIRTUAL_RC_LEVERS = {"safe": Lever.DOWN, "manual": Lever.MIDDLE, "grasp": Lever.UP}
"""``--virtual-rc`` choices: the right lever position each one ends in (DOWN first, always)."""

FOXGLOVE_PORT: Final = 8765
"""Foxglove's default WebSocket port (``--foxglove`` without a port)."""


def _mav_id(text: str) -> int:
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not an id: {text!r}") from None
    if not 1 <= v <= 255:
        raise argparse.ArgumentTypeError(f"MAVLink ids are 1..255: {text!r}")
    return v


def _mav_compid(text: str) -> int:
    v = _mav_id(text)
    if v < 7:  # MAVLink reserves 0..6 (broadcast, the autopilot, payload slots)
        raise argparse.ArgumentTypeError(f"component ids 0..6 are reserved by MAVLink; use 7..255: {text!r}")
    return v


def _follow_servo(text: str) -> ServoFollowConfig:
    # Imported here: host.drone.servo loads pymavlink, which a run without --mavlink never needs.
    from host.drone.servo import parse_follow_servo

    return parse_follow_servo(text)


def _preset(text: str) -> str:
    # The spirob-hil commands' own check (a name, or a fitted model file that reads), loaded only when
    # the flag is given: it reads the file.
    from hil.cli.design import preset_arg  # type: ignore[import-not-found,unused-ignore]

    return str(preset_arg(text))


def _arms(text: str) -> int:
    try:
        arms = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a whole number of arms (1-{ARMS_MAX})") from None
    if not 1 <= arms <= ARMS_MAX:
        raise argparse.ArgumentTypeError(
            f"{arms} arms: a C-board drives 1-{ARMS_MAX} (one motor each at least)"
        )
    return arms


def _excite_profile(text: str) -> str:
    from hil.identify.excitation import profile  # type: ignore[import-not-found,unused-ignore]

    try:
        profile(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    return text


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
        "--virtual-rc-script",
        type=Path,
        metavar="FILE",
        help="play a timeline of lever and stick positions (TOML [[step]] tables, docs/host.md) on the "
        "virtual radio; the run ends with it: exit 0 only if every step was reached, e.g. "
        "examples/06_scripted_grasp.toml",
    )
    src.add_argument(
        "--no-shadow",
        action="store_true",
        help="with --port: do not run the shadow plant (the arm's shape from the measured motor currents "
        "of a board that sends no poses)",
    )
    src.add_argument(
        "--object",
        action="append",
        default=[],
        metavar="SPEC",
        help="virtual board only, repeatable: a fixed object in the scene, placed from the arm's base "
        "(x right, y forward, z up), lengths with units: SHAPE:d=DIAMETER,z=HEIGHT[,x=..][,y=..][,len=..]"
        "[,axis=x|y|z], SHAPE cylinder or capsule, e.g. cylinder:d=20mm,x=40mm,z=-110mm. "
        f"Default: one {describe_object(DEFAULT_OBJECT)}, a pole the grasp strategy wraps",
    )
    src.add_argument("--no-object", action="store_true", help="virtual board only: an empty scene")
    src.add_argument(
        "--arms",
        type=_arms,
        metavar="N",
        help=f"virtual board only: an array of N arms (1-{ARMS_MAX}) on a ring under the drone, as many "
        "cables per arm as fit the board's eight motors, at most 3 (1-2 arms: 3, 3-4: 2, 5-8: 1); one stick "
        "and the grasp drive them all. A real board's layout comes from the board. Default: one arm",
    )
    src.add_argument(
        "--preset",
        type=_preset,
        metavar="NAME|FILE.toml",
        help="the plant model of the virtual board (with --port: of the shadow plant): a preset's name "
        "(default prototype; docs/plant.md lists them) or a model file fitted by spirob-hil identify",
    )
    src.add_argument(
        "--params",
        type=Path,
        metavar="FILE.toml",
        help="a firmware parameter file (spirob-hil tune writes one): its run-time values are sent to the "
        "board as parameter sets each time the link comes up (SAFE-only ones while disarmed)",
    )
    src.add_argument(
        "--gamepad",
        metavar="DEVICE",
        help="a Linux joystick device (/dev/input/js0) as the virtual radio: right stick ch0/ch1, left "
        "stick ch2/ch3, D-pad up/down steps the right lever, Y/A the left lever, Start asks for control "
        "(Xbox layout); a browser tab that asks for control gets it",
    )
    src.add_argument(
        "--gamepad-map",
        metavar="MAP",
        help="with --gamepad: change inputs of the mapping, e.g. ch1=-a4,right=b5/b4 (chN=[-]aK axis K, "
        f"levers UP/DOWN inputs aK, -aK or bK); default {format_mapping(DEFAULT_MAPPING)}",
    )
    ui = p.add_argument_group("panel")
    ui.add_argument("--ui-host", default="127.0.0.1", help="address the panel binds (default 127.0.0.1)")
    ui.add_argument("--ui-port", type=port_number, default=8080, help="panel port (default 8080; 0 = any)")
    ui.add_argument("--headless", action="store_true", help="no panel")
    ui.add_argument(
        "--token",
        help="the panel's access token (default: a fresh random one, in the URL printed at start)",
    )
    ui.add_argument(
        "--no-token",
        action="store_true",
        help="loopback --ui-host only: no access token; any program on this machine may then drive "
        "the arm through the panel (pages from other origins are still refused)",
    )
    run = p.add_argument_group("run")
    run.add_argument("--duration", type=positive_duration, metavar="S", help="exit after S seconds")
    run.add_argument("--record", type=Path, metavar="FILE", help="record the board link to an MCAP file")
    run.add_argument(
        "--replay", type=Path, metavar="FILE", help="replay a recording (no board) through the same listeners"
    )
    run.add_argument(
        "--replay-speed", type=positive_duration, metavar="X", help="with --replay: speed factor (default 1)"
    )
    run.add_argument(
        "--excite",
        type=_excite_profile,
        nargs="?",
        const="standard",
        metavar="PROFILE",
        help="play an excitation profile on the board in DIRECT mode for identification (standard, 60 s, "
        "the default; quick, 14.5 s): it starts when the right lever goes MIDDLE, stops when it goes DOWN, "
        "and the run ends with it",
    )
    run.add_argument(
        "--foxglove",
        type=port_number,
        nargs="?",
        const=FOXGLOVE_PORT,
        metavar="PORT",
        help=f"serve the run live to Foxglove on ws://127.0.0.1:PORT (default {FOXGLOVE_PORT}; 0 = any)",
    )
    run.add_argument(
        "--foxglove-origin",
        action="append",
        default=[],
        metavar="ORIGIN",
        help="a browser origin --foxglove lets in besides Foxglove's desktop app (no Origin), e.g. "
        "https://app.foxglove.dev for Foxglove's web app (repeatable); others are refused",
    )
    mav = p.add_argument_group("drone link (MAVLink)")
    mav.add_argument(
        "--mavlink", metavar="URL", help="pymavlink connection string, e.g. udpout:127.0.0.1:14550"
    )
    mav.add_argument("--mav-sysid", type=_mav_id, default=1, help="the drone's system id (default 1)")
    mav.add_argument(
        "--mav-compid", type=_mav_compid, default=25, help="the arm's component id, 7..255 (default 25)"
    )
    mav.add_argument(
        "--follow-servo",
        type=_follow_servo,
        metavar="N[,grab=PWM][,release=PWM][,stale_ms=MS]",
        help="follow the autopilot's gripper output N (SERVO_OUTPUT_RAW) with grab/release on the board "
        "(default PWM grab=1900 release=1100, stale after 1000 ms)",
    )
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


def _foxglove_origins(ns: argparse.Namespace) -> tuple[str, ...]:
    """``--foxglove-origin`` values checked and normalised (lower-case, no trailing slash).

    Raises:
        HostError: without ``--foxglove``, or a value that is not ``scheme://host[:port]``.
    """
    if not ns.foxglove_origin:
        return ()
    if ns.foxglove is None:
        raise HostError("--foxglove-origin needs --foxglove")
    from host.http_headers import normalise_origin

    try:
        return tuple(dict.fromkeys(normalise_origin(o) for o in ns.foxglove_origin))
    except ValueError as exc:
        raise HostError(f"--foxglove-origin: {exc}") from None


@dataclass(frozen=True, slots=True)
class HostOptions:
    """Validated options of one `spirob-host` run (what :func:`build_parser` produced, checked).

    Attributes:
        port: board link URL; None = start the virtual board.
        ui: serve the panel.
        ui_host: panel bind address.
        ui_port: panel port (0 = any free port).
        token: access token of the panel: by default a fresh random one, as on the command line (a panel
            built in code is as closed as one started from it); None: no token (headless, or
            ``--no-token`` on loopback).
        duration_s: stop after this long (None = until interrupted).
        record: MCAP file to write.
        replay: MCAP file to replay instead of a board.
        replay_speed: replay speed factor.
        foxglove_port: serve the Foxglove channels live on 127.0.0.1 at this port (None = not).
        foxglove_origins: browser origins the live server lets in besides none (``--foxglove-origin``).
        virtual_rc: right lever the command line drives the virtual radio to (None = it does not).
        virtual_rc_script: the radio script the command line plays (``--virtual-rc-script``; None: none).
        mavlink: MAVLink connection string.
        mav_sysid: drone system id.
        mav_compid: our component id.
        mav_signing_key: signing key file.
        mav_signing_timestamp: file persisting the signing timestamp (None with a key:
            ``<key file>.timestamp``).
        follow_servo: the autopilot output followed as the gripper (None = off).
        shadow: with ``port``, run the shadow plant when the board sends no poses.
        arms: arms of the virtual board (``host.plant_model.array_cables`` cables each); 1: the one
            3-cable arm.
        objects: fixed objects added to the virtual board's scene (the command line's default:
            ``host.object_spec.DEFAULT_OBJECT``; ``--no-object``: none).
        gamepad: joystick device driving the virtual radio (None: none).
        gamepad_map: its mapping.
        preset: the plant model (``hil.sim.presets.resolve``: a preset's name or a fitted model file) of
            the virtual board, or of the shadow plant with ``port``; None: the default prototype.
        excite: the excitation profile to play (``host.excite``); None: none.
        params: ``--params``: wire name -> value, sent as parameter sets at every link-up
            (``host.param_push``).
    """

    port: str | None = None
    ui: bool = True
    ui_host: str = "127.0.0.1"
    ui_port: int = 8080
    token: str | None = field(default_factory=new_token)
    duration_s: float | None = None
    record: Path | None = None
    replay: Path | None = None
    replay_speed: float = 1.0
    foxglove_port: int | None = None
    foxglove_origins: tuple[str, ...] = ()
    virtual_rc: Lever | None = None
    virtual_rc_script: RadioScript | None = None
    mavlink: str | None = None
    mav_sysid: int = 1
    mav_compid: int = 25
    mav_signing_key: Path | None = None
    mav_signing_timestamp: Path | None = None
    follow_servo: ServoFollowConfig | None = None
    shadow: bool = True
    arms: int = 1
    objects: tuple[ObjectSpec, ...] = ()
    gamepad: str | None = None
    gamepad_map: GamepadMapping = DEFAULT_MAPPING
    preset: str | None = None
    excite: str | None = None
    params: tuple[tuple[str, float], ...] = ()

    @classmethod
    def from_args(cls, ns: argparse.Namespace) -> HostOptions:
        """Check the combination of flags.

        Raises:
            HostError: flags that cannot go together, or a missing file.
        """
        if ns.arms is not None and (ns.port is not None or ns.replay is not None):
            flag = "--port" if ns.port is not None else "--replay"
            raise HostError(
                f"--arms is for the virtual board, not with {flag}: a board's layout comes from the board "
                "(its ArmsTelemetry)"
            )
        if ns.replay_speed is not None and ns.replay is None:
            raise HostError("--replay-speed needs --replay")
        if ns.replay is not None:
            if ns.port is not None:
                raise HostError("--replay and --port cannot be combined (a replay has no board)")
            if ns.record is not None:
                raise HostError("--replay and --record cannot be combined")
            if ns.virtual_rc is not None:
                raise HostError("--virtual-rc needs a board; it cannot be used with --replay")
            if ns.virtual_rc_script is not None:
                raise HostError("--virtual-rc-script needs a board; it cannot be used with --replay")
            if ns.gamepad is not None:
                raise HostError("--gamepad needs a board; it cannot be used with --replay")
            if ns.excite is not None:
                raise HostError("--excite needs a board; it cannot be used with --replay")
            if ns.preset is not None:
                raise HostError("--preset is a model of the virtual board or the shadow plant: no --replay")
            if ns.params is not None:
                raise HostError("--params needs a board; it cannot be used with --replay")
            if not ns.replay.is_file():
                raise HostError(f"no such recording: {ns.replay}")
            from hil.mcap_bounded import RecordingError
            from hil.recording import is_mcap, read_metadata

            if not is_mcap(ns.replay):
                raise HostError(f"{ns.replay} is not an MCAP recording")
            try:  # the top-level records through the bounded reader (a chunk is checked as it is played)
                read_metadata(ns.replay)
            except RecordingError as exc:
                raise HostError(f"--replay {ns.replay}: {exc}") from exc
        if ns.port is not None:
            check_board_url(ns.port)
        _check_excite_and_preset(ns)
        script = _script_from_args(ns)
        objects = _objects_from_args(ns)
        gamepad_map = _gamepad_from_args(ns)
        if ns.mavlink is not None:
            check_mavlink_url(ns.mavlink)
        if ns.record is not None and not ns.record.parent.exists():
            raise HostError(f"cannot record to {ns.record}: directory {ns.record.parent} does not exist")
        if ns.mav_signing_key is not None and ns.mavlink is None:
            raise HostError("--mav-signing-key needs --mavlink")
        if ns.mav_signing_key is not None and not ns.mav_signing_key.is_file():
            raise HostError(f"no such signing key file: {ns.mav_signing_key}")
        if ns.follow_servo is not None and ns.mavlink is None:
            raise HostError("--follow-servo needs --mavlink")
        if ns.mav_signing_timestamp is not None and ns.mav_signing_key is None:
            raise HostError("--mav-signing-timestamp needs --mav-signing-key")
        token: str | None = None
        if ns.no_token:
            if ns.token is not None:
                raise HostError("--no-token and --token cannot be combined")
            if not is_loopback_host(ns.ui_host):
                raise HostError(
                    f"--no-token is for a loopback --ui-host only ({ns.ui_host} is reachable from elsewhere)"
                )
        elif not ns.headless:
            # Every bind, loopback too: any program or web page on this machine could drive the arm.
            token = ns.token or new_token()
        return cls(
            port=ns.port,
            ui=not ns.headless,
            ui_host=ns.ui_host,
            ui_port=ns.ui_port,
            token=token,
            duration_s=ns.duration,
            record=ns.record,
            replay=ns.replay,
            replay_speed=1.0 if ns.replay_speed is None else ns.replay_speed,
            foxglove_port=ns.foxglove,
            foxglove_origins=_foxglove_origins(ns),
            virtual_rc=VIRTUAL_RC_LEVERS[ns.virtual_rc] if ns.virtual_rc else None,
            virtual_rc_script=script,
            mavlink=ns.mavlink,
            mav_sysid=ns.mav_sysid,
            mav_compid=ns.mav_compid,
            mav_signing_key=ns.mav_signing_key,
            mav_signing_timestamp=ns.mav_signing_timestamp,
            follow_servo=ns.follow_servo,
            shadow=not ns.no_shadow,
            arms=1 if ns.arms is None else ns.arms,
            objects=objects,
            gamepad=ns.gamepad,
            gamepad_map=gamepad_map,
            preset=ns.preset,
            excite=ns.excite,
            params=_params_from_args(ns),
        )


def _params_from_args(ns: argparse.Namespace) -> tuple[tuple[str, float], ...]:
    """``--params FILE``: its run-time values by wire name (``host.param_push.wire_values``)."""
    if ns.params is None:
        return ()
    from host.param_push import wire_values

    return tuple(wire_values(ns.params).items())


def _check_excite_and_preset(ns: argparse.Namespace) -> None:
    """``--excite`` needs a lever that can go MIDDLE; ``--preset`` with ``--port`` a shadow plant to model.

    Raises:
        HostError: a combination that cannot work.
    """
    lever = VIRTUAL_RC_LEVERS.get(ns.virtual_rc or "")
    if ns.excite is not None and lever is not None and lever != Lever.MIDDLE:
        raise HostError(
            f"--excite runs with the right lever MIDDLE: --virtual-rc {ns.virtual_rc} never puts it there "
            "(use --virtual-rc manual, or the pilot's radio)"
        )
    if ns.preset is not None and ns.port is not None and ns.no_shadow:
        raise HostError("--preset with --port is the shadow plant's model; it cannot go with --no-shadow")


def _script_from_args(ns: argparse.Namespace) -> RadioScript | None:
    """``--virtual-rc-script``: the script read and checked, alone on the radio.

    Raises:
        HostError: another driver of the radio, ``--excite``, or a script that is not valid (one line).
    """
    path = ns.virtual_rc_script
    if path is None:
        return None
    for flag, given in (("--virtual-rc", ns.virtual_rc), ("--gamepad", ns.gamepad), ("--excite", ns.excite)):
        if given is not None:
            raise HostError(f"--virtual-rc-script and {flag} cannot be combined (both drive the board)")
    try:
        return RadioScript.load(path)
    except ScriptError as exc:
        raise HostError(f"--virtual-rc-script {path}: {exc}") from None


def _gamepad_from_args(ns: argparse.Namespace) -> GamepadMapping:
    """Check ``--gamepad`` / ``--gamepad-map``; the mapping to use.

    Raises:
        HostError: a combination that cannot work, a device that cannot be read, a malformed mapping.
    """
    if ns.gamepad is None:
        if ns.gamepad_map is not None:
            raise HostError("--gamepad-map needs --gamepad")
        return DEFAULT_MAPPING
    if ns.virtual_rc is not None:
        raise HostError("--gamepad and --virtual-rc cannot be combined (both drive the virtual radio)")
    mapping = DEFAULT_MAPPING
    if ns.gamepad_map is not None:
        try:
            mapping = parse_mapping(ns.gamepad_map)
        except ValueError as exc:
            raise HostError(f"--gamepad-map {ns.gamepad_map}: {exc}") from None
    try:
        st = os.stat(ns.gamepad)
    except FileNotFoundError:
        raise HostError(f"--gamepad {ns.gamepad}: no such device") from None
    except OSError as exc:
        raise HostError(f"--gamepad {ns.gamepad}: {exc.strerror or exc}") from None
    # A joystick is a character device of the input major (13); a FIFO delivers recorded events. Anything
    # else (a file, /dev/null) would read as a pad unplugged over and over.
    joystick = stat.S_ISCHR(st.st_mode) and os.major(st.st_rdev) == _INPUT_MAJOR
    if not (joystick or stat.S_ISFIFO(st.st_mode)):
        raise HostError(f"--gamepad {ns.gamepad}: not a joystick device (/dev/input/jsN)")
    if not os.access(ns.gamepad, os.R_OK):
        raise HostError(f"--gamepad {ns.gamepad}: not readable (is your user in the 'input' group?)")
    return mapping


_INPUT_MAJOR = 13
"""Linux's input subsystem's device major number (``/dev/input/js*``, ``event*``)."""


def _objects_from_args(ns: argparse.Namespace) -> tuple[ObjectSpec, ...]:
    """``--object`` / ``--no-object``: the virtual board's objects (the default demo's one if neither, for one
    arm).

    Raises:
        HostError: a malformed spec, or objects asked of a board that has no scene to add them to.
    """
    if ns.no_object and ns.object:
        raise HostError("--object and --no-object cannot be combined")
    if ns.port is not None or ns.replay is not None:
        if ns.object or ns.no_object:
            flag = "--object" if ns.object else "--no-object"
            raise HostError(f"{flag} is for the virtual board (no --port, no --replay)")
        return ()
    if ns.no_object:
        return ()
    if not ns.object:
        # The one arm's pole stands where an array's first arm hangs (6 cm from the axis): an array
        # starts with an empty scene unless --object places something.
        return () if ns.arms not in (None, 1) else (DEFAULT_OBJECT,)
    specs = []
    for text in ns.object:
        try:
            specs.append(parse_object(text))
        except ValueError as exc:
            raise HostError(f"--object {text}: {exc}") from None
    return tuple(specs)


def signing_timestamp_path(options: HostOptions) -> Path | None:
    """Where the MAVLink signing timestamp persists (None without a signing key).

    ``--mav-signing-timestamp`` if given, else ``<key file>.timestamp``, the default of
    ``host.drone.link.DroneLinkConfig.with_signing_key_file``; passed explicitly so the check at start
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


_MAV_HOST_PORT = ("tcp", "tcpin", "udp", "udpin", "udpout", "udpbcast", "wsserver", "mcast")
"""pymavlink connection types followed by ``HOST:PORT``."""
_MAV_OTHER = ("uds", "unix", "ws", "wss")
"""pymavlink connection types followed by a path or a URL."""


def _check_host_port(flag: str, url: str, rest: str, form: str) -> None:
    host, sep, port_text = rest.rpartition(":")
    if not sep or not host or not port_text.isdigit():
        raise HostError(f"{flag} {url}: expected {form}")
    if not 1 <= int(port_text) <= 65535:
        raise HostError(f"{flag} {url}: port {port_text} is out of range 1..65535")


def check_board_url(url: str) -> None:
    """Check a ``--port`` ``socket://`` URL's form before anything starts (pyserial's own errors are
    not one readable line). Other URLs and device paths are checked when opened.

    Raises:
        HostError: a malformed ``socket://`` URL.
    """
    if url.startswith("socket://"):
        rest = url[len("socket://") :].split("?", 1)[0].rstrip("/")
        _check_host_port("--port", url, rest, "socket://HOST:PORT")


def check_mavlink_url(url: str) -> None:
    """Check a ``--mavlink`` connection string's form before the board starts.

    Network types (``udpout:``, ``udpin:``, ``tcp:`` ...) need ``HOST:PORT`` with a port in 1..65535;
    an unknown ``type:`` prefix is refused; anything else is a serial device, opened at start.

    Raises:
        HostError: one line saying what is wrong.
    """
    kind, sep, rest = url.partition(":")
    if not sep or "/" in kind or "\\" in kind or len(kind) == 1:  # a device path (or a drive letter)
        return
    if kind.lower() in _MAV_HOST_PORT:
        _check_host_port("--mavlink", url, rest, f"{kind}:HOST:PORT")
    elif kind.lower() not in _MAV_OTHER:
        known = ", ".join(f"{k}:" for k in (*_MAV_HOST_PORT, *_MAV_OTHER))
        raise HostError(f"--mavlink {url}: unknown connection type {kind!r} ({known} or a serial device)")


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
