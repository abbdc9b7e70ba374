"""Tests for protocol.session: the host's end of the board link, driven with times and bytes only."""

from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from protocol.dbus import FRAME_PERIOD_US, Lever, RcFrame
from protocol.link import LinkParser
from protocol.messages import (
    HEARTBEAT_PERIOD_US,
    HOLD_HERE,
    HOLD_RELEASE,
    HOLD_UNCHANGED,
    PARAM_INDEX_BY_NAME,
    AckResult,
    Command,
    CommandAck,
    CommandCode,
    Event,
    EventKind,
    Heartbeat,
    Message,
    Mode,
    ParamRequest,
    ParamSet,
    ParamValue,
    Phase,
    Telemetry,
    TelemetryFlags,
    VirtualRc,
    decode,
    encode,
)
from protocol.session import HostSession, next_slot

SETTINGS = settings(max_examples=100, deadline=None)
RC = RcFrame((0, 0, 0, 300), Lever.MIDDLE, Lever.DOWN).pack()
MS = 1000


def _frames(data: bytes) -> list[tuple[int, Message]]:
    return [(f.seq, decode(f)) for f in LinkParser().feed(data)]


def _telemetry(t_us: int) -> Telemetry:
    return Telemetry(
        time_us=t_us,
        mode=Mode.MANUAL,
        phase=Phase.OK,
        flags=TelemetryFlags.ARMED | TelemetryFlags.RC_OK,
        motors_online=0b111,
        rc_channels=(0, 0, 0, 0),
        right_lever=Lever.MIDDLE,
        left_lever=Lever.DOWN,
        motor_angle=(1, 2, 3),
        motor_speed_rpm=(0, 0, 0),
        motor_current=(0, 0, 0),
        commanded_current=(0, 0, 0),
        tension_target_n=(1.0, 1.0, 1.0),
        tension_est_n=(1.0, 1.0, 1.0),
        cable_length_m=(0.0, 0.0, 0.0),
        control_late=0,
        control_exec_p99_us=10,
        control_exec_max_us=20,
        control_lateness_max_us=5,
        rc_frames_ok=1,
        link_frames_ok=1,
    )


# --- golden bytes ---------------------------------------------------------------------------------


def test_golden_heartbeat_and_command_bytes() -> None:
    session = HostSession()
    session.poll(0)
    assert session.data_to_send() == bytes.fromhex("a50c0000780102" + "00" * 12 + "461c")
    session.command(CommandCode.ARM, now_us=5)
    assert session.data_to_send() == bytes.fromhex("a50d00018d030201" + "00" * 12 + "7dcf")
    assert session.data_to_send() == b""  # taken once


def test_parameter_requests() -> None:
    session = HostSession(heartbeats=False)
    session.request_params(0)
    session.request_params(0, PARAM_INDEX_BY_NAME, "tension_max")
    session.set_param("tension_max", 9.5, 0)
    assert [m for _, m in _frames(session.data_to_send())] == [
        ParamRequest(),
        ParamRequest(PARAM_INDEX_BY_NAME, "tension_max"),
        ParamSet("tension_max", 9.5),
    ]


# --- seq ------------------------------------------------------------------------------------------


def test_every_frame_takes_the_next_seq_and_it_wraps() -> None:
    session = HostSession(heartbeats=False)
    for i in range(300):
        assert session.send(Heartbeat(i, i), i) == i & 0xFF
    seqs = [seq for seq, _ in _frames(session.data_to_send())]
    assert seqs == [i & 0xFF for i in range(300)]
    assert session.next_seq == 300 & 0xFF


def test_unpackable_message_uses_no_seq() -> None:
    session = HostSession(heartbeats=False)
    with pytest.raises(ValueError):
        session.send(ParamSet("a name much too long for the wire", 1.0), 0)
    assert session.next_seq == 0 and session.sent == [] and session.data_to_send() == b""


# --- the lockstep schedule ------------------------------------------------------------------------


def _reference_scripted_host(ticks: int, script: list[tuple[int, Message]], blocked: range) -> bytes:
    """The lockstep host as it was before the session: its own seq, heartbeat clock and script."""
    out = bytearray()
    seq = 0
    next_hb = 0
    count = 0
    pending = list(script)
    for t in range(0, ticks * MS, MS):
        if t >= next_hb:
            next_hb = t + HEARTBEAT_PERIOD_US
            if t not in blocked:
                out += encode(Heartbeat(t, count), seq)
                seq = (seq + 1) & 0xFF
                count += 1
        while pending and pending[0][0] <= t:
            out += encode(pending.pop(0)[1], seq)
            seq = (seq + 1) & 0xFF
    return bytes(out)


def test_lockstep_bytes_equal_the_scripted_host_schedule() -> None:
    script: list[tuple[int, Message]] = [
        (0, Command(CommandCode.ARM)),
        (100 * MS, Command(CommandCode.SET_MODE, (float(Mode.DIRECT), 0.0, 0.0))),
        (250 * MS, ParamSet("tension_max", 8.0)),
        (250 * MS, Command(CommandCode.HOLD)),
    ]
    blocked = range(300 * MS, 600 * MS)
    session = HostSession(heartbeat_allowed=lambda t: t not in blocked)
    pending = list(script)
    out = bytearray()
    for t in range(0, 1200 * MS, MS):
        session.poll(t)
        while pending and pending[0][0] <= t:
            session.send(pending.pop(0)[1], t)
        out += session.data_to_send()
    assert bytes(out) == _reference_scripted_host(1200, script, blocked)


def test_blocked_heartbeat_passes_its_slot_and_keeps_the_count() -> None:
    allowed = [True]
    session = HostSession(heartbeat_allowed=lambda t: allowed[0])
    session.poll(0)
    allowed[0] = False
    session.poll(HEARTBEAT_PERIOD_US)
    allowed[0] = True
    session.poll(HEARTBEAT_PERIOD_US + 1)  # the blocked slot is not retried
    session.poll(2 * HEARTBEAT_PERIOD_US)
    beats = [m for _, m in _frames(session.data_to_send())]
    assert beats == [Heartbeat(0, 0), Heartbeat(2 * HEARTBEAT_PERIOD_US, 1)]
    assert session.last_heartbeat_us == 2 * HEARTBEAT_PERIOD_US
    assert session.heartbeats_sent == 2


def test_no_heartbeats_when_disabled() -> None:
    session = HostSession(heartbeats=False)
    for t in range(0, 500 * MS, MS):
        session.poll(t)
    assert session.data_to_send() == b"" and session.next_deadline_us() is None


# --- RC slots -------------------------------------------------------------------------------------


def test_rc_slots_are_a_grid_from_the_first_poll_and_missed_slots_are_skipped() -> None:
    slots: list[int] = []

    def source(slot_us: int) -> bytes:
        slots.append(slot_us)
        return RC

    session = HostSession(heartbeats=False, rc_source=source)
    p = FRAME_PERIOD_US
    for t in (1_000, 1_000 + p - 1, 1_000 + p, 1_000 + 4 * p + 5, 1_000 + 5 * p - 1, 1_000 + 5 * p):
        session.poll(t)
    # Late at 4p: one frame (for the first slot missed, 2p), then the grid resumes at 5p; no burst.
    assert slots == [1_000, 1_000 + p, 1_000 + 2 * p, 1_000 + 5 * p]
    assert session.next_rc_slot_us() == 1_000 + 6 * p
    frames = _frames(session.rc_to_send())
    assert [m for _, m in frames] == [VirtualRc(RC)] * 4
    assert session.rc_frames_sent == 4 and session.last_rc_us == 1_000 + 5 * p
    assert session.data_to_send() == b"" and session.sent == []  # RC is kept apart from link traffic


def test_fixed_rc_frame_and_none() -> None:
    session = HostSession(heartbeats=False)
    session.poll(0)
    assert session.rc_to_send() == b""  # nothing set: no RC
    session.set_rc(RC)
    session.poll(FRAME_PERIOD_US)
    session.set_rc(None)
    session.poll(2 * FRAME_PERIOD_US)
    assert [m for _, m in _frames(session.rc_to_send())] == [VirtualRc(RC)]


def test_source_returning_none_passes_the_slot() -> None:
    session = HostSession(heartbeats=False, rc_source=lambda slot_us: None if slot_us == 0 else RC)
    session.poll(0)
    session.poll(1)
    assert session.rc_to_send() == b""
    session.poll(FRAME_PERIOD_US)
    assert len(_frames(session.rc_to_send())) == 1


def test_bad_fixed_rc_frame_is_refused_at_once() -> None:
    session = HostSession()
    with pytest.raises(ValueError):
        session.set_rc(b"short")


def test_heartbeat_before_rc_in_one_poll_and_the_seq_order_across_queues() -> None:
    session = HostSession(rc_source=lambda slot_us: RC)
    session.poll(0)
    assert [seq for seq, _ in _frames(session.data_to_send())] == [0]
    assert [seq for seq, _ in _frames(session.rc_to_send())] == [1]


def test_next_deadline() -> None:
    session = HostSession(rc_source=lambda slot_us: RC)
    assert session.next_deadline_us() == 0
    session.poll(10)
    assert session.next_deadline_us() == 10 + FRAME_PERIOD_US
    hb_only = HostSession()
    hb_only.poll(10)
    assert hb_only.next_deadline_us() == 10 + HEARTBEAT_PERIOD_US


def test_next_slot() -> None:
    assert next_slot(0, 0, 14) == 14
    assert next_slot(0, 13, 14) == 14
    assert next_slot(0, 14, 14) == 28
    assert next_slot(5, 60, 14) == 61


# --- commands and acks ----------------------------------------------------------------------------


def _ack(code: CommandCode | int, result: AckResult, seq: int) -> bytes:
    return encode(CommandAck(code, result, seq), 0)


def test_ack_resolves_the_command_and_in_progress_is_followed_by_the_final_one() -> None:
    session = HostSession(heartbeats=False)
    token = session.command(CommandCode.GRASP, 0.5, now_us=1_000)
    assert session.ack(token) is None
    (seq, cmd), *_ = _frames(session.data_to_send())
    assert cmd == Command(CommandCode.GRASP, (0.5, 0.0, 0.0))
    session.receive_data(_ack(CommandCode.GRASP, AckResult.IN_PROGRESS, seq), 2_000)
    ack = session.ack(token)
    assert ack is not None and ack.result is AckResult.IN_PROGRESS
    assert session.rtt_us is None  # not answered yet
    session.receive_data(_ack(CommandCode.GRASP, AckResult.ACCEPTED, seq), 900_000)
    ack = session.ack(token)
    assert ack is not None and ack.result is AckResult.ACCEPTED
    assert session.rtt_us == 899_000
    session.receive_data(_ack(CommandCode.GRASP, AckResult.FAILED, seq), 950_000)
    assert session.ack(token) == ack  # answered: a later ack for the same seq is not ours
    assert session.unmatched_acks == 1


def test_ack_for_another_code_on_the_seq_is_not_ours() -> None:
    session = HostSession(heartbeats=False)
    token = session.command(CommandCode.ARM, now_us=0)
    session.receive_data(_ack(CommandCode.DISARM, AckResult.ACCEPTED, 0), 1)
    assert session.ack(token) is None and session.unmatched_acks == 1


def test_tokens_survive_the_seq_wrap() -> None:
    session = HostSession(heartbeats=False)
    first = session.command(CommandCode.ARM, now_us=0)  # seq 0
    for i in range(255):
        session.send(Heartbeat(i, i), i)
    second = session.command(CommandCode.ESTOP, now_us=300)  # seq 0 again
    third = session.command(CommandCode.DISARM, now_us=301)  # seq 1
    assert (first, second, third) == (0, 1, 2)
    session.receive_data(
        _ack(CommandCode.DISARM, AckResult.ACCEPTED, 1) + _ack(CommandCode.ESTOP, AckResult.ACCEPTED, 0), 400
    )
    assert session.ack(first) is None  # its seq was reused before an answer came
    second_ack, third_ack = session.ack(second), session.ack(third)
    assert second_ack is not None and second_ack.command == CommandCode.ESTOP
    assert third_ack is not None and third_ack.command == CommandCode.DISARM


def test_too_many_command_arguments() -> None:
    session = HostSession()
    with pytest.raises(ValueError):
        session.command(CommandCode.SET_TENSIONS, 1.0, 2.0, 3.0, 4.0, now_us=0)
    assert session.next_seq == 0


# --- receiving ------------------------------------------------------------------------------------


def test_parameters_telemetry_and_answers_since_a_mark() -> None:
    session = HostSession()
    session.receive_data(encode(ParamValue(0, 2, "a", 1.0), 0) + encode(ParamValue(1, 2, "b", 2.0), 1), 0)
    mark = session.param_mark()
    assert session.answered_since(mark) == set()
    tel = _telemetry(77)
    got = session.receive_data(encode(ParamValue(1, 2, "b", 3.0), 2) + encode(tel, 3), 10)
    assert got == [ParamValue(1, 2, "b", 3.0), tel]
    assert session.params == {"a": 1.0, "b": 3.0}
    assert session.param_count == 2
    assert session.answered_since(mark) == {"b"}
    assert session.last_telemetry == tel


BOARD_MESSAGES: list[Message] = [
    Event(1, EventKind.BOOT, 0, 0.0, "boot"),
    ParamValue(0, 1, "x", 1.5),
    CommandAck(CommandCode.ARM, AckResult.REJECTED, 9, "lever"),
    Event(2, EventKind.INFO, 1, 2.0, "more"),
]


@SETTINGS
@given(st.data())
def test_any_chunking_and_garbage_give_the_same_messages(data: st.DataObject) -> None:
    garbage = data.draw(st.lists(st.binary(max_size=40).filter(lambda b: 0xA5 not in b), max_size=4))
    parts: list[bytes] = []
    for i, msg in enumerate(BOARD_MESSAGES * 2):
        parts.append(garbage[i % len(garbage)] if garbage else b"")
        parts.append(encode(msg, i))
    wire = b"".join(parts)
    cuts = sorted(data.draw(st.lists(st.integers(0, len(wire)), max_size=10)))
    session = HostSession()
    got: list[Message] = []
    start = 0
    for cut in [*cuts, len(wire)]:
        got += session.receive_data(wire[start:cut], cut)
        start = cut
    assert got == BOARD_MESSAGES * 2
    assert session.counters()["bytes_skipped"] == sum(len(p) for p in parts[::2])


def test_corrupted_frames_are_counted_and_the_next_one_decodes() -> None:
    session = HostSession()
    bad = bytearray(encode(BOARD_MESSAGES[0], 0))
    bad[10] ^= 0x40
    got = session.receive_data(bytes(bad) + b"\xa5\xa5\x00" + encode(BOARD_MESSAGES[1], 1), 0)
    assert got == [BOARD_MESSAGES[1]]
    counters = session.counters()
    assert counters["body_crc_errors"] == 1 and counters["decode_errors"] == 0
    assert session.stream.crc_errors >= 1


def test_keep_sent_off() -> None:
    session = HostSession(keep_sent=False)
    session.poll(0)
    session.command(CommandCode.ARM, now_us=0)
    assert session.sent == []
    assert len(_frames(session.data_to_send())) == 2


def test_hold_lengths_sends_one_acked_command() -> None:
    session = HostSession(heartbeats=False)
    token = session.hold_lengths((HOLD_HERE, HOLD_UNCHANGED, 0.25), now_us=0)
    (seq, cmd), *_ = _frames(session.data_to_send())
    assert isinstance(cmd, Command) and cmd.code is CommandCode.HOLD_LENGTHS
    assert cmd.args[0] == math.inf and math.isnan(cmd.args[1]) and cmd.args[2] == 0.25
    session.receive_data(_ack(CommandCode.HOLD_LENGTHS, AckResult.ACCEPTED, seq), 1_000)
    ack = session.ack(token)
    assert ack is not None and ack.result is AckResult.ACCEPTED
    assert -math.inf == HOLD_RELEASE
    with pytest.raises(ValueError):
        session.hold_lengths((HOLD_HERE,), now_us=0)
