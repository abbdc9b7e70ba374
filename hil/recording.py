"""Recordings in MCAP: every byte in and out of the board plus decoded telemetry.

Raw channels (``message_encoding`` ``spirob.raw``, no schema) hold the exact bytes that crossed each wire,
so a recording can be replayed through the firmware byte for byte. Decoded channels hold JSON objects
with a JSON schema, which Foxglove plots directly.

The writer chunks and compresses (zstd) and flushes a finished chunk every ``flush_every`` messages (and
the header with the metadata at once), so a process killed mid-run leaves a file whose complete chunks
:func:`read_records` and :func:`read_metadata` still read: a truncated tail is where reading stops,
never an error. Such a file has no summary, which the mcap library's normal (seeking) reader needs;
:func:`recover` copies what it holds into a complete file that reader opens, and
:func:`is_truncated` tells the two apart.

Timestamps: ``log_time`` is the board's clock in nanoseconds (``time_us * 1000``): simulated time in
lockstep runs, the monotonic clock in real-time runs; the host's monotonic clock in a recording of a run
against a port (metadata ``kind`` = :data:`KIND_PORT`).
"""

from __future__ import annotations

import dataclasses
import enum
import json
import struct
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from types import TracebackType
from typing import IO, Any, Final

import numpy as np
import numpy.typing as npt
from mcap.exceptions import McapError
from mcap.reader import make_reader
from mcap.records import Channel, Header, Message, Metadata, Schema
from mcap.stream_reader import StreamReader
from mcap.writer import CompressionType, Writer

from protocol.messages import Telemetry

PROFILE: Final = "spirob"
RAW_ENCODING: Final = "spirob.raw"

# Raw wires, named from the board's side (rx = into the board).
DBUS_RX: Final = "/board/dbus_rx"
"""DBUS bytes as the board's UART received them (one record per received chunk)."""
CAN_RX: Final = "/board/can_rx"
"""CAN frames into the board (C610 feedback): ``can_id u16 LE`` + data."""
CAN_TX: Final = "/board/can_tx"
"""CAN frames out of the board (0x200 current commands): ``can_id u16 LE`` + data."""
LINK_RX: Final = "/board/link_rx"
"""Board-link bytes from the host into the board."""
LINK_TX: Final = "/board/link_tx"
"""Board-link bytes from the board to the host."""
TICK: Final = "/board/tick"
"""One empty record per firmware tick, at the time the firmware saw (lockstep recordings)."""
POSES: Final = "/board/poses"
"""The plant's body poses as handed to the firmware's pose provider: n rows of x y z qw qx qy qz (f64)."""
RAW_TOPICS: Final = (DBUS_RX, CAN_RX, CAN_TX, LINK_RX, LINK_TX, TICK, POSES)

# Decoded channels (JSON) for people and plotting tools.
TELEMETRY: Final = "/telemetry"
"""The firmware's telemetry messages, decoded."""

KIND_PORT: Final = "port"
"""Metadata ``kind`` of a recording of a run against a port (``spirob-hil run --port --record``): the
link's bytes as the host saw them (``/board/link_rx``, ``/board/link_tx``) and the decoded telemetry, on
the host's monotonic clock. It has none of the board's other inputs, so it cannot be replayed."""

_CAN_HEADER = struct.Struct("<H")
_JSON_SCHEMA: Final = json.dumps({"type": "object"}).encode()


def pack_can(can_id: int, data: bytes) -> bytes:
    """One CAN frame as stored on a raw CAN channel."""
    return _CAN_HEADER.pack(can_id) + data


def unpack_can(record: bytes) -> tuple[int, bytes]:
    """Inverse of :func:`pack_can`."""
    (can_id,) = _CAN_HEADER.unpack_from(record)
    return can_id, record[_CAN_HEADER.size :]


def pack_poses(positions_m: npt.ArrayLike, quats_wxyz: npt.ArrayLike) -> bytes:
    """Body poses as stored on :data:`POSES`: n rows of x, y, z, qw, qx, qy, qz (float64 LE)."""
    return np.ascontiguousarray(np.hstack([positions_m, quats_wxyz]), dtype="<f8").tobytes()


def unpack_poses(data: bytes) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """Inverse of :func:`pack_poses`."""
    rows = np.frombuffer(data, dtype="<f8").reshape(-1, 7)
    return rows[:, :3], rows[:, 3:]


@dataclass(frozen=True, slots=True)
class Record:
    """One recorded message."""

    topic: str
    time_us: int
    data: bytes

    def json(self) -> Any:
        """The payload of a decoded (JSON) channel."""
        return json.loads(self.data)


class Recorder:
    """Writes an MCAP recording; a context manager, :meth:`close` is safe twice.

    Args:
        path: File to create (overwritten).
        metadata: String pairs stored as the ``spirob`` metadata record (scenario, seed, design...).
        flush_every: Finish and flush the current chunk after this many messages, bounding what a
            killed process can lose.
    """

    def __init__(
        self, path: str | Path, *, metadata: Mapping[str, str] | None = None, flush_every: int = 2000
    ) -> None:
        if flush_every < 1:
            raise ValueError("flush_every must be >= 1")
        self.path = Path(path)
        self._file: IO[bytes] = open(self.path, "wb")  # noqa: SIM115 - closed in close()
        self._writer = Writer(self._file, chunk_size=256 * 1024, compression=CompressionType.ZSTD)
        self._writer.start(profile=PROFILE, library="spirob-teleop")
        self._channels: dict[str, int] = {}
        self._json_schema = self._writer.register_schema("spirob.json", "jsonschema", _JSON_SCHEMA)
        self._flush_every = flush_every
        self._since_flush = 0
        self._closed = False
        self.messages_written = 0
        if metadata:
            self._writer.add_metadata(PROFILE, {str(k): str(v) for k, v in metadata.items()})
        # On disk at once: a file killed before its first chunk still says what it records.
        self._writer.flush()

    def _channel(self, topic: str, raw: bool) -> int:
        channel = self._channels.get(topic)
        if channel is None:
            if raw:
                channel = self._writer.register_channel(topic, RAW_ENCODING, schema_id=0)
            else:
                channel = self._writer.register_channel(topic, "json", schema_id=self._json_schema)
            self._channels[topic] = channel
        return channel

    def _add(self, channel: int, time_us: int, data: bytes) -> None:
        if self._closed:
            raise ValueError(f"recording {self.path} is closed")
        t_ns = time_us * 1000
        self._writer.add_message(channel, log_time=t_ns, data=data, publish_time=t_ns)
        self.messages_written += 1
        self._since_flush += 1
        if self._since_flush >= self._flush_every:
            self.flush()

    def write_raw(self, topic: str, time_us: int, data: bytes) -> None:
        """Records the exact bytes that crossed a wire at ``time_us``."""
        self._add(self._channel(topic, raw=True), time_us, bytes(data))

    def write_json(self, topic: str, time_us: int, obj: Mapping[str, Any]) -> None:
        """Records a decoded object (numbers, strings, lists) for plotting tools."""
        self._add(self._channel(topic, raw=False), time_us, json.dumps(obj, separators=(",", ":")).encode())

    def flush(self) -> None:
        """Writes the chunk in progress to disk."""
        if not self._closed:
            self._writer.flush()
            self._since_flush = 0

    def close(self) -> None:
        """Writes the summary and closes the file."""
        if self._closed:
            return
        self._closed = True
        try:
            self._writer.finish()
        finally:
            self._file.close()

    def __enter__(self) -> Recorder:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()


MCAP_MAGIC: Final = b"\x89MCAP0\r\n"
"""The first bytes of every MCAP file."""


def is_mcap(path: str | Path) -> bool:
    """The file starts with MCAP's magic bytes (a cheap check before reading it as a recording)."""
    with open(path, "rb") as f:
        return f.read(len(MCAP_MAGIC)) == MCAP_MAGIC


TRUNCATED_KEY: Final = "truncated"
"""Metadata key :func:`recover` sets: the file is complete, the run it records is not."""


def _ends_with_magic(f: IO[bytes]) -> bool:
    """The file ends with MCAP's closing magic (its writer finished); leaves ``f`` at its start."""
    f.seek(0, 2)
    ends = False
    if f.tell() >= 2 * len(MCAP_MAGIC):
        f.seek(-len(MCAP_MAGIC), 2)
        ends = f.read() == MCAP_MAGIC
    f.seek(0)
    return ends


def is_truncated(path: str | Path) -> bool:
    """True for a recording cut short: no closing magic (its writer never finished), or recovered."""
    with open(path, "rb") as f:
        if not _ends_with_magic(f):
            return True
    return read_metadata(path).get(TRUNCATED_KEY) == "true"


def read_metadata(path: str | Path) -> dict[str, str]:
    """The ``spirob`` metadata record of a recording (empty if none), of a truncated file too."""
    with open(path, "rb") as f:
        try:
            if _ends_with_magic(f):
                for meta in make_reader(f).iter_metadata():
                    if meta.name == PROFILE:
                        return dict(meta.metadata)
                return {}
            for rec in StreamReader(f, skip_magic=False).records:
                if isinstance(rec, Metadata) and rec.name == PROFILE:
                    return dict(rec.metadata)
        except (McapError, EOFError, struct.error, ValueError):
            pass
    return {}


@dataclass(frozen=True, slots=True)
class Recovered:
    """What :func:`recover` copied.

    Attributes:
        messages_n: messages copied.
        last_time_us: log time of the last one (None without messages).
    """

    messages_n: int
    last_time_us: int | None


def recover(path: str | Path, out: str | Path) -> Recovered:
    """Copy every complete record of a (truncated) recording into a complete MCAP file at ``out``.

    Schemas, channels, metadata and messages are kept as they were, in file order; the new file has a
    summary and an index, so the mcap library's normal reader (and Foxglove) opens it. Its ``spirob``
    metadata gains ``truncated`` = ``true``: the run it records was cut short all the same.
    """
    schema_ids: dict[int, int] = {0: 0}
    channel_ids: dict[int, int] = {}
    n = 0
    last: int | None = None
    with open(path, "rb") as src, open(out, "wb") as dst:
        writer = Writer(dst, chunk_size=256 * 1024, compression=CompressionType.ZSTD)
        started = False
        try:
            for rec in StreamReader(src, skip_magic=False).records:
                if isinstance(rec, Header):
                    writer.start(profile=rec.profile, library=rec.library)
                    started = True
                elif not started:
                    continue
                elif isinstance(rec, Schema):
                    schema_ids[rec.id] = writer.register_schema(rec.name, rec.encoding, rec.data)
                elif isinstance(rec, Channel) and rec.id not in channel_ids:
                    channel_ids[rec.id] = writer.register_channel(
                        rec.topic, rec.message_encoding, schema_ids.get(rec.schema_id, 0), dict(rec.metadata)
                    )
                elif isinstance(rec, Metadata):
                    meta = dict(rec.metadata)
                    if rec.name == PROFILE:
                        meta[TRUNCATED_KEY] = "true"  # complete now, but its run was cut short
                    writer.add_metadata(rec.name, meta)
                elif isinstance(rec, Message) and rec.channel_id in channel_ids:
                    channel = channel_ids[rec.channel_id]
                    writer.add_message(channel, rec.log_time, bytes(rec.data), rec.publish_time, rec.sequence)
                    n += 1
                    last = rec.log_time // 1000
        except (McapError, EOFError, struct.error, ValueError):
            pass  # the truncated tail
        if not started:
            writer.start(profile=PROFILE, library="spirob-teleop")
        writer.finish()
    return Recovered(n, last)


def read_records(path: str | Path, topics: frozenset[str] | set[str] | None = None) -> Iterator[Record]:
    """Every message of a recording in file order, stopping quietly at a truncated tail.

    Reads sequentially (no index needed), so files of a killed process read up to their last complete
    chunk.
    """
    channels: dict[int, str] = {}
    with open(path, "rb") as f:
        reader = StreamReader(f, skip_magic=False)
        try:
            for rec in reader.records:
                if isinstance(rec, Message):
                    topic = channels.get(rec.channel_id)
                    if topic is not None and (topics is None or topic in topics):
                        yield Record(topic, rec.log_time // 1000, bytes(rec.data))
                elif isinstance(rec, Channel):
                    channels[rec.id] = rec.topic
        except (McapError, EOFError, struct.error, ValueError):
            return


def telemetry_json(msg: Telemetry) -> dict[str, Any]:
    """A telemetry message as plain JSON numbers (enums as their values, so plotting tools plot them)."""
    out: dict[str, Any] = {}
    for f in dataclasses.fields(msg):
        v = getattr(msg, f.name)
        if isinstance(v, enum.Enum):
            out[f.name] = int(v.value)
        elif isinstance(v, tuple):
            out[f.name] = list(v)
        else:
            out[f.name] = v
    return out
