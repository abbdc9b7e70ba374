"""Hostile MCAP files, crafted byte by byte (no binary fixtures): bombs, huge lengths, bad records, cuts.

Each :class:`Crafted` builds one file and states the one-line outcome every reader must give: the text
the bounded reader's refusal contains (``None``: read quietly up to a cut), and the exit status of
``spirob-hil replay``, ``spirob-hil recover`` and ``spirob-host --replay``. The files carry a lockstep
recording's ``spirob`` metadata (a default firmware, RC from the link) and no footer, so every command
reaches the hostile record: ``replay`` builds its firmware first, ``recover`` takes them for killed files.
Used by tests/hil/test_mcap_bounded.py and bench/recording_bombs.py.
"""

from __future__ import annotations

import json
import struct
import zlib
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import lz4.frame
import zstandard
from mcap.opcode import Opcode

from controller.config import FirmwareConfig
from hil.mcap_bounded import MAGIC
from protocol.messages import Event, EventKind, encode

GIB = 1 << 30
MIB = 1 << 20
LINK_TX_CHANNEL = 1


def _str(s: str | bytes) -> bytes:
    b = s.encode() if isinstance(s, str) else s
    return struct.pack("<I", len(b)) + b


def _map(pairs: dict[str, str]) -> bytes:
    body = b"".join(_str(k) + _str(v) for k, v in pairs.items())
    return struct.pack("<I", len(body)) + body


def record(opcode: int, body: bytes, length: int | None = None) -> bytes:
    """One record: opcode, length (``length`` overrides the true one), body."""
    return struct.pack("<BQ", opcode, len(body) if length is None else length) + body


def header() -> bytes:
    return record(Opcode.HEADER, _str("spirob") + _str("hostile-mcap"))


def metadata(pairs: dict[str, str]) -> bytes:
    return record(Opcode.METADATA, _str("spirob") + _map(pairs))


def schema(schema_id: int, name: str | bytes, data: bytes = b"{}") -> bytes:
    return record(Opcode.SCHEMA, struct.pack("<H", schema_id) + _str(name) + _str("jsonschema") + _str(data))


def channel(channel_id: int, topic: str | bytes, encoding: str = "spirob.raw", schema_id: int = 0) -> bytes:
    body = struct.pack("<HH", channel_id, schema_id) + _str(topic) + _str(encoding) + _map({})
    return record(Opcode.CHANNEL, body)


def message(channel_id: int, t_ns: int, data: bytes, length: int | None = None) -> bytes:
    body = struct.pack("<HIQQ", channel_id, 0, t_ns, t_ns) + data
    return record(Opcode.MESSAGE, body, length)


def chunk(compressed: bytes, compression: str, uncompressed_size: int, crc: int = 0) -> bytes:
    body = struct.pack("<QQQI", 0, 0, uncompressed_size, crc) + _str(compression)
    body += struct.pack("<Q", len(compressed)) + compressed
    return record(Opcode.CHUNK, body)


def zstd_zeros(n: int) -> bytes:
    """``n`` zero bytes zstd-compressed without holding them (1 GiB makes about 32 KiB)."""
    comp = zstandard.ZstdCompressor(level=3).compressobj()
    block = bytes(MIB)
    out = [comp.compress(block) for _ in range(n // MIB)]
    out.append(comp.compress(bytes(n % MIB)))
    out.append(comp.flush())
    return b"".join(out)


def lz4_zeros(n: int) -> bytes:
    """``n`` zero bytes lz4-compressed (one frame) without holding them (1 GiB makes about 4 MiB)."""
    comp = lz4.frame.LZ4FrameCompressor()
    out = [comp.begin()]
    block = bytes(MIB)
    out.extend(comp.compress(block) for _ in range(n // MIB))
    out.append(comp.compress(bytes(n % MIB)))
    out.append(comp.flush())
    return b"".join(out)


def recording_meta() -> dict[str, str]:
    """A lockstep recording's metadata: what ``spirob-hil replay`` needs to build its firmware."""
    return {"format": "2", "firmware": json.dumps(FirmwareConfig().to_dict()), "rc": "link"}


def preamble(topic: str = "/board/link_tx") -> bytes:
    """Magic, header, metadata and channel :data:`LINK_TX_CHANNEL` (the board -> host link by default)."""
    return MAGIC + header() + metadata(recording_meta()) + channel(LINK_TX_CHANNEL, topic)


_INFO_FRAME = encode(Event(0, EventKind.INFO), 0)
"""A board-link frame the host decodes (an empty INFO event, 27 bytes)."""


def small_messages(n: int, start_ns: int = 0, step_ns: int = 1_000_000) -> bytes:
    """``n`` small messages on the board -> host link channel, one INFO event frame each."""
    return b"".join(message(LINK_TX_CHANNEL, start_ns + k * step_ns, _INFO_FRAME) for k in range(n))


def zstd_chunk(inner: bytes) -> bytes:
    return chunk(zstandard.ZstdCompressor().compress(inner), "zstd", len(inner), zlib.crc32(inner))


@dataclass(frozen=True)
class Crafted:
    """One hostile file and what must come of it.

    Attributes:
        name: short name (the bench's row).
        what: what it is, in words.
        build: the file's bytes.
        refusal: text the one-line refusal contains; None: it reads quietly up to a cut.
        exits: exit status of ``spirob-hil replay``, ``spirob-hil recover``, ``spirob-host --replay``.
    """

    name: str
    what: str
    build: Callable[[], bytes]
    refusal: str | None
    exits: tuple[int, int, int] = (2, 2, 2)

    def write(self, directory: Path) -> Path:
        path = directory / f"{self.name}.mcap"
        path.write_bytes(self.build())
        return path


def _bad_schema() -> bytes:
    """A schema record of 7 bytes whose name announces 4 GiB."""
    return record(Opcode.SCHEMA, struct.pack("<HI", 1, 0xFFFF_FFFF) + b"x")


def _bad_schema_in_chunk() -> bytes:
    return preamble() + zstd_chunk(_bad_schema() + small_messages(3))


def _truncated() -> bytes:
    first = zstd_chunk(small_messages(100))
    second = zstd_chunk(small_messages(100, start_ns=100_000_000))
    return preamble() + first + second[: len(second) // 2]


CRAFTED: tuple[Crafted, ...] = (
    Crafted(
        "zstd-bomb",
        "a 32 KiB zstd chunk of 1 GiB of zeros announcing 1 GiB",
        lambda: preamble() + chunk(zstd_zeros(GIB), "zstd", GIB),
        "announces 1.0 GiB once inflated, over the 32.0 MiB cap",
    ),
    Crafted(
        "zstd-liar",
        "a zstd chunk announcing 1 MiB that inflates to 64 MiB",
        lambda: preamble() + chunk(zstd_zeros(64 * MIB), "zstd", MIB),
        "inflates past the 1.0 MiB it announces (zstd)",
    ),
    Crafted(
        "lz4-bomb",
        "an lz4 chunk of 1 GiB of zeros announcing 1 GiB",
        lambda: preamble() + chunk(lz4_zeros(GIB), "lz4", GIB),
        "announces 1.0 GiB once inflated, over the 32.0 MiB cap",
    ),
    Crafted(
        "lz4-liar",
        "an lz4 chunk announcing 1 KiB that inflates to 256 MiB (the mcap library has no lz4 limit)",
        lambda: preamble() + chunk(lz4_zeros(256 * MIB), "lz4", 1024),
        "inflates past the 1024 bytes it announces (lz4)",
    ),
    Crafted(
        "none-liar",
        "an uncompressed chunk announcing 1 MiB holding 10 bytes",
        lambda: preamble() + chunk(b"\x00" * 10, "", MIB),
        "inflates to 10 bytes, not the 1.0 MiB it announces",
    ),
    Crafted(
        "unknown-compression",
        "a chunk compressed with 'brotli'",
        lambda: preamble() + chunk(b"\x00" * 10, "brotli", 10),
        "unknown compression 'brotli'",
    ),
    Crafted(
        "huge-record",
        "a top-level message record announcing 1 TiB",
        lambda: preamble() + message(LINK_TX_CHANNEL, 0, b"\x00" * 8, length=1 << 40),
        "message record at byte ",
    ),
    Crafted(
        "huge-inner-record",
        "a message inside a zstd chunk announcing 2 GiB",
        lambda: preamble() + zstd_chunk(message(LINK_TX_CHANNEL, 0, b"\x00" * 8, length=2 * GIB)),
        "announces 2.0 GiB, past the chunk's end",
    ),
    Crafted(
        "bad-schema",
        "a schema whose name announces 4 GiB inside a 7-byte record",
        lambda: (
            preamble() + record(Opcode.SCHEMA, struct.pack("<H", 1) + struct.pack("<I", 0xFFFF_FFFF) + b"x")
        ),
        "malformed schema record at byte ",
    ),
    Crafted(
        "bad-schema-in-chunk",
        "the same schema inside a zstd chunk",
        _bad_schema_in_chunk,
        "malformed schema record at byte ",
    ),
    Crafted(
        "bad-channel-topic",
        "a channel whose topic is not UTF-8",
        lambda: preamble() + channel(2, b"\xff\xfe/topic"),
        "malformed channel record at byte ",
    ),
    Crafted(
        "truncated",
        "two zstd chunks of 100 messages, cut in the middle of the second (a killed writer)",
        _truncated,
        None,
        # replay: board outputs before any tick mark, not a lockstep recording (2); recover: the first chunk
        # (0); host: plays it (0)
        (2, 0, 0),
    ),
)
"""Every crafted file, in the bench's order."""
