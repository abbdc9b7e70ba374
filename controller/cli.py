"""``python -m controller``: run the firmware against real hardware (or a fake bus) in real time.

Examples::

    python -m controller --can slcan:///dev/ttyACM0 --rc /dev/ttyUSB0 --link /dev/ttyGS0
    python -m controller --can fake --link socket://127.0.0.1:5760 --duration 10

``--can`` takes any python-can ``interface:channel`` (``slcan:///dev/ttyACM0``, ``socketcan:can0``,
``virtual:bus0``) or ``fake`` (the in-process C610 trio). Without ``--rc`` the sticks come from the host's
virtual RC frames over ``--link``. A missing or busy port is a one-line error and exit status 2.
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
from collections.abc import Sequence
from contextlib import ExitStack

from controller.cli_kit import (
    EXIT_OK,
    EXIT_USAGE,
    Parser,
    error_line,
    parse_or_exit,
    positive_duration,
    stop_on_signals,
)
from controller.clock import RealTimeClock
from controller.config import FirmwareConfig
from controller.errors import ConfigError, PortError
from controller.firmware import Firmware
from controller.motorbus import CanMotorBus, FakeMotorBus, MotorBus, parse_can_spec
from controller.rc import DbusSerialSource, LinkRcSource, RcSource
from controller.transport import SerialTransport, Transport

__all__ = ["build_parser", "main", "parse_args"]


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``python -m controller``."""
    p = Parser(
        prog="python -m controller",
        description="SpiRob C-board firmware emulator: 1 kHz control of three C610/M2006 motors.",
    )
    p.add_argument(
        "--can",
        required=True,
        metavar="SPEC",
        help="motor CAN bus: python-can interface:channel (slcan:///dev/ttyACM0, socketcan:can0, "
        "virtual:bus0) or 'fake' (in-process C610 trio)",
    )
    p.add_argument("--rc", metavar="PORT", help="DR16 DBUS UART (100000 8E1), e.g. /dev/ttyUSB0")
    p.add_argument("--link", metavar="PORT", help="host link: device path or pyserial URL (socket://...)")
    p.add_argument("--require-host", action="store_true", help="zero current when the host heartbeat stops")
    p.add_argument(
        "--duration", type=positive_duration, metavar="S", help="stop after S seconds (default: until Ctrl-C)"
    )
    p.add_argument("--config", metavar="JSON", help="FirmwareConfig fields as a JSON object")
    p.add_argument("--no-fifo", action="store_true", help="do not ask for SCHED_FIFO")
    p.add_argument("-v", "--verbose", action="store_true", help="log at INFO level")
    return p


def parse_args(argv: Sequence[str] | None = None) -> argparse.Namespace:
    """Parse ``argv`` (default ``sys.argv[1:]``); a usage error is one line on stderr and exit status 2."""
    parser = build_parser()
    args = parse_or_exit(parser, argv)
    if args.rc is None and args.link is None:
        error_line(parser.prog, "give --rc (DBUS UART) or --link (virtual RC from the host), or both")
        raise SystemExit(EXIT_USAGE)
    return args


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
    if args.require_host:
        values["host_required"] = True
    return FirmwareConfig.from_dict(values)


def _open_bus(spec: str) -> MotorBus:
    if spec == "fake":
        return FakeMotorBus()
    try:
        interface, channel = parse_can_spec(spec)
    except ValueError as exc:
        raise PortError(str(exc)) from exc
    return CanMotorBus(channel, interface)


def main(argv: Sequence[str] | None = None) -> int:
    """Run the firmware until ``--duration`` elapses or SIGINT/SIGTERM; return the exit status."""
    args = parse_args(argv)
    logging.basicConfig(
        level=logging.INFO if args.verbose else logging.WARNING, format="%(levelname)s %(name)s: %(message)s"
    )
    try:
        config = _load_config(args)
        with ExitStack() as stack:
            bus = _open_bus(args.can)
            stack.callback(bus.shutdown)
            link: Transport | None = None
            if args.link:
                link = SerialTransport(args.link)
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
