"""host.drone.link as a complete MAVLink component, against pymavlink peers over UDP loopback.

COMMAND_INT, REQUEST_MESSAGE / REQUEST_PROTOCOL_VERSION, typed parameters in both encodings, requests
that arrive before the board answers, and the servo follower driven by a stand-in autopilot (1:1,
a quadrotor running ArduPilot) that steps its gripper output in SERVO_OUTPUT_RAW.
"""

from __future__ import annotations

import struct
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest

from host.drone.config import DroneLinkConfig
from host.drone.link import DroneLink
from host.drone.servo import ServoFollowConfig
from protocol import mavlink as mav
from protocol import messages as bm
from tests.support.drone_peer import WAIT_S, GripperBoard, Peer, Rig, free_udp_port, rig_factory
from tests.support.fake_board import FakeBoard

R = mav.MavResult
D = mav.dialect()
GRAB_PWM, RELEASE_PWM, OUTPUT_N = 1900, 1100, 9


@pytest.fixture
def make_rig(tmp_path: Path) -> Iterator[Callable[..., Rig]]:
    yield from rig_factory(tmp_path)


def wait_until(cond: Callable[[], bool], what: str) -> None:
    deadline = time.monotonic() + WAIT_S
    while time.monotonic() < deadline:
        if cond():
            return
        time.sleep(0.01)
    raise AssertionError(f"timed out waiting for {what}")


# --------------------------------------------------------------------------------------------------
# commands


def test_command_int_do_gripper_is_handled_like_command_long(make_rig: Callable[..., Rig]) -> None:
    rig = make_rig()
    rig.ready()
    rig.peer.conn.mav.command_int_send(1, 25, 0, mav.MAV_CMD_DO_GRIPPER, 0, 0, 25, 1, 0, 0, 0, 0, 0)
    acks = rig.peer.acks_until_final()
    assert [acks[0].result, acks[-1].result] == [R.IN_PROGRESS, R.ACCEPTED]
    assert rig.board.commands() == [bm.Command(bm.CommandCode.GRASP)]


def test_request_message_answers_heartbeat_protocol_and_autopilot_version(
    make_rig: Callable[..., Rig],
) -> None:
    rig = make_rig()
    rig.ready()
    caps = {}
    for msg_id, mtype in ((0, "HEARTBEAT"), (148, "AUTOPILOT_VERSION")):
        rig.peer.command(mav.MAV_CMD_REQUEST_MESSAGE, float(msg_id))
        ack = rig.peer.recv_type("COMMAND_ACK", lambda m: m.command == mav.MAV_CMD_REQUEST_MESSAGE)
        assert (ack.result, ack.progress) == (R.ACCEPTED, 0)
        reply = rig.peer.recv_type(mtype, lambda m: m.get_srcComponent() == 25)
        if mtype == "AUTOPILOT_VERSION":
            caps = {"caps": reply.capabilities}
    assert caps["caps"] & D.MAV_PROTOCOL_CAPABILITY_MAVLINK2
    assert caps["caps"] & D.MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE  # no autopilot seen: bytewise
    assert caps["caps"] & D.MAV_PROTOCOL_CAPABILITY_COMMAND_INT
    rig.peer.command(mav.MAV_CMD_REQUEST_MESSAGE, 33.0)  # GLOBAL_POSITION_INT: not ours
    ack = rig.peer.recv_type("COMMAND_ACK", lambda m: m.command == mav.MAV_CMD_REQUEST_MESSAGE)
    assert ack.result == R.UNSUPPORTED


def test_protocol_version_by_request_message_and_by_request_protocol_version(
    make_rig: Callable[..., Rig],
) -> None:
    rig = make_rig()
    rig.ready()
    for command, p1 in ((mav.MAV_CMD_REQUEST_PROTOCOL_VERSION, 1.0), (mav.MAV_CMD_REQUEST_MESSAGE, 300.0)):
        rig.peer.command(command, p1)
        ack = rig.peer.recv_type("COMMAND_ACK", lambda m, c=command: m.command == c)
        assert ack.result == R.ACCEPTED
        # pymavlink generates no PROTOCOL_VERSION; protocol.mavlink registers one in the dialect.
        pv = rig.peer.recv(lambda m: m.get_msgId() == mav.MSG_ID_PROTOCOL_VERSION)
        assert (pv.version, pv.min_version, pv.max_version) == (200, 100, 200)


# --------------------------------------------------------------------------------------------------
# typed parameters


TYPED = {"HOST_TIMEOUT_US": 30_000_000.0, "GRASP_STRATEGY": 1.0}


def fetch(peer: Peer, name: str) -> Any:
    peer.conn.mav.param_request_read_send(1, 25, name.encode(), -1)
    return peer.recv_type("PARAM_VALUE", lambda m: m.param_id == name)


def test_integer_and_boolean_parameters_are_typed_and_bytewise(make_rig: Callable[..., Rig]) -> None:
    rig = make_rig(board_params=TYPED)
    rig.ready()
    pv = fetch(rig.peer, "HOST_TIMEOUT_US")
    assert pv.param_type == mav.ParamType.INT32
    assert struct.unpack("<i", struct.pack("<f", pv.param_value))[0] == 30_000_000  # exact above 2^24
    pv = fetch(rig.peer, "GRASP_STRATEGY")
    assert pv.param_type == mav.ParamType.UINT8
    assert struct.pack("<f", pv.param_value) == b"\x01\x00\x00\x00"
    assert fetch(rig.peer, "PRETENSION_N").param_type == mav.ParamType.REAL32
    # A bytewise-encoded set: the board is asked for 0.
    wire = struct.unpack("<f", b"\x00\x00\x00\x00")[0]
    rig.peer.conn.mav.param_set_send(1, 25, b"GRASP_STRATEGY", wire, mav.ParamType.UINT8)
    rig.peer.recv_type("PARAM_VALUE", lambda m: m.param_id == "GRASP_STRATEGY")
    assert rig.board.params["GRASP_STRATEGY"] == 0.0


def test_with_an_ardupilot_autopilot_parameters_are_c_cast(make_rig: Callable[..., Rig]) -> None:
    rig = make_rig(board_params=TYPED)
    rig.ready()
    autopilot = StandInAutopilot(rig, servo=False)
    try:
        wait_until(lambda: not rig.link.params_bytewise, "the link to see the ArduPilot heartbeat")
        pv = fetch(rig.peer, "HOST_TIMEOUT_US")
        assert (pv.param_type, pv.param_value) == (mav.ParamType.INT32, 30_000_000.0)
        rig.peer.conn.mav.param_set_send(1, 25, b"HOST_TIMEOUT_US", 40_000.0, mav.ParamType.REAL32)
        rig.peer.recv_type(
            "PARAM_VALUE", lambda m: m.param_id == "HOST_TIMEOUT_US" and m.param_value == 40_000
        )
        assert rig.board.params["HOST_TIMEOUT_US"] == 40_000.0
    finally:
        autopilot.stop()


# --------------------------------------------------------------------------------------------------
# requests before the board answers


class LateBoard(GripperBoard):
    """The board behind a link that drops what the host sends until :meth:`come_up`."""

    def __init__(self, board: FakeBoard) -> None:
        super().__init__(board)
        self.up.clear()

    def come_up(self) -> None:
        self.up.set()
        self.board.start()


@pytest.fixture
def late(tmp_path: Path) -> Iterator[tuple[DroneLink, LateBoard, Peer]]:
    port = free_udp_port()
    peer = Peer(f"udpin:127.0.0.1:{port}")
    board = FakeBoard()
    late_board = LateBoard(board)
    link = DroneLink(
        DroneLinkConfig(url=f"udpout:127.0.0.1:{port}", param_confirm_timeout_us=200_000), late_board
    )
    late_board.attach(link.on_board_message)
    link.start()
    try:
        yield link, late_board, peer
    finally:
        link.close()
        board.stop()
        peer.close()


def test_requests_before_the_board_answers_are_served_once_it_does(
    late: tuple[DroneLink, LateBoard, Peer],
) -> None:
    link, board, peer = late
    hb = peer.recv_type("HEARTBEAT", lambda m: m.get_srcComponent() == 25)
    assert hb.system_status == mav.MavState.BOOT
    peer.conn.mav.param_request_list_send(1, 25)  # what a ground station does on discovery
    peer.command(mav.MAV_CMD_DO_GRIPPER, 25.0, 1.0)
    time.sleep(0.3)  # the board's first answers are lost: the link must ask again
    board.come_up()
    peer.recv_type("HEARTBEAT", lambda m: m.system_status == mav.MavState.ACTIVE)
    acks = peer.acks_until_final()
    assert [acks[0].result, acks[-1].result] == [R.IN_PROGRESS, R.ACCEPTED]
    names = {m.param_id for m in peer.seen if m.get_type() == "PARAM_VALUE"}  # some came with the ACKs
    while len(names) < len(board.board.params):
        names.add(peer.recv_type("PARAM_VALUE").param_id)
    assert names == {n.upper() for n in board.board.params}
    assert link.counters.internal_errors == 0


# --------------------------------------------------------------------------------------------------
# the servo follower


class StandInAutopilot:
    """1:1, a quadrotor running ArduPilot: heartbeats and the gripper output in SERVO_OUTPUT_RAW at 20 Hz.

    Sends through the rig's ground-station socket with autopilot ids (the link tells senders apart by
    their MAVLink ids, not by their address).
    """

    def __init__(self, rig: Rig, *, servo: bool = True, pwm_us: int = RELEASE_PWM) -> None:
        self.mav = D.MAVLink(rig.peer.conn, srcSystem=1, srcComponent=1)
        self.pwm_us = pwm_us
        self.servo = servo
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        n = 0
        while not self._stop.wait(0.05) and n < 2000:
            if n % 20 == 0:
                self.mav.heartbeat_send(D.MAV_TYPE_QUADROTOR, D.MAV_AUTOPILOT_ARDUPILOTMEGA, 0, 0, 4)
            if self.servo:
                servos = [1500] * 16
                servos[OUTPUT_N - 1] = self.pwm_us
                self.mav.servo_output_raw_send(n * 50_000, 0, *servos)
            n += 1

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(timeout=5.0)


def follower_rig(make_rig: Callable[..., Rig]) -> tuple[Rig, StandInAutopilot]:
    rig = make_rig(servo_follow=ServoFollowConfig(OUTPUT_N, GRAB_PWM, RELEASE_PWM, stale_us=300_000))
    rig.ready()
    autopilot = StandInAutopilot(rig)
    wait_until(lambda: rig.link.servo_reading == mav.GripperAction.RELEASE, "a baseline")
    return rig, autopilot


def test_the_autopilot_output_grabs_and_releases(make_rig: Callable[..., Rig]) -> None:
    rig, autopilot = follower_rig(make_rig)
    try:
        autopilot.pwm_us = GRAB_PWM
        rig.peer.statustext("grab started (autopilot servo)")
        wait_until(lambda: rig.board.grasp_state == bm.GraspState.HOLD, "the board to hold")
        autopilot.pwm_us = 1650  # inside the hysteresis band: the grasp is held, nothing sent
        time.sleep(0.3)
        autopilot.pwm_us = RELEASE_PWM
        wait_until(lambda: rig.board.grasp_state == bm.GraspState.IDLE, "the board to release")
        assert [c.code for c in rig.board.commands()] == [bm.CommandCode.GRASP, bm.CommandCode.RELEASE]
        assert not any(m.get_type() == "COMMAND_ACK" for m in rig.peer.seen)  # the follower gets no ACKs
    finally:
        autopilot.stop()


def test_the_radio_still_wins_over_the_autopilot_output(make_rig: Callable[..., Rig]) -> None:
    rig, autopilot = follower_rig(make_rig)
    try:
        rig.board.set(mode=bm.Mode.MANUAL)  # right lever MIDDLE
        rig.peer.recv_type("HEARTBEAT", lambda m: m.custom_mode & 0xFF == bm.Mode.MANUAL)
        autopilot.pwm_us = GRAB_PWM
        rig.peer.statustext("lever not UP")
        rig.board.set(mode=bm.Mode.GRASP)  # a refused request is never carried out later
        time.sleep(0.3)
        assert rig.board.commands() == []
    finally:
        autopilot.stop()


def test_stale_output_reports_are_safe(make_rig: Callable[..., Rig]) -> None:
    rig, autopilot = follower_rig(make_rig)
    autopilot.pwm_us = GRAB_PWM
    wait_until(lambda: rig.board.grasp_state == bm.GraspState.HOLD, "the board to hold")
    autopilot.stop()  # the autopilot's telemetry stops with the arm holding
    rig.peer.statustext("output 9 not reported, no command")
    time.sleep(0.3)
    assert [c.code for c in rig.board.commands()] == [bm.CommandCode.GRASP]  # nothing new sent
    assert rig.board.grasp_state == bm.GraspState.HOLD  # the load stays held
    # Reports return with the output at RELEASE: a baseline, not a release.
    back = StandInAutopilot(rig, pwm_us=RELEASE_PWM)
    try:
        wait_until(lambda: rig.link.servo_reading is not None, "fresh reports")
        time.sleep(0.3)
        assert rig.board.grasp_state == bm.GraspState.HOLD
        back.pwm_us = GRAB_PWM
        time.sleep(0.2)
        back.pwm_us = RELEASE_PWM  # a real edge after the baseline releases
        wait_until(lambda: rig.board.grasp_state == bm.GraspState.IDLE, "the board to release")
    finally:
        back.stop()


def test_a_change_while_the_gripper_is_busy_waits_for_the_job_to_end(make_rig: Callable[..., Rig]) -> None:
    rig, autopilot = follower_rig(make_rig)
    try:
        rig.board.set(ticks_per_phase=30)  # REACH and WRAP take about 0.3 s each
        autopilot.pwm_us = GRAB_PWM
        rig.peer.statustext("grab started (autopilot servo)")
        autopilot.pwm_us = RELEASE_PWM  # while the grab runs
        rig.peer.statustext("grab done, HOLD")
        rig.peer.statustext("release started (autopilot servo)")
        wait_until(lambda: rig.board.grasp_state == bm.GraspState.IDLE, "the board to release")
        assert [c.code for c in rig.board.commands()] == [bm.CommandCode.GRASP, bm.CommandCode.RELEASE]
    finally:
        autopilot.stop()
