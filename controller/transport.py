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

import os
import select
import threading
from abc import ABC, abstractmethod
from types import TracebackType
from typing import Any

from controller.errors import PortError

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
