"""RC sources: DBUS over a real pty (idle-gap framing with simulated arrival times), link and script."""

from __future__ import annotations

import os
import time
from collections.abc import Iterator

import pytest

from controller.errors import PortError
from controller.rc import RAW_RC_QUEUE, DbusSerialSource, LinkRcSource, RcInput, ScriptedRcSource, Uart
from protocol.dbus import Lever, RcFrame

GOOD = RcFrame((100, -200, 300, -400), Lever.MIDDLE, Lever.UP)


@pytest.fixture
def dbus_pty() -> Iterator[tuple[int, DbusSerialSource]]:
    master, slave = os.openpty()
    source = DbusSerialSource(os.ttyname(slave))
    try:
        yield master, source
    finally:
        source.close()
        source.close()  # safe twice
        os.close(slave)
        os.close(master)


def _write_then_poll(master: int, source: DbusSerialSource, data: bytes, now_us: int) -> list[RcFrame]:
    """Write ``data`` on the radio side, wait (bounded) until the pty holds it, then poll at ``now_us``."""
    os.write(master, data)
    deadline = time.monotonic() + 5.0
    while source._serial.in_waiting < len(data) and time.monotonic() < deadline:
        time.sleep(0.0005)
    return source.poll(now_us)


def test_dbus_frames_over_a_pty_split_on_idle_gaps(dbus_pty: tuple[int, DbusSerialSource]) -> None:
    master, source = dbus_pty
    assert source._serial.baudrate == 100_000 and source._serial.parity == "E"
    # a frame, then silence past the idle gap: delivered
    assert _write_then_poll(master, source, GOOD.pack(), 0) == []
    assert source.poll(1_000) == []
    assert source.poll(2_600) == [GOOD]
    # half a frame, a gap, garbage, a gap, then a good frame: only the good one survives
    assert _write_then_poll(master, source, GOOD.pack()[:9], 10_000) == []
    assert source.poll(13_000) == []
    assert _write_then_poll(master, source, b"\x55" * 30, 20_000) == []
    assert _write_then_poll(master, source, GOOD.pack(), 30_000) == []
    assert source.poll(33_000) == [GOOD]
    assert source.bytes_dropped == 9 + 30
    assert source.framer.frames_ok == 2


def test_what_arrived_before_the_loop_started_is_dropped(
    dbus_pty: tuple[int, DbusSerialSource],
) -> None:
    """Two frames buffered since the port opened would be one 36-byte burst at the first poll: stale
    positions, counted as dropped bytes. ``discard_pending`` drops them unread, and counts nothing."""
    master, source = dbus_pty
    os.write(master, GOOD.pack() * 2)
    deadline = time.monotonic() + 5.0
    while source._serial.in_waiting < 36 and time.monotonic() < deadline:
        time.sleep(0.0005)
    assert source.discard_pending() == 36
    assert _write_then_poll(master, source, GOOD.pack(), 0) == [] and source.poll(2_600) == [GOOD]
    assert source.bytes_dropped == 0 and source.framer.frames_ok == 1


def test_missing_rc_port_is_a_port_error() -> None:
    with pytest.raises(PortError, match="ttyNOPE"):
        DbusSerialSource("/dev/ttyNOPE")


def test_busy_rc_port_is_a_port_error(dbus_pty: tuple[int, DbusSerialSource]) -> None:
    _, source = dbus_pty
    with pytest.raises(PortError):
        DbusSerialSource(source._serial.port)


class ChunkUart(Uart):
    """A UART in memory that hands out at most ``chunk_n`` bytes per read and can fail."""

    def __init__(self, data: bytes, chunk_n: int) -> None:
        self.data = bytearray(data)
        self.chunk_n = chunk_n
        self.fail = False
        self.closed_n = 0

    @property
    def in_waiting(self) -> int:
        if self.fail:
            raise OSError("adapter unplugged")
        return min(len(self.data), self.chunk_n)

    def read(self, n: int, /) -> bytes:
        out = bytes(self.data[:n])
        del self.data[:n]
        return out

    def close(self) -> None:
        self.closed_n += 1


def test_dbus_source_reads_any_uart_and_counts_read_errors() -> None:
    uart = ChunkUart(GOOD.pack(), chunk_n=10)
    source = DbusSerialSource(uart)
    assert source.poll(0) == [] and source.poll(100) == []  # 10 + 8 bytes, no gap yet
    uart.fail = True
    assert source.poll(200) == []
    assert source.read_errors == 1
    assert source.poll(3_000) == [GOOD]  # the idle gap closed the frame
    source.close()
    source.close()
    assert uart.closed_n == 1


def test_scripted_source_repeats_at_the_dr16_cadence() -> None:
    src = ScriptedRcSource(GOOD)
    times = [t for t in range(0, 50_000, 1000) if src.poll(t)]
    assert times == [0, 14_000, 28_000, 42_000]
    src.set_frame(None)
    assert not any(src.poll(t) for t in range(50_000, 100_000, 1000))
    src.schedule(120_000, GOOD)
    assert src.poll(110_000) == [] and src.poll(120_000) == [GOOD]
    bad = RcFrame((0, 0, 0, 0), 0, 0)
    src.inject(bad)
    assert src.poll(121_000) == [bad]


def test_link_source_takes_pushed_bytes() -> None:
    src = LinkRcSource(capacity=2)
    src.push(GOOD.pack(), 0)
    src.push(b"short", 0)
    assert src.poll(1000) == [GOOD]
    assert src.poll(2000) == []
    for _ in range(3):
        src.push(GOOD.pack(), 3000)
    assert len(src.poll(4000)) == 2
    assert src.frames_dropped == 2


def test_rc_input_accepts_valid_frames_counts_invalid_ones_and_keeps_raw() -> None:
    seen: list[tuple[int, int]] = []
    rc = RcInput(lambda now_us, lever: seen.append((now_us, lever)), keep_raw=True)
    good = RcFrame((0, 0, 0, 0), Lever.MIDDLE, Lever.DOWN)
    bad = RcFrame((700, 0, 0, 0), Lever.DOWN, Lever.DOWN)
    rc.take(5, [good, bad])
    assert (rc.frame, rc.frames_ok, rc.rejected) == (good, 1, 1)
    assert seen == [(5, Lever.MIDDLE)]  # the invalid frame never reaches the failsafe
    assert rc.raw == [(5, good), (5, bad)]
    rc.take(6, [bad] * RAW_RC_QUEUE)
    assert len(rc.raw) == RAW_RC_QUEUE and rc.raw[0] == (6, bad)  # oldest dropped
    quiet = RcInput(lambda now_us, lever: None, keep_raw=False)
    quiet.take(7, [good])
    assert quiet.raw == [] and quiet.frames_ok == 1
