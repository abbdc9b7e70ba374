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
import tty
from typing import Final

from controller.transport import Transport

_log = logging.getLogger(__name__)

_READ_CHUNK: Final = 4096


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
