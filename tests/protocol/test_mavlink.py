"""protocol.mavlink: golden bytes, round trips, a byte stream fed in pieces, signing, helpers."""

from __future__ import annotations

import hashlib
import math
import os
import struct

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from protocol import mavlink as mav

KEY = mav.signing_key_from_passphrase("spirob")
T0 = mav.signing_timestamp_from_unix_us(1_750_000_000_000_000)


def x25(data: bytes) -> int:
    """CRC-16/MCRF4XX as MAVLink computes it (written out here, independent of pymavlink)."""
    crc = 0xFFFF
    for b in data:
        tmp = b ^ (crc & 0xFF)
        tmp = (tmp ^ (tmp << 4)) & 0xFF
        crc = ((crc >> 8) ^ (tmp << 8) ^ (tmp << 3) ^ (tmp >> 4)) & 0xFFFF
    return crc


def v2_packet(seq: int, sysid: int, compid: int, msg_id: int, payload: bytes, crc_extra: int) -> bytes:
    """A MAVLink 2 packet built by hand: trailing zero bytes of the payload are trimmed."""
    trimmed = payload.rstrip(b"\x00") or payload[:1]
    header = struct.pack(
        "<BBBBBBBHB", 0xFD, len(trimmed), 0, 0, seq, sysid, compid, msg_id & 0xFFFF, msg_id >> 16
    )
    body = header + trimmed
    return body + struct.pack("<H", x25(body[1:] + bytes([crc_extra])))


def crc_extra(name: str) -> int:
    return int(getattr(mav.dialect(), f"MAVLink_{name}_message").crc_extra)


# --------------------------------------------------------------------------------------------------
# environment and constants


def test_mavlink2_is_forced() -> None:
    assert os.environ["MAVLINK20"] == "1"
    assert str(mav.dialect().WIRE_PROTOCOL_VERSION) == "2.0"
    assert mav.MAV_TYPE_ARM == 48  # MAV_TYPE_GRIPPER is in the default "all" dialect
    assert mav.MAV_AUTOPILOT_INVALID == 8
    assert mav.MAV_CMD_DO_GRIPPER == 211
    assert mav.DEFAULT_COMPONENT_ID == 25


def test_enums_match_the_dialect() -> None:
    d = mav.dialect()
    for r in mav.MavResult:
        assert getattr(d, f"MAV_RESULT_{r.name}") == r
    for a in mav.GripperAction:
        assert getattr(d, f"GRIPPER_ACTION_{a.name}") == a
    for s in mav.Severity:
        assert getattr(d, f"MAV_SEVERITY_{s.name}") == s
    for t in mav.ParamType:
        assert getattr(d, f"MAV_PARAM_TYPE_{t.name}") == t
    for st_ in mav.MavState:
        assert getattr(d, f"MAV_STATE_{st_.name}") == st_
    assert mav.MavResult.COMMAND_LONG_ONLY == d.MAV_RESULT_COMMAND_LONG_ONLY
    assert mav.MIN_COMPONENT_ID == 7


# --------------------------------------------------------------------------------------------------
# golden bytes


def test_heartbeat_golden_bytes() -> None:
    codec = mav.MavCodec(1, 25)
    got = codec.encode(mav.Heartbeat(mav.MAV_TYPE_ARM, mav.MAV_AUTOPILOT_INVALID, 0, 0, mav.MavState.STANDBY))
    payload = struct.pack("<IBBBBB", 0, 48, 8, 0, 3, 3)
    assert got == v2_packet(0, 1, 25, 0, payload, crc_extra("heartbeat"))
    assert got.hex() == "fd09000000011900000000000000300800030391ea"


def test_command_ack_golden_bytes_and_sequence() -> None:
    codec = mav.MavCodec(1, 25)
    codec.encode(mav.Heartbeat(48))  # seq 0
    got = codec.encode(mav.CommandAck(211, mav.MavResult.IN_PROGRESS, 30, 0, 255, 230))
    payload = struct.pack("<HBBiBB", 211, 5, 30, 0, 255, 230)
    assert got == v2_packet(1, 1, 25, 77, payload, crc_extra("command_ack"))


def test_command_long_and_named_value_golden_bytes() -> None:
    codec = mav.MavCodec(255, 230)
    got = codec.encode(mav.CommandLong(1, 25, 211, (25.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0)))
    payload = struct.pack("<7fHBBB", 25.0, 1.0, 0, 0, 0, 0, 0, 211, 1, 25, 0)
    assert got == v2_packet(0, 255, 230, 76, payload, crc_extra("command_long"))
    got = codec.encode(mav.NamedValueFloat(1234, "ARM_T1_N", 2.5))
    payload = struct.pack("<If10s", 1234, 2.5, b"ARM_T1_N")
    assert got == v2_packet(1, 255, 230, 251, payload, crc_extra("named_value_float"))


def test_encoding_matches_pymavlinks_own_encoder() -> None:
    codec = mav.MavCodec(1, 25)
    d = mav.dialect()

    class Sink:
        data = b""

        def write(self, b: bytes) -> None:
            self.data += bytes(b)

    sink = Sink()
    ref = d.MAVLink(sink, srcSystem=1, srcComponent=25)
    ref.param_value_send(b"PRETENSION_N", 0.5, 9, 5, 0)
    assert codec.encode(mav.ParamValue("PRETENSION_N", 0.5, mav.ParamType.REAL32, 5, 0)) == sink.data


# --------------------------------------------------------------------------------------------------
# round trips

f32 = st.floats(width=32, allow_nan=False)
u8 = st.integers(0, 255)
u16 = st.integers(0, 0xFFFF)
u32 = st.integers(0, 0xFFFFFFFF)
name10 = st.text(st.characters(min_codepoint=33, max_codepoint=126), min_size=1, max_size=10)
name16 = st.text(st.characters(min_codepoint=33, max_codepoint=126), min_size=1, max_size=16)

messages = st.one_of(
    st.builds(mav.Heartbeat, u8, u8, u8, u32, u8, u8),
    st.builds(mav.CommandLong, u8, u8, u16, st.tuples(f32, f32, f32, f32, f32, f32, f32), u8),
    st.builds(mav.CommandAck, u16, u8, u8, st.integers(-(2**31), 2**31 - 1), u8, u8),
    st.builds(mav.NamedValueFloat, u32, name10, f32),
    st.builds(
        mav.ActuatorOutputStatus, st.integers(0, 2**64 - 1), u32, st.lists(f32, max_size=32).map(tuple)
    ),
    st.builds(
        mav.StatusText, u8, st.text(st.characters(min_codepoint=32, max_codepoint=126), max_size=50), u16, u8
    ),
    st.builds(mav.ParamRequestList, u8, u8),
    st.builds(mav.ParamRequestRead, u8, u8, name16, st.integers(-1, 2**15 - 1)),
    st.builds(mav.ParamValue, name16, f32, st.integers(1, 10), u16, u16),
    st.builds(mav.ParamSet, u8, u8, name16, f32, st.integers(1, 10)),
    st.builds(mav.Attitude, u32, f32, f32, f32, f32, f32, f32),
    st.builds(mav.LocalPositionNed, u32, f32, f32, f32, f32, f32, f32),
    st.builds(
        mav.CommandInt,
        u8,
        u8,
        u16,
        st.tuples(f32, f32, f32, f32),
        st.integers(-(2**31), 2**31 - 1),
        st.integers(-(2**31), 2**31 - 1),
        f32,
        u8,
    ),
    st.builds(mav.ServoOutputRaw, u32, u8, st.lists(u16, min_size=16, max_size=16).map(tuple)),
    st.builds(mav.AutopilotVersion, st.integers(0, 2**64 - 1), u32, u16, u16),
    st.builds(mav.ProtocolVersion, u16, u16, u16),
)


def normalised(msg: mav.MavMessage) -> mav.MavMessage:
    """What a receiver sees: actuator arrays come back with all 32 slots, trailing text spaces kept."""
    if isinstance(msg, mav.ActuatorOutputStatus):
        return mav.ActuatorOutputStatus(
            msg.time_usec, msg.active, msg.actuator + (0.0,) * (32 - len(msg.actuator))
        )
    return msg


@settings(max_examples=300, deadline=None)
@given(messages, st.integers(1, 255), st.integers(1, 255))
def test_every_message_round_trips(msg: mav.MavMessage, sysid: int, compid: int) -> None:
    tx, rx = mav.MavCodec(sysid, compid), mav.MavCodec(255, 190)
    raw = tx.encode(msg)
    assert raw[0] == 0xFD  # MAVLink 2
    (pkt,) = rx.feed(raw)
    assert normalised(pkt.msg) == normalised(msg)
    assert (pkt.src_system, pkt.src_component, pkt.seq, pkt.signed, pkt.raw) == (sysid, compid, 0, False, raw)


@settings(max_examples=100, deadline=None)
@given(st.lists(messages, min_size=1, max_size=6), st.data())
def test_stream_split_anywhere_yields_every_packet(msgs: list[mav.MavMessage], data: st.DataObject) -> None:
    tx, rx = mav.MavCodec(1, 25), mav.MavCodec(255, 190)
    stream = b"".join(tx.encode(m) for m in msgs)
    cuts = sorted(data.draw(st.lists(st.integers(0, len(stream)), max_size=8)))
    got: list[mav.MavPacket] = []
    for a, b in zip([0, *cuts], [*cuts, len(stream)], strict=True):
        got += rx.feed(stream[a:b])
    assert [normalised(p.msg) for p in got] == [normalised(m) for m in msgs]
    assert rx.malformed == 0


def test_half_packet_gap_garbage_then_good_packet() -> None:
    tx, rx = mav.MavCodec(1, 25), mav.MavCodec(255, 190)
    good = tx.encode(mav.StatusText(6, "hello"))
    assert rx.feed(good[:7]) == []
    assert rx.discard_partial() == 7  # a datagram boundary: leftovers are garbage
    assert rx.feed(b"\x00\x13garbage\xfe\x01" + good)[0].msg == mav.StatusText(6, "hello")
    assert rx.malformed >= 2


@settings(max_examples=200, deadline=None)
@given(st.binary(max_size=300))
def test_random_bytes_never_raise(data: bytes) -> None:
    rx = mav.MavCodec(255, 190)
    rx.feed(data)
    rx.feed(data[::-1])
    good = mav.MavCodec(1, 25).encode(mav.Heartbeat(48))
    rx.discard_partial()
    assert [p.msg for p in rx.feed(good)] == [mav.Heartbeat(48)]


@settings(max_examples=300, deadline=None)
@given(st.binary(max_size=120), messages)
def test_a_good_packet_after_garbage_is_always_delivered(garbage: bytes, msg: mav.MavMessage) -> None:
    good = mav.MavCodec(1, 25).encode(msg)
    rx = mav.MavCodec(255, 190)
    # Trailing filler lets a false start marker in the garbage run out of bytes and be rescanned.
    got = rx.feed(garbage + good + bytes(300))
    assert normalised(msg) in [normalised(p.msg) for p in got if p.raw == good]


def test_every_single_bit_flip_is_rejected() -> None:
    good = mav.MavCodec(1, 25).encode(mav.CommandLong(1, 25, 211, (25.0, 1.0, 0, 0, 0, 0, 0)))
    for bit in range(len(good) * 8):
        bad = bytearray(good)
        bad[bit // 8] ^= 1 << (bit % 8)
        rx = mav.MavCodec(255, 190)
        got = rx.feed(bytes(bad))
        assert all(isinstance(p.msg, mav.Unhandled) for p in got), f"bit {bit} delivered {got}"


def test_unknown_message_id_is_counted_not_delivered() -> None:
    raw = v2_packet(0, 1, 1, 0xABCDE, b"\x01\x02\x03", 0)
    good = mav.MavCodec(1, 25).encode(mav.Heartbeat(48))
    rx = mav.MavCodec(255, 190)
    assert [p.msg for p in rx.feed(raw + good)] == [mav.Heartbeat(48)]
    assert rx.unknown_ids == 1


def test_messages_outside_our_set_decode_as_unhandled() -> None:
    d = mav.dialect()

    class Sink:
        data = b""

        def write(self, b: bytes) -> None:
            self.data += bytes(b)

    sink = Sink()
    d.MAVLink(sink, srcSystem=1, srcComponent=1).system_time_send(1, 2)
    (pkt,) = mav.MavCodec(255, 190).feed(sink.data)
    assert pkt.msg == mav.Unhandled("SYSTEM_TIME", 2)


def test_mavlink1_packets_are_still_understood() -> None:
    d = mav.dialect()

    class Sink:
        data = b""

        def write(self, b: bytes) -> None:
            self.data += bytes(b)

    sink = Sink()
    d.MAVLink(sink, srcSystem=1, srcComponent=1).heartbeat_send(2, 3, 0, 0, 4, force_mavlink1=True)
    assert sink.data[0] == 0xFE
    (pkt,) = mav.MavCodec(255, 190).feed(sink.data)
    assert pkt.msg == mav.Heartbeat(2, 3, 0, 0, 4, 3)


# --------------------------------------------------------------------------------------------------
# validation


@pytest.mark.parametrize(
    "msg",
    [
        mav.NamedValueFloat(0, "ELEVENCHARS", 1.0),
        mav.NamedValueFloat(0, "tensión", 1.0),
        mav.ParamSet(1, 25, "X" * 17, 1.0),
        mav.StatusText(6, "x" * 51),
        mav.Heartbeat(256),
        mav.CommandAck(211, 5, 0, 0, 300, 0),
        mav.ActuatorOutputStatus(0, 33, (0.0,) * 33),
    ],
)
def test_out_of_range_fields_raise_value_error(msg: mav.MavMessage) -> None:
    with pytest.raises(ValueError):
        mav.MavCodec(1, 25).encode(msg)


def test_bad_codec_ids_and_unencodable_messages() -> None:
    with pytest.raises(ValueError):
        mav.MavCodec(0, 25)
    with pytest.raises(ValueError):
        mav.MavCodec(1, 256)
    with pytest.raises(TypeError):
        mav.MavCodec(1, 25).encode(mav.Unhandled("X", 1))


# --------------------------------------------------------------------------------------------------
# STATUSTEXT chunks


def test_short_statustext_is_one_chunk() -> None:
    assert mav.statustext_chunks(4, "grasp failed", 9) == [mav.StatusText(4, "grasp failed")]


def test_long_statustext_is_chunked_and_terminated() -> None:
    chunks = mav.statustext_chunks(6, "a" * 100, 7)
    assert [(c.text_id, c.chunk_seq, len(c.text)) for c in chunks] == [(7, 0, 50), (7, 1, 50), (7, 2, 0)]
    chunks = mav.statustext_chunks(6, "é" + "b" * 60, 8)
    assert "".join(c.text for c in chunks) == "?" + "b" * 60
    for c in chunks:
        mav.MavCodec(1, 25).encode(c)


# --------------------------------------------------------------------------------------------------
# signing


def test_passphrase_key_is_sha256_like_mavproxy() -> None:
    assert mav.signing_key_from_passphrase("spirob") == hashlib.sha256(b"spirob").digest()
    try:
        from MAVProxy.modules.mavproxy_signing import SigningModule
    except ImportError:  # MAVProxy is a test extra; the hashlib check above is the contract
        return
    assert SigningModule.passphrase_to_key(None, "spirob") == KEY  # type: ignore[arg-type]


def test_key_file_content_rules() -> None:
    raw = bytes(range(32))
    assert mav.signing_key_from_file_bytes(raw) == raw
    assert mav.signing_key_from_file_bytes(b"spirob\n") == KEY
    with pytest.raises(ValueError):
        mav.signing_key_from_file_bytes(b"  \n")
    with pytest.raises(ValueError):
        mav.signing_key_from_file_bytes(b"\xff\xfe")


def test_signing_timestamp_units() -> None:
    assert mav.signing_timestamp_from_unix_us(mav.SIGNING_EPOCH_UNIX_S * 1_000_000) == 0
    assert mav.signing_timestamp_from_unix_us((mav.SIGNING_EPOCH_UNIX_S + 1) * 1_000_000) == 100_000
    assert mav.signing_timestamp_from_unix_us(0) == 0


def signed_pair() -> tuple[mav.MavCodec, mav.MavCodec]:
    tx, rx = mav.MavCodec(255, 230), mav.MavCodec(1, 25)
    tx.enable_signing(KEY, timestamp=T0, link_id=1)
    rx.enable_signing(KEY, timestamp=T0)
    return tx, rx


def test_signed_packets_verify_and_advance_the_timestamp() -> None:
    tx, rx = signed_pair()
    raw = tx.encode(mav.CommandLong(1, 25, 211, (25.0, 1.0, 0, 0, 0, 0, 0)))
    assert raw[2] & 0x01 and len(raw) == 10 + raw[1] + 2 + 13
    assert tx.signing_timestamp == T0 + 1
    (pkt,) = rx.feed(raw)
    assert pkt.signed and rx.signatures_good == 1
    tx.advance_signing_timestamp(T0 - 5)  # never backwards
    assert tx.signing_timestamp == T0 + 1


def test_unsigned_wrong_key_and_replayed_packets_are_refused() -> None:
    tx, rx = signed_pair()
    unsigned = mav.MavCodec(255, 230).encode(mav.CommandLong(1, 25, 211, (25.0, 1.0, 0, 0, 0, 0, 0)))
    assert rx.feed(unsigned) == []
    wrong = mav.MavCodec(255, 230)
    wrong.enable_signing(mav.signing_key_from_passphrase("nope"), timestamp=T0)
    assert rx.feed(wrong.encode(mav.Heartbeat(6))) == []
    good = tx.encode(mav.Heartbeat(6))
    assert len(rx.feed(good)) == 1
    assert rx.feed(good) == []  # replay: same timestamp
    assert rx.signature_refused == 3
    assert rx.malformed == 0


def test_a_forged_future_timestamp_does_not_lock_out_the_real_sender() -> None:
    tx, rx = signed_pair()
    assert len(rx.feed(tx.encode(mav.Heartbeat(6)))) == 1
    forger = mav.MavCodec(255, 230)
    forger.enable_signing(mav.signing_key_from_passphrase("nope"), timestamp=T0 + 10**12, link_id=1)
    assert rx.feed(forger.encode(mav.Heartbeat(6))) == []
    assert len(rx.feed(tx.encode(mav.Heartbeat(6)))) == 1


def test_allow_unsigned_callback_and_radio_status_default() -> None:
    rx = mav.MavCodec(1, 25)
    rx.enable_signing(KEY, timestamp=T0)
    d = mav.dialect()

    class Sink:
        data = b""

        def write(self, b: bytes) -> None:
            self.data += bytes(b)

    sink = Sink()
    d.MAVLink(sink, srcSystem=51, srcComponent=68).radio_status_send(1, 2, 3, 4, 5, 6, 7)
    assert len(rx.feed(sink.data)) == 1  # radios cannot sign: MAVProxy's default allow-list
    rx.enable_signing(KEY, timestamp=T0, allow_unsigned=lambda msg_id: msg_id == 0)
    assert len(rx.feed(mav.MavCodec(1, 1).encode(mav.Heartbeat(2)))) == 1
    rx.disable_signing()
    assert not rx.signing_enabled
    assert len(rx.feed(mav.MavCodec(1, 1).encode(mav.StatusText(6, "x")))) == 1


@pytest.mark.parametrize("key", [b"short", bytes(33)])
def test_bad_signing_keys_raise(key: bytes) -> None:
    with pytest.raises(ValueError):
        mav.MavCodec(1, 25).enable_signing(key, timestamp=0)


def test_float_fields_survive_as_float32() -> None:
    rx = mav.MavCodec(255, 190)
    (pkt,) = rx.feed(mav.MavCodec(1, 1).encode(mav.Attitude(5, 0.1, -0.2, math.pi)))
    assert isinstance(pkt.msg, mav.Attitude)
    assert pkt.msg.roll_rad == pytest.approx(0.1, abs=1e-7)
    assert pkt.msg.yaw_rad == pytest.approx(math.pi, abs=1e-6)


# --------------------------------------------------------------------------------------------------
# PROTOCOL_VERSION (not generated by pymavlink) and the parameter value encodings


def test_protocol_version_golden_bytes() -> None:
    raw = mav.MavCodec(1, 25).encode(mav.ProtocolVersion(200, 100, 200))
    payload = struct.pack("<HHH8s8s", 200, 100, 200, bytes(8), bytes(8))
    assert raw == v2_packet(0, 1, 25, 300, payload, 217)  # 217: MAVLink's CRC extra for PROTOCOL_VERSION


def test_command_int_as_command_long() -> None:
    ci = mav.CommandInt(1, 25, mav.MAV_CMD_DO_GRIPPER, (25.0, 1.0, 0.0, 0.0), 3, -4, 5.0)
    assert ci.as_long() == mav.CommandLong(1, 25, 211, (25.0, 1.0, 0.0, 0.0, 3.0, -4.0, 5.0))


@pytest.mark.parametrize(
    ("ptype", "value", "raw"),
    [
        (mav.ParamType.UINT8, 1, b"\x01\x00\x00\x00"),
        (mav.ParamType.INT8, -2, b"\xfe\x00\x00\x00"),
        (mav.ParamType.UINT16, 0xBEEF, b"\xef\xbe\x00\x00"),
        (mav.ParamType.INT16, -2, b"\xfe\xff\x00\x00"),
        (mav.ParamType.UINT32, 30_000_001, struct.pack("<I", 30_000_001)),
        (mav.ParamType.INT32, 30_000_001, struct.pack("<i", 30_000_001)),
    ],
)
def test_bytewise_encoding_puts_the_integer_bytes_in_the_float(
    ptype: mav.ParamType, value: int, raw: bytes
) -> None:
    wire = mav.encode_param_value(value, ptype, bytewise=True)
    assert struct.pack("<f", wire) == raw
    assert mav.decode_param_value(wire, ptype, bytewise=True) == value  # exact, even above 2^24
    # Through a real packet (float32 on the wire) too.
    (pkt,) = mav.MavCodec(255, 190).feed(mav.MavCodec(1, 25).encode(mav.ParamValue("X", wire, ptype, 1, 0)))
    assert isinstance(pkt.msg, mav.ParamValue)
    assert mav.decode_param_value(pkt.msg.param_value, ptype, bytewise=True) == value


def test_c_cast_encoding_and_float_parameters_pass_through() -> None:
    assert mav.encode_param_value(7, mav.ParamType.INT32, bytewise=False) == 7.0
    assert mav.decode_param_value(7.0, mav.ParamType.INT32, bytewise=False) == 7.0
    assert mav.encode_param_value(0.25, mav.ParamType.REAL32, bytewise=True) == 0.25
    # A sender that casts says REAL32: the value is taken as it is even in bytewise mode.
    assert mav.decode_param_value(40_000.0, mav.ParamType.REAL32, bytewise=True) == 40_000.0


def test_param_encoding_clamps_and_never_raises() -> None:
    assert mav.param_type_range(mav.ParamType.UINT8) == (0, 255)
    assert mav.param_type_range(mav.ParamType.INT16) == (-32768, 32767)
    assert mav.param_type_range(mav.ParamType.REAL32) is None
    wire = mav.encode_param_value(300, mav.ParamType.UINT8, bytewise=True)
    assert mav.decode_param_value(wire, mav.ParamType.UINT8, bytewise=True) == 255
    assert math.isnan(mav.decode_param_value(1.0, 99, bytewise=True))  # not a MAV_PARAM_TYPE
    assert math.isnan(mav.decode_param_value(1e300, mav.ParamType.INT32, bytewise=True))  # not a float32
