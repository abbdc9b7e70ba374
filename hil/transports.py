"""Board-side endpoints of the board link for the virtual board: a pseudo-terminal or a TCP server.

The real board is a USB CDC device (/dev/ttyACM0); the virtual board offers the same byte stream on a
pty (``spirob-host --port /dev/pts/N``) or on a TCP port (``spirob-host --port socket://127.0.0.1:P``).
Both are :class:`controller.transport.Transport` back ends, so they never block the firmware loop.
"""

from __future__ import annotations

import contextlib
import errno
import logging
import os
import socket
import tty
from typing import Final

from controller.transport import Transport

_log = logging.getLogger(__name__)

_READ_CHUNK: Final = 4096
_KEEPALIVE_S: Final = 1
"""TCP keepalive idle time and probe interval: a host that vanished without closing its socket (a
network gone, a machine off) frees the link after about 4 s instead of holding it forever."""
_KEEPALIVE_PROBES: Final = 3


class PtyTransport(Transport):
    """The board's end of a pseudo-terminal pair; :attr:`path` is what the host opens."""

    def __init__(self, tx_capacity: int = 64 * 1024) -> None:
        super().__init__(tx_capacity)
        self._master, self._slave = os.openpty()
        tty.setraw(self._slave)
        self.path = os.ttyname(self._slave)
        # We keep the slave open ourselves: when the host closes its end the master would otherwise
        # read EIO until someone reopens it.
        os.set_blocking(self._master, False)

    @property
    def url(self) -> str:
        """What the host passes to ``--port``."""
        return self.path

    def _read(self) -> bytes:
        try:
            return os.read(self._master, _READ_CHUNK)
        except BlockingIOError:
            return b""
        except OSError as exc:
            if exc.errno == errno.EIO:  # no reader/writer on the slave side right now
                return b""
            raise

    def _write(self, data: bytearray) -> int:
        try:
            return os.write(self._master, data)
        except BlockingIOError:
            return 0

    def _close(self) -> None:
        for fd in (self._master, self._slave):
            with contextlib.suppress(OSError):
                os.close(fd)


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
            data = self._client.recv(_READ_CHUNK)
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
