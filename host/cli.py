"""`spirob-host`: the board link, the browser teleop panel, recording, replay and the drone link.

With no arguments it starts the virtual board (``hil.board``, in its own process) and serves the panel
on http://127.0.0.1:8080. ``--port`` connects to a real board (``/dev/ttyACM0``) or any pyserial URL
instead. Start-up errors (wrong port, busy port, UI port taken, bad flags) print one line and exit 2;
a board that vanishes mid-run is retried until it comes back, with the panel showing "disconnected".

Exit status: 0 normal end (``--duration`` elapsed, Ctrl-C, replay finished headless, a
``--virtual-rc-script`` that reached its every step), 1 runtime failure, a ``--virtual-rc`` or
``--virtual-rc-script`` run that ended latched in a failsafe, saw a fault or got no telemetry, or a radio
script that did not reach a step, 2 start-up or usage error (a ``--replay`` file the bounded reader
refuses too, even mid-replay; a radio script that is not valid). A summary of the run
(time per mode and phase, failsafes, faults, RC gaps) is printed at exit.
"""

from __future__ import annotations

import logging
import sys
from collections.abc import Sequence

from controller.cli_kit import (
    EXIT_FAILURE,
    EXIT_OK,
    EXIT_USAGE,
    add_version,
    error_line,
    parse_or_exit,
    stop_on_signals,
)
from host.app import HostApp
from host.errors import HostError
from host.object_spec import describe_object
from host.options import PROG, HostOptions, build_parser
from host.virtual_rc import ScriptState

__all__ = ["main"]

_log = logging.getLogger("spirob-host")


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of `spirob-host`; returns the exit status (0 ok, 1 runtime failure, 2 start-up error)."""
    ns = parse_or_exit(add_version(build_parser()), argv, hint=" (see --help)")
    # Shorter GIL hand-offs keep the panel's push loop and the link dispatcher responsive while the
    # viser server and numpy work run in other threads (default 5 ms).
    sys.setswitchinterval(0.001)
    logging.basicConfig(
        level=getattr(logging, ns.log_level.upper()),
        format="%(asctime)s.%(msecs)03d %(levelname)s %(name)s: %(message)s",
        datefmt="%H:%M:%S",
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
            for n, spec in enumerate(options.objects, start=1):
                print(f"{PROG}: scene object{n} {describe_object(spec)}", flush=True)
            if app.url:
                print(f"{PROG}: panel at {app.url}", flush=True)
                if options.token is None:
                    print(
                        f"{PROG}: --no-token: any program or user on this machine can drive the arm "
                        "through the panel (pages from other origins are still refused)",
                        flush=True,
                    )
            if options.record is not None:
                print(f"{PROG}: recording to {options.record}", flush=True)
            if app.foxglove is not None:
                print(f"{PROG}: Foxglove live at {app.foxglove.url}", flush=True)
            status = app.run(options.duration_s, stop)
            if app.replay is not None and app.replay.error is not None:
                error_line(PROG, f"--replay {options.replay}: {app.replay.error}")
                return status
            report = app.report
            if report is not None:
                for line in report.lines():
                    print(f"{PROG}: {line}", flush=True)
                failure = report.failure()
                script = app.script
                if script is not None and script.run.state is not ScriptState.DONE:
                    pass  # the script said why in its own error line
                elif status == EXIT_FAILURE and failure is not None:
                    flag = "--virtual-rc-script" if script is not None else "--virtual-rc"
                    error_line(PROG, f"{flag} run failed: {failure}")
            return status
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
