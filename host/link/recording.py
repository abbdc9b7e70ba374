"""Recording the board link from the host's side, and reading a recording back for replay."""

from __future__ import annotations

import contextlib
import dataclasses
import struct
import threading
import time
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any, Final

from host.drone.tlog import TLOG_LINK_OUT
from host.errors import HostError
from host.link.source import LinkState
from protocol.mavlink import MavCodec, dialect
from protocol.messages import Message, SimPoses, Telemetry
from protocol.stream import MessageStream

__all__ = ["MAVLINK", "MAVLINK_SCHEMA", "LinkRecording", "TlogRead", "read_tlog", "replay_messages"]

MAVLINK: Final = "/mavlink"
"""The MAVLink traffic of ``--mavlink`` (JSON with :data:`MAVLINK_SCHEMA`), copied from the ``.tlog``."""

MAVLINK_SCHEMA: Final[dict[str, Any]] = {
    "$schema": "https://json-schema.org/draft/2020-12/schema",
    "title": "spirob.MavlinkPacket",
    "description": "one MAVLink packet in or out of the drone link, as the .tlog holds it",
    "type": "object",
    "properties": {
        "direction": {"enum": ["in", "out"]},
        "type": {"type": "string", "description": "message name (HEARTBEAT, ...)"},
        "src_system": {"type": "integer"},
        "src_component": {"type": "integer"},
        "seq": {"type": "integer"},
        "fields": {"type": "object", "description": "decoded fields of the messages we know"},
        "raw_hex": {"type": "string", "description": "the packet's bytes"},
    },
    "required": ["direction", "type", "src_system", "src_component", "seq", "fields", "raw_hex"],
    "additionalProperties": False,
}

_TLOG_STAMP = struct.Struct(">Q")
_MAGIC_V1 = 0xFE
_MAGIC_V2 = 0xFD


@dataclasses.dataclass(frozen=True, slots=True)
class TlogRead:
    """The packets of a ``.tlog``.

    Attributes:
        packets: (Unix µs, direction ``in``/``out``, packet bytes), in file order.
        skipped_bytes: bytes that did not start a packet (resynchronised past), and a cut tail.
    """

    packets: list[tuple[int, str, bytes]]
    skipped_bytes: int


def read_tlog(path: Path) -> TlogRead:
    """Split a ``.tlog`` (8-byte big-endian Unix µs stamp, its two low bits the link, then one MAVLink
    packet) into packets; never raises on bad bytes: it resynchronises on the next packet start."""
    data = path.read_bytes()
    out: list[tuple[int, str, bytes]] = []
    i = skipped = 0
    while i + _TLOG_STAMP.size + 3 <= len(data):
        start = i + _TLOG_STAMP.size
        magic, length = data[start], data[start + 1]
        if magic == _MAGIC_V1:
            size = 8 + length
        elif magic == _MAGIC_V2:
            size = 12 + length + (13 if data[start + 2] & 0x01 else 0)  # 0x01: signed
        else:
            i += 1
            skipped += 1
            continue
        if start + size > len(data):
            break
        (stamp,) = _TLOG_STAMP.unpack_from(data, i)
        direction = "out" if stamp & 3 == TLOG_LINK_OUT else "in"
        out.append((stamp & ~3, direction, data[start : start + size]))
        i = start + size
    return TlogRead(out, skipped + (len(data) - i))


def _header(raw: bytes) -> tuple[str, int, int, int]:
    """Message name (the dialect's, from the header's message id), sender system, component and
    sequence number of a packet whose length :func:`read_tlog` checked."""
    if raw[0] == _MAGIC_V1:
        seq, system, component, msg_id = raw[2], raw[3], raw[4], raw[5]
    else:
        seq, system, component, msg_id = raw[4], raw[5], raw[6], int.from_bytes(raw[7:10], "little")
    cls = dialect().mavlink_map.get(msg_id)
    return (str(cls.msgname) if cls is not None else f"MSG_{msg_id}"), system, component, seq


def _jsonable(value: Any) -> Any:
    if isinstance(value, bytes):
        return value.hex()
    if isinstance(value, tuple | list):
        return [_jsonable(v) for v in value]
    return value


def _now_us() -> int:
    return time.monotonic_ns() // 1000


class LinkRecording:
    """Records the board link from the host's side into MCAP (``hil.recording``): a listener and a tap.

    Raw bytes go to the same topics the virtual board uses (``/board/link_tx`` = board -> host,
    ``/board/link_rx`` = host -> board), so ``--replay`` and ``spirob-hil`` read either kind of file.
    What the board reports goes to the Foxglove channels a ``spirob-hil`` recording has: telemetry in the
    same JSON layout (``/telemetry``), its poses as transforms and the arm's shape (``/tf``,
    ``/arm/scene``), and the link's state changes with the board's own as events (``/events``).
    ``log_time`` and ``publish_time`` are both the Unix time of the instant the host handled the message
    (the host's monotonic clock plus the recording's ``clock_offset_ns``).
    """

    def __init__(self, path: Path, metadata: Mapping[str, str], *, tlog: Path | None = None) -> None:
        """Create the file.

        Args:
            path: the file.
            metadata: the run's description (source, port, and the virtual board's ``design`` and
                ``firmware`` when the host started it: the design sizes the arm's drawing).
            tlog: the ``.tlog`` the drone link writes; :meth:`close` copies its packets to
                :data:`MAVLINK` (the drone link closes first, so the file is complete by then).

        Raises:
            HostError: the file cannot be created.
        """
        from hil import foxglove_log, recording

        self._rec_mod = recording
        self._fox = foxglove_log
        try:
            self._rec = recording.Recorder(
                path, metadata=metadata, clock_offset_ns=recording.monotonic_clock_offset_ns()
            )
        except OSError as exc:
            raise HostError(f"cannot record to {path}: {exc.strerror or exc}") from exc
        self._lock = threading.Lock()
        self.path = path
        self.tlog = tlog
        self.mavlink_packets = 0

    def tap(self, direction: str, data: bytes, t_us: int) -> None:
        """Byte tap of :class:`BoardClient`."""
        topic = self._rec_mod.LINK_TX if direction == "rx" else self._rec_mod.LINK_RX
        with self._lock, contextlib.suppress(ValueError):
            self._rec.write_raw(topic, t_us, data)

    def on_board_message(self, msg: Message) -> None:
        """Listener: telemetry (and the events it shows) and the simulated poses."""
        if isinstance(msg, Telemetry):
            obj = self._fox.telemetry_json(msg)
            with self._lock, contextlib.suppress(ValueError):
                self._rec.write_json(self._fox.TELEMETRY, _now_us(), obj)
        elif isinstance(msg, SimPoses) and msg.positions_m:
            with self._lock, contextlib.suppress(ValueError):
                self._rec.write_poses(_now_us(), msg.positions_m, msg.quats_wxyz)

    def on_link_state(self, state: LinkState) -> None:
        """State listener of :class:`BoardClient`: each change of the link's state is an event."""
        warning = state is LinkState.DISCONNECTED
        with self._lock, contextlib.suppress(ValueError):
            self._rec.write_event(_now_us(), f"board link {state.value}", warning=warning)

    def write_json(self, topic: str, obj: Mapping[str, Any], schema: Mapping[str, Any]) -> None:
        """A message of the host's own, now, on a JSON channel with its schema (``--excite``'s start on
        ``/excitation``); nothing once the file is closed."""
        with self._lock, contextlib.suppress(ValueError):
            self._rec.write_json(topic, _now_us(), obj, schema=schema)

    def write_event(self, text: str, *, warning: bool = False) -> None:
        """A line of the host's own on ``/events``, now (an excitation's start and end)."""
        with self._lock, contextlib.suppress(ValueError):
            self._rec.write_event(_now_us(), text, warning=warning)

    def copy_tlog(self, tlog: Path) -> int:
        """Copy every packet of a ``.tlog`` to :data:`MAVLINK`, at the ``.tlog``'s own Unix times (to
        the µs), so the two files line up; returns the packets copied."""
        read = read_tlog(tlog)
        codec = MavCodec(255, 190)
        offset_ns = self._rec.clock_offset_ns
        n = 0
        with self._lock:
            for unix_us, direction, raw in read.packets:
                # Fields for the messages our codec knows; a packet it refuses keeps its header and bytes.
                decoded = codec.feed(raw)
                fields = (
                    {k: _jsonable(v) for k, v in dataclasses.asdict(decoded[0].msg).items()}
                    if decoded
                    else {}
                )
                name, system, component, seq = _header(raw)
                obj = {
                    "direction": direction,
                    "type": name,
                    "src_system": system,
                    "src_component": component,
                    "seq": seq,
                    "fields": fields,
                    "raw_hex": raw.hex(),
                }
                t_us = (unix_us * 1000 - offset_ns) // 1000
                self._rec.write_json(MAVLINK, t_us, obj, schema=MAVLINK_SCHEMA)
                n += 1
        self.mavlink_packets += n
        return n

    def close(self) -> None:
        """Copy the ``.tlog`` (when there is one) and finish the file (safe twice)."""
        if self.tlog is not None and self.tlog.is_file():
            tlog, self.tlog = self.tlog, None
            with contextlib.suppress(ValueError, OSError):
                self.copy_tlog(tlog)
        with self._lock:
            self._rec.close()


def replay_messages(path: Path) -> Iterator[tuple[int, Message]]:
    """Every board -> host message of a recording with its time (µs), in order, decoded as it is read:
    one chunk of the file in memory at a time, whatever its size (``hil.recording.read_records``).

    Raises:
        HostError: the file is refused by the bounded reader (a record over its cap, a chunk bomb, a
            malformed record): one line naming the record (the iteration stops there).
    """
    from hil import recording
    from hil.mcap_bounded import RecordingError

    stream = MessageStream()
    try:
        for rec in recording.read_records(path, {recording.LINK_TX}):
            for _, msg in stream.feed(rec.data):
                yield rec.time_us, msg
    except RecordingError as exc:
        raise HostError(str(exc)) from exc
