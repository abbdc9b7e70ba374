"""Byte transports for the board link: never block the firmware loop.

``read()`` returns what has arrived (possibly ``b""``) at once. ``write(data)`` queues one whole frame
and sends as much as the peer accepts now; the rest goes out on later calls. When the outgoing queue
would exceed its capacity the *new* frame is dropped whole and counted (a stalled host loses telemetry,
never stalls the loop, and the byte stream never carries half a frame).

The serial transport goes through pyserial's own API (``in_waiting``, ``read``, ``write``), so every
URL handler pyserial knows works on the board link: ``spy://`` logs the traffic, ``socket://`` and
``hwgrep://`` open what they name. The port is opened with ``timeout=0`` and ``write_timeout=0``:
``read`` returns what one non-blocking read got, ``write`` returns how many bytes the descriptor took.
One trap remains: pyserial's zero-timeout ``write`` retries for ever on ``EAGAIN`` (its loop only gives
up on a timeout, which a zero timeout never reaches). So a port with a descriptor is first asked, with a
zero-timeout ``select``, whether it takes bytes now; a pty or socket that says so accepts at least one
byte, and a stalled peer costs one ``select`` per flush, never a spin.
"""

from __future__ import annotations

import contextlib
import logging
import os
import select
import socket
import threading
from abc import ABC, abstractmethod
from types import TracebackType
from typing import Any, Final

from controller.errors import PortError

_log = logging.getLogger(__name__)

__all__ = ["MemoryTransport", "SerialTransport", "Transport", "set_tcp_nodelay"]

DEFAULT_TX_CAPACITY = 64 * 1024
"""Bytes queued for a slow peer before new frames are dropped (about 0.4 s of 100 Hz telemetry)."""
_READ_CHUNK_N = 65536
"""Most bytes one ``read`` takes from a serial port (one non-blocking read of the descriptor)."""


class Transport(ABC):
    """A non-blocking byte pipe to the host.

    Attributes:
        frames_dropped: frames refused because the outgoing queue was full (or the port failed).
        bytes_dropped: the bytes of those frames.
        errors: read/write errors (the port went away, ...); the transport keeps going.
        peer_changes: times a host connected or went away, for back ends that see connections (a TCP
            server); the board treats each as a link loss. Stays 0 on a serial port.
    """

    def __init__(self, tx_capacity: int = DEFAULT_TX_CAPACITY) -> None:
        """Create the transport with an outgoing queue of ``tx_capacity`` bytes.

        Raises:
            ValueError: ``tx_capacity`` < 1.
        """
        if tx_capacity < 1:
            raise ValueError(f"tx_capacity must be >= 1, got {tx_capacity}")
        self.tx_capacity = tx_capacity
        self.frames_dropped = 0
        self.bytes_dropped = 0
        self.errors = 0
        self.peer_changes = 0
        self._tx = bytearray()
        self._closed = False

    @property
    def closed(self) -> bool:
        """:meth:`close` has been called."""
        return self._closed

    @property
    def pending_tx(self) -> int:
        """Bytes queued but not yet accepted by the peer."""
        return len(self._tx)

    def read(self) -> bytes:
        """Everything received since the last call (``b""`` if nothing); never blocks."""
        if self._closed:
            return b""
        try:
            return self._read()
        except OSError:
            self.errors += 1
            return b""

    def write(self, data: bytes) -> bool:
        """Queue one whole frame and push out what the peer accepts now; never blocks.

        Returns:
            False if the frame was dropped (queue full, or the transport is closed).
        """
        if self._closed:
            self.frames_dropped += 1
            self.bytes_dropped += len(data)
            return False
        tx = self._tx
        if len(tx) + len(data) > self.tx_capacity:
            self.flush()
            if len(tx) + len(data) > self.tx_capacity:
                self.frames_dropped += 1
                self.bytes_dropped += len(data)
                return False
        tx += data
        self.flush()
        return True

    def flush(self) -> None:
        """Send as much of the queue as the peer accepts now."""
        tx = self._tx
        if not tx or self._closed:
            return
        try:
            n = self._write(tx)
        except OSError:
            self.errors += 1
            return
        if n:
            del tx[:n]

    def close(self) -> None:
        """Release the port (safe twice)."""
        if not self._closed:
            self._closed = True
            self._close()

    def __enter__(self) -> Transport:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()

    @abstractmethod
    def _read(self) -> bytes:
        """Back end: return available bytes without blocking (may raise OSError)."""

    @abstractmethod
    def _write(self, data: bytearray) -> int:
        """Back end: write a prefix of ``data`` without blocking; return its length (may raise OSError)."""

    def _close(self) -> None:  # noqa: B027 - optional hook
        """Back end: release resources."""


def set_tcp_nodelay(fd: int) -> bool:
    """Turn Nagle's algorithm off if ``fd`` is a TCP socket (pyserial's ``socket://`` leaves it on).

    With Nagle on, a small frame written right after another waits for the peer's delayed ACK (measured
    here: 4-10 ms), which delays heartbeats and virtual RC frames behind each other.

    Returns:
        True if ``fd`` was a socket and the option was set.
    """
    import socket
    import stat

    try:
        if not stat.S_ISSOCK(os.fstat(fd).st_mode):
            return False
        with socket.socket(fileno=os.dup(fd)) as sock:
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    except OSError:
        return False
    return True


class SerialTransport(Transport):
    """Board link over any pyserial port or URL (``/dev/ttyACM0``, a pty path, ``socket://``, ``loop://``)."""

    def __init__(self, port: str | Any, *, baudrate: int = 115200, tx_capacity: int = DEFAULT_TX_CAPACITY):
        """Open ``port`` (a path or pyserial URL) or wrap an open pyserial object.

        Args:
            port: device path / URL, or an already open ``serial.SerialBase``.
            baudrate: ignored by USB CDC and ptys, used by real UARTs.
            tx_capacity: outgoing queue size in bytes.

        Raises:
            PortError: the port cannot be opened (missing, busy, not permitted).
        """
        super().__init__(tx_capacity)
        if isinstance(port, str):
            import serial

            try:
                self._serial = serial.serial_for_url(
                    port, baudrate=baudrate, timeout=0, write_timeout=0, exclusive=True
                )
            except (serial.SerialException, OSError, ValueError) as exc:
                raise PortError(f"cannot open link port {port}: {exc}") from exc
            self.name = port
        else:
            self._serial = port
            self.name = str(getattr(port, "name", port))
            self._serial.timeout = 0
        try:
            self._fd: int | None = self._serial.fileno()
        except Exception:  # loop:// and friends have no descriptor: bounded writes through pyserial
            self._fd = None
            self._serial.write_timeout = None
        else:
            self._serial.write_timeout = 0
            set_tcp_nodelay(self._fd)

    @property
    def serial(self) -> Any:
        """The underlying pyserial object."""
        return self._serial

    def _read(self) -> bytes:
        ser = self._serial
        # in_waiting is an ioctl on a tty (a zero-timeout select on socket://, where it reports 0 or 1):
        # an idle port costs no read call, and a ready one is read in one go up to _READ_CHUNK_N.
        n = ser.in_waiting
        if not n:
            return b""
        return bytes(ser.read(max(n, _READ_CHUNK_N)))

    def _write(self, data: bytearray) -> int:
        ser = self._serial
        fd = self._fd
        if fd is None:
            room = getattr(ser, "buffer_size", 4096) - ser.out_waiting  # loop://: never block on a full queue
            n = min(len(data), room)
            return int(ser.write(bytes(data[:n])) or 0) if n > 0 else 0
        _, ready, _ = select.select((), (fd,), (), 0)
        if not ready:
            return 0
        return int(ser.write(data) or 0)

    def _close(self) -> None:
        try:
            self._serial.close()
        except Exception:
            self.errors += 1


class MemoryTransport(Transport):
    """In-memory transport; :meth:`pair` returns two connected ends (thread-safe)."""

    def __init__(self, tx_capacity: int = DEFAULT_TX_CAPACITY, rx_capacity: int = 1 << 20) -> None:
        """Create an unconnected end (use :meth:`pair`).

        Args:
            tx_capacity: outgoing queue size in bytes.
            rx_capacity: bytes the peer may leave unread here before writes to us stall.
        """
        super().__init__(tx_capacity)
        self._rx = bytearray()
        self._rx_capacity = rx_capacity
        self._lock = threading.Lock()
        self._peer: MemoryTransport | None = None

    @classmethod
    def pair(cls, tx_capacity: int = DEFAULT_TX_CAPACITY) -> tuple[MemoryTransport, MemoryTransport]:
        """Two connected ends: bytes written to one are read from the other."""
        a = cls(tx_capacity)
        b = cls(tx_capacity)
        a._peer = b
        b._peer = a
        return a, b

    def _read(self) -> bytes:
        with self._lock:
            if not self._rx:
                return b""
            data = bytes(self._rx)
            self._rx.clear()
        return data

    def _write(self, data: bytearray) -> int:
        peer = self._peer
        if peer is None or peer._closed:
            raise BrokenPipeError("memory transport peer is closed")
        with peer._lock:
            n = min(len(data), peer._rx_capacity - len(peer._rx))
            if n > 0:
                peer._rx += data[:n]
        return max(n, 0)


# --- a TCP listener: the board end of a host link over a network ----------------------------------

_READ_CHUNK_TCP: Final = 4096
_KEEPALIVE_S: Final = 1
"""TCP keepalive idle time and probe interval: a host that vanished without closing its socket (a
network gone, a machine off) frees the link after about 4 s instead of holding it forever."""
_KEEPALIVE_PROBES: Final = 3


class TcpServerTransport(Transport):
    """A TCP listener that serves one host at a time: a second connection is refused while one is live.

    The refused connection is accepted and closed at once (its peer reads end-of-file), logged and
    counted (:attr:`refused`); the host in control keeps the link. A host whose socket has closed (seen
    when the next connection arrives, before refusing it) or that stopped answering TCP keepalive
    probes frees the link. Each connect and each loss of a host counts in ``peer_changes``.

    Args:
        host: address to bind; loopback by default.
        port: 0 picks a free port (read :attr:`port`).
        tx_capacity: outgoing queue, as for every transport.

    Raises:
        OSError: the address cannot be bound (port in use, ...).
    """

    def __init__(self, host: str = "127.0.0.1", port: int = 0, tx_capacity: int = 64 * 1024) -> None:
        super().__init__(tx_capacity)
        self._server = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        self._server.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            self._server.bind((host, port))
            self._server.listen(1)
        except OSError:
            self._server.close()
            raise
        self._server.setblocking(False)
        self.host, self.port = self._server.getsockname()[:2]
        self._client: socket.socket | None = None
        self._peer = ""
        self.connections = 0
        self.refused = 0

    @property
    def url(self) -> str:
        """The pyserial URL the host connects to."""
        return f"socket://{self.host}:{self.port}"

    @property
    def connected(self) -> bool:
        """True while a host is connected."""
        self._accept()
        return self._client is not None

    def _accept(self) -> None:
        if self.closed:
            return
        try:
            conn, addr = self._server.accept()
        except (BlockingIOError, InterruptedError):
            return
        peer = f"{addr[0]}:{addr[1]}"
        if self._client is not None and self._client_alive():
            with contextlib.suppress(OSError):
                conn.close()
            self.refused += 1
            _log.warning("board link: refused a second host from %s while %s is connected", peer, self._peer)
            return
        self._drop_client()
        conn.setblocking(False)
        conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        conn.setsockopt(socket.SOL_SOCKET, socket.SO_KEEPALIVE, 1)
        conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_KEEPIDLE, _KEEPALIVE_S)
        conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_KEEPINTVL, _KEEPALIVE_S)
        conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_KEEPCNT, _KEEPALIVE_PROBES)
        self._client = conn
        self._peer = peer
        self.connections += 1
        self.peer_changes += 1
        _log.info("board link: host connected from %s", peer)

    def _client_alive(self) -> bool:
        """The connected host's socket is still open (peeked, nothing consumed)."""
        assert self._client is not None
        try:
            return bool(self._client.recv(1, socket.MSG_PEEK))
        except (BlockingIOError, InterruptedError):
            return True  # open, nothing to read
        except OSError:
            return False

    def _drop_client(self) -> None:
        if self._client is not None:
            with contextlib.suppress(OSError):
                self._client.close()
            self._client = None
            self.peer_changes += 1
        # A new host must start on a frame boundary: forget what the old one did not take.
        self._tx.clear()

    def _read(self) -> bytes:
        self._accept()
        if self._client is None:
            return b""
        try:
            data = self._client.recv(_READ_CHUNK_TCP)
        except (BlockingIOError, InterruptedError):
            return b""
        except OSError:
            self._drop_client()
            return b""
        if not data:  # orderly shutdown by the host
            self._drop_client()
        return data

    def _write(self, data: bytearray) -> int:
        if self._client is None:
            self._accept()
            if self._client is None:
                # Nobody listening: the bytes are gone, like a USB CDC endpoint with no host.
                return len(data)
        try:
            return self._client.send(data)
        except (BlockingIOError, InterruptedError):
            return 0
        except OSError:
            self._drop_client()
            return 0

    def _close(self) -> None:
        self._drop_client()
        with contextlib.suppress(OSError):
            self._server.close()


def parse_listen(listen: str, *, listen_any: bool = False) -> tuple[str, int]:
    """``socket://HOST:PORT`` -> (host, port), a loopback HOST unless ``listen_any``.

    Raises:
        ValueError: not that form, or reachable from other machines without ``listen_any``.
    """
    if not listen.startswith("socket://"):
        raise ValueError(f"--listen takes socket://HOST:PORT, got {listen!r}")
    host, sep, port = listen[len("socket://") :].rpartition(":")
    if not sep or not host or not port.isdigit() or not 0 <= int(port) <= 65535:
        raise ValueError(f"--listen takes socket://HOST:PORT, got {listen!r}")
    if not listen_any and not is_loopback_host(host):
        raise ValueError(
            f"--listen {listen} is reachable from other machines (anyone there can drive the arm): "
            "use a loopback address, or add --listen-any"
        )
    return host, int(port)


def is_loopback_host(host: str) -> bool:
    """``host`` (a name or an address, IPv6 in brackets or not) binds only this machine's loopback.

    Only ``localhost`` among names: any other name may resolve to an address other machines reach.
    """
    import ipaddress

    host = host.strip("[]")
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False
