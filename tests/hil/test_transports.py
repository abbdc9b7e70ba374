"""The virtual board's link endpoints: a real pty and a real TCP socket on loopback."""

from __future__ import annotations

import socket
import time

import pytest
import serial

from controller.transport import TcpServerTransport
from hil.transports import PtyTransport


def _read_until(read: object, n: int, timeout_s: float = 2.0) -> bytes:
    out = b""
    deadline = time.monotonic() + timeout_s
    while len(out) < n and time.monotonic() < deadline:
        out += read()  # type: ignore[operator]
        time.sleep(0.001)
    return out


def test_pty_round_trip_with_pyserial() -> None:
    with PtyTransport() as board:
        port = serial.serial_for_url(board.url, timeout=1)
        try:
            assert board.write(b"\xa5hello")
            assert port.read(6) == b"\xa5hello"
            port.write(b"from host")
            assert _read_until(board.read, 9) == b"from host"
        finally:
            port.close()
        assert board.read() == b""  # host gone: no EIO, no exception
        assert board.write(b"x")


def test_tcp_serves_one_host_and_accepts_a_reconnect() -> None:
    with TcpServerTransport() as board:
        assert board.url.startswith("socket://127.0.0.1:")
        assert not board.connected
        assert board.write(b"nobody")  # no host: dropped silently, loop not blocked
        for attempt in range(2):
            port = serial.serial_for_url(board.url, timeout=1)
            try:
                deadline = time.monotonic() + 2
                while not board.connected and time.monotonic() < deadline:
                    time.sleep(0.001)
                assert board.connected and board.connections == attempt + 1
                board.write(b"telemetry")
                assert port.read(9) == b"telemetry"
                port.write(b"hb")
                assert _read_until(board.read, 2) == b"hb"
            finally:
                port.close()
            assert _read_until(board.read, 1, timeout_s=0.5) == b""


def test_tcp_port_in_use_raises() -> None:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen(1)
        busy = s.getsockname()[1]
        with pytest.raises(OSError):
            TcpServerTransport(port=busy)


def _connect(url: str) -> socket.socket:
    host, port = url.removeprefix("socket://").rsplit(":", 1)
    return socket.create_connection((host, int(port)), timeout=2)


def _closed_by_peer(sock: socket.socket, timeout_s: float = 2.0) -> bool:
    sock.settimeout(timeout_s)
    try:
        return sock.recv(1) == b""
    except ConnectionResetError:
        return True
    except TimeoutError:
        return False


def test_tcp_refuses_a_second_host_while_one_is_live(caplog: pytest.LogCaptureFixture) -> None:
    """Issue 18: a new connection used to replace the host silently; now it is refused and logged."""
    with TcpServerTransport() as board:
        first = _connect(board.url)
        try:
            deadline = time.monotonic() + 2
            while not board.connected and time.monotonic() < deadline:
                time.sleep(0.001)
            assert board.connected and board.peer_changes == 1
            second = _connect(board.url)
            try:
                with caplog.at_level("WARNING", logger="hil.transports"):
                    deadline = time.monotonic() + 2
                    while board.refused == 0 and time.monotonic() < deadline:
                        board.read()
                        time.sleep(0.001)
                assert board.refused == 1 and board.connections == 1 and board.peer_changes == 1
                assert _closed_by_peer(second)
                assert "refused a second host" in caplog.text
                # the first host still owns the link, both ways
                first.sendall(b"hb")
                assert _read_until(board.read, 2) == b"hb"
                board.write(b"telemetry")
                first.settimeout(2)
                assert first.recv(9) == b"telemetry"
            finally:
                second.close()
        finally:
            first.close()
        # once the first host has gone, a new one is taken even before its end-of-file was read
        third = _connect(board.url)
        try:
            deadline = time.monotonic() + 2
            while board.connections < 2 and time.monotonic() < deadline:
                board.read()
                time.sleep(0.001)
            assert board.connections == 2 and board.refused == 1
            assert board.peer_changes == 3  # first in, first out, third in
            third.sendall(b"x")
            assert _read_until(board.read, 1) == b"x"
        finally:
            third.close()
