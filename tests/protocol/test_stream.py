"""Tests for protocol.stream: bytes in, messages out, never raises, counts what it rejects."""

from __future__ import annotations

from hypothesis import given, settings
from hypothesis import strategies as st

from protocol.link import LinkFrame, encode_frame
from protocol.messages import (
    AckResult,
    Command,
    CommandAck,
    CommandCode,
    Event,
    EventKind,
    Heartbeat,
    Message,
    ParamValue,
    encode,
)
from protocol.stream import MessageStream, Received

SETTINGS = settings(max_examples=200, deadline=None)

MESSAGES: list[Message] = [
    Heartbeat(1_000, 1),
    CommandAck(CommandCode.ARM, AckResult.ACCEPTED, 7, "armed"),
    Event(5, EventKind.PHASE, 1, 0.0, "phase OK"),
    ParamValue(3, 40, "tension_max", 12.5),
    Command(CommandCode.GRASP, (0.5, 0.0, 0.0)),
]


def _wire(messages: list[Message]) -> bytes:
    return b"".join(encode(m, seq) for seq, m in enumerate(messages))


def test_decodes_messages_with_their_seq() -> None:
    stream = MessageStream()
    got = stream.feed(_wire(MESSAGES))
    assert got == [Received(seq, m) for seq, m in enumerate(MESSAGES)]
    assert stream.frames_ok == len(MESSAGES)
    assert stream.decode_errors == stream.crc_errors == stream.bytes_skipped == 0


def test_empty_feed_returns_nothing() -> None:
    stream = MessageStream()
    assert stream.feed(b"") == []
    assert stream.counters()["frames_ok"] == 0


def test_unknown_id_and_bad_payload_are_counted_and_handed_to_the_hook() -> None:
    seen: list[LinkFrame] = []
    stream = MessageStream(undecodable=seen.append)
    unknown = encode_frame(0x0299, b"\x01\x02", 3)
    short = encode_frame(Heartbeat.CMD_ID, b"\x00" * 5, 4)  # a Heartbeat is 12 bytes
    bad_code = encode_frame(Command.CMD_ID, bytes([200]) + b"\x00" * 12, 5)
    got = stream.feed(unknown + short + encode(MESSAGES[0], 6) + bad_code)
    assert got == [Received(6, MESSAGES[0])]
    assert stream.frames_ok == 4
    assert stream.decode_errors == 3
    assert stream.unknown_ids == 1
    assert [(f.cmd_id, f.seq) for f in seen] == [(0x0299, 3), (Heartbeat.CMD_ID, 4), (Command.CMD_ID, 5)]
    assert seen[2].payload[0] == 200  # what a board needs to answer UNSUPPORTED


def test_garbage_and_corruption_resync_and_count() -> None:
    stream = MessageStream()
    good = encode(MESSAGES[0], 9)
    corrupt = bytearray(encode(MESSAGES[1], 10))
    corrupt[-1] ^= 0xFF  # body CRC
    bad_header = bytearray(encode(MESSAGES[2], 11))
    bad_header[4] ^= 0xFF  # header CRC
    got = stream.feed(b"\x00\xa5junk" + bytes(corrupt) + bytes(bad_header) + good)
    assert got == [Received(9, MESSAGES[0])]
    assert stream.crc_errors == 3  # the stray 0xA5 in the garbage starts a header that fails too
    assert stream.bytes_skipped > 0
    counters = stream.counters()
    assert counters["body_crc_errors"] == 1 and counters["header_crc_errors"] == 2


def test_oversize_length_is_counted() -> None:
    stream = MessageStream(max_payload=20)
    big = encode(Event(0, EventKind.INFO, 0, 0.0, "x" * 30), 0)
    assert stream.feed(big + encode(MESSAGES[0], 1)) == [Received(1, MESSAGES[0])]
    assert stream.oversize_errors == 1


def test_reset_drops_a_partial_frame() -> None:
    stream = MessageStream()
    frame = encode(MESSAGES[0], 0)
    assert stream.feed(frame[:7]) == []
    assert stream.pending == 7
    stream.reset()
    assert stream.pending == 0
    assert stream.feed(frame) == [Received(0, MESSAGES[0])]


@SETTINGS
@given(st.data())
def test_any_chunking_gives_the_same_messages(data: st.DataObject) -> None:
    wire = _wire(MESSAGES * 3)
    cuts = sorted(data.draw(st.lists(st.integers(0, len(wire)), max_size=12)))
    stream = MessageStream()
    got: list[Received] = []
    start = 0
    for cut in [*cuts, len(wire)]:
        got += stream.feed(wire[start:cut])
        start = cut
    assert got == [Received(seq, m) for seq, m in enumerate(MESSAGES * 3)]


@SETTINGS
@given(st.binary(max_size=600), st.binary(max_size=600))
def test_never_raises_and_finds_a_frame_after_any_garbage(head: bytes, tail: bytes) -> None:
    stream = MessageStream()
    stream.feed(head)
    stream.reset()  # a frame hidden in the garbage may be incomplete: start clean, as after a reconnect
    good = encode(MESSAGES[3], 42)
    got = stream.feed(good + tail)
    assert got[0] == Received(42, MESSAGES[3])
