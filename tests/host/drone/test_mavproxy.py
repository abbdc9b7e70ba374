"""The drone link against a real MAVProxy (headless, 127.0.0.1), driven through its stdin.

MAVProxy listens (``--master=udpin:127.0.0.1:PORT``) and targets our component
(``--target-system=1 --target-component=25``); the link connects with ``udpout`` and a fake board
answers like the firmware. What MAVProxy prints is the observable: "Detected vehicle 1:25",
"PRETENSION_N = ...", "Got COMMAND_ACK: DO_GRIPPER: IN_PROGRESS" / "ACCEPTED" (it prints an ACK only
when its target fields are MAVProxy's own ids or 0, which ours are), and watched NAMED_VALUE_FLOATs.
"""

from __future__ import annotations

import re
import threading
from collections.abc import Iterator
from pathlib import Path

import pytest
from pymavlink import mavutil

from controller.params import PARAMS
from host.drone.config import DroneLinkConfig
from host.drone.link import DroneLink
from protocol import mavlink as mav
from tests.support.drone_peer import GripperBoard
from tests.support.fake_board import FakeBoard
from tests.support.mavproxy_proc import MavProxy, free_udp_port, wait_for

pytestmark = pytest.mark.mavproxy

PASSPHRASE = "spirob-drone"
TYPED = {"HOST_TIMEOUT_US": 30_000.0, "GRASP_STRATEGY": 1.0}
MSG_ID_COMMAND_LONG = 76


class Setup:
    def __init__(self, tmp_path: Path) -> None:
        self.tmp_path = tmp_path
        self.port = free_udp_port()
        self.proxy: MavProxy | None = None
        self.board: FakeBoard | None = None
        self.link: DroneLink | None = None

    def start(
        self, *, mavproxy_cmds: list[str], key: bytes | None, board_params: dict[str, float] | None = None
    ) -> tuple[MavProxy, DroneLink, FakeBoard]:
        state_dir = self.tmp_path / "mavproxy"
        state_dir.mkdir()
        # MAVProxy first: its udpin socket must exist before the link sends.
        self.proxy = MavProxy(self.port, state_dir, mavproxy_cmds)
        self.proxy.expect(r"Waiting for heartbeat|Connect udpin")
        self.board = FakeBoard()
        self.board.params.update(board_params or {})
        cfg = DroneLinkConfig(
            url=f"udpout:127.0.0.1:{self.port}",
            signing_key=key,
            signing_timestamp_path=self.tmp_path / "signing.timestamp" if key else None,
            tlog_path=self.tmp_path / "link.tlog",
        )
        to_board = GripperBoard(self.board)
        self.link = DroneLink(cfg, to_board)
        to_board.attach(self.link.on_board_message)
        self.board.start()
        self.link.start()
        return self.proxy, self.link, self.board

    def close(self) -> None:
        if self.link is not None:
            self.link.close()
        if self.board is not None:
            self.board.stop()
        if self.proxy is not None:
            self.proxy.close()


@pytest.fixture
def setup(tmp_path: Path) -> Iterator[Setup]:
    s = Setup(tmp_path)
    try:
        yield s
    finally:
        s.close()


def grab_and_expect_acks(proxy: MavProxy, board: FakeBoard) -> None:
    start = len(proxy.lines())
    proxy.send("long DO_GRIPPER 25 1")
    i = proxy.expect(r"Got COMMAND_ACK: DO_GRIPPER: IN_PROGRESS", start)
    proxy.expect(r"Got COMMAND_ACK: DO_GRIPPER: ACCEPTED", i + 1)
    assert [c.code.name for c in board.commands()] == ["GRASP"]


def test_mavproxy_sees_the_arm_fetches_and_sets_a_param_grabs_and_watches(setup: Setup) -> None:
    proxy, link, board = setup.start(mavproxy_cmds=[], key=None)
    proxy.expect(r"Detected vehicle 1:25")

    # Parameters: MAVProxy fetches the list on its own; then set one and read it back.
    proxy.expect(rf"Received {len(PARAMS)} parameters")
    start = len(proxy.lines())
    proxy.send("param set PRETENSION_N 0.8")
    wait_for(lambda: abs(board.params["PRETENSION_N"] - 0.8) < 1e-6, "the board to take PRETENSION_N")
    proxy.send("param fetch PRETENSION_N")
    proxy.expect(r"PRETENSION_N = 0\.8000000", start)

    grab_and_expect_acks(proxy, board)

    start = len(proxy.lines())
    proxy.send("watch NAMED_VALUE_FLOAT")
    proxy.expect(r"NAMED_VALUE_FLOAT \{.*name : ARM_T1_N, value : 1\.5", start)
    proxy.send("watch")

    peers = {(p.sysid, p.compid): p for p in link.state().peers}
    assert (255, 230) in peers  # MAVProxy's own ids
    assert link.counters.malformed == 0


def test_mavproxy_with_signing_on_both_sides(setup: Setup) -> None:
    key = mav.signing_key_from_passphrase(PASSPHRASE)
    proxy, link, board = setup.start(
        mavproxy_cmds=[f"signing key {PASSPHRASE}", "set allow_unsigned 0"], key=key
    )
    # MAVProxy refuses unsigned packets now, so seeing us proves our signatures verify.
    proxy.expect(r"Setup signing key")
    proxy.expect(r"Detected vehicle 1:25")
    grab_and_expect_acks(proxy, board)
    state = link.state()
    assert state.signing
    assert {p.signed for p in state.peers if (p.sysid, p.compid) == (255, 230)} == {True}
    assert link.signature_refusals.get(MSG_ID_COMMAND_LONG, 0) == 0


def test_mavproxy_with_a_wrong_key_is_refused(setup: Setup) -> None:
    key = mav.signing_key_from_passphrase(PASSPHRASE)
    proxy, link, board = setup.start(
        mavproxy_cmds=["signing key not-the-passphrase", "set allow_unsigned 0"], key=key
    )
    proxy.expect(r"Setup signing key")
    wait_for(lambda: link.counters.signature_refused > 0, "the link to refuse MAVProxy's packets")
    start = len(proxy.lines())
    proxy.send("long DO_GRIPPER 25 1")
    wait_for(
        lambda: link.signature_refusals.get(MSG_ID_COMMAND_LONG, 0) >= 1,
        "the link to refuse MAVProxy's wrongly signed COMMAND_LONG",
    )
    assert board.commands() == []
    assert link.state().last_command is None
    assert not any("COMMAND_ACK" in line for line in proxy.lines()[start:])
    assert not any("Detected vehicle 1:25" in line for line in proxy.lines())  # it refuses ours too


class StandInArduPilot:
    """1:1 behind MAVProxy (one of its outputs): ArduPilot heartbeats, which MAVProxy forwards to the arm.

    MAVProxy decodes parameters bytewise only for a PX4 system; with an ArduPilot autopilot on the
    system the arm casts its integers, so MAVProxy round-trips them.
    """

    def __init__(self, port: int) -> None:
        self.conn = mavutil.mavlink_connection(f"udpin:127.0.0.1:{port}", source_system=1, source_component=1)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        heard = False
        for _ in range(2400):  # at most 120 s
            if self._stop.wait(0.05):
                return
            heard = heard or self.conn.recv_match(blocking=False) is not None
            if heard:  # udpin: MAVProxy's forwarded traffic gave us its address
                d = self.conn.mav
                d.heartbeat_send(
                    mavutil.mavlink.MAV_TYPE_QUADROTOR, mavutil.mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA, 0, 0, 4
                )

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=5.0)
        self.conn.close()


def test_mavproxy_typed_params_command_int_and_request_message(setup: Setup) -> None:
    out_port = free_udp_port()
    autopilot = StandInArduPilot(out_port)
    try:
        proxy, link, board = setup.start(
            mavproxy_cmds=["module load output", f"output add 127.0.0.1:{out_port}"],
            key=None,
            board_params=TYPED,
        )
        proxy.expect(r"Detected vehicle 1:25")
        wait_for(lambda: not link.params_bytewise, "the arm to see the ArduPilot heartbeat")

        # An integer and a boolean parameter, set and fetched back by MAVProxy.
        start = len(proxy.lines())
        proxy.send("param set HOST_TIMEOUT_US 40000")
        wait_for(lambda: board.params["HOST_TIMEOUT_US"] == 40_000.0, "the board to take HOST_TIMEOUT_US")
        proxy.send("param set GRASP_STRATEGY 0")
        wait_for(lambda: board.params["GRASP_STRATEGY"] == 0.0, "the board to take GRASP_STRATEGY")
        proxy.send("param fetch HOST_TIMEOUT_US")
        proxy.expect(r"HOST_TIMEOUT_US = 40000(\.0+)?$", start)
        proxy.send("param fetch GRASP_STRATEGY")
        proxy.expect(r"GRASP_STRATEGY = 0(\.0+)?$", start)

        # DO_GRIPPER as COMMAND_INT: frame 0, current 0, autocontinue 0, param1 25, param2 1 (grab).
        start = len(proxy.lines())
        proxy.send("command_int 0 DO_GRIPPER 0 0 25 1 0 0 0 0 0")
        i = proxy.expect(r"Got COMMAND_ACK: DO_GRIPPER: IN_PROGRESS", start)
        proxy.expect(r"Got COMMAND_ACK: DO_GRIPPER: ACCEPTED", i + 1)
        assert [c.code.name for c in board.commands()] == ["GRASP"]

        # REQUEST_MESSAGE for AUTOPILOT_VERSION (148): acknowledged, then the message with our capabilities.
        # MAVProxy never prints REQUEST_MESSAGE ACKs on its own ("too noisy"): watch them.
        start = len(proxy.lines())
        proxy.send("watch COMMAND_ACK AUTOPILOT_VERSION")
        proxy.send("long REQUEST_MESSAGE 148")
        i = proxy.expect(r"COMMAND_ACK \{command : 512, result : 0, progress : 0", start)
        i = proxy.expect(r"AUTOPILOT_VERSION \{.*capabilities : (\d+)", i + 1)
        caps = int(re.search(r"capabilities : (\d+)", proxy.lines()[i]).group(1))  # type: ignore[union-attr]
        proxy.send("watch")
        d = mavutil.mavlink
        assert caps & d.MAV_PROTOCOL_CAPABILITY_MAVLINK2
        assert caps & d.MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_C_CAST  # what this ArduPilot system uses
        assert caps & d.MAV_PROTOCOL_CAPABILITY_COMMAND_INT
        assert link.counters.malformed == 0
    finally:
        autopilot.close()
