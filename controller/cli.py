"""``python -m controller``: run the firmware against real hardware (or a fake bus) in real time.

Examples::

    python -m controller --can-interface socketcan --can-channel can0 --rc /dev/ttyUSB0 --link /dev/ttyGS0
    python -m controller --can-interface gs_usb --can-channel 0 --can-log run.blf --link /dev/ttyGS0
    python -m controller --can-interface fake --link socket://127.0.0.1:5760 --duration 10
    python -m controller --can-interface fake --listen socket://127.0.0.1:5760   # the host link over TCP

The CAN options are python-can's: ``--can-interface`` and ``--can-channel`` name the bus, ``--can-bitrate``
(1 Mbit/s unless told otherwise) is passed to every interface, and what the flags leave open comes from
python-can's configuration (``--can-config FILE``, else ``CAN_INTERFACE``/``CAN_CHANNEL``/``CAN_BITRATE``
and ``~/.canrc``), as ``can.util.load_config`` reads it. ``--can-interface fake`` is the in-process C610
trio. ``--can-log`` writes every frame through python-can's ``can.Logger`` (``.log`` candump, ``.blf``).
Without ``--rc`` the sticks come from the host's virtual RC frames over ``--link`` (or ``--listen``: the board
listens on TCP for one host at a time, as ``spirob-hil board --listen`` does). A missing or busy port is a
one-line error and exit status 2.

``--arms N`` (and ``--cables-per-arm C``) lays the board out as an array of N arms of C cables (C610 ids
1..N·C, at most 8; motor m drives cable (m-1) % C of arm (m-1) // C): every arm takes the same tensions,
so the sticks and the grasp close them together (docs/hardware.md, Arrays). The default is one
three-cable arm.

``--preflight`` runs the pre-arm checks instead (``controller.preflight``): 2 s of the 1 kHz loop with zero
current commanded, then one line per check (motors, RC, clock, lateness, host link), each failure with its
fix; exit status 1 when any check fails. A port that does not open is one of those failed checks.
"""

from __future__ import annotations

import argparse
import configparser
import json
import logging
import sys
from collections.abc import Sequence
from contextlib import ExitStack
from pathlib import Path
from typing import Any

from controller.cli_kit import (
    EXIT_FAILURE,
    EXIT_OK,
    EXIT_USAGE,
    Parser,
    add_version,
    error_line,
    parse_or_exit,
    positive_duration,
    stop_on_signals,
)
from controller.clock import RealTimeClock
from controller.config import CABLES_PER_ARM_MAX, FirmwareConfig
from controller.errors import ConfigError, PortError
from controller.fake_c610 import FakeC610Set
from controller.firmware import Firmware
from controller.motorbus import CAN_BITRATE, CanMotorBus, FakeMotorBus, MotorBus
from controller.param_file import apply_param_file
from controller.preflight import run_preflight
from controller.preflight_checks import WINDOW_US
from controller.rc import DbusSerialSource, LinkRcSource, RcSource
from controller.transport import SerialTransport, TcpServerTransport, Transport, parse_listen
from protocol.c610 import MOTORS_MAX

__all__ = ["PROG", "SCRIPT_PROG", "build_parser", "can_bus_config", "main", "parse_args", "script_main"]


PROG = "python -m controller"
"""The program name in messages; the ``spirob-firmware`` console script runs the same parser as itself."""
SCRIPT_PROG = "spirob-firmware"


def build_parser(prog: str = PROG) -> argparse.ArgumentParser:
    """The argument parser of ``python -m controller`` (``prog``: the name it reports itself by)."""
    p = Parser(
        prog=prog,
        description="SpiRob C-board firmware emulator: 1 kHz control of C610/M2006 motors (one three-cable "
        "arm, or an array of up to eight motors).",
    )
    add_version(p)
    can = p.add_argument_group("motor CAN bus (python-can's options)")
    can.add_argument(
        "--can-interface",
        metavar="NAME",
        help="python-can interface (socketcan, gs_usb, slcan, pcan, virtual, ...) or 'fake' (the "
        "in-process C610 trio); default: python-can's configuration",
    )
    can.add_argument("--can-channel", metavar="CH", help="python-can channel (can0, 0, /dev/ttyACM0, ...)")
    can.add_argument(
        "--can-bitrate",
        type=_bitrate,
        metavar="BPS",
        help=f"bit rate passed to every interface (default: the configuration's, else {CAN_BITRATE})",
    )
    can.add_argument(
        "--can-config",
        metavar="FILE",
        help="python-can configuration file ([default] section; default: ~/.canrc and friends)",
    )
    can.add_argument(
        "--can-log",
        metavar="FILE",
        help="log every CAN frame through python-can's logger: FILE.log (candump) or FILE.blf",
    )
    # The private ``--can interface:channel`` of earlier versions: refused with the flags that replace it.
    p.add_argument("--can", help=argparse.SUPPRESS)
    arms = p.add_argument_group("arms and cables (an array of SpiRobs on one board)")
    arms.add_argument(
        "--arms",
        type=_arm_count,
        metavar="N",
        help="arms driven together (1-8; default: the configuration's, one); motors = N x cables <= 8",
    )
    arms.add_argument(
        "--cables-per-arm",
        type=_cable_count,
        metavar="C",
        help="cables of each arm (1, 2 or 3; default: the configuration's, three); motor m drives cable "
        "(m-1) %% C of arm (m-1) // C",
    )
    p.add_argument("--rc", metavar="PORT", help="DR16 DBUS UART (100000 8E1), e.g. /dev/ttyUSB0")
    link = p.add_mutually_exclusive_group()
    link.add_argument("--link", metavar="PORT", help="host link: device path or pyserial URL (socket://...)")
    link.add_argument(
        "--listen",
        metavar="socket://HOST:PORT",
        help="host link over TCP: listen here for one host at a time (spirob-host --port socket://...); "
        "a loopback HOST unless --listen-any",
    )
    p.add_argument(
        "--listen-any",
        action="store_true",
        help="let --listen bind an address other machines reach (whoever reaches it can drive the arm)",
    )
    p.add_argument("--require-host", action="store_true", help="zero current when the host heartbeat stops")
    p.add_argument(
        "--duration", type=positive_duration, metavar="S", help="stop after S seconds (default: until Ctrl-C)"
    )
    p.add_argument("--config", metavar="JSON", help="FirmwareConfig fields as a JSON object")
    p.add_argument(
        "--params",
        metavar="FILE.toml",
        help="a firmware parameter file (flat keys, e.g. from spirob-hil tune), applied over --config",
    )
    p.add_argument("--no-fifo", action="store_true", help="do not ask for SCHED_FIFO")
    p.add_argument(
        "--preflight",
        action="store_true",
        help=f"pre-arm checks instead of running: {WINDOW_US / 1e6:.0f} s at zero current, one line per "
        "check (motors, RC, clock, lateness, host link), exit 1 if any fails",
    )
    p.add_argument("-v", "--verbose", action="store_true", help="log at INFO level")
    return p


def parse_args(argv: Sequence[str] | None = None, prog: str = PROG) -> argparse.Namespace:
    """Parse ``argv`` (default ``sys.argv[1:]``); a usage error is one line on stderr and exit status 2."""
    parser = build_parser(prog)
    args = parse_or_exit(parser, argv)
    if args.can is not None:
        error_line(
            parser.prog,
            "--can is gone: use --can-interface and --can-channel (python-can's names, e.g. "
            "--can-interface slcan --can-channel /dev/ttyACM0), or --can-interface fake",
        )
        raise SystemExit(EXIT_USAGE)
    if args.preflight and args.duration is not None:
        error_line(
            parser.prog, f"--duration does not apply to --preflight (it listens {WINDOW_US / 1e6:.0f} s)"
        )
        raise SystemExit(EXIT_USAGE)
    if args.rc is None and args.link is None and args.listen is None:
        error_line(
            parser.prog, "give --rc (DBUS UART) or --link / --listen (virtual RC from the host), or both"
        )
        raise SystemExit(EXIT_USAGE)
    if args.listen_any and args.listen is None:
        error_line(parser.prog, "--listen-any needs --listen")
        raise SystemExit(EXIT_USAGE)
    if args.listen is not None:
        try:
            parse_listen(args.listen, listen_any=args.listen_any)
        except ValueError as exc:
            error_line(parser.prog, str(exc))
            raise SystemExit(EXIT_USAGE) from None
    args.link_name = args.link or args.listen or ""
    return args


def _open_link(args: argparse.Namespace) -> Transport | None:
    """The host link ``--link`` or ``--listen`` names (None with neither).

    Raises:
        PortError: the port does not open, or the address cannot be listened on (in use, ...).
    """
    if args.listen is not None:
        host, port = parse_listen(args.listen, listen_any=args.listen_any)
        try:
            server = TcpServerTransport(host, port)
        except OSError as exc:
            raise PortError(f"cannot listen on {args.listen}: {exc.strerror or exc}") from None
        print(f"host link: listening on {server.url}", file=sys.stderr, flush=True)
        return server
    if args.link:
        return SerialTransport(args.link)
    return None


def _load_config(args: argparse.Namespace) -> FirmwareConfig:
    values: dict[str, object] = {}
    if args.config:
        try:
            with open(args.config, encoding="utf-8") as fh:
                loaded = json.load(fh)
        except (OSError, json.JSONDecodeError) as exc:
            raise ConfigError(f"cannot read config {args.config}: {exc}") from exc
        if not isinstance(loaded, dict):
            raise ConfigError(f"config {args.config} must hold a JSON object")
        values.update(loaded)
    config = FirmwareConfig.from_dict(values)
    if args.params:
        config = apply_param_file(args.params, config)
    if args.require_host:
        config = config.replaced(host_required=True)
    if args.arms is not None or args.cables_per_arm is not None:
        config = config.with_arms(args.arms or config.arm_count, args.cables_per_arm)
    return config


def _arm_count(text: str) -> int:
    """An ``--arms``: 1..8."""
    return _whole_in(text, 1, MOTORS_MAX)


def _cable_count(text: str) -> int:
    """A ``--cables-per-arm``: 1..3."""
    return _whole_in(text, 1, CABLES_PER_ARM_MAX)


def _whole_in(text: str, lo: int, hi: int) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a whole number {lo}..{hi}, got {text!r}") from None
    if not lo <= value <= hi:
        raise argparse.ArgumentTypeError(f"must be {lo}..{hi}, got {text!r}")
    return value


def _bitrate(text: str) -> int:
    """A ``--can-bitrate``: a whole number of bit/s > 0."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a whole number of bit/s, got {text!r}") from None
    if value <= 0:
        raise argparse.ArgumentTypeError(f"must be > 0, got {text!r}")
    return value


def can_bus_config(args: argparse.Namespace) -> dict[str, Any]:
    """The python-can bus configuration of a command line, as ``can.Bus`` would resolve it.

    The flags win; what they leave open comes from ``--can-config`` (or, without it, python-can's own
    sources: ``CAN_INTERFACE``/``CAN_CHANNEL``/``CAN_BITRATE``/``CAN_CONFIG`` and ``~/.canrc``); the bit
    rate falls back to the C610's 1 Mbit/s, never to python-can's 500 kbit/s.

    Raises:
        PortError: no interface or channel anywhere, an unknown interface, a config file that cannot
            be read or holds a bad value.
    """
    import can

    given: dict[str, Any] = {}
    if args.can_interface is not None:
        given["interface"] = args.can_interface
    if args.can_channel is not None:
        given["channel"] = args.can_channel
    if args.can_bitrate is not None:
        given["bitrate"] = args.can_bitrate
    if args.can_config is not None and not Path(args.can_config).is_file():
        raise PortError(f"cannot read CAN config {args.can_config}: no such file")
    try:
        config = dict(can.util.load_config(path=args.can_config, config=given))
    except can.CanInterfaceNotImplementedError as exc:
        # python-can reports a missing interface as the unknown interface "None": say what is missing.
        sources = (
            given,
            can.rc,
            can.util.load_environment_config(),
            can.util.load_file_config(args.can_config),
        )
        if not any(src.get("interface") or src.get("bustype") for src in sources):
            raise PortError(
                "no CAN interface: give --can-interface (or set it in python-can's config)"
            ) from exc
        raise PortError(f"CAN configuration: {exc}") from exc
    except (ValueError, TypeError, configparser.Error) as exc:
        raise PortError(f"CAN configuration: {exc}") from exc
    if config.get("channel") is None:
        raise PortError(f"no CAN channel for {config['interface']}: give --can-channel")
    if config.get("bitrate") is None:
        config["bitrate"] = CAN_BITRATE
    return config


def _open_bus(args: argparse.Namespace, config: FirmwareConfig) -> MotorBus:
    """The motor bus the flags name, with the configuration's motors (C610 ids 1..n)."""
    if args.can_interface == "fake":
        if args.can_log is not None:
            raise PortError("--can-log needs a python-can interface: the fake C610 set has no CAN frames")
        return FakeMotorBus(FakeC610Set.of(config.motor_count))
    options = can_bus_config(args)
    if options["bitrate"] != CAN_BITRATE:
        logging.getLogger(__name__).warning(
            "CAN bit rate %s: C610s talk at %s only", options["bitrate"], CAN_BITRATE
        )
    interface, channel = options.pop("interface"), options.pop("channel")
    # Resolved above already: python-can must not merge its config files in a second time.
    return CanMotorBus(
        str(channel),
        str(interface),
        log_file=args.can_log,
        motor_count=config.motor_count,
        ignore_config=True,
        **options,
    )


def main(argv: Sequence[str] | None = None, prog: str = PROG) -> int:
    """Run the firmware until ``--duration`` elapses or SIGINT/SIGTERM; return the exit status."""
    args = parse_args(argv, prog)
    logging.basicConfig(
        level=logging.INFO if args.verbose else logging.WARNING, format="%(levelname)s %(name)s: %(message)s"
    )
    try:
        config = _load_config(args)
        if args.preflight:
            return _preflight(args, config)
        with ExitStack() as stack:
            bus = _open_bus(args, config)
            stack.callback(bus.shutdown)
            link = _open_link(args)
            if link is not None:
                stack.callback(link.close)
            rc: RcSource = DbusSerialSource(args.rc) if args.rc else LinkRcSource()
            stack.callback(rc.close)
            firmware = Firmware(config, bus, rc, link)
            # Ctrl-C and SIGTERM end the loop between two ticks; the ExitStack then closes bus and ports.
            stop = stack.enter_context(stop_on_signals())
            duration_us = None if args.duration is None else int(args.duration * 1e6)
            firmware.run(RealTimeClock(fifo=not args.no_fifo), duration_us=duration_us, stop=stop)
            ctl = firmware.scheduler["control"]
            print(
                f"stopped: phase {firmware.phase.name}, mode {firmware.mode.name}, "
                f"control runs {ctl.runs}, late {ctl.late}, max lateness {ctl.lateness_max_us} us",
                file=sys.stderr,
            )
    except (PortError, ConfigError) as exc:
        error_line(None, str(exc))
        return EXIT_USAGE
    return EXIT_OK


def _preflight(args: argparse.Namespace, config: FirmwareConfig) -> int:
    """``--preflight``: open what opens (a port that does not is a failed check), check, print, judge."""
    with ExitStack() as stack:
        bus: MotorBus | None = None
        can_error = rc_error = link_error = None
        try:
            bus = _open_bus(args, config)
            stack.callback(bus.shutdown)
        except PortError as exc:
            can_error = str(exc)
        link: Transport | None = None
        try:
            link = _open_link(args)
        except PortError as exc:
            link_error = str(exc)
        if link is not None:
            stack.callback(link.close)
        rc: RcSource | None = None
        if args.rc:
            try:
                rc = DbusSerialSource(args.rc)
            except PortError as exc:
                rc_error = str(exc)
            rc_name = args.rc
        else:
            rc = LinkRcSource() if link is not None else None
            rc_error = None if link is not None else f"no RC: the link {args.link_name} did not open"
            rc_name = f"the host (VirtualRc on {args.link_name})"
        if rc is not None:
            stack.callback(rc.close)
        stop = stack.enter_context(stop_on_signals())
        report = run_preflight(
            RealTimeClock(fifo=not args.no_fifo),
            bus,
            rc,
            link,
            config=config,
            fifo_wanted=not args.no_fifo,
            can_error=can_error,
            rc_error=rc_error,
            link_error=link_error,
            rc_name=rc_name,
            link_name=args.link_name,
            stop=stop,
        )
    for line in report.lines():
        print(line)
    return EXIT_OK if report.passed else EXIT_FAILURE


def script_main() -> int:
    """Entry point of the ``spirob-firmware`` console script: :func:`main` under that name."""
    return main(prog=SCRIPT_PROG)
