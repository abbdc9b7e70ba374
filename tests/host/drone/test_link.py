"""host.drone.link against a pymavlink peer over UDP loopback, with a firmware-like fake board.

The peer plays the ground station (255/190) on ``udpin:127.0.0.1:PORT``; the link connects with
``udpout``. Every wait is bounded; nothing asserts how long anything took.
"""

from __future__ import annotations

import socket
import struct
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest
from pymavlink import mavutil

from controller.params import PARAMS
from host.drone.config import DroneLinkConfig, DroneLinkError, load_signing_key
from host.drone.gripper import gripper_denial
from host.drone.link import DroneLink
from host.drone.params import PARAM_TYPES
from host.drone.tlog import TLOG_LINK_IN, TLOG_LINK_OUT
from protocol import mavlink as mav
from protocol import messages as bm
from tests.support.drone_peer import WAIT_S, GripperBoard, Peer, Rig, free_udp_port, rig_factory
from tests.support.fake_board import FakeBoard

GRAB, RELEASE, HOLD = (
    float(mav.GripperAction.GRAB),
    float(mav.GripperAction.RELEASE),
    float(mav.GripperAction.HOLD),
)
R = mav.MavResult
KEY = mav.signing_key_from_passphrase("spirob")


@pytest.fixture
def make_rig(tmp_path: Path) -> Iterator[Callable[..., Rig]]:
    yield from rig_factory(tmp_path)


# --------------------------------------------------------------------------------------------------
# presence and telemetry


def test_heartbeat_identifies_a_gripper_component_in_mavlink2(make_rig: Callable[..., Rig]) -> None:
    rig = make_rig(start_board=False)
    hb = rig.peer.recv_type("HEARTBEAT")
    assert (hb.get_srcSystem(), hb.get_srcComponent()) == (1, 25)
    assert (hb.type, hb.autopilot, hb.system_status) == (48, 8, mav.MavState.BOOT)
    assert hb.get_msgbuf()[0] == 0xFD
    rig.board.start()
    hb = rig.peer.recv_type("HEARTBEAT", lambda m: m.system_status == mav.MavState.ACTIVE)
    assert hb.base_mode == 1 | 128
    assert hb.custom_mode == bm.Mode.GRASP | bm.Phase.OK << 8 | bm.GraspState.IDLE << 16


def test_tensions_mode_and_currents_are_streamed(make_rig: Callable[..., Rig]) -> None:
    rig = make_rig()
    names: dict[str, float] = {}
    while len(names) < 6:
        m = rig.peer.recv_type("NAMED_VALUE_FLOAT")
        names[m.name] = m.value
    assert names == {
        "ARM_T1_N": 1.5,
        "ARM_T2_N": 2.5,
        "ARM_T3_N": 3.5,
        "ARM_MODE": 2.0,
        "ARM_PHASE": 1.0,
        "ARM_GRASP": 0.0,
    }
    aos = rig.peer.recv_type("ACTUATOR_OUTPUT_STATUS")
    assert aos.active == 3
    assert list(aos.actuator[:4]) == [0.5, 1.0, 1.5, 0.0]


def test_board_events_become_statustext(make_rig: Callable[..., Rig]) -> None:
    rig = make_rig()
    rig.ready()
    rig.board.emit_event(bm.EventKind.PHASE, bm.Phase.RC_LOST, "RC lost: zero current")
    st = rig.peer.statustext("RC lost")
    assert st.severity == mav.Severity.CRITICAL
    rig.link.send_statustext("host says hello " + "x" * 60, mav.Severity.NOTICE)
    first = rig.peer.statustext("host says hello")
    assert first.id > 0 and first.chunk_seq == 0


# --------------------------------------------------------------------------------------------------
# DO_GRIPPER: every ACK outcome


def test_grab_in_progress_then_accepted(make_rig: Callable[..., Rig]) -> None:
    rig = make_rig()
    rig.ready()
    rig.peer.gripper(GRAB)
    acks = rig.peer.acks_until_final()
    assert acks[0].result == R.IN_PROGRESS
    assert acks[-1].result == R.ACCEPTED
    assert acks[-1].progress == 0  # progress belongs to IN_PROGRESS only
    assert {(a.command, a.target_system, a.target_component) for a in acks} == {(211, 255, 190)}
    assert [a.progress for a in acks if a.result == R.IN_PROGRESS] == sorted(
        a.progress for a in acks if a.result == R.IN_PROGRESS
    )
    assert rig.board.commands() == [bm.Command(bm.CommandCode.GRASP)]
    last = rig.link.state().last_command
    assert last is not None and (last.action, last.result) == (1, R.ACCEPTED)


def test_release_and_hold_complete(make_rig: Callable[..., Rig]) -> None:
    rig = make_rig()
    rig.ready()
    rig.peer.gripper(HOLD, instance=0.0)  # instance 0 = any gripper
    assert [a.result for a in rig.peer.acks_until_final()][-1] == R.ACCEPTED
    rig.peer.gripper(HOLD)  # already holding: nothing to do
    assert [a.result for a in rig.peer.acks_until_final()] == [R.ACCEPTED]
    rig.peer.gripper(RELEASE)
    acks = rig.peer.acks_until_final()
    assert (acks[0].result, acks[-1].result) == (R.IN_PROGRESS, R.ACCEPTED)
    assert [c.code for c in rig.board.commands()] == [bm.CommandCode.HOLD, bm.CommandCode.RELEASE]


def test_grab_fails_when_the_grasp_fails(make_rig: Callable[..., Rig]) -> None:
    rig = make_rig()
    rig.board.set(outcome="fail")
    rig.ready()
    rig.peer.gripper(GRAB)
    assert [a.result for a in rig.peer.acks_until_final()][-1] == R.FAILED
    rig.peer.statustext("grasp FAILED")


def test_grab_fails_on_a_failsafe_mid_grasp(make_rig: Callable[..., Rig]) -> None:
    rig = make_rig()
    rig.board.set(ticks_per_phase=10_000)
    rig.ready()
    rig.peer.gripper(GRAB)
    assert rig.peer.recv_type("COMMAND_ACK").result == R.IN_PROGRESS
    rig.board.set(phase=bm.Phase.RC_LOST)
    final = rig.peer.acks_until_final()[-1]
    assert final.result == R.FAILED
    rig.peer.statustext("failsafe RC_LOST")


def test_grab_fails_on_timeout(make_rig: Callable[..., Rig]) -> None:
    rig = make_rig(grasp_timeout_us=300_000)
    rig.board.set(outcome="stall")
    rig.ready()
    rig.peer.gripper(GRAB)
    assert rig.peer.acks_until_final()[-1].result == R.FAILED
    rig.peer.statustext("timeout")
    assert not rig.link.state().gripper_busy


def test_busy_is_temporarily_rejected_and_a_retransmission_is_in_progress(
    make_rig: Callable[..., Rig],
) -> None:
    rig = make_rig()
    rig.board.set(ticks_per_phase=10_000)
    rig.ready()
    rig.peer.gripper(GRAB)
    assert rig.peer.recv_type("COMMAND_ACK").result == R.IN_PROGRESS
    rig.peer.gripper(GRAB, conf=1)  # the commander retransmits: still in progress, not run twice
    rig.peer.gripper(RELEASE)
    acks = rig.peer.acks_until_final()  # (a progress report may come in between)
    assert [a.result for a in acks].count(R.IN_PROGRESS) >= 1
    assert acks[-1].result == R.TEMPORARILY_REJECTED
    assert rig.link.state().gripper_busy
    assert len(rig.board.commands()) == 1


def test_a_grasp_started_from_the_radio_makes_the_gripper_busy(make_rig: Callable[..., Rig]) -> None:
    rig = make_rig()
    rig.board.set(grasp_state=bm.GraspState.WRAP, ticks_per_phase=10_000)
    rig.ready()
    rig.peer.gripper(RELEASE)
    assert rig.peer.recv_type("COMMAND_ACK").result == R.TEMPORARILY_REJECTED
    assert rig.board.commands() == []


@pytest.mark.parametrize(
    ("state", "why"),
    [
        ({"mode": bm.Mode.MANUAL}, "mode MANUAL, lever not UP"),
        ({"mode": bm.Mode.SAFE}, "mode SAFE"),
        ({"armed": False}, "not armed"),
        ({"phase": bm.Phase.HOST_LOST}, "failsafe HOST_LOST"),
        ({"phase": bm.Phase.ESTOP, "armed": False}, "failsafe ESTOP"),
        ({"phase": bm.Phase.GATE, "armed": False}, "start-up gate"),
    ],
)
def test_denied_unless_armed_ok_and_lever_up(
    make_rig: Callable[..., Rig], state: dict[str, Any], why: str
) -> None:
    rig = make_rig()
    rig.board.set(**state)
    rig.ready()
    rig.peer.gripper(GRAB)
    assert [a.result for a in rig.peer.acks_until_final()] == [R.DENIED]
    assert rig.peer.statustext(why).severity == mav.Severity.WARNING
    assert rig.board.commands() == []


def test_a_gripper_command_before_any_board_telemetry_waits_then_is_rejected_temporarily(
    make_rig: Callable[..., Rig],
) -> None:
    rig = make_rig(start_board=False, early_command_wait_us=200_000)
    rig.peer.recv_type("HEARTBEAT")
    rig.peer.gripper(GRAB)
    assert rig.peer.recv_type("COMMAND_ACK").result == R.TEMPORARILY_REJECTED
    assert rig.board.commands() == []


def test_denied_when_board_telemetry_stops(make_rig: Callable[..., Rig]) -> None:
    rig = make_rig(board_stale_us=100_000)
    rig.ready()
    rig.board.stop()
    rig.peer.recv_type("HEARTBEAT", lambda m: m.system_status == mav.MavState.CRITICAL)
    rig.peer.gripper(GRAB)
    assert rig.peer.recv_type("COMMAND_ACK").result == R.DENIED
    rig.peer.statustext("no board telemetry")


@pytest.mark.parametrize(("instance", "action"), [(25.0, 3.0), (25.0, 1.5), (7.0, 1.0), (float("nan"), 1.0)])
def test_bad_params_are_denied(make_rig: Callable[..., Rig], instance: float, action: float) -> None:
    rig = make_rig()
    rig.ready()
    rig.peer.gripper(action, instance=instance)
    assert rig.peer.recv_type("COMMAND_ACK").result == R.DENIED
    rig.peer.statustext("bad params")


def test_other_commands_are_unsupported_and_broadcasts_for_others_ignored(
    make_rig: Callable[..., Rig],
) -> None:
    rig = make_rig()
    rig.ready()
    rig.peer.command(183, 1, 1500, comp=0)  # DO_SET_SERVO broadcast: not ours to answer
    rig.peer.command(184, 1, 1500, comp=25)  # DO_REPEAT_SERVO to us: unsupported
    ack = rig.peer.recv_type("COMMAND_ACK")
    assert (ack.command, ack.result) == (184, R.UNSUPPORTED)


def test_commands_for_another_component_or_system_are_ignored(make_rig: Callable[..., Rig]) -> None:
    rig = make_rig()
    rig.ready()
    rig.peer.gripper(RELEASE, comp=26)  # if answered, an immediate ACCEPTED ("already IDLE")
    rig.peer.command(mav.MAV_CMD_DO_GRIPPER, 25, RELEASE, sys_=2)
    rig.peer.gripper(GRAB, comp=0)  # broadcast DO_GRIPPER is ours
    acks = rig.peer.acks_until_final()
    assert (acks[0].result, acks[-1].result) == (R.IN_PROGRESS, R.ACCEPTED)
    assert rig.link.counters.not_for_us >= 2


# --------------------------------------------------------------------------------------------------
# parameters


def test_param_list_read_and_set(make_rig: Callable[..., Rig]) -> None:
    rig = make_rig()
    rig.ready()
    rig.peer.conn.mav.param_request_list_send(1, 25)
    got: dict[str, Any] = {}
    while len(got) < len(PARAMS):
        m = rig.peer.recv_type("PARAM_VALUE")
        got[m.param_id] = m
    assert set(got) == {n.upper() for n in PARAMS}
    assert {m.param_index for m in got.values()} == set(range(len(PARAMS)))
    assert {m.param_count for m in got.values()} == {len(PARAMS)}
    assert {n: m.param_type for n, m in got.items()} == PARAM_TYPES  # typed by the firmware's table

    rig.peer.conn.mav.param_request_read_send(1, 25, b"grasp_wrap_n", -1)  # names match case-insensitively
    assert rig.peer.recv_type("PARAM_VALUE").param_id == "GRASP_WRAP_N"
    rig.peer.conn.mav.param_request_read_send(1, 25, b"", PARAMS.index("CURRENT_LIMIT_A"))
    assert rig.peer.recv_type("PARAM_VALUE").param_id == "CURRENT_LIMIT_A"

    rig.peer.conn.mav.param_set_send(1, 25, b"PRETENSION_N", 0.75, mav.ParamType.REAL32)
    m = rig.peer.recv_type("PARAM_VALUE", lambda m: m.param_id == "PRETENSION_N")
    assert m.param_value == 0.75
    assert rig.board.params["PRETENSION_N"] == 0.75
    assert bm.ParamSet("PRETENSION_N", 0.75) in rig.board.received


def test_param_set_answers_with_what_the_board_took(make_rig: Callable[..., Rig]) -> None:
    rig = make_rig()
    rig.ready()
    rig.peer.conn.mav.param_set_send(1, 25, b"TENSION_MAX_N", -5.0, mav.ParamType.REAL32)  # the board refuses
    m = rig.peer.recv_type("PARAM_VALUE", lambda m: m.param_id == "TENSION_MAX_N")
    assert m.param_value == 20.0
    rig.peer.conn.mav.param_set_send(1, 25, b"NO_SUCH_PARAM", 1.0, mav.ParamType.REAL32)
    rig.peer.statustext("NO_SUCH_PARAM unknown")
    rig.peer.conn.mav.param_set_send(1, 26, b"TENSION_MAX_N", 5.0, mav.ParamType.REAL32)  # not ours
    rig.peer.conn.mav.param_request_read_send(1, 25, b"TENSION_MAX_N", -1)
    m = rig.peer.recv_type("PARAM_VALUE", lambda m: m.param_id == "TENSION_MAX_N")
    assert m.param_value == 20.0


def test_param_set_before_any_list_is_answered_by_the_board(make_rig: Callable[..., Rig]) -> None:
    """A PARAM_SET before the mirror holds anything (no PARAM_REQUEST_LIST yet, a board slow to list)
    goes to the board, whose confirmation answers; it was answered "unknown"."""
    rig = make_rig(board_state={"answer_param_list": False})
    rig.ready()
    assert rig.link._params.known == 0
    rig.peer.conn.mav.param_set_send(1, 25, b"pretension_n", 0.75, mav.ParamType.REAL32)
    m = rig.peer.recv_type("PARAM_VALUE", lambda m: m.param_id == "PRETENSION_N")
    assert m.param_value == 0.75 and m.param_count == len(PARAMS)
    assert rig.board.params["PRETENSION_N"] == 0.75
    assert bm.ParamSet("PRETENSION_N", 0.75) in rig.board.received
    assert not [m for m in rig.peer.seen if m.get_type() == "STATUSTEXT" and "unknown" in m.text]
    # a name the firmware's table does not have is still unknown
    rig.peer.conn.mav.param_set_send(1, 25, b"NO_SUCH_PARAM", 1.0, mav.ParamType.REAL32)
    rig.peer.statustext("NO_SUCH_PARAM unknown")
    assert not [m for m in rig.board.received if isinstance(m, bm.ParamSet) and m.name == "NO_SUCH_PARAM"]


def test_param_read_right_after_a_set_waits_for_the_board(make_rig: Callable[..., Rig]) -> None:
    """A read of a parameter whose set the board has not confirmed yet gets the confirmed value."""
    rig = make_rig()
    rig.board.set(defer_param_set=True)
    rig.ready()
    rig.peer.conn.mav.param_request_read_send(1, 25, b"CURRENT_LIMIT_A", -1)  # past the start-up mirror
    rig.peer.recv_type("PARAM_VALUE", lambda m: m.param_id == "CURRENT_LIMIT_A")
    start = len(rig.peer.seen)
    rig.peer.conn.mav.param_set_send(1, 25, b"GRASP_WRAP_N", 12.0, mav.ParamType.REAL32)
    rig.peer.conn.mav.param_request_read_send(1, 25, b"GRASP_WRAP_N", -1)
    rig.peer.conn.mav.param_request_read_send(1, 25, b"", PARAMS.index("GRASP_WRAP_N"))  # the same, by index
    rig.peer.conn.mav.param_request_list_send(1, 25)
    rig.peer.conn.mav.param_request_read_send(1, 25, b"PRETENSION_N", -1)  # a marker
    rig.peer.recv_type("PARAM_VALUE", lambda m: m.param_id == "PRETENSION_N")
    rig.peer.recv_type("PARAM_VALUE", lambda m: m.param_id == PARAMS[-1])  # the list went out
    rig.peer.conn.mav.param_request_read_send(1, 25, b"TENSION_MAX_N", -1)  # a second marker
    rig.peer.recv_type("PARAM_VALUE", lambda m: m.param_id == "TENSION_MAX_N")
    assert not [
        m for m in rig.peer.seen[start:] if m.get_type() == "PARAM_VALUE" and m.param_id == "GRASP_WRAP_N"
    ]
    rig.board.confirm_param_sets()
    m = rig.peer.recv_type("PARAM_VALUE", lambda m: m.param_id == "GRASP_WRAP_N")
    assert m.param_value == 12.0


def test_param_set_the_board_never_confirms_gets_the_value_in_force(make_rig: Callable[..., Rig]) -> None:
    rig = make_rig(param_confirm_timeout_us=200_000)
    rig.board.set(answer_param_set=False)
    rig.ready()
    rig.peer.conn.mav.param_set_send(1, 25, b"GRASP_WRAP_N", 12.0, mav.ParamType.REAL32)
    rig.peer.statustext("GRASP_WRAP_N: board did not confirm")
    assert rig.board.params["GRASP_WRAP_N"] == 15.0  # the default: never taken


# --------------------------------------------------------------------------------------------------
# drone state in, link state for the panel


def test_drone_pose_and_peers(make_rig: Callable[..., Rig]) -> None:
    rig = make_rig()
    rig.ready()
    autopilot = mav.MavCodec(1, 1)
    rig.peer.send_raw(autopilot.encode(mav.Heartbeat(2, 3, 0, 0, mav.MavState.ACTIVE)))
    rig.peer.send_raw(autopilot.encode(mav.Attitude(10, 0.1, 0.2, 0.3)))
    rig.peer.send_raw(autopilot.encode(mav.LocalPositionNed(11, 1.0, 2.0, -3.0)))
    rig.peer.send_raw(mav.MavCodec(255, 190).encode(mav.Attitude(12, 9.0, 9.0, 9.0)))  # not the autopilot
    rig.peer.gripper(RELEASE)  # a marker: once answered, everything before it was handled
    rig.peer.recv_type("COMMAND_ACK")
    state = rig.link.state()
    assert state.drone.attitude is not None and state.drone.attitude.yaw_rad == pytest.approx(0.3)
    assert state.drone.position is not None and state.drone.position.z_m == -3.0
    peers = {(p.sysid, p.compid): p for p in state.peers}
    assert peers[(1, 1)].mav_type == 2 and peers[(1, 1)].autopilot == 3 and peers[(1, 1)].alive
    assert (255, 190) in peers
    assert state.last_command is not None and state.last_command.src_component == 190
    deadline = time.monotonic() + WAIT_S
    while rig.link.state().tx_rate_hz == 0.0 and time.monotonic() < deadline:
        time.sleep(0.05)
    assert rig.link.state().tx_rate_hz > 0.0


# --------------------------------------------------------------------------------------------------
# malformed and unexpected input


def test_malformed_and_unexpected_messages_are_counted_never_fatal(make_rig: Callable[..., Rig]) -> None:
    rig = make_rig()
    rig.ready()
    gcs = mav.MavCodec(255, 190)
    good = gcs.encode(mav.CommandLong(1, 25, 211, (25.0, 1.0, 0, 0, 0, 0, 0)))
    bad_crc = bytearray(good)
    bad_crc[-1] ^= 0xFF
    unknown = struct.pack("<BBBBBBBHB", 0xFD, 2, 0, 0, 0, 255, 190, 0xBEEF, 0x0A) + b"\x01\x02\x00\x00"
    for junk in (
        b"\x00" * 40,
        bytes(range(256)),
        good[:9],  # truncated datagram
        bytes(bad_crc),
        b"\xfd\xff" + bytes(20),  # a start marker with an impossible length
        unknown,
        gcs.encode(mav.CommandAck(211, 0)),  # unexpected: we send no commands
        gcs.encode(mav.NamedValueFloat(0, "X", 1.0)),  # unexpected
        mav.MavCodec(1, 25).encode(mav.Heartbeat(48)),  # someone using our ids
    ):
        rig.peer.send_raw(junk)
    rig.peer.gripper(GRAB)
    acks = rig.peer.acks_until_final()
    assert (acks[0].result, acks[-1].result) == (R.IN_PROGRESS, R.ACCEPTED)
    c = rig.link.counters
    assert c.malformed >= 4
    assert c.unknown_msg_id == 1
    assert c.unexpected >= 2
    assert c.own_id_conflicts == 1
    assert rig.link.running


def test_board_queue_overflow_is_counted() -> None:
    link = DroneLink(DroneLinkConfig(url="udpout:127.0.0.1:9"), lambda m: None)
    for i in range(5000):
        link.on_board_message(bm.Telemetry(i))
    assert link.counters.board_queue_dropped == 5000 - 4096
    link.close()
    link.close()  # safe twice
    with pytest.raises(DroneLinkError):
        link.start()


# --------------------------------------------------------------------------------------------------
# signing


def test_signed_link_refuses_unsigned_and_wrong_key(make_rig: Callable[..., Rig], tmp_path: Path) -> None:
    ts_path = tmp_path / "signing.timestamp"
    rig = make_rig(signing_key=KEY, signing_timestamp_path=ts_path, peer_key=KEY)
    rig.ready()
    hb = rig.peer.recv_type("HEARTBEAT", lambda m: m.get_srcComponent() == 25)
    assert hb.get_signed()  # verified by the peer with the same key
    # Unsigned, then wrongly signed, then correctly signed: only the last is answered.
    signing = rig.peer.conn.mav.signing
    signing.sign_outgoing = False
    rig.peer.command(184, comp=25)
    good_key, signing.secret_key, signing.sign_outgoing = signing.secret_key, bytes(32), True
    rig.peer.command(185, comp=25)
    signing.secret_key = good_key
    rig.peer.gripper(GRAB)
    ack = rig.peer.recv_type("COMMAND_ACK")
    assert (ack.command, ack.result) == (211, R.IN_PROGRESS)
    assert rig.peer.acks_until_final()[-1].result == R.ACCEPTED
    c = rig.link.counters
    assert c.signature_refused >= 2
    state = rig.link.state()
    assert state.signing and {p.signed for p in state.peers if p.compid == 190} == {True}
    rig.link.close()
    saved = int(ts_path.read_text())
    assert saved >= mav.signing_timestamp_from_unix_us(time.time_ns() // 1000) - 10**8


def test_signing_timestamp_survives_a_restart_even_if_the_clock_is_behind(tmp_path: Path) -> None:
    ts_path = tmp_path / "ts"
    future = mav.signing_timestamp_from_unix_us(4_000_000_000_000_000)  # year 2096
    ts_path.write_text(f"{future}\n")
    cfg = DroneLinkConfig(
        url=f"udpout:127.0.0.1:{free_udp_port()}", signing_key=KEY, signing_timestamp_path=ts_path
    )
    with DroneLink(cfg, lambda m: None) as link:
        assert link.signing_timestamp > future
    assert int(ts_path.read_text()) > future


def test_signing_key_file_and_config_helpers(tmp_path: Path) -> None:
    raw = tmp_path / "raw.key"
    raw.write_bytes(bytes(range(32)))
    assert load_signing_key(raw) == bytes(range(32))
    phrase = tmp_path / "phrase.key"
    phrase.write_text("spirob\n")
    cfg = DroneLinkConfig(url="udpout:127.0.0.1:9").with_signing_key_file(phrase)
    assert cfg.signing_key == KEY
    assert cfg.signing_timestamp_path == tmp_path / "phrase.key.timestamp"
    with pytest.raises(DroneLinkError):
        load_signing_key(tmp_path / "missing.key")


@pytest.mark.parametrize(
    "bad",
    [
        {"compid": 0},
        {"compid": 1},
        {"compid": 6},
        {"early_command_wait_us": 0},
        {"sysid": 0},
        {"telemetry_rate_hz": 0.0},
        {"signing_key": b"short"},
        {"url": ""},
        {"grasp_timeout_us": 0},
    ],
)
def test_config_validation(bad: dict[str, Any]) -> None:
    kwargs: dict[str, Any] = {"url": "udpout:127.0.0.1:9", **bad}
    with pytest.raises(ValueError):
        DroneLinkConfig(**kwargs)


def test_unopenable_connection_raises() -> None:
    link = DroneLink(DroneLinkConfig(url="udpin:203.0.113.1:1"), lambda m: None)  # not a local address
    with pytest.raises(DroneLinkError):
        link.start()
    link.close()


def test_gripper_denial_rules() -> None:
    from controller.grasp import grasp_refusal

    ok = bm.Telemetry(0, bm.Mode.GRASP, bm.Phase.OK, flags=bm.TelemetryFlags.ARMED)
    assert gripper_denial(ok, 0, 500_000) is None
    assert gripper_denial(ok, 600_000, 500_000) == "gripper denied: no board telemetry"
    assert gripper_denial(None, 0, 500_000) == "gripper denied: no board telemetry"
    # The board's own rule, word for word (one rule, one place: controller.grasp).
    for phase in bm.Phase:
        for mode in bm.Mode:
            for armed in (False, True):
                flags = bm.TelemetryFlags.ARMED if armed else bm.TelemetryFlags.NONE
                t = bm.Telemetry(0, mode, phase, flags=flags)
                why = grasp_refusal(phase, armed, mode)
                assert gripper_denial(t, 0, 500_000) == (None if why is None else f"gripper denied: {why}")


class ScriptedPort:
    """The board side of the drone link, answered by hand: every command's ``on_ack`` is kept."""

    def __init__(self, board: FakeBoard, sent_ok: bool = True) -> None:
        self.board = board
        self.sent_ok = sent_ok
        self.handlers: list[Callable[[bm.CommandAck | None], None]] = []
        self.sent: list[tuple[bm.Message, str]] = []

    def __call__(
        self,
        msg: bm.Message,
        *,
        origin: str = "host",
        on_ack: Callable[[bm.CommandAck | None], None] | None = None,
    ) -> bool:
        self.sent.append((msg, origin))
        if on_ack is not None:
            self.handlers.append(on_ack)
        return self.sent_ok


@pytest.fixture
def scripted(tmp_path: Path) -> Iterator[tuple[DroneLink, ScriptedPort, Peer]]:
    port = free_udp_port()
    peer = Peer(f"udpin:127.0.0.1:{port}")
    board = FakeBoard(ticks_per_phase=2)
    to_board = ScriptedPort(board)
    link = DroneLink(DroneLinkConfig(url=f"udpout:127.0.0.1:{port}", grasp_timeout_us=60_000_000), to_board)
    board.attach(link.on_board_message)
    board.start()
    link.start()
    try:
        peer.recv_type("HEARTBEAT", lambda m: m.get_srcComponent() == 25)
        peer.recv_type("NAMED_VALUE_FLOAT")
        yield link, to_board, peer
    finally:
        link.close()
        board.stop()
        peer.close()


def test_the_boards_final_answer_ends_the_job_not_telemetry(
    scripted: tuple[DroneLink, ScriptedPort, Peer],
) -> None:
    link, port, peer = scripted
    peer.gripper(GRAB)
    assert peer.recv_type("COMMAND_ACK").result == R.IN_PROGRESS
    ((cmd, origin),) = [(m, o) for m, o in port.sent if isinstance(m, bm.Command)]
    assert (cmd, origin) == (bm.Command(bm.CommandCode.GRASP), "MAVLink")
    # The fake board's telemetry never saw the command: it shows IDLE all along; the board answers
    # IN_PROGRESS, and the job is still running: telemetry does not end it.
    (answer,) = port.handlers
    answer(bm.CommandAck(bm.CommandCode.GRASP, bm.AckResult.IN_PROGRESS, 0, "grasping"))
    port.board.set(grasp_state=bm.GraspState.HOLD)  # not the board's answer either
    time.sleep(0.3)
    assert link.state().gripper_busy
    # The board's final word: FAILED with its reason, whatever telemetry shows.
    answer(bm.CommandAck(bm.CommandCode.GRASP, bm.AckResult.FAILED, 0, "superseded"))
    final = peer.recv_type("COMMAND_ACK", lambda m: m.result != R.IN_PROGRESS)
    assert (final.result, final.progress) == (R.FAILED, 0)
    peer.statustext("grab failed: superseded")
    assert _wait_until(lambda: not link.state().gripper_busy)
    # A late answer for a job that ended changes nothing.
    answer(bm.CommandAck(bm.CommandCode.GRASP, bm.AckResult.ACCEPTED, 0, "holding"))
    last = link.state().last_command
    assert last is not None and last.result == R.FAILED


def test_a_board_refusal_or_a_lost_link_fails_the_job_with_its_reason(
    scripted: tuple[DroneLink, ScriptedPort, Peer],
) -> None:
    link, port, peer = scripted
    peer.gripper(GRAB)
    assert peer.recv_type("COMMAND_ACK").result == R.IN_PROGRESS
    # The board's gate shut between the telemetry and the command: the board's rule decides.
    refusal = bm.CommandAck(bm.CommandCode.GRASP, bm.AckResult.REJECTED, 0, "mode MANUAL, lever not UP")
    port.handlers[-1](refusal)
    assert peer.recv_type("COMMAND_ACK").result == R.FAILED
    peer.statustext("grab failed: mode MANUAL, lever not UP")
    assert _wait_until(lambda: not link.state().gripper_busy)
    peer.gripper(GRAB)
    assert peer.recv_type("COMMAND_ACK").result == R.IN_PROGRESS
    port.handlers[-1](None)  # the board link went down: the command can have no answer
    assert peer.recv_type("COMMAND_ACK").result == R.FAILED
    peer.statustext("grab failed: board link lost")
    # A command that cannot go out at all fails at once (no IN_PROGRESS first).
    assert _wait_until(lambda: not link.state().gripper_busy)
    port.sent_ok = False
    peer.gripper(GRAB)
    assert peer.recv_type("COMMAND_ACK").result == R.FAILED
    peer.statustext("grab failed: the board link is down")


def _wait_until(cond: Callable[[], bool], timeout_s: float = WAIT_S) -> bool:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if cond():
            return True
        time.sleep(0.01)
    return cond()


# --------------------------------------------------------------------------------------------------
# .tlog


def test_tlog_holds_both_directions_and_mavlogdump_reads_it(
    make_rig: Callable[..., Rig], tmp_path: Path
) -> None:
    path = tmp_path / "run.tlog"
    rig = make_rig(tlog_path=path)
    rig.ready()
    rig.peer.conn.mav.heartbeat_send(6, 8, 0, 0, 0)
    rig.peer.gripper(GRAB)
    rig.peer.acks_until_final()
    rig.link.close()
    records = rig.link.counters.tlog_records
    assert records > 0

    log = mavutil.mavlink_connection(str(path))
    seen: set[tuple[str, int, int]] = set()
    for _ in range(records + 1):
        m = log.recv_match()
        if m is None:
            break
        seen.add((m.get_type(), m.get_srcSystem(), m.get_srcComponent()))
    log.close()
    assert {
        ("HEARTBEAT", 1, 25),
        ("HEARTBEAT", 255, 190),
        ("COMMAND_LONG", 255, 190),
        ("COMMAND_ACK", 1, 25),
    } <= seen

    data = path.read_bytes()
    links, offset = set(), 0
    codec = mav.MavCodec(255, 190)
    while offset < len(data):
        (stamp,) = struct.unpack_from(">Q", data, offset)
        length = data[offset + 9] + 12 + (13 if data[offset + 10] & 1 else 0)
        (pkt,) = codec.feed(data[offset + 8 : offset + 8 + length])
        links.add((stamp & 3, pkt.src_component))
        offset += 8 + length
    assert links == {(TLOG_LINK_OUT, 25), (TLOG_LINK_IN, 190)}

    mavlogdump = Path(sys.executable).with_name("mavlogdump.py")
    out = subprocess.run(
        ["timeout", "60", sys.executable, str(mavlogdump), "--types", "COMMAND_LONG,COMMAND_ACK", str(path)],
        capture_output=True,
        text=True,
        check=True,
    ).stdout
    assert "COMMAND_LONG" in out and "COMMAND_ACK" in out and "command : 211" in out


def test_a_stream_transport_works_too() -> None:
    """tcp: a byte stream, where packets may arrive split (no datagram boundaries)."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = int(s.getsockname()[1])
    peer = Peer(f"tcpin:127.0.0.1:{port}")
    board = FakeBoard()
    to_board = GripperBoard(board)
    link = DroneLink(DroneLinkConfig(url=f"tcp:127.0.0.1:{port}"), to_board)
    to_board.attach(link.on_board_message)
    board.start()
    try:
        link.start()
        peer.recv_type("NAMED_VALUE_FLOAT")
        peer.gripper(GRAB)
        acks = peer.acks_until_final()
        assert (acks[0].result, acks[-1].result) == (R.IN_PROGRESS, R.ACCEPTED)
        assert link.counters.malformed == 0
    finally:
        link.close()
        board.stop()
        peer.close()
