"""02 — the firmware in lockstep against the fake C610 trio, with a scripted radio and a host link.

Shows the start-up gate, MANUAL curl and bend from the sticks, the RC-lost failsafe (zero current 30 ms
after the last valid frame), and the telemetry a host receives. Runs in under 2 s (0.4 s measured on a
loaded 2-core machine), no hardware: ``python examples/02_firmware_fake_bus.py``; exits 1 with one line if
what it shows does not happen.

The same ``Firmware`` runs on hardware with ``spirob-firmware --can-interface socketcan --can-channel can0
--rc /dev/ttyUSB0 --link /dev/ttyGS0``; only the bus, the RC source and the clock change.
"""

from __future__ import annotations

import sys

from controller.clock import LockstepClock
from controller.config import FirmwareConfig
from controller.firmware import Firmware
from controller.motorbus import FakeMotorBus
from controller.rc import ScriptedRcSource
from controller.transport import MemoryTransport
from protocol.dbus import Lever, RcFrame
from protocol.link import LinkParser
from protocol.messages import Event, Telemetry, decode


def sticks(right: Lever, *, curl: int = 0, bend_x: int = 0, bend_y: int = 0) -> RcFrame:
    """A DT7 frame: right lever, left stick up = curl, right stick = bend (channels ±660)."""
    return RcFrame((bend_x, bend_y, 0, curl), int(right), int(Lever.DOWN))


def main() -> None:
    # The script: the radio is switched on with the lever in MANUAL (the gate must refuse), then
    # SAFE, MANUAL with curl, a bend toward cable 2 (120°), and finally the radio dies.
    radio = ScriptedRcSource(
        sticks(Lever.MIDDLE, curl=400),
        schedule=[
            (100_000, sticks(Lever.DOWN)),
            (200_000, sticks(Lever.MIDDLE, curl=400)),
            (600_000, sticks(Lever.MIDDLE, bend_x=-330, bend_y=572)),
            (1_000_000, None),
        ],
    )
    host, board = MemoryTransport.pair()
    firmware = Firmware(FirmwareConfig(), FakeMotorBus(), radio, board)
    clock = LockstepClock()

    print(" time ms  phase        mode     currents (raw, mA)      tensions (N)")
    last_state = None
    gate_current = manual_current = 0  # the largest |current| before the gate opened, and in MANUAL
    while clock.now_us() < 1_200_000:
        now = clock.now_us()
        firmware.run_due(now)
        state = (firmware.phase.name, firmware.mode.name)
        peak = max(abs(c) for c in firmware.commanded_currents)
        if now < 100_000:
            gate_current = max(gate_current, peak)
        elif state == ("OK", "MANUAL"):
            manual_current = max(manual_current, peak)
        if state != last_state or now % 100_000 == 0:  # every change, and every 100 ms
            tensions = ", ".join(f"{t:5.2f}" for t in firmware.tensions_n)
            currents = str(firmware.commanded_currents)
            print(f"{now / 1000:8.0f}  {state[0]:11s}  {state[1]:7s}  {currents:22s}  {tensions}")
            last_state = state
        clock.advance(1000)

    # What the host saw: decode the board link.
    messages = [decode(f) for f in LinkParser().feed(host.read())]
    telemetry = [m for m in messages if isinstance(m, Telemetry)]
    print(f"\nhost received {len(messages)} frames, {len(telemetry)} Telemetry (100 Hz); events:")
    for event in (m for m in messages if isinstance(m, Event)):
        print(f"  {event.time_us / 1000:7.0f} ms  {event.kind.name:6s} {event.text}")

    # What the demo claims, checked: a run that does not show it exits 1.
    if gate_current != 0:
        sys.exit(f"demo failed: current {gate_current} flowed before the start-up gate opened")
    if manual_current == 0:
        sys.exit("demo failed: no current in MANUAL with the curl stick up")
    if firmware.phase.name != "RC_LOST" or any(firmware.commanded_currents):
        sys.exit(f"demo failed: after the radio died: {firmware.phase.name}, {firmware.commanded_currents}")
    if not 110 <= len(telemetry) <= 130:
        sys.exit(f"demo failed: {len(telemetry)} Telemetry in 1.2 s (expected about 120 at 100 Hz)")


if __name__ == "__main__":
    main()
