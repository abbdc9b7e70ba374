"""03 - The host side in code: board client, listeners, virtual radio, the teleop panel.

Run: ``.venv/bin/python examples/03_host_panel.py [--port URL] [--ui]`` (about ten seconds). What it shows:

1. :class:`~host.cli.HostApp` (what ``spirob-host`` runs) starting the virtual board in its own process
   (or connecting to ``--port``), with the UI model as one listener of the board link and a listener of
   our own beside it (the recorder and the MAVLink bridge are listeners the same way);
2. control ownership: the program takes control as the command-line client, drives the virtual radio
   through the start-up gate (right lever DOWN, then MIDDLE = MANUAL) and moves the curl stick; the
   board answers with higher tension targets and currents;
3. E-stop: zero current, latched;
4. with ``--ui``, the same state in the browser panel (http://127.0.0.1:8080) while it runs.
"""

from __future__ import annotations

import argparse
import time

from host.cli import HostApp, HostOptions
from host.model import CLI_CLIENT
from protocol.dbus import Lever
from protocol.messages import CommandCode, Message, Telemetry


def wait_for(cond: object, timeout_s: float = 10.0) -> bool:
    """Poll a callable until it is true or ``timeout_s`` passes."""
    assert callable(cond)
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if cond():
            return True
        time.sleep(0.02)
    return bool(cond())


def main() -> None:
    p = argparse.ArgumentParser(description="host side tour")
    p.add_argument("--port", help="board link URL (default: start the virtual board)")
    p.add_argument("--ui", action="store_true", help="also serve the panel on http://127.0.0.1:8080")
    args = p.parse_args()

    with HostApp(HostOptions(port=args.port, ui=args.ui)) as app:
        app.start()
        print(f"board link: {app.board_url}" + (f"; panel at {app.url}" if app.url else ""))
        assert app.client is not None

        # 1. Our own listener beside the UI model: count telemetry frames.
        seen = {"telemetry": 0}

        def count(msg: Message) -> None:
            if isinstance(msg, Telemetry):
                seen["telemetry"] += 1

        app.client.add_listener(count)
        m = app.model
        assert wait_for(lambda: m.telemetry is not None, 30.0), "no telemetry"

        # 2. Take control (nobody else holds it), pass the gate with the right lever DOWN, then MANUAL.
        print("take control:", m.request_control(CLI_CLIENT).value)
        m.set_lever(CLI_CLIENT, "right", Lever.DOWN)
        wait_for(lambda: m.telemetry is not None and m.telemetry.phase.name == "OK")
        m.command(CLI_CLIENT, CommandCode.ARM)
        m.set_lever(CLI_CLIENT, "right", Lever.MIDDLE)
        wait_for(lambda: m.telemetry is not None and m.telemetry.mode.name == "MANUAL")
        t = m.telemetry
        assert t is not None
        print(f"mode {t.mode.name}, phase {t.phase.name}, tension targets {t.tension_target_n}")
        m.set_stick(CLI_CLIENT, 3, 500)  # left stick up: curl
        time.sleep(1.0)
        t = m.telemetry
        assert t is not None
        print(f"curl stick at 500: tension targets {[round(x, 2) for x in t.tension_target_n]} N,")
        print(f"  commanded currents {t.commanded_current} (raw, 1000 = 1 A)")

        # 3. E-stop from any authorised client: zero current, latched until cleared and re-armed.
        m.estop(CLI_CLIENT)
        wait_for(lambda: m.telemetry is not None and m.telemetry.phase.name == "ESTOP")
        t = m.telemetry
        assert t is not None
        print(f"after E-stop: phase {t.phase.name}, commanded currents {t.commanded_current}")
        stats = app.client.stats()
        print(
            f"link: {seen['telemetry']} telemetry frames, {stats.rx_rate_hz.get('Telemetry', 0):.0f} Hz, "
            f"errors {stats.errors}, virtual RC max gap {stats.rc_max_gap_us / 1000:.1f} ms"
        )
        if args.ui:
            print("panel stays up for 5 s ...")
            time.sleep(5.0)


if __name__ == "__main__":
    main()
