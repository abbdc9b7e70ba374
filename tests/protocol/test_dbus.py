"""Tests for protocol.dbus: golden DR16 frames, round trips and the idle-gap framer."""

from __future__ import annotations

import random

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from protocol.dbus import (
    BYTE_TIME_US,
    CH_LIMIT,
    FRAME_LEN,
    FRAME_TIME_US,
    IDLE_GAP_US,
    DbusFramer,
    Key,
    Lever,
    RcFrame,
)
from protocol.errors import DecodeError

SETTINGS = settings(max_examples=300, deadline=None)


def build_frame(
    raw_channels: tuple[int, int, int, int] = (1024, 1024, 1024, 1024),
    s0: int = 2,
    s1: int = 2,
    tail: bytes = bytes(10) + b"\x00\x04",
) -> bytes:
    """Reference encoder written from the DJI bit layout, independent of RcFrame.pack."""
    bits = [0] * 48
    for ch, raw in enumerate(raw_channels):
        for i in range(11):
            bits[11 * ch + i] = (raw >> i) & 1
    for i in range(2):
        bits[44 + i] = (s0 >> i) & 1
        bits[46 + i] = (s1 >> i) & 1
    head = bytes(sum(bits[8 * k + i] << i for i in range(8)) for k in range(6))
    assert len(tail) == 12
    return head + tail


# --- golden frames -------------------------------------------------------------------------------

NEUTRAL_BOTH_DOWN = bytes.fromhex("0004200001a8" + "000000000000" + "0000" + "0000" + "0004")


def test_golden_neutral_frame() -> None:
    assert build_frame() == NEUTRAL_BOTH_DOWN
    f = RcFrame.unpack(NEUTRAL_BOTH_DOWN)
    assert f == RcFrame.neutral()
    assert f.channels == (0, 0, 0, 0)
    assert f.right_lever == Lever.DOWN
    assert f.left_lever == Lever.DOWN
    assert f.wheel == 0
    assert f.is_valid()
    assert RcFrame.neutral().pack() == NEUTRAL_BOTH_DOWN


@pytest.mark.parametrize("ch", range(4))
@pytest.mark.parametrize(("raw", "value"), [(364, -660), (1024, 0), (1684, 660)])
def test_channel_extremes(ch: int, raw: int, value: int) -> None:
    raws = [1024] * 4
    raws[ch] = raw
    data = build_frame((raws[0], raws[1], raws[2], raws[3]))
    f = RcFrame.unpack(data)
    expected = [0] * 4
    expected[ch] = value
    assert f.channels == tuple(expected)
    assert f.is_valid()
    assert f.pack() == data


def test_golden_all_extremes_literal() -> None:
    # ch0 = 364, ch1 = 1684, ch2 = 364, ch3 = 1684, right lever UP, left lever MIDDLE.
    data = build_frame((364, 1684, 364, 1684), s0=1, s1=3)
    assert data[:6] == bytes.fromhex("6ca1345b28dd")
    f = RcFrame.unpack(data)
    assert f.channels == (-660, 660, -660, 660)
    assert (f.right_lever, f.left_lever) == (Lever.UP, Lever.MIDDLE)


@pytest.mark.parametrize("lever", [Lever.UP, Lever.DOWN, Lever.MIDDLE])
def test_each_lever_position(lever: Lever) -> None:
    right = RcFrame.unpack(build_frame(s0=lever, s1=Lever.DOWN))
    left = RcFrame.unpack(build_frame(s0=Lever.DOWN, s1=lever))
    assert right.right_lever == lever and right.left_lever == Lever.DOWN
    assert left.left_lever == lever and left.right_lever == Lever.DOWN
    assert right.is_valid() and left.is_valid()


def test_lever_values() -> None:
    assert (Lever.UP, Lever.DOWN, Lever.MIDDLE) == (1, 2, 3)


@pytest.mark.parametrize(("s0", "s1"), [(0, 2), (2, 0), (0, 0)])
def test_lever_zero_is_invalid(s0: int, s1: int) -> None:
    f = RcFrame.unpack(build_frame(s0=s0, s1=s1))
    assert (f.right_lever, f.left_lever) == (s0, s1)
    assert not f.is_valid()


@pytest.mark.parametrize("raw", [363, 1685, 0, 2047])
@pytest.mark.parametrize("ch", range(4))
def test_out_of_range_frame_is_invalid(ch: int, raw: int) -> None:
    raws = [1024] * 4
    raws[ch] = raw
    data = build_frame((raws[0], raws[1], raws[2], raws[3]))
    f = RcFrame.unpack(data)
    assert f.channels[ch] == raw - 1024
    assert abs(f.channels[ch]) > CH_LIMIT
    assert not f.is_valid()
    assert f.pack() == data  # invalid frames still round-trip byte for byte


def test_golden_mouse_keys_wheel() -> None:
    tail = bytes.fromhex("feff64000080010001809406")
    f = RcFrame.unpack(build_frame(tail=tail))
    assert (f.mouse_x, f.mouse_y, f.mouse_z) == (-2, 100, -32768)
    assert (f.mouse_left, f.mouse_right) == (1, 0)
    assert f.keys == Key.W | Key.B
    assert f.wheel == 660  # 0x0694 = 1684
    assert f.pack()[6:] == tail


def test_old_receiver_wheel_reads_minus_1024() -> None:
    f = RcFrame.unpack(build_frame(tail=bytes(12)))
    assert f.wheel == -1024
    assert f.is_valid()  # the wheel is not checked, as in DJI's firmware


def test_key_bits_in_dji_order() -> None:
    names = ["W", "S", "A", "D", "SHIFT", "CTRL", "Q", "E", "R", "F", "G", "Z", "X", "C", "V", "B"]
    assert [Key[n].value for n in names] == [1 << i for i in range(16)]


# --- round trips and validation ------------------------------------------------------------------


@SETTINGS
@given(st.binary(min_size=FRAME_LEN, max_size=FRAME_LEN))
def test_pack_unpack_every_18_bytes(data: bytes) -> None:
    assert RcFrame.unpack(data).pack() == data


rc_frames = st.builds(
    RcFrame,
    channels=st.tuples(*[st.integers(-1024, 1023)] * 4),
    right_lever=st.integers(0, 3),
    left_lever=st.integers(0, 3),
    mouse_x=st.integers(-32768, 32767),
    mouse_y=st.integers(-32768, 32767),
    mouse_z=st.integers(-32768, 32767),
    mouse_left=st.integers(0, 255),
    mouse_right=st.integers(0, 255),
    keys=st.integers(0, 0xFFFF),
    wheel=st.integers(-32768 - 1024, 32767 - 1024),
)


@SETTINGS
@given(rc_frames)
def test_unpack_pack_every_frame(frame: RcFrame) -> None:
    data = frame.pack()
    assert len(data) == FRAME_LEN
    assert RcFrame.unpack(data) == frame


@pytest.mark.parametrize(
    "kwargs",
    [
        {"channels": (1024, 0, 0, 0)},
        {"channels": (0, 0, 0, -1025)},
        {"channels": (0, 0, 0)},
        {"right_lever": 4},
        {"left_lever": -1},
        {"mouse_x": 32768},
        {"mouse_left": 256},
        {"keys": 0x10000},
        {"wheel": 31744},
        {"wheel": -33793},
    ],
)
def test_pack_rejects_out_of_range_fields(kwargs: dict[str, object]) -> None:
    fields: dict[str, object] = {"channels": (0, 0, 0, 0), "right_lever": 2, "left_lever": 2}
    fields.update(kwargs)
    frame = RcFrame(**fields)  # type: ignore[arg-type]
    with pytest.raises(ValueError):
        frame.pack()


@pytest.mark.parametrize("n", [0, 17, 19, 36])
def test_unpack_rejects_wrong_length(n: int) -> None:
    with pytest.raises(DecodeError):
        RcFrame.unpack(bytes(n))


def test_neutral_levers() -> None:
    f = RcFrame.neutral(right_lever=Lever.MIDDLE, left_lever=Lever.UP)
    assert f.is_valid()
    assert (f.right_lever, f.left_lever) == (3, 1)
    assert RcFrame.unpack(f.pack()) == f


# --- framer --------------------------------------------------------------------------------------

GOOD = build_frame((1100, 900, 1024, 1684), s0=Lever.MIDDLE, s1=Lever.UP)


def test_frame_needs_a_gap_after_it() -> None:
    fr = DbusFramer()
    assert fr.feed(GOOD, 1_000) == []
    assert fr.pending == FRAME_LEN
    assert fr.feed(b"", 1_000 + IDLE_GAP_US - 1) == []
    assert fr.flush(1_000 + IDLE_GAP_US) == [RcFrame.unpack(GOOD)]
    assert (fr.frames_ok, fr.frames_dropped, fr.bytes_dropped, fr.pending) == (1, 0, 0, 0)


def test_frame_delivered_by_next_feed_with_data_after_gap() -> None:
    fr = DbusFramer()
    assert fr.feed(GOOD, 0) == []
    assert fr.feed(GOOD[:5], 14_000) == [RcFrame.unpack(GOOD)]
    assert fr.pending == 5


def test_frame_split_across_chunks() -> None:
    fr = DbusFramer()
    out = []
    for i, chunk in enumerate((GOOD[:7], GOOD[7:8], GOOD[8:])):
        out += fr.feed(chunk, 10_000 + 900 * i)
    out += fr.flush(10_000 + 1_800 + IDLE_GAP_US)
    assert out == [RcFrame.unpack(GOOD)]


def test_half_frame_gap_garbage_gap_good_frame() -> None:
    fr = DbusFramer()
    out = fr.feed(GOOD[:9], 0)
    out += fr.feed(b"\xff\x00\x13" * 5, 20_000)  # half frame closed: dropped
    out += fr.feed(GOOD, 40_000)  # garbage closed: dropped
    out += fr.flush(60_000)
    assert out == [RcFrame.unpack(GOOD)]
    assert (fr.frames_ok, fr.frames_dropped, fr.bytes_dropped) == (1, 2, 9 + 15)


@pytest.mark.parametrize("n", [1, 17, 19, 36, 200])
def test_burst_not_18_bytes_is_dropped(n: int) -> None:
    fr = DbusFramer()
    data = (GOOD * 12)[:n]
    assert fr.feed(data, 0) == []
    assert fr.flush(IDLE_GAP_US) == []
    assert (fr.frames_ok, fr.frames_dropped, fr.bytes_dropped) == (0, 1, n)


def test_bytes_without_gap_merge_into_one_burst() -> None:
    fr = DbusFramer()
    fr.feed(GOOD, 0)
    fr.feed(GOOD, IDLE_GAP_US - 1)  # too soon: same burst, 36 bytes
    assert fr.flush(10 * IDLE_GAP_US) == []
    assert fr.frames_dropped == 1 and fr.bytes_dropped == 36


def test_start_of_stream_counts_as_gap_and_reset_forgets() -> None:
    fr = DbusFramer()
    fr.feed(GOOD[:4], 0)
    fr.reset()
    fr.feed(GOOD, 100)
    assert fr.flush(100 + IDLE_GAP_US) == [RcFrame.unpack(GOOD)]
    assert fr.frames_dropped == 0


def test_invalid_frames_are_framed_not_judged() -> None:
    bad = build_frame((0, 1024, 1024, 1024))
    fr = DbusFramer()
    fr.feed(bad, 0)
    (f,) = fr.flush(IDLE_GAP_US)
    assert not f.is_valid()


def test_rejects_non_positive_gap() -> None:
    with pytest.raises(ValueError):
        DbusFramer(idle_gap_us=0)


@pytest.mark.parametrize("period_us", [14_000, 7_000])
def test_real_uart_timing_with_polling_jitter(period_us: int) -> None:
    """Bytes 110 µs apart, read by a 1 kHz poll with up to 0.3 ms of lateness: every frame arrives."""
    rng = random.Random(period_us)
    frames = [build_frame((rng.randint(364, 1684), 1024, 1024, 1024), s0=3, s1=2) for _ in range(60)]
    arrivals = [
        (k * period_us + i * BYTE_TIME_US + BYTE_TIME_US, byte)
        for k, frame in enumerate(frames)
        for i, byte in enumerate(frame)
    ]
    fr = DbusFramer()
    out: list[RcFrame] = []
    latencies: list[int] = []
    idx = 0
    for tick in range(len(frames) * period_us // 1000 + 20):
        now = tick * 1000 + rng.randint(0, 300)
        chunk = bytearray()
        while idx < len(arrivals) and arrivals[idx][0] <= now:
            chunk.append(arrivals[idx][1])
            idx += 1
        got = fr.feed(bytes(chunk), now)
        for _ in got:
            end_us = len(out) * period_us + FRAME_TIME_US
            latencies.append(now - end_us)
        out += got
    assert out == [RcFrame.unpack(f) for f in frames]
    assert fr.frames_dropped == 0
    assert max(latencies) <= IDLE_GAP_US + 2 * 1000


chunks = st.lists(
    st.tuples(st.binary(max_size=40), st.integers(0, 20_000)),
    max_size=40,
)


@SETTINGS
@given(chunks)
def test_framer_never_raises_and_accounts_for_every_byte(items: list[tuple[bytes, int]]) -> None:
    fr = DbusFramer()
    now = 0
    total = 0
    delivered = 0
    for data, dt in items:
        now += dt
        total += len(data)
        delivered += len(fr.feed(data, now))
    delivered += len(fr.flush(now + IDLE_GAP_US))
    assert delivered == fr.frames_ok
    assert fr.pending == 0
    assert fr.frames_ok * FRAME_LEN + fr.bytes_dropped == total


@SETTINGS
@given(st.lists(st.tuples(st.binary(min_size=18, max_size=18), st.integers(1, 17)), min_size=1, max_size=20))
def test_framer_delivers_frames_split_anywhere(items: list[tuple[bytes, int]]) -> None:
    fr = DbusFramer()
    out: list[RcFrame] = []
    now = 0
    for frame, cut in items:
        now += 7_000
        out += fr.feed(frame[:cut], now)
        out += fr.feed(frame[cut:], now + 1_000)
    out += fr.flush(now + 1_000 + IDLE_GAP_US)
    assert [f.pack() for f in out] == [frame for frame, _ in items]
