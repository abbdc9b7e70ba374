"""The ``.tlog`` of every MAVLink packet in and out (the format MAVProxy and ``mavlogdump.py`` read)."""

from __future__ import annotations

import struct
from pathlib import Path
from typing import IO, Final

__all__ = ["TLOG_LINK_IN", "TLOG_LINK_OUT", "TlogWriter"]

TLOG_LINK_IN: Final[int] = 0
"""Low two bits of a ``.tlog`` timestamp for a received packet (MAVProxy puts the link number there)."""
TLOG_LINK_OUT: Final[int] = 3
"""Low two bits for a packet we sent (MAVProxy's value for its own outgoing packets)."""


class TlogWriter:
    """Append packets to a ``.tlog``: 8-byte big-endian µs Unix timestamp, then the raw packet.

    The timestamp's two low bits carry the direction (:data:`TLOG_LINK_IN` / :data:`TLOG_LINK_OUT`),
    as MAVProxy stores a link number there. ``mavlogdump.py`` and ``mavutil.mavlink_connection(path)``
    read the file back.

    Args:
        path: File to create (truncated if it exists; parent directories are created).
    """

    def __init__(self, path: Path) -> None:
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        self.path = path
        self._file: IO[bytes] | None = open(path, "wb")  # noqa: SIM115 - closed by close()
        self.records = 0

    def write(self, packet: bytes, unix_us: int, link: int) -> None:
        """Write one record (no-op after :meth:`close`).

        Args:
            packet: The raw packet.
            unix_us: Unix time in µs.
            link: :data:`TLOG_LINK_IN` or :data:`TLOG_LINK_OUT`.
        """
        if self._file is None:
            return
        self._file.write(struct.pack(">Q", (unix_us & ~3) | (link & 3)) + packet)
        self.records += 1

    def flush(self) -> None:
        """Flush buffered records to the OS."""
        if self._file is not None:
            self._file.flush()

    def close(self) -> None:
        """Flush and close (safe twice)."""
        if self._file is not None:
            self._file.close()
            self._file = None
