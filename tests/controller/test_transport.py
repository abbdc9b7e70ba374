"""Transports: never block; drop whole frames when the peer stalls; memory pair; serial over a pty;
pyserial URL handlers (spy://) on the board link."""

from __future__ import annotations

import os
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from controller.errors import PortError
from controller.transport import MemoryTransport, SerialTransport
from protocol.link import encode_frame


def test_memory_pair_carries_bytes_both_ways() -> None:
    a, b = MemoryTransport.pair()
    assert a.write(b"hello") and b.write(b"world")
    assert b.read() == b"hello" and a.read() == b"world"
    assert a.read() == b""
    a.close()
    a.close()
    assert not a.write(b"x") and a.frames_dropped == 1


def test_memory_pair_drops_whole_frames_when_the_peer_stalls() -> None:
    a, b = MemoryTransport.pair(tx_capacity=100)
    b._rx_capacity = 50
    sent = sum(a.write(bytes([i]) * 20) for i in range(10))
    assert sent < 10 and a.frames_dropped == 10 - sent
    data = b.read()
    a.flush()
    data += b.read()
    a.flush()
    data += b.read()
    # whole frames only, in order
    assert len(data) == 20 * sent
    assert all(data[i * 20 : (i + 1) * 20] == bytes([data[i * 20]]) * 20 for i in range(sent))


@pytest.fixture
def pty_transport() -> Iterator[tuple[int, SerialTransport]]:
    master, slave = os.openpty()
    t = SerialTransport(os.ttyname(slave), tx_capacity=4096)
    try:
        yield master, t
    finally:
        t.close()
        os.close(slave)
        os.close(master)


def test_serial_transport_over_a_pty(pty_transport: tuple[int, SerialTransport]) -> None:
    master, t = pty_transport
    assert t.write(b"\xa5abc")
    assert os.read(master, 100) == b"\xa5abc"
    os.write(master, b"xyz")
    got = b""
    # The pty hands the bytes over when the kernel gets to it: on a loaded machine that is not within a
    # thousand back-to-back reads (about 1 ms), so wait between them (bounded: about 2 s).
    for _ in range(2000):
        got += t.read()
        if len(got) >= 3:
            break
        time.sleep(0.001)
    assert got == b"xyz"


def test_serial_transport_never_blocks_on_a_stalled_host(pty_transport: tuple[int, SerialTransport]) -> None:
    master, t = pty_transport
    os.set_blocking(master, False)
    frame = bytes(range(256)) * 4
    results = [t.write(frame) for _ in range(500)]  # 500 KB into a pty nobody reads
    assert not all(results)
    assert t.frames_dropped == results.count(False)
    assert t.pending_tx <= 4096
    # the host wakes up: what arrives is whole frames
    received = b""
    for _ in range(200):
        try:
            chunk = os.read(master, 65536)
        except BlockingIOError:
            chunk = b""
        received += chunk
        t.flush()
        if not t.pending_tx and not chunk:
            break
    assert len(received) % len(frame) == 0 and received[: len(frame)] == frame


def test_missing_link_port_is_a_port_error() -> None:
    with pytest.raises(PortError):
        SerialTransport("/dev/ttyNOPE")


def test_serial_transport_over_loop_url_never_blocks() -> None:
    t = SerialTransport("loop://", tx_capacity=8192)
    try:
        results = [t.write(bytes([i]) * 1000) for i in range(20)]  # loop:// holds only 4096 bytes
        assert results.count(True) >= 8 and t.frames_dropped == results.count(False)
        data = t.read()
        assert data[:1000] == bytes([0]) * 1000
    finally:
        t.close()


def test_spy_url_logs_the_board_link_over_a_pty(tmp_path: Path) -> None:
    """pyserial's spy:// handler sees both directions because the transport reads and writes through it."""
    log = tmp_path / "link.txt"
    master, slave = os.openpty()
    try:
        t = SerialTransport(f"spy://{os.ttyname(slave)}?file={log}")
        try:
            frame = encode_frame(0x0201, bytes(12), seq=7)
            assert t.write(frame)
            assert os.read(master, 100) == frame
            os.write(master, b"\x5a\x42\x17")
            got = b""
            for _ in range(2000):  # as above: wait for the pty's bytes, bounded at about 2 s
                got += t.read()
                if len(got) >= 3:
                    break
                time.sleep(0.001)
            assert got == b"\x5a\x42\x17"
        finally:
            t.close()
    finally:
        os.close(slave)
        os.close(master)
    text = log.read_text()
    tx_hex = " ".join(f"{b:02X}" for b in frame[:8])
    assert any(line.split()[1] == "TX" and tx_hex in line for line in text.splitlines())
    assert any(line.split()[1] == "RX" and "5A 42 17" in line for line in text.splitlines())
