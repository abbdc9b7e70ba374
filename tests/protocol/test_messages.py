"""Tests for protocol.messages: every board-link message's layout, round trips and the docs."""

from __future__ import annotations

import dataclasses
import math
import re
import struct
from pathlib import Path
from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from protocol.dbus import RcFrame
from protocol.errors import DecodeError, UnknownMessageError
from protocol.link import MAX_PAYLOAD, LinkFrame, LinkParser, crc8, crc16, encode_frame
from protocol.messages import (
    ACK_TEXT_MAX,
    ARMS_MOTORS_MAX,
    EVENT_TEXT_MAX,
    HOST_TO_BOARD_MAX_PAYLOAD,
    MAX_SIM_BODIES,
    MAX_TASKS,
    MESSAGES,
    AckResult,
    ArmBlocker,
    ArmPoses,
    ArmsTelemetry,
    BoardStatus,
    ClockKind,
    Command,
    CommandAck,
    CommandCode,
    Direction,
    Event,
    EventKind,
    GraspState,
    Heartbeat,
    Message,
    Mode,
    MotorFrames,
    ParamRequest,
    ParamSet,
    ParamValue,
    Phase,
    RawRc,
    SimPoses,
    TaskStats,
    Telemetry,
    TelemetryFlags,
    VirtualRc,
    decode,
    encode,
    truncate_utf8,
)

SETTINGS = settings(max_examples=200, deadline=None)
DOC = Path(__file__).resolve().parents[2] / "docs" / "board-link.md"

EXPECTED_IDS = {
    Telemetry: 0x0101,
    RawRc: 0x0102,
    MotorFrames: 0x0103,
    Event: 0x0104,
    ParamValue: 0x0105,
    SimPoses: 0x0106,
    BoardStatus: 0x0107,
    CommandAck: 0x0108,
    ArmsTelemetry: 0x0109,
    ArmPoses: 0x010A,
    Heartbeat: 0x0201,
    VirtualRc: 0x0202,
    Command: 0x0203,
    ParamRequest: 0x0204,
    ParamSet: 0x0205,
}

# --- strategies -----------------------------------------------------------------------------------

u8 = st.integers(0, 0xFF)
u16 = st.integers(0, 0xFFFF)
i16 = st.integers(-0x8000, 0x7FFF)
u32 = st.integers(0, 0xFFFF_FFFF)
i32 = st.integers(-(2**31), 2**31 - 1)
u64 = st.integers(0, 2**64 - 1)
f32 = st.floats(width=32, allow_nan=False)
v3i16 = st.tuples(i16, i16, i16)
v3f = st.tuples(f32, f32, f32)
name16 = st.text(st.characters(min_codepoint=1, max_codepoint=127), max_size=16)
name12 = st.text(st.characters(min_codepoint=1, max_codepoint=127), max_size=12)


def utf8_text(max_bytes: int) -> st.SearchStrategy[str]:
    return st.text(max_size=max_bytes).filter(lambda s: len(s.encode()) <= max_bytes)


_LAYOUTS = [(a, c) for c in (1, 2, 3) for a in range(1, 9) if a * c <= ARMS_MOTORS_MAX]
"""(arms, cables per arm) of every layout an ArmsTelemetry can carry."""

STRATEGIES: dict[type[Message], st.SearchStrategy[Any]] = {
    Telemetry: st.builds(
        Telemetry,
        time_us=u64,
        mode=st.sampled_from(Mode),
        phase=st.sampled_from(Phase),
        grasp_state=st.sampled_from(GraspState),
        flags=u8.map(TelemetryFlags),
        motors_online=u8,
        rc_channels=st.tuples(i16, i16, i16, i16),
        right_lever=u8,
        left_lever=u8,
        motor_angle=st.tuples(u16, u16, u16),
        motor_speed_rpm=v3i16,
        motor_current=v3i16,
        commanded_current=v3i16,
        tension_target_n=v3f,
        tension_est_n=v3f,
        cable_length_m=v3f,
        control_late=u32,
        control_exec_p99_us=u16,
        control_exec_max_us=u16,
        control_lateness_max_us=u32,
        rc_frames_ok=u32,
        rc_rejected=u32,
        dbus_bytes_dropped=u32,
        link_frames_ok=u32,
        link_crc_errors=u32,
        motor_offline_events=u32,
        can_errors=u32,
        control_lateness_p99_us=u16,
        arm_blocker=st.sampled_from(ArmBlocker),
    ),
    RawRc: st.builds(RawRc, u64, st.binary(min_size=18, max_size=18)),
    MotorFrames: st.builds(
        MotorFrames,
        u64,
        st.tuples(*[st.tuples(u16, st.binary(min_size=8, max_size=8))] * 3),
    ),
    Event: st.builds(Event, u64, st.sampled_from(EventKind), i32, f32, utf8_text(EVENT_TEXT_MAX)),
    ParamValue: st.builds(ParamValue, u16, u16, name16, f32),
    SimPoses: st.integers(0, MAX_SIM_BODIES).flatmap(
        lambda n: st.builds(
            SimPoses,
            u64,
            st.lists(v3f, min_size=n, max_size=n).map(tuple),
            st.lists(st.tuples(f32, f32, f32, f32), min_size=n, max_size=n).map(tuple),
        )
    ),
    BoardStatus: st.builds(
        BoardStatus,
        u64,
        name16,
        st.sampled_from(ClockKind),
        st.lists(st.builds(TaskStats, name12, u32, u32, u32, u32, u32, u32), max_size=MAX_TASKS).map(tuple),
    ),
    CommandAck: st.builds(
        CommandAck, st.one_of(st.sampled_from(CommandCode), u8), st.sampled_from(AckResult), u8, utf8_text(48)
    ),
    ArmsTelemetry: st.sampled_from(
        [(a, c) for c in (1, 2, 3) for a in range(1, 9) if a * c <= ARMS_MOTORS_MAX]
    ).flatmap(
        lambda ac: st.builds(
            ArmsTelemetry,
            u64,
            st.just(ac[0]),
            st.just(ac[1]),
            *[
                st.lists(e, min_size=ac[0] * ac[1], max_size=ac[0] * ac[1]).map(tuple)
                for e in (u16, i16, i16, i16, f32, f32, f32, st.booleans())
            ],
        )
    ),
    ArmPoses: st.integers(1, ARMS_MOTORS_MAX).flatmap(
        lambda arms: st.tuples(st.integers(0, arms - 1), st.integers(0, MAX_SIM_BODIES)).flatmap(
            lambda an: st.builds(
                ArmPoses,
                u64,
                st.just(an[0]),
                st.just(arms),
                st.lists(v3f, min_size=an[1], max_size=an[1]).map(tuple),
                st.lists(st.tuples(f32, f32, f32, f32), min_size=an[1], max_size=an[1]).map(tuple),
            )
        )
    ),
    Heartbeat: st.builds(Heartbeat, u64, u32),
    VirtualRc: st.builds(VirtualRc, st.binary(min_size=18, max_size=18)),
    Command: st.builds(Command, st.sampled_from(CommandCode), v3f),
    ParamRequest: st.builds(ParamRequest, st.integers(-2, 0x7FFF), name16),
    ParamSet: st.builds(ParamSet, name16, f32),
}

any_message = st.one_of(*STRATEGIES.values())


# --- registry and ids -----------------------------------------------------------------------------


def test_registry_is_complete_and_ids_are_stable() -> None:
    assert {cls: cls.CMD_ID for cls in MESSAGES.values()} == EXPECTED_IDS
    assert set(STRATEGIES) == set(MESSAGES.values())
    for cls in MESSAGES.values():
        expected = Direction.BOARD_TO_HOST if cls.CMD_ID >> 8 == 0x01 else Direction.HOST_TO_BOARD
        assert cls.DIRECTION is expected, cls.__name__
        assert dataclasses.is_dataclass(cls)
        assert cls.__dataclass_params__.frozen


def test_host_to_board_max_payload() -> None:
    host_to_board = [c for c in MESSAGES.values() if c.DIRECTION is Direction.HOST_TO_BOARD]
    assert max(len(_sample(c).pack()) for c in host_to_board) == HOST_TO_BOARD_MAX_PAYLOAD


def test_wire_enum_values() -> None:
    assert [m.value for m in Mode] == [0, 1, 2, 3]
    assert [int(c) for c in CommandCode] == list(range(1, 12))
    assert [m.name for m in Phase] == ["GATE", "OK", "RC_LOST", "MOTOR_FAULT", "HOST_LOST", "ESTOP"]
    assert [m.name for m in GraspState] == ["IDLE", "REACH", "WRAP", "HOLD", "RELEASE", "FAILED"]
    assert [int(m) for m in Phase] == list(range(6))
    assert [int(m) for m in GraspState] == list(range(6))
    # AckResult values are MAVLink's MAV_RESULT values.
    assert (AckResult.ACCEPTED, AckResult.REJECTED, AckResult.DENIED) == (0, 1, 2)
    assert (AckResult.UNSUPPORTED, AckResult.FAILED, AckResult.IN_PROGRESS) == (3, 4, 5)


# --- golden bytes ---------------------------------------------------------------------------------


def _ref_crc(data: bytes, poly: int, init: int) -> int:
    crc = init
    for byte in data:
        crc ^= byte
        for _ in range(8):
            crc = (crc >> 1) ^ poly if crc & 1 else crc >> 1
    return crc


def ref_frame(cmd_id: int, payload: bytes, seq: int) -> bytes:
    head = bytes([0xA5, len(payload) & 0xFF, len(payload) >> 8, seq])
    body = head + bytes([_ref_crc(head, 0x8C, 0xFF)]) + bytes([cmd_id & 0xFF, cmd_id >> 8]) + payload
    crc = _ref_crc(body, 0x8408, 0xFFFF)
    return body + bytes([crc & 0xFF, crc >> 8])


def test_golden_heartbeat_frame() -> None:
    msg = Heartbeat(host_time_us=0x0102030405060708, counter=9)
    payload = bytes.fromhex("080706050403020109000000")
    assert msg.pack() == payload
    assert encode(msg, 0x2A) == ref_frame(0x0201, payload, 0x2A)
    assert (
        encode(msg, 0x2A)[:7]
        == bytes.fromhex("a50c002a") + bytes([crc8(bytes.fromhex("a50c002a"))]) + b"\x01\x02"
    )


def test_golden_command_frame() -> None:
    msg = Command(CommandCode.SET_MODE, (1.0, 0.0, -2.5))
    payload = bytes.fromhex("080000803f00000000000020c0")
    assert msg.pack() == payload
    frame = encode(msg, 0)
    assert frame == ref_frame(0x0203, payload, 0)
    assert decode(LinkParser().feed(frame)[0]) == msg


def test_golden_hold_lengths_command() -> None:
    # HOLD_LENGTHS: NaN = unchanged, -inf = release, +inf = hold at the present length, finite = set-point.
    msg = Command(CommandCode.HOLD_LENGTHS, (math.nan, -math.inf, 0.125))
    payload = bytes.fromhex("0b0000c07f000080ff0000003e")
    assert msg.pack() == payload
    frame = encode(msg, 7)
    assert frame == ref_frame(0x0203, payload, 7)
    back = decode(LinkParser().feed(frame)[0])
    assert isinstance(back, Command) and back.code is CommandCode.HOLD_LENGTHS
    assert math.isnan(back.args[0]) and back.args[1] == -math.inf and back.args[2] == 0.125
    assert Command(CommandCode.HOLD_LENGTHS, (math.inf, math.nan, math.nan)).pack()[1:5] == bytes.fromhex(
        "0000807f"
    )


@given(st.tuples(*[st.one_of(st.just(math.inf), st.just(-math.inf), f32)] * 3))
def test_hold_lengths_round_trips(args: tuple[float, float, float]) -> None:
    msg = Command(CommandCode.HOLD_LENGTHS, args)
    assert decode(LinkParser().feed(encode(msg, 3))[0]) == msg


def test_golden_hold_flags() -> None:
    assert (TelemetryFlags.HOLD_1, TelemetryFlags.HOLD_2, TelemetryFlags.HOLD_3) == (0x20, 0x40, 0x80)
    assert Telemetry(time_us=0, flags=TelemetryFlags.HOLD_1 | TelemetryFlags.HOLD_3).pack()[11] == 0xA0


def test_golden_telemetry_payload() -> None:
    msg = Telemetry(
        time_us=1_000_000,
        mode=Mode.MANUAL,
        phase=Phase.OK,
        grasp_state=GraspState.IDLE,
        flags=TelemetryFlags.ARMED | TelemetryFlags.RC_OK,
        motors_online=0b111,
        rc_channels=(660, -660, 0, 1),
        right_lever=3,
        left_lever=2,
        motor_angle=(8191, 0, 1),
        motor_speed_rpm=(-1, 2, 3),
        motor_current=(100, 200, 300),
        commanded_current=(-3000, 0, 3000),
        tension_target_n=(1.0, 2.0, 0.5),
        tension_est_n=(0.0, -1.0, 4.0),
        cable_length_m=(0.25, 0.0, -0.125),
        control_late=7,
        control_exec_p99_us=40,
        control_exec_max_us=300,
        control_lateness_max_us=1234,
        rc_frames_ok=10,
        rc_rejected=1,
        dbus_bytes_dropped=2,
        link_frames_ok=3,
        link_crc_errors=4,
        motor_offline_events=5,
        can_errors=6,
        control_lateness_p99_us=29,
        arm_blocker=ArmBlocker.LEVER_NOT_DOWN,
    )
    payload = msg.pack()
    assert len(payload) == 126
    expected = (
        bytes.fromhex("40420f0000000000")  # time_us
        + bytes([1, 1, 0, 0b1001, 0b111])  # mode, phase, grasp_state, flags, motors_online
        + struct.pack("<4h", 660, -660, 0, 1)
        + bytes([3, 2])
        + bytes.fromhex("ff1f00000100")  # motor_angle u16
        + bytes.fromhex("ffff02000300")
        + bytes.fromhex("6400c8002c01")
        + bytes.fromhex("48f40000b80b")
        + bytes.fromhex("0000803f000000400000003f")
        + bytes.fromhex("00000000000080bf00008040")
        + bytes.fromhex("0000803e00000000000000be")
        + bytes.fromhex("0700000028002c01d2040000")
        + b"".join(struct.pack("<I", n) for n in (10, 1, 2, 3, 4, 5, 6))
        + bytes.fromhex("1d00")  # control_lateness_p99_us, u16
        + bytes([2])  # arm_blocker, last
    )
    assert payload == expected
    assert Telemetry.unpack(payload) == msg


def test_golden_event_and_ack_payloads() -> None:
    ev = Event(time_us=5, kind=EventKind.PHASE, code=2, value=0.5, text="RC lost")
    assert ev.pack() == bytes.fromhex("050000000000000002020000000000003f07") + b"RC lost"
    ack = CommandAck(CommandCode.ARM, AckResult.DENIED, 17, "no")
    assert ack.pack() == bytes([1, 2, 17, 2]) + b"no"


def test_golden_param_payloads() -> None:
    pv = ParamValue(index=2, count=9, name="spool_radius_m", value=0.5)
    assert pv.pack() == bytes.fromhex("02000900") + b"spool_radius_m\0\0" + bytes.fromhex("0000003f")
    assert ParamRequest(-1, "x").pack() == bytes.fromhex("ffff") + b"x" + bytes(15)
    assert ParamRequest().pack() == bytes.fromhex("feff") + bytes(16)
    assert ParamSet("a" * 16, 1.0).pack() == b"a" * 16 + bytes.fromhex("0000803f")


def test_golden_status_and_poses_layouts() -> None:
    st_ = BoardStatus(1, "0.1.0", ClockKind.LOCKSTEP, (TaskStats("control", 1000, 5, 1, 90, 40, 12),))
    assert st_.pack() == (
        struct.pack("<Q", 1)
        + b"0.1.0".ljust(16, b"\0")
        + bytes([2, 1])
        + b"control".ljust(12, b"\0")
        + struct.pack("<6I", 1000, 5, 1, 90, 40, 12)
    )
    poses = SimPoses(3, ((0.0, 0.0, 1.0), (1.0, 2.0, 3.0)), ((1.0, 0.0, 0.0, 0.0), (0.0, 1.0, 0.0, 0.0)))
    assert poses.pack() == struct.pack("<QB", 3, 2) + struct.pack(
        "<14f", 0, 0, 1, 1, 0, 0, 0, 1, 2, 3, 0, 1, 0, 0
    )
    assert poses.tip_position_m == (1.0, 2.0, 3.0)


def test_golden_arms_telemetry() -> None:
    """Two one-cable arms: the head (time, arms, cables per arm, motors) then 21 bytes per motor."""
    msg = ArmsTelemetry(
        5, 2, 1, (1, 2), (3, -4), (5, 6), (7, 8), (1.5, 2.5), (0.5, 0.25), (0.125, 0.0), (True, False)
    )
    assert msg.pack().hex() == (
        "0500000000000000" "020102"
        "0100" "0300" "0500" "0700" "0000c03f" "0000003f" "0000003e" "01"
        "0200" "fcff" "0600" "0800" "00002040" "0000803e" "00000000" "00"
    )  # fmt: skip
    assert ArmsTelemetry.unpack(msg.pack()) == msg
    with pytest.raises(ValueError, match="one value per motor"):
        ArmsTelemetry(
            5, 2, 1, (1, 2), (3,), (5, 6), (7, 8), (1.5, 2.5), (0.5, 0.25), (0.1, 0.0), (True, False)
        ).pack()
    with pytest.raises(ValueError, match="arms x cables"):
        ArmsTelemetry(
            5, 3, 1, (1, 2), (3, 4), (5, 6), (7, 8), (1.5, 2.5), (0.5, 0.25), (0.1, 0.0), (True, False)
        ).pack()


def test_golden_arm_poses() -> None:
    """Arm 2 of 4, two units: the head (time, arm, arms, units) then 28 bytes per unit as in SimPoses."""
    msg = ArmPoses(7, 2, 4, ((0.0, 0.0, 1.0), (1.0, 2.0, 3.0)), ((1.0, 0.0, 0.0, 0.0), (0.0, 1.0, 0.0, 0.0)))
    assert msg.pack().hex() == (
        "0700000000000000" "020402"
        "00000000" "00000000" "0000803f" "0000803f" "00000000" "00000000" "00000000"
        "0000803f" "00000040" "00004040" "00000000" "0000803f" "00000000" "00000000"
    )  # fmt: skip
    assert ArmPoses.unpack(msg.pack()) == msg
    assert msg.tip_position_m == (1.0, 2.0, 3.0)
    # The units' bytes are SimPoses' bodies' bytes: one codec for a pose on the wire.
    simposes = SimPoses(7, msg.positions_m, msg.quats_wxyz).pack()
    assert msg.pack()[11:] == simposes[9:]


def test_golden_motor_frames_and_rc() -> None:
    fb = bytes.fromhex("1fff03e8ff382400")
    mf = MotorFrames(9, ((0x201, fb), (0x202, fb), (0, bytes(8))))
    assert mf.pack() == struct.pack("<Q", 9) + b"\x01\x02" + fb + b"\x02\x02" + fb + b"\x00\x00" + bytes(8)
    neutral = RcFrame.neutral().pack()
    assert RawRc(4, neutral).pack() == struct.pack("<Q", 4) + neutral
    assert RawRc(4, neutral).frame == RcFrame.neutral()
    vrc = VirtualRc.from_frame(RcFrame.neutral())
    assert vrc.pack() == neutral
    assert vrc.frame == RcFrame.neutral()


# --- round trips ----------------------------------------------------------------------------------


@SETTINGS
@given(any_message, u8)
def test_every_message_round_trips(msg: Message, seq: int) -> None:
    payload = msg.pack()
    assert len(payload) <= MAX_PAYLOAD
    assert type(msg).unpack(payload) == msg
    frame = encode(msg, seq)
    (parsed,) = LinkParser().feed(frame)
    assert parsed == LinkFrame(msg.CMD_ID, seq, payload)
    assert decode(parsed) == msg


def _floats(obj: Any) -> list[float]:
    if isinstance(obj, float):
        return [obj]
    if isinstance(obj, tuple):
        return [x for item in obj for x in _floats(item)]
    if dataclasses.is_dataclass(obj):
        return [x for f in dataclasses.fields(obj) for x in _floats(getattr(obj, f.name))]
    return []


@SETTINGS
@given(st.sampled_from(sorted(MESSAGES)), st.data())
def test_payload_bytes_round_trip_or_decode_error(cmd_id: int, data: st.DataObject) -> None:
    """Random payloads of a plausible length either decode to a message that re-packs to the same bytes,
    or raise DecodeError: nothing else escapes."""
    cls = MESSAGES[cmd_id]
    size = len(data.draw(STRATEGIES[cls]).pack())
    payload = data.draw(st.binary(min_size=max(0, size - 2), max_size=size + 2))
    try:
        msg = cls.unpack(payload)
    except DecodeError:
        return
    if any(math.isnan(x) for x in _floats(msg)):
        return  # a NaN's payload bits need not survive the float32 -> float -> float32 trip
    assert msg.pack() == payload


@pytest.mark.parametrize("cls", list(EXPECTED_IDS))
def test_wrong_length_is_a_decode_error(cls: type[Message]) -> None:
    payload = _sample(cls).pack()
    for bad in (payload + b"\0", payload[:-1], b""):
        with pytest.raises(DecodeError):
            cls.unpack(bad)


def _sample(cls: type[Message]) -> Message:
    samples: dict[type[Message], Message] = {
        Telemetry: Telemetry(time_us=1),
        RawRc: RawRc(1, bytes(18)),
        MotorFrames: MotorFrames(1, ((0, bytes(8)),) * 3),
        Event: Event(1, EventKind.INFO, text="hi"),
        ParamValue: ParamValue(0, 1, "a", 1.0),
        SimPoses: SimPoses(1, ((0.0, 0.0, 0.0),), ((1.0, 0.0, 0.0, 0.0),)),
        BoardStatus: BoardStatus(1, "v", ClockKind.REALTIME_FIFO, (TaskStats("c", 1000),)),
        CommandAck: CommandAck(CommandCode.ARM, AckResult.ACCEPTED, 0, "ok"),
        ArmsTelemetry: ArmsTelemetry(1, 1, 1, (0,), (0,), (0,), (0,), (0.0,), (0.0,), (0.0,), (False,)),
        ArmPoses: ArmPoses(1, 1, 2, ((0.0, 0.0, 0.0),), ((1.0, 0.0, 0.0, 0.0),)),
        Heartbeat: Heartbeat(1, 2),
        VirtualRc: VirtualRc(bytes(18)),
        Command: Command(CommandCode.ARM),
        ParamRequest: ParamRequest(-1, "a"),
        ParamSet: ParamSet("a", 1.0),
    }
    return samples[cls]


@pytest.mark.parametrize(
    ("cls", "payload"),
    [
        (Telemetry, bytes(8) + b"\x09" + bytes(115)),  # mode 9
        (Telemetry, bytes(9) + b"\x06" + bytes(114)),  # phase 6
        (Telemetry, bytes(125) + b"\x07"),  # arm_blocker 7
        (Command, bytes(13)),  # code 0
        (Event, bytes(8) + b"\xc8" + bytes(9)),  # kind 200
        (Event, bytes(17) + b"\x41" + bytes(65)),  # text longer than 64
        (Event, bytes(17) + b"\x02\xff\xfe"),  # text not UTF-8
        (CommandAck, b"\x01\x09\x00\x00"),  # result 9
        (ParamSet, b"ab\0c" + bytes(16)),  # junk after the NUL
        (ParamSet, b"\xe9" + bytes(19)),  # not ASCII
        (ParamRequest, b"\xfd\xff" + bytes(16)),  # index -3
        (SimPoses, bytes(8) + bytes([MAX_SIM_BODIES + 1]) + bytes(28 * (MAX_SIM_BODIES + 1))),
        (ArmsTelemetry, bytes(8) + bytes([9, 1, 9]) + bytes(21 * 9)),  # nine motors
        (ArmsTelemetry, bytes(8) + bytes([2, 2, 3]) + bytes(21 * 3)),  # 2 arms x 2 cables is not 3
        (ArmsTelemetry, bytes(8) + bytes([1, 4, 4]) + bytes(21 * 4)),  # 4 cables per arm
        (ArmsTelemetry, bytes(8) + bytes([1, 1, 1]) + bytes(20) + b"\x02"),  # hold 2
        (ArmPoses, bytes(8) + bytes([2, 2, 0])),  # arm 2 of 2 (arms count from 0)
        (ArmPoses, bytes(8) + bytes([0, 0, 0])),  # no arms
        (ArmPoses, bytes(8) + bytes([0, 9, 0])),  # nine arms
        (ArmPoses, bytes(8) + bytes([1, 2, MAX_SIM_BODIES + 1]) + bytes(28 * (MAX_SIM_BODIES + 1))),
        (ArmPoses, bytes(8) + bytes([1, 2, 2]) + bytes(28)),  # two units said, one sent
        (BoardStatus, bytes(24) + b"\x03\x00"),  # clock kind 3
        (BoardStatus, bytes(24) + b"\x00" + bytes([MAX_TASKS + 1])),
    ],
)
def test_bad_values_are_decode_errors(cls: type[Message], payload: bytes) -> None:
    with pytest.raises(DecodeError):
        cls.unpack(payload)


def test_command_ack_keeps_unknown_command_codes() -> None:
    ack = CommandAck.unpack(bytes([200, AckResult.UNSUPPORTED, 5, 0]))
    assert ack.command == 200 and ack.result is AckResult.UNSUPPORTED
    assert CommandAck.unpack(bytes([3, 0, 5, 0])).command is CommandCode.ESTOP


def test_unknown_cmd_id() -> None:
    with pytest.raises(UnknownMessageError):
        decode(LinkFrame(0x0999, 0, b""))
    with pytest.raises(DecodeError):
        decode(LinkFrame(0x0999, 0, b""))


@pytest.mark.parametrize(
    "msg",
    [
        Event(1, EventKind.INFO, text="x" * (EVENT_TEXT_MAX + 1)),
        CommandAck(CommandCode.ARM, AckResult.ACCEPTED, 0, "é" * 25),
        ParamSet("a" * 17, 0.0),
        ParamSet("é", 0.0),
        ParamSet("a\0b", 0.0),
        ParamRequest(-3, ""),
        RawRc(0, bytes(17)),
        VirtualRc(bytes(19)),
        MotorFrames(0, ((0, bytes(8)), (0, bytes(8)), (0, bytes(7)))),
        SimPoses(0, ((0.0, 0.0, 0.0),), ()),
        SimPoses(0, ((0.0, 0.0, 0.0),) * 65, ((1.0, 0.0, 0.0, 0.0),) * 65),
        ArmPoses(0, 0, 2, ((0.0, 0.0, 0.0),), ()),
        ArmPoses(0, 2, 2, (), ()),
        ArmPoses(0, 0, ARMS_MOTORS_MAX + 1, (), ()),
        ArmPoses(0, -1, 2, (), ()),
        ArmPoses(0, 0, 2, ((0.0, 0.0, 0.0),) * 65, ((1.0, 0.0, 0.0, 0.0),) * 65),
        BoardStatus(0, "v" * 17, ClockKind.LOCKSTEP),
        BoardStatus(0, "v", ClockKind.LOCKSTEP, (TaskStats("x" * 13, 1),)),
        BoardStatus(0, "v", ClockKind.LOCKSTEP, (TaskStats("x", 1),) * (MAX_TASKS + 1)),
        Heartbeat(-1, 0),
        Heartbeat(0, 2**32),
        Command(CommandCode.ARM, (1e39, 0.0, 0.0)),
        Telemetry(time_us=0, rc_channels=(0, 0, 0)),  # type: ignore[arg-type]
        Telemetry(time_us=0, motor_current=(0, 0, 40000)),
        Telemetry(time_us=-1),
    ],
)
def test_unpackable_fields_are_value_errors(msg: Message) -> None:
    with pytest.raises(ValueError):
        msg.pack()


def test_telemetry_saturates_u16_exec_times() -> None:
    t = Telemetry.unpack(Telemetry(time_us=0, control_exec_p99_us=70_000, control_exec_max_us=10**6).pack())
    assert (t.control_exec_p99_us, t.control_exec_max_us) == (0xFFFF, 0xFFFF)


def test_telemetry_saturates_u16_lateness_p99() -> None:
    t = Telemetry.unpack(Telemetry(time_us=0, control_lateness_p99_us=2**32 - 1).pack())
    assert t.control_lateness_p99_us == 0xFFFF
    with pytest.raises(ValueError):
        Telemetry(time_us=0, control_lateness_p99_us=-1).pack()


def test_truncate_utf8() -> None:
    assert truncate_utf8("abc", 3) == "abc"
    assert truncate_utf8("abcd", 3) == "abc"
    assert truncate_utf8("aé", 2) == "a"  # never splits a character
    long = "ü" * 40
    assert len(truncate_utf8(long, ACK_TEXT_MAX).encode()) == ACK_TEXT_MAX
    Event(0, EventKind.INFO, text=truncate_utf8("ß" * 100, EVENT_TEXT_MAX)).pack()


def test_encode_checks_seq() -> None:
    with pytest.raises(ValueError):
        encode(Heartbeat(0, 0), 256)


def test_crc_helpers_used_by_frames_agree() -> None:
    frame = encode(Heartbeat(1, 1), 1)
    assert crc8(frame[:4]) == frame[4]
    assert crc16(frame[:-2]) == int.from_bytes(frame[-2:], "little")
    assert frame == encode_frame(0x0201, Heartbeat(1, 1).pack(), 1)


# --- documentation agrees with the code -----------------------------------------------------------


def _doc_sections() -> dict[str, str]:
    text = DOC.read_text(encoding="utf-8")
    parts = re.split(r"^### ", text, flags=re.MULTILINE)
    return {p.split("\n", 1)[0].strip(): p for p in parts[1:]}


def test_doc_summary_table_lists_every_message() -> None:
    text = DOC.read_text(encoding="utf-8")
    rows = re.findall(r"^\| `(0x[0-9A-F]{4})` \| \[`(\w+)`\]", text, flags=re.MULTILINE)
    assert {name: int(cid, 16) for cid, name in rows} == {c.__name__: c.CMD_ID for c in MESSAGES.values()}


def _layout_rows(section: str) -> list[tuple[int, int, str]]:
    """(offset, size, field) rows of a section's layout table; offsets of repeated parts are relative."""
    rows = re.findall(r"^\| (\d+) \| (\d+) \| [^|]+ \| `([\w\[\].]+)`", section, flags=re.MULTILINE)
    return [(int(o), int(s), f) for o, s, f in rows]


@pytest.mark.parametrize("cls", list(EXPECTED_IDS))
def test_doc_layout_matches_code(cls: type[Message]) -> None:
    sections = _doc_sections()
    title = next((t for t in sections if t.lower().startswith(f"`{cls.CMD_ID:#06x}`")), None)
    assert title is not None, f"no section for {cls.__name__}"
    assert cls.__name__ in title
    section = sections[title]
    rows = _layout_rows(section)
    assert rows, f"no layout table for {cls.__name__}"
    # Offsets are contiguous within each table block (a repeated part restarts at 0).
    expected = 0
    for offset, size, _ in rows:
        if offset == 0:
            expected = 0
        assert offset == expected, (cls.__name__, offset)
        expected = offset + size
    documented = {f.split("[")[0].split(".")[0] for _, _, f in rows}
    for field in dataclasses.fields(cls):  # type: ignore[arg-type]
        assert field.name in documented, (cls.__name__, field.name)
    fixed = re.search(r"Payload: (\d+) bytes\.", section)
    if fixed is not None:
        assert len(_sample(cls).pack()) == int(fixed.group(1))
        assert rows[-1][0] + rows[-1][1] == int(fixed.group(1))
