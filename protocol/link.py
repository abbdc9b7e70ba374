"""The board link: DJI's serial frame (as used for the RoboMaster referee system) over USB CDC.

Frame layout (all multi-byte fields little-endian)::

    offset  size  field
    0       1     SOF = 0xA5
    1       2     data_length (payload bytes, u16)
    3       1     seq (u8, wraps)
    4       1     CRC8 of bytes 0..3
    5       2     cmd_id (u16)
    7       n     payload (data_length bytes)
    7+n     2     CRC16 of bytes 0..6+n

CRC8: polynomial 0x31 reflected (0x8C), init 0xFF, no final xor; check value of b"123456789" is 0x0B.
CRC16: CRC-16/MCRF4XX (0x1021 reflected = 0x8408, init 0xFFFF, no final xor); check value 0x6F91.
Both are what DJI's ``CRC8_CRC16.c`` (``Development-Board-C-Examples``, ``components/support``) computes
with its tables ``CRC8_TAB`` and ``wCRC_Table``, computed here by ``fastcrc`` (CRC-8/MAXIM-DOW started
at 0xFF, CRC-16/MCRF4XX); the command ids and payloads carried are ours (see
``protocol.messages`` and ``docs/board-link.md``).
"""

from __future__ import annotations

import struct
from collections.abc import Mapping
from dataclasses import dataclass

from fastcrc.crc8 import maxim_dow as _crc8_maxim_dow
from fastcrc.crc16 import mcrf4xx as _crc16_mcrf4xx

__all__ = [
    "CRC8_INIT",
    "CRC16_INIT",
    "HEADER_LEN",
    "ID_END",
    "MAX_PAYLOAD",
    "OVERHEAD",
    "SOF",
    "LinkFrame",
    "LinkParser",
    "crc8",
    "crc16",
    "encode_frame",
]

SOF = 0xA5
"""Start-of-frame byte."""
HEADER_LEN = 5
"""SOF, data_length, seq, CRC8."""
OVERHEAD = HEADER_LEN + 2 + 2
"""Bytes around the payload: header, cmd_id, CRC16."""
ID_END = HEADER_LEN + 2
"""Bytes of a frame up to and including its ``cmd_id``: what a parser with per-id lengths reads first."""
MAX_PAYLOAD = 2048
"""Largest payload accepted by :func:`encode_frame` and :class:`LinkParser`.

Our largest message is ``ArmPoses`` with 64 units (1803 bytes); a corrupted length can make the parser
wait for at most this many bytes before the CRC16 rejects the frame.
"""
CRC8_INIT = 0xFF
CRC16_INIT = 0xFFFF


def crc8(data: bytes | bytearray | memoryview, init: int = CRC8_INIT) -> int:
    """DJI CRC8 (poly 0x31 reflected, init 0xFF, no final xor) of ``data``; chainable through ``init``.

    fastcrc's CRC-8/MAXIM-DOW is this polynomial, reflected, without final xor; only its standard init
    (0x00) differs, so DJI's 0xFF goes in as the starting value.
    """
    return _crc8_maxim_dow(data, init)


def crc16(data: bytes | bytearray | memoryview, init: int = CRC16_INIT) -> int:
    """CRC-16/MCRF4XX (DJI's CRC16: poly 0x1021 reflected, init 0xFFFF, no final xor) of ``data``;
    chainable through ``init`` (fastcrc's ``mcrf4xx``)."""
    return _crc16_mcrf4xx(data, init)


_HEAD = struct.Struct("<BHB")
_CMD = struct.Struct("<H")
_U16 = struct.Struct("<H")


def encode_frame(cmd_id: int, payload: bytes | bytearray | memoryview, seq: int) -> bytes:
    """Build one complete link frame.

    Args:
        cmd_id: command id, 0..0xFFFF.
        payload: the message body, at most ``MAX_PAYLOAD`` bytes.
        seq: sequence number, 0..255 (the sender increments it modulo 256 per frame).

    Returns:
        The frame bytes, ``len(payload) + OVERHEAD`` long.

    Raises:
        ValueError: an argument is out of range.
    """
    n = len(payload)
    if n > MAX_PAYLOAD:
        raise ValueError(f"payload of {n} bytes exceeds MAX_PAYLOAD = {MAX_PAYLOAD}")
    if not 0 <= seq <= 0xFF:
        raise ValueError(f"seq must be 0..255, got {seq}")
    if not 0 <= cmd_id <= 0xFFFF:
        raise ValueError(f"cmd_id must be 0..0xFFFF, got {cmd_id}")
    head = _HEAD.pack(SOF, n, seq)
    body = b"".join((head, bytes((crc8(head),)), _CMD.pack(cmd_id), payload))
    return body + _U16.pack(crc16(body))


@dataclass(frozen=True, slots=True)
class LinkFrame:
    """One verified link frame.

    Attributes:
        cmd_id: command id (see ``protocol.messages``).
        seq: the sender's sequence number, 0..255.
        payload: the message body.
    """

    cmd_id: int
    seq: int
    payload: bytes

    def encode(self) -> bytes:
        """The frame's wire bytes (``encode_frame(cmd_id, payload, seq)``)."""
        return encode_frame(self.cmd_id, self.payload, self.seq)


class LinkParser:
    """Incremental board-link parser: feed any chunks of bytes, get verified frames back.

    Never raises on any input. After an error it resynchronises on the next 0xA5: scanning resumes at
    the byte after the 0xA5 that started the bad frame, so a good frame hidden inside a corrupted or
    truncated one is still found. A frame is delivered only if both CRCs match.

    With ``lengths`` (``cmd_id -> longest payload``, the board's receive side) the parser also reads the
    ``cmd_id`` right after a good header and refuses, at once, an id not in the table and a length above
    that id's own: no header then makes it wait for more than one real frame of the longest accepted id.
    (Without the table a corrupted length can hold it for up to ``max_payload`` + 9 bytes.)

    Counters (monotonic): ``frames_ok``; ``header_crc_errors``; ``body_crc_errors``; ``oversize_errors``
    (header CRC good but data_length > ``max_payload``, or above its id's length); ``id_errors`` (header
    CRC good but an id not in ``lengths``); ``bytes_skipped`` (every byte discarded while hunting for a
    frame: garbage and the SOF bytes of rejected frames).
    """

    def __init__(self, max_payload: int = MAX_PAYLOAD, lengths: Mapping[int, int] | None = None) -> None:
        """Create a parser.

        Args:
            max_payload: longest payload accepted; longer declared lengths are rejected and counted.
            lengths: if given, the only ids accepted, each with its longest payload (capped by
                ``max_payload``).

        Raises:
            ValueError: ``max_payload`` or a length is negative or above 0xFFFF.
        """
        if not 0 <= max_payload <= 0xFFFF:
            raise ValueError(f"max_payload must be 0..65535, got {max_payload}")
        if lengths is not None and not all(0 <= n <= 0xFFFF for n in lengths.values()):
            raise ValueError(f"lengths must be 0..65535, got {dict(lengths)}")
        self.max_payload = max_payload
        self.lengths: dict[int, int] | None = (
            None if lengths is None else {i: min(n, max_payload) for i, n in lengths.items()}
        )
        self.frames_ok = 0
        self.header_crc_errors = 0
        self.body_crc_errors = 0
        self.oversize_errors = 0
        self.id_errors = 0
        self.bytes_skipped = 0
        self._buf = bytearray()

    def counters(self) -> dict[str, int]:
        """All counters by name (for telemetry and health displays)."""
        return {
            "frames_ok": self.frames_ok,
            "header_crc_errors": self.header_crc_errors,
            "body_crc_errors": self.body_crc_errors,
            "oversize_errors": self.oversize_errors,
            "id_errors": self.id_errors,
            "bytes_skipped": self.bytes_skipped,
        }

    @property
    def pending(self) -> int:
        """Bytes buffered waiting for the rest of a frame."""
        return len(self._buf)

    def reset(self) -> None:
        """Drop buffered bytes without counting them (e.g. after a reconnect)."""
        self._buf.clear()

    def feed(self, data: bytes | bytearray | memoryview) -> list[LinkFrame]:
        """Add received bytes; return every frame they complete, in order."""
        if not data:
            # The buffer holds at most the start of one incomplete frame (each call consumes everything
            # else), so no bytes cannot complete or reject anything: skip the scan (most polls are empty).
            return []
        buf = self._buf
        buf += data
        out: list[LinkFrame] = []
        lengths = self.lengths
        pos = 0
        end = len(buf)
        while True:
            start = buf.find(SOF, pos)
            if start < 0:
                self.bytes_skipped += end - pos
                pos = end
                break
            self.bytes_skipped += start - pos
            pos = start
            if end - pos < HEADER_LEN:
                break
            if crc8(buf[pos : pos + 4]) != buf[pos + 4]:
                self.header_crc_errors += 1
                self.bytes_skipped += 1
                pos += 1
                continue
            n = buf[pos + 1] | (buf[pos + 2] << 8)
            if n > self.max_payload:
                self.oversize_errors += 1
                self.bytes_skipped += 1
                pos += 1
                continue
            if lengths is not None:
                if end - pos < ID_END:
                    break
                cap = lengths.get(buf[pos + 5] | (buf[pos + 6] << 8))
                if cap is None or n > cap:
                    if cap is None:
                        self.id_errors += 1
                    else:
                        self.oversize_errors += 1
                    self.bytes_skipped += 1
                    pos += 1
                    continue
            total = n + OVERHEAD
            if end - pos < total:
                break
            crc_at = pos + total - 2
            if crc16(buf[pos:crc_at]) != (buf[crc_at] | (buf[crc_at + 1] << 8)):
                self.body_crc_errors += 1
                self.bytes_skipped += 1
                pos += 1
                continue
            out.append(
                LinkFrame(buf[pos + 5] | (buf[pos + 6] << 8), buf[pos + 3], bytes(buf[pos + 7 : crc_at]))
            )
            self.frames_ok += 1
            pos += total
        if pos:
            del buf[:pos]
        return out
