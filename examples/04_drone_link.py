"""04 - The MAVLink drone link: the arm as a gripper component that a ground station can command.

Run it with no arguments for a self-contained demo on 127.0.0.1: a pymavlink "ground station" sees the
arm's HEARTBEAT, reads its parameters, sets one, grabs with MAV_CMD_DO_GRIPPER (IN_PROGRESS, then
ACCEPTED), reads the NAMED_VALUE_FLOAT tensions, and measures the command round trip. Everything in and
out is written to a .tlog that ``mavlogdump.py`` reads.

    .venv/bin/python examples/04_drone_link.py       # under 10 s (1.5 s measured on a loaded 2-core machine)
    .venv/bin/python examples/04_drone_link.py --url udpout:127.0.0.1:14550 --seconds 60

With ``--url`` it just runs the link for a while so you can attach MAVProxy or QGroundControl, e.g.
``mavproxy.py --master=udpin:127.0.0.1:14550 --target-system=1 --target-component=25 --mav20`` then
``param fetch``, ``long DO_GRIPPER 25 1``, ``watch NAMED_VALUE_FLOAT``.

The demo exits 1 with one line when a step does not happen (a message missing for 5 s, the parameter not
taken, the grab not ACCEPTED). The board here is a few lines of script standing in for the firmware
(armed, GRASP mode, the firmware's parameters checked by the firmware's own rule, a grasp that reaches,
wraps and holds); ``spirob-host --mavlink URL`` wires the same link to the real board.
"""

from __future__ import annotations

import argparse
import contextlib
import socket
import statistics
import sys
import tempfile
import threading
import time
from collections.abc import Callable
from pathlib import Path

from controller.config import FirmwareConfig
from controller.errors import ConfigError
from controller.params import WIRE_ROWS
from host.drone.config import DroneLinkConfig
from host.drone.link import DroneLink
from protocol import mavlink as mav
from protocol import messages as bm

from pymavlink import mavutil  # after protocol.mavlink: MAVLINK20=1 is set  # isort: skip


AckHandler = Callable[[bm.CommandAck | None], None]


class ScriptedBoard:
    """Stands in for the board: 100 Hz telemetry, the firmware's parameters, a grasp that ends in HOLD.

    It is what the drone link sends to (``BoardClient.send`` in ``spirob-host``): a command's answers go
    to its ``on_ack``, IN_PROGRESS at once and ACCEPTED when the grasp holds, as the firmware answers.
    """

    def __init__(self) -> None:
        self.config = FirmwareConfig()
        self.params = {name: self.config.get_param(name) for name in WIRE_ROWS}  # the firmware's, in order
        self.grasp = bm.GraspState.IDLE
        self.ticks = 0
        self.sink = None  # set to DroneLink.on_board_message
        self.owed: tuple[bm.CommandCode, AckHandler] | None = None
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="scripted-board", daemon=True)

    def __call__(self, msg: bm.Message, *, origin: str = "host", on_ack: AckHandler | None = None) -> bool:
        names = list(self.params)
        replies: list[bm.Message] = []
        if isinstance(msg, bm.ParamRequest):
            replies = [bm.ParamValue(i, len(names), n, self.params[n]) for i, n in enumerate(names)]
        elif isinstance(msg, bm.ParamSet) and msg.name in self.params:
            with contextlib.suppress(ConfigError):  # the firmware's rule; a refused value keeps the old
                self.config = self.config.with_param(msg.name, msg.value)
            self.params[msg.name] = value = self.config.get_param(msg.name)
            replies = [bm.ParamValue(names.index(msg.name), len(names), msg.name, value)]
        elif isinstance(msg, bm.Command):
            code = bm.CommandCode(msg.code)
            self.grasp = {
                bm.CommandCode.GRASP: bm.GraspState.REACH,
                bm.CommandCode.RELEASE: bm.GraspState.RELEASE,
            }.get(code, bm.GraspState.HOLD)
            self.ticks = 0
            done = self.grasp == bm.GraspState.HOLD
            result = bm.AckResult.ACCEPTED if done else bm.AckResult.IN_PROGRESS
            if on_ack is not None:
                on_ack(bm.CommandAck(code, result, 0))
                self.owed = None if done else (code, on_ack)
        for r in replies:
            self.sink(r)  # type: ignore[misc]
        return True

    def _run(self) -> None:
        t_us = 0
        while not self._stop.wait(0.01):
            t_us += 10_000
            self.ticks += 1
            if self.ticks % 20 == 0:  # 200 ms per grasp phase
                nxt = {
                    bm.GraspState.REACH: bm.GraspState.WRAP,
                    bm.GraspState.WRAP: bm.GraspState.HOLD,
                    bm.GraspState.RELEASE: bm.GraspState.IDLE,
                }
                self.grasp = nxt.get(self.grasp, self.grasp)
                if self.owed is not None and self.grasp in (bm.GraspState.HOLD, bm.GraspState.IDLE):
                    code, on_ack = self.owed
                    self.owed = None
                    on_ack(bm.CommandAck(code, bm.AckResult.ACCEPTED, 0))  # the final answer
            self.sink(  # type: ignore[misc]
                bm.Telemetry(
                    t_us,
                    bm.Mode.GRASP,
                    bm.Phase.OK,
                    self.grasp,
                    bm.TelemetryFlags.ARMED | bm.TelemetryFlags.RC_OK,
                    0b111,
                    motor_current=(420, 610, 380),
                    tension_est_n=(2.1, 3.0, 1.9),
                )
            )

    def start(self) -> None:
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(timeout=5)


def free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def recv(gcs: object, mtype: str, timeout_s: float = 5.0, cond: str | None = None) -> object:
    msg = gcs.recv_match(type=mtype, blocking=True, timeout=timeout_s, condition=cond)  # type: ignore[attr-defined]
    if msg is None:
        sys.exit(f"demo failed: no {mtype} within {timeout_s} s")
    return msg


def demo(tlog: Path) -> None:
    port = free_udp_port()
    gcs = mavutil.mavlink_connection(f"udpin:127.0.0.1:{port}", source_system=255, source_component=190)
    board = ScriptedBoard()
    link = DroneLink(DroneLinkConfig(url=f"udpout:127.0.0.1:{port}", tlog_path=tlog), board)
    board.sink = link.on_board_message  # type: ignore[assignment]
    board.start()
    try:
        with link:
            hb = recv(gcs, "HEARTBEAT", cond="HEARTBEAT.type==48")
            print(f"arm heard: sysid {hb.get_srcSystem()} compid {hb.get_srcComponent()} type {hb.type}")  # type: ignore[attr-defined]
            recv(gcs, "NAMED_VALUE_FLOAT")  # board telemetry is flowing

            gcs.mav.param_request_list_send(1, 25)
            params: dict[str, float] = {}
            count = 1
            while len(params) < count:
                pv = recv(gcs, "PARAM_VALUE")
                count = pv.param_count  # type: ignore[attr-defined]
                # Integers travel bytewise in the float (MAVLink's parameter protocol): decode by type.
                value = mav.decode_param_value(pv.param_value, pv.param_type, bytewise=True)  # type: ignore[attr-defined]
                params[pv.param_id] = value  # type: ignore[attr-defined]
            shown = ("HOST_TIMEOUT_US", "TENSION_MAX_N", "PRETENSION_N")
            print(f"  {len(params)} params, e.g. " + ", ".join(f"{n} = {params[n]:g}" for n in shown))
            gcs.mav.param_set_send(1, 25, b"PRETENSION_N", 0.8, mav.ParamType.REAL32)
            deadline = time.monotonic() + 5.0
            while True:  # the list may still be streaming: wait for the board's answer to the set
                pv = recv(gcs, "PARAM_VALUE", cond="PARAM_VALUE.param_id=='PRETENSION_N'")
                took: float = pv.param_value  # type: ignore[attr-defined]
                if abs(took - 0.8) <= 1e-6 or time.monotonic() > deadline:
                    break
            print(f"  set PRETENSION_N -> board took {took:g}")
            if abs(took - 0.8) > 1e-6:
                sys.exit(f"demo failed: PRETENSION_N is {took:g}, not 0.8")

            gcs.mav.command_long_send(
                1, 25, mav.MAV_CMD_DO_GRIPPER, 0, 25, mav.GripperAction.GRAB, 0, 0, 0, 0, 0
            )
            while True:
                ack = recv(gcs, "COMMAND_ACK")
                print(f"  DO_GRIPPER grab: {mav.MavResult(ack.result).name} progress {ack.progress}")  # type: ignore[attr-defined]
                if ack.result != mav.MavResult.IN_PROGRESS:  # type: ignore[attr-defined]
                    break
            if ack.result != mav.MavResult.ACCEPTED:  # type: ignore[attr-defined]
                sys.exit(f"demo failed: DO_GRIPPER grab ended {mav.MavResult(ack.result).name}")  # type: ignore[attr-defined]

            values = {}
            while len(values) < 6:
                nv = recv(gcs, "NAMED_VALUE_FLOAT")
                values[nv.name] = nv.value  # type: ignore[attr-defined]
            print("  telemetry:", ", ".join(f"{k}={v:g}" for k, v in values.items()))
            aos = recv(gcs, "ACTUATOR_OUTPUT_STATUS")
            print(f"  motor currents [A]: {[round(a, 3) for a in aos.actuator[:3]]}")  # type: ignore[attr-defined]

            # Round trip of a command answered at once (UNSUPPORTED), GCS -> link -> GCS on loopback.
            rtts: list[float] = []
            for _ in range(200):
                t0 = time.perf_counter()
                gcs.mav.command_long_send(1, 25, 31000, 0, 0, 0, 0, 0, 0, 0, 0)
                recv(gcs, "COMMAND_ACK", cond="COMMAND_ACK.command==31000")
                rtts.append((time.perf_counter() - t0) * 1e3)
            rtts.sort()
            print(
                f"  command round trip over 127.0.0.1: median {statistics.median(rtts):.2f} ms, "
                f"p99 {rtts[int(0.99 * len(rtts)) - 1]:.2f} ms (link polls every 5 ms at most)"
            )
            c = link.counters
            print(f"  link: {c.packets_in} packets in, {c.packets_out} out, {c.malformed} malformed")
    finally:
        board.stop()
        gcs.close()
    print(f".tlog: {tlog} (read it with: mavlogdump.py {tlog})")


def serve(url: str, seconds: float, tlog: Path) -> None:
    board = ScriptedBoard()
    link = DroneLink(DroneLinkConfig(url=url, tlog_path=tlog), board)
    board.sink = link.on_board_message  # type: ignore[assignment]
    board.start()
    try:
        with link:
            print(f"arm on {url} as 1/25 for {seconds:g} s; attach a GCS now")
            deadline = time.monotonic() + seconds
            while time.monotonic() < deadline:
                time.sleep(1.0)
                s = link.state()
                peers = ", ".join(f"{p.sysid}/{p.compid}" for p in s.peers) or "none"
                print(f"  peers: {peers}; last command: {s.last_command}")
    finally:
        board.stop()


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--url", help="run the link on this connection instead of the demo")
    parser.add_argument("--seconds", type=float, default=30.0, help="how long --url runs")
    parser.add_argument("--tlog", type=Path, default=Path(tempfile.gettempdir()) / "spirob-drone-link.tlog")
    args = parser.parse_args(argv)
    if args.url:
        serve(args.url, args.seconds, args.tlog)
    else:
        demo(args.tlog)
    return 0


if __name__ == "__main__":
    sys.exit(main())
