"""Recordings in MCAP: every byte in and out of the board plus decoded telemetry.

Raw channels (``message_encoding`` ``spirob.raw``, no schema) hold the exact bytes that crossed each wire,
so a recording can be replayed through the firmware byte for byte. Decoded channels hold JSON objects
with a JSON schema, which Foxglove plots directly.

The writer chunks and compresses (zstd) and flushes a finished chunk every ``flush_every`` messages, so a
process killed mid-run leaves a file whose complete chunks :func:`read_records` still reads: a truncated
tail is where reading stops, never an error.

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
from mcap.records import Channel, Message
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


def read_metadata(path: str | Path) -> dict[str, str]:
    """The ``spirob`` metadata record of a recording (empty if none)."""
    with open(path, "rb") as f:
        try:
            for meta in make_reader(f).iter_metadata():
                if meta.name == PROFILE:
                    return dict(meta.metadata)
        except (McapError, EOFError, struct.error, ValueError):
            pass
    return {}


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
