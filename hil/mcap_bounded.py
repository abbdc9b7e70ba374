"""Bounded sequential reading of any MCAP file: the one place every recording is read through.

A recording is something a lab mails around, so its reader must not trust a single length in it. The
``mcap`` library's readers allocate whatever a record announces (up to 4 GiB per record) and inflate a
chunk to its announced size (zstd) or without any limit (lz4): a 35 KB file whose zstd chunk announces
1 GiB took 2.2 GB of memory. :func:`iter_records` reads the same records with two rules:

- **a cap** (:data:`MAX_RECORD_BYTES`): a record (chunk, message, schema, attachment...) announcing more,
  a chunk announcing more once inflated, or a chunk that inflates past what it announced (every
  compression MCAP allows: ``zstd``, ``lz4``, none) is refused with one :class:`RecordingError` line that
  names the record and its byte offset. A chunk is inflated at most to its announced size plus one byte.
- **truncation is not corruption**: a file that ends inside a record (its writer was killed) ends the
  iteration quietly at the last complete record; a record that is complete but does not parse (a string
  longer than its record, an unknown compression, a chunk that inflates to less than it announced) is
  refused.

Records are yielded one at a time, a chunk's records straight out of its inflated bytes, so memory is
bounded by the cap (twice: a compressed and an inflated chunk) whatever the file's size.
"""

from __future__ import annotations

import io
import struct
from collections.abc import Callable, Iterator
from typing import IO, Final

import lz4.frame
import zstandard
from mcap.data_stream import ReadDataStream
from mcap.exceptions import EndOfFile, McapError
from mcap.opcode import Opcode
from mcap.records import (
    Channel,
    Chunk,
    DataEnd,
    Footer,
    Header,
    McapRecord,
    Message,
    Metadata,
    Schema,
)

from hil.errors import HilError

__all__ = ["MAGIC", "MAX_RECORD_BYTES", "RecordingError", "iter_records"]

MAGIC: Final = b"\x89MCAP0\r\n"
"""The first (and last) bytes of every MCAP file."""

MAX_RECORD_BYTES: Final = 32 * 1024 * 1024
"""The largest record, and the largest inflated chunk, any reader here accepts (32 MiB). Our recorder
writes 256 KiB chunks; Foxglove's and the ``mcap`` CLI's writers default to a few MiB."""

_PREFIX = struct.Struct("<BQ")  # opcode u8, record length u64

_KNOWN: Final[dict[int, Callable[[ReadDataStream], McapRecord]]] = {
    Opcode.HEADER: Header.read,
    Opcode.FOOTER: Footer.read,
    Opcode.SCHEMA: Schema.read,
    Opcode.CHANNEL: Channel.read,
    Opcode.METADATA: Metadata.read,
    Opcode.DATA_END: DataEnd.read,
}
"""Records parsed and yielded besides messages and chunks; the others (indexes, statistics,
attachments, summary offsets, unknown opcodes) are skipped by their length."""


class RecordingError(HilError):
    """A recording that no reader here will open: a record over the cap, a bomb, a malformed record."""


def _size(n: int) -> str:
    if n >= 1 << 30:
        return f"{n / (1 << 30):.1f} GiB"
    if n >= 1 << 20:
        return f"{n / (1 << 20):.1f} MiB"
    return f"{n} bytes"


def _name(opcode: int) -> str:
    try:
        return Opcode(opcode).name.replace("_", " ").lower()
    except ValueError:
        return f"opcode 0x{opcode:02x}"


class _Exact(ReadDataStream):
    """A record's bytes, read strictly: a field that runs past the record's end is an error."""

    def __init__(self, data: bytes) -> None:
        super().__init__(io.BytesIO(data))

    def read(self, length: int) -> bytes:
        data = super().read(length)
        if len(data) != length:
            raise EndOfFile()
        return data


def _parse(opcode: int, body: bytes, where: str) -> McapRecord:
    stream = _Exact(body)
    try:
        if opcode == Opcode.MESSAGE:
            if len(body) < 22:
                raise EndOfFile()
            message: McapRecord = Message.read(stream, len(body))
            return message
        record: McapRecord = _KNOWN[opcode](stream)
        return record
    except (McapError, struct.error, UnicodeDecodeError, ValueError) as exc:
        raise RecordingError(f"malformed {_name(opcode)} record at {where}") from exc


def _inflate(chunk: Chunk, where: str, cap: int) -> bytes:
    announced = chunk.uncompressed_size
    if announced > cap:
        raise RecordingError(
            f"chunk at {where} announces {_size(announced)} once inflated, over the {_size(cap)} cap"
        )
    want = announced + 1  # one byte more than announced tells an inflation past it
    try:
        if chunk.compression == "zstd":
            with zstandard.ZstdDecompressor().stream_reader(chunk.data, read_across_frames=True) as r:
                data = r.read(want)
        elif chunk.compression == "lz4":
            data = lz4.frame.LZ4FrameDecompressor().decompress(chunk.data, max_length=want)
        elif chunk.compression == "":
            data = chunk.data
        else:
            raise RecordingError(f"chunk at {where} has an unknown compression {chunk.compression!r}")
    except (zstandard.ZstdError, RuntimeError) as exc:
        raise RecordingError(f"chunk at {where} does not inflate ({chunk.compression}): {exc}") from exc
    if len(data) > announced:
        raise RecordingError(
            f"chunk at {where} inflates past the {_size(announced)} it announces ({chunk.compression})"
        )
    if len(data) < announced:
        raise RecordingError(
            f"chunk at {where} inflates to {_size(len(data))}, not the {_size(announced)} it announces"
        )
    return data


def _chunk_records(chunk: Chunk, offset: int, cap: int) -> Iterator[McapRecord]:
    where = f"byte {offset}"
    data = _inflate(chunk, where, cap)
    view = memoryview(data)
    i = 0
    while i < len(data):
        if i + _PREFIX.size > len(data):
            raise RecordingError(f"chunk at {where} ends inside a record header")
        opcode, length = _PREFIX.unpack_from(data, i)
        i += _PREFIX.size
        if length > len(data) - i:
            raise RecordingError(
                f"{_name(opcode)} record {i - _PREFIX.size} bytes into the chunk at {where} announces "
                f"{_size(length)}, past the chunk's end"
            )
        if opcode == Opcode.MESSAGE or opcode in _KNOWN:
            yield _parse(opcode, bytes(view[i : i + length]), f"{where} (+{i - _PREFIX.size})")
        i += length


def iter_records(
    f: IO[bytes], *, chunks: bool = True, max_record_bytes: int = MAX_RECORD_BYTES
) -> Iterator[McapRecord]:
    """Every record of an MCAP file in file order, a chunk's records in place of the chunk.

    Yields headers, schemas, channels, messages, metadata, data ends and footers (the ``mcap``
    library's record classes); skips indexes, statistics, attachments and unknown records by their
    length. Stops quietly where the file is cut (a killed writer), and after the footer.

    Args:
        f: the file, at its start (its magic).
        chunks: False skips chunks unread (seeking past them): what reading the metadata needs.
        max_record_bytes: the cap (:data:`MAX_RECORD_BYTES`; tests lower it).

    Raises:
        RecordingError: not an MCAP file, a record over the cap, a chunk that inflates past its
            announced size or the cap, a malformed record (one line with the byte offset).
    """
    if f.read(len(MAGIC)) != MAGIC:
        raise RecordingError("not an MCAP file (no MCAP magic at its start)")
    offset = len(MAGIC)
    while True:
        prefix = f.read(_PREFIX.size)
        if len(prefix) < _PREFIX.size:
            return  # the end of a cut file
        opcode, length = _PREFIX.unpack(prefix)
        if length > max_record_bytes:
            raise RecordingError(
                f"{_name(opcode)} record at byte {offset} announces {_size(length)}, over the "
                f"{_size(max_record_bytes)} cap"
            )
        wanted = opcode in _KNOWN or opcode == Opcode.MESSAGE or (chunks and opcode == Opcode.CHUNK)
        if not wanted:
            here = f.tell()
            end = f.seek(0, io.SEEK_END)
            if here + length > end:
                return  # cut inside this record
            f.seek(here + length)
        else:
            body = f.read(length)
            if len(body) < length:
                return  # cut inside this record
            if opcode == Opcode.CHUNK:
                chunk = _parse_chunk(body, offset)
                del body
                yield from _chunk_records(chunk, offset, max_record_bytes)
            else:
                record = _parse(opcode, body, f"byte {offset}")
                yield record
                if isinstance(record, Footer):
                    return
        offset += _PREFIX.size + length


def _parse_chunk(body: bytes, offset: int) -> Chunk:
    try:
        chunk: Chunk = Chunk.read(_Exact(body))
        return chunk
    except (McapError, struct.error, UnicodeDecodeError, ValueError) as exc:
        raise RecordingError(f"malformed chunk record at byte {offset}") from exc
