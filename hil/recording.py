"""Recordings in MCAP: every byte in and out of the board, and the run in Foxglove's own schemas.

Raw channels (``message_encoding`` ``spirob.raw``, no schema) hold the exact bytes that crossed each wire,
so a recording can be replayed through the firmware byte for byte. The other channels are what Foxglove
opens with no set-up (:mod:`hil.foxglove_log`): the drone and every unit as ``foxglove.FrameTransforms``
(``/tf``), the arm's shape as ``foxglove.SceneUpdate`` (``/arm/scene``), events as ``foxglove.Log``
(``/events``), and JSON channels with a real JSON schema (``/telemetry``, one layout for host and HIL
recordings; ``/board/config``). A channel is declared when its first message is written, so a file
declares no channel it does not hold.

The writer is the ``mcap`` library's, fed the Foxglove SDK's encodings and schemas: it writes channels
without a schema (the raw wires), flushes a finished chunk on demand and reads back sequentially, which
the crash-safety below needs; the SDK's own writer does not expose those.

The writer chunks and compresses (zstd) and flushes a finished chunk every ``flush_every`` messages (and
the header with the metadata at once), so a process killed mid-run leaves a file whose complete chunks
:func:`read_records` and :func:`read_metadata` still read: a truncated tail is where reading stops,
never an error. Such a file has no summary, which the mcap library's normal (seeking) reader needs;
:func:`recover` copies what it holds into a complete file that reader opens, and
:func:`is_truncated` tells the two apart.

Timestamps (format 3): ``log_time`` and ``publish_time`` are equal, the board's clock (``time_us * 1000``)
plus ``clock_offset_ns`` (metadata key of that name). A recording of something that ran in real time (a run
against a port, metadata ``kind`` = :data:`KIND_PORT`, and ``spirob-host`` recordings) is on the host's
monotonic clock with the offset that makes both times Unix time, so it lines up with the ``.tlog`` and
anything else logged beside it, and Foxglove's log-time and publish-time timelines agree. A lockstep run has
no wall clock: its simulated time runs faster than real time, and a recording of it stays byte-identical for
a seed, so its offset is 0 and both times are simulated time. :attr:`Record.time_us` (the board's clock) is
``log_time - clock_offset_ns``, which holds for every format: format 2 wrote the board's clock in
``publish_time`` (``log_time`` = it + the offset), format 1 (no ``format`` key, no offset) both times equal to
the board's.
"""

from __future__ import annotations

import importlib.metadata
import json
import struct
import time
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from types import TracebackType
from typing import IO, Any, Final

import numpy as np
import numpy.typing as npt
from foxglove.messages import LogLevel
from mcap.records import Channel, Header, Message, Metadata, Schema
from mcap.writer import CompressionType, Writer

from hil import foxglove_log
from hil.foxglove_log import TELEMETRY, ChannelSpec, FoxgloveView
from hil.mcap_bounded import MAGIC, RecordingError, iter_records

__all__ = [
    "BOARD_CONFIG",
    "CAN_RX",
    "CAN_TX",
    "DBUS_RX",
    "FORMAT",
    "KIND_PORT",
    "LINK_RX",
    "LINK_TX",
    "POSES",
    "RAW_TOPICS",
    "TICK",
    "Record",
    "Recorder",
    "Recovered",
    "clock_offset_of",
    "is_mcap",
    "is_truncated",
    "monotonic_clock_offset_ns",
    "pack_can",
    "pack_poses",
    "package_version",
    "read_metadata",
    "read_records",
    "recording_format",
    "recover",
    "unpack_can",
    "unpack_poses",
]

PROFILE: Final = "spirob"
RAW_ENCODING: Final = "spirob.raw"

FORMAT: Final = 3
"""Layout of the files this module writes (metadata ``format``). 1 (no key): JSON channels with an empty
schema, ``log_time`` on the board's clock. 2: Foxglove's schemas, Unix ``log_time``, the board's clock in
``publish_time``. 3: ``publish_time`` equal to ``log_time`` (Unix time in real-time recordings)."""

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

BOARD_CONFIG: Final = "/board/config"
"""The virtual board's configuration (JSON, once at board time 0)."""

_JSON_CHANNELS: Final[dict[str, ChannelSpec]] = {
    TELEMETRY: foxglove_log.CHANNELS[TELEMETRY],
    BOARD_CONFIG: foxglove_log.json_spec(BOARD_CONFIG, foxglove_log.BOARD_CONFIG_SCHEMA),
}

KIND_PORT: Final = "port"
"""Metadata ``kind`` of a recording of a run against a port (``spirob-hil run --port --record``): the
link's bytes as the host saw them (``/board/link_rx``, ``/board/link_tx``) and the decoded telemetry, on
the host's monotonic clock. It has none of the board's other inputs, so it cannot be replayed."""

_CAN_HEADER = struct.Struct("<H")


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


def monotonic_clock_offset_ns() -> int:
    """Unix time minus the monotonic clock, in ns: what turns a monotonic time into a Unix one."""
    return time.time_ns() - time.monotonic_ns()


def package_version() -> str:
    """The installed spirob-teleop version (``unknown`` when run from a tree that was never installed)."""
    try:
        return importlib.metadata.version("spirob-teleop")
    except importlib.metadata.PackageNotFoundError:
        return "unknown"


def recording_format(meta: Mapping[str, str]) -> int:
    """The ``format`` of a recording from its metadata (1 for files written before the key existed).

    Raises:
        ValueError: the key is not an integer.
    """
    return int(meta.get("format", "1"))


def clock_offset_of(meta: Mapping[str, str]) -> int:
    """The ``clock_offset_ns`` of a recording's metadata: ``log_time`` minus the board's clock (0 when
    absent, as in format 1).

    Raises:
        RecordingError: the value is not an integer.
    """
    value = meta.get("clock_offset_ns", "0")
    try:
        return int(value)
    except ValueError as exc:
        raise RecordingError(f"metadata clock_offset_ns {value[:40]!r} is not an integer") from exc


@dataclass(frozen=True, slots=True)
class Record:
    """One recorded message.

    Attributes:
        topic: its channel's topic.
        time_us: the board's clock (MCAP ``log_time`` minus the metadata's ``clock_offset_ns``).
        data: the payload.
        log_time_ns: MCAP ``log_time`` (Unix ns in real-time recordings of format 2 and later).
    """

    topic: str
    time_us: int
    data: bytes
    log_time_ns: int = 0

    def json(self) -> Any:
        """The payload of a decoded (JSON) channel."""
        return json.loads(self.data)


class Recorder:
    """Writes an MCAP recording; a context manager, :meth:`close` is safe twice.

    Args:
        path: File to create (overwritten).
        metadata: String pairs stored as the ``spirob`` metadata record (scenario, seed, design...);
            ``format``, ``version`` (the package's) and ``clock_offset_ns`` are added.
        flush_every: Finish and flush the current chunk after this many messages, bounding what a
            killed process can lose.
        clock_offset_ns: Added to every ``time_us`` (in ns) to make ``log_time`` and ``publish_time``
            (equal). Default: for a
            recording of ``kind`` :data:`KIND_PORT` (the host's monotonic clock)
            :func:`monotonic_clock_offset_ns`, so both are Unix time; else 0, simulated time
            (deterministic: a lockstep recording is byte-identical for a seed).
    """

    def __init__(
        self,
        path: str | Path,
        *,
        metadata: Mapping[str, str] | None = None,
        flush_every: int = 2000,
        clock_offset_ns: int | None = None,
    ) -> None:
        if flush_every < 1:
            raise ValueError("flush_every must be >= 1")
        meta = {str(k): str(v) for k, v in (metadata or {}).items()}
        if clock_offset_ns is None:
            port = meta.get("kind") == KIND_PORT
            clock_offset_ns = monotonic_clock_offset_ns() if port else 0
        self._offset_ns = clock_offset_ns
        meta.update(format=str(FORMAT), version=package_version(), clock_offset_ns=str(clock_offset_ns))
        self.path = Path(path)
        self._file: IO[bytes] = open(self.path, "wb")  # noqa: SIM115 - closed in close()
        self._writer = Writer(self._file, chunk_size=256 * 1024, compression=CompressionType.ZSTD)
        self._writer.start(profile=PROFILE, library=f"spirob-teleop {meta['version']}")
        self._channels: dict[str, int] = {}
        self._view = FoxgloveView(foxglove_log.design_sizes(meta.get("design")))
        self._flush_every = flush_every
        self._since_flush = 0
        self._closed = False
        self.messages_written = 0
        self._writer.add_metadata(PROFILE, meta)
        # On disk at once: a file killed before its first chunk still says what it records.
        self._writer.flush()

    def _raw_channel(self, topic: str) -> int:
        channel = self._channels.get(topic)
        if channel is None:
            channel = self._writer.register_channel(topic, RAW_ENCODING, schema_id=0)
            self._channels[topic] = channel
        return channel

    def _spec_channel(self, spec: ChannelSpec) -> int:
        channel = self._channels.get(spec.topic)
        if channel is None:
            schema = self._writer.register_schema(spec.schema_name, spec.schema_encoding, spec.schema_data)
            channel = self._writer.register_channel(spec.topic, spec.message_encoding, schema_id=schema)
            self._channels[spec.topic] = channel
        return channel

    def _add(self, channel: int, time_us: int, data: bytes) -> None:
        if self._closed:
            raise ValueError(f"recording {self.path} is closed")
        t_ns = time_us * 1000 + self._offset_ns
        self._writer.add_message(channel, log_time=t_ns, data=data, publish_time=t_ns)
        self.messages_written += 1
        self._since_flush += 1
        if self._since_flush >= self._flush_every:
            self.flush()

    def _add_view(self, time_us: int, messages: list[tuple[str, bytes]]) -> None:
        for topic, data in messages:
            self._add(self._spec_channel(foxglove_log.CHANNELS[topic]), time_us, data)

    @property
    def clock_offset_ns(self) -> int:
        """Unix time of board time 0 in a real-time recording, 0 in a lockstep one (``log_time`` minus the
        board's clock)."""
        return self._offset_ns

    def unix_ns(self, time_us: int) -> int:
        """The ``log_time`` (and ``publish_time``) of a message written at ``time_us``."""
        return time_us * 1000 + self._offset_ns

    def write_raw(self, topic: str, time_us: int, data: bytes, *, view_bodies: int | None = None) -> None:
        """Records the exact bytes that crossed a wire at ``time_us``.

        Poses (:data:`POSES`) are also written as Foxglove transforms (and the arm's shape when due): of
        their first ``view_bodies`` bodies if given (an array's drone and arm 0: the view draws one chain).
        """
        self._add(self._raw_channel(topic), time_us, bytes(data))
        if topic == POSES:
            positions, quats = unpack_poses(data)
            if view_bodies is not None:
                positions, quats = positions[:view_bodies], quats[:view_bodies]
            self.write_poses(time_us, positions, quats)

    def write_poses(self, time_us: int, positions_m: npt.ArrayLike, quats_wxyz: npt.ArrayLike) -> None:
        """Records body poses (drone first, then the units base to tip) as Foxglove transforms."""
        self._add_view(time_us, self._view.poses(self.unix_ns(time_us), time_us, positions_m, quats_wxyz))

    def write_json(
        self, topic: str, time_us: int, obj: Mapping[str, Any], *, schema: Mapping[str, Any] | None = None
    ) -> None:
        """Records a decoded object on a JSON channel with its JSON schema: :data:`TELEMETRY` and
        :data:`BOARD_CONFIG` have theirs, another topic passes ``schema`` (its ``title`` names it).
        Telemetry also writes an event for each change of state it shows.

        Raises:
            ValueError: a topic without a JSON schema, or the recording is closed.
        """
        if topic == TELEMETRY:
            self._add_view(time_us, self._view.telemetry(self.unix_ns(time_us), obj))
            return
        spec = _JSON_CHANNELS.get(topic)
        if spec is None and schema is not None:
            spec = foxglove_log.json_spec(topic, schema)
        if spec is None:
            raise ValueError(f"no JSON schema for topic {topic!r} (known: {', '.join(_JSON_CHANNELS)})")
        self._add(self._spec_channel(spec), time_us, json.dumps(obj, separators=(",", ":")).encode())

    def write_event(self, time_us: int, text: str, *, warning: bool = False) -> None:
        """Records an event (``foxglove.Log`` on ``/events``)."""
        level = LogLevel.Warning if warning else LogLevel.Info
        message = foxglove_log.log_message(self.unix_ns(time_us), level, text)
        self._add_view(time_us, [(foxglove_log.EVENTS, message)])

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


MCAP_MAGIC: Final = MAGIC
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
    """The ``spirob`` metadata record of a recording (empty if none), of a truncated file too.

    Reads the top-level records only (chunks are skipped unread), through the bounded reader.

    Raises:
        RecordingError: a record over the cap or a malformed one (:mod:`hil.mcap_bounded`).
    """
    with open(path, "rb") as f:
        for rec in iter_records(f, chunks=False):
            if isinstance(rec, Metadata) and rec.name == PROFILE:
                return dict(rec.metadata)
    return {}


@dataclass(frozen=True, slots=True)
class Recovered:
    """What :func:`recover` copied.

    Attributes:
        messages_n: messages copied.
        last_time_us: board time of the last one (None without messages).
    """

    messages_n: int
    last_time_us: int | None


def recover(path: str | Path, out: str | Path) -> Recovered:
    """Copy every complete record of a (truncated) recording into a complete MCAP file at ``out``.

    Schemas, channels, metadata and messages are kept as they were, in file order; the new file has a
    summary and an index, so the mcap library's normal reader (and Foxglove) opens it. Its ``spirob``
    metadata gains ``truncated`` = ``true``: the run it records was cut short all the same.

    Raises:
        RecordingError: a record over the cap, a chunk bomb or a malformed record (``out`` is removed).
    """
    try:
        with open(path, "rb") as src, open(out, "wb") as dst:
            return _copy_records(src, dst)
    except RecordingError:
        Path(out).unlink(missing_ok=True)  # half a copy of a file refused is no recovery
        raise


def _copy_records(src: IO[bytes], dst: IO[bytes]) -> Recovered:
    """The loop of :func:`recover`."""
    schema_ids: dict[int, int] = {0: 0}
    channel_ids: dict[int, int] = {}
    n = 0
    last: int | None = None
    offset_ns = 0
    writer = Writer(dst, chunk_size=256 * 1024, compression=CompressionType.ZSTD)
    started = False
    for rec in iter_records(src):
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
                offset_ns = clock_offset_of(meta)
            writer.add_metadata(rec.name, meta)
        elif isinstance(rec, Message) and rec.channel_id in channel_ids:
            channel = channel_ids[rec.channel_id]
            writer.add_message(channel, rec.log_time, bytes(rec.data), rec.publish_time, rec.sequence)
            n += 1
            last = (rec.log_time - offset_ns) // 1000
    if not started:
        writer.start(profile=PROFILE, library="spirob-teleop")
    writer.finish()
    return Recovered(n, last)


def read_records(path: str | Path, topics: frozenset[str] | set[str] | None = None) -> Iterator[Record]:
    """Every message of a recording in file order, stopping quietly at a truncated tail.

    Reads sequentially (no index needed), so files of a killed process read up to their last complete
    chunk; one record at a time through the bounded reader (:mod:`hil.mcap_bounded`), so memory stays
    bounded whatever the file's size.

    Raises:
        RecordingError: a record over the cap, a chunk bomb or a malformed record.
    """
    channels: dict[int, str] = {}
    offset_ns = 0  # the metadata (written before any message) sets it
    with open(path, "rb") as f:
        for rec in iter_records(f):
            if isinstance(rec, Message):
                topic = channels.get(rec.channel_id)
                if topic is not None and (topics is None or topic in topics):
                    yield Record(topic, (rec.log_time - offset_ns) // 1000, bytes(rec.data), rec.log_time)
            elif isinstance(rec, Channel):
                channels[rec.id] = rec.topic
            elif isinstance(rec, Metadata) and rec.name == PROFILE:
                offset_ns = clock_offset_of(rec.metadata)
