"""Replay a lockstep recording through the firmware and check that every output byte matches.

A recording holds every input of the firmware with the board time it arrived (DBUS bytes, CAN feedback
frames, board-link bytes from the host, the plant poses handed to the pose provider) and every output
(CAN command frames, board-link bytes to the host), plus one tick record per firmware tick. Replay
rebuilds the firmware from the recording's metadata, feeds it the same inputs at the same ticks, with no
plant at all, and compares what it emits with what was recorded, record by record.
"""

from __future__ import annotations

import json
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from controller.clock import zero_ns
from controller.config import FirmwareConfig
from controller.firmware import Firmware
from controller.rc import DbusSerialSource, LinkRcSource, RcSource
from hil import recording
from hil.board import WireEnd, pose_messages
from hil.canbus import ReplayBus
from hil.errors import HilError
from hil.radio import MemoryUart
from hil.recording import (
    FORMAT,
    KIND_PORT,
    Record,
    is_mcap,
    package_version,
    read_metadata,
    read_records,
    recording_format,
)

_INPUTS = frozenset({recording.DBUS_RX, recording.CAN_RX, recording.LINK_RX, recording.POSES})
_OUTPUTS = frozenset({recording.CAN_TX, recording.LINK_TX})

HOST_SOURCE = "spirob-host"
"""Metadata ``source`` of a ``spirob-host`` recording (``spirob-host (panel)`` from the panel's switch):
the link's bytes as the host saw them, on the host's clock, no tick marks; never replayable."""

MAX_SEGMENT_RECORDS = 100_000
"""Records between two tick marks a replay holds (a lockstep tick has a handful)."""
MAX_SEGMENT_BYTES = 64 << 20
"""Their bytes."""


@dataclass(frozen=True)
class ReplayResult:
    """Outcome of a replay.

    Attributes:
        path: the recording.
        ticks: firmware ticks replayed.
        outputs_compared: output records compared.
        mismatches: how many differed (or were missing / extra).
        first_mismatch: description of the first difference, if any.
        truncated: the file ends mid-run (its recorder was killed): replayed up to its last complete
            tick, whose outputs are compared; the board's shutdown frame was never recorded.
    """

    path: str
    ticks: int
    outputs_compared: int
    mismatches: int
    first_mismatch: str | None
    truncated: bool = False

    @property
    def matched(self) -> bool:
        """Every output byte matched."""
        return self.mismatches == 0 and self.ticks > 0

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        return {
            "path": self.path,
            "matched": self.matched,
            "ticks": self.ticks,
            "outputs_compared": self.outputs_compared,
            "mismatches": self.mismatches,
            "first_mismatch": self.first_mismatch,
            "truncated": self.truncated,
        }


def _firmware_from(meta: dict[str, str]) -> tuple[FirmwareConfig, str]:
    try:
        config = FirmwareConfig.from_dict(json.loads(meta["firmware"]))
        rc = meta["rc"]
    except (KeyError, ValueError) as exc:
        raise HilError(f"not a lockstep board recording (metadata: {exc})") from exc
    return config, rc


def _check_format(meta: dict[str, str]) -> None:
    """Files of an older format replay as they are (their board time reads the same); a newer one is
    refused, naming the version that wrote it."""
    try:
        fmt = recording_format(meta)
    except ValueError as exc:
        raise HilError(f"unreadable recording format {meta.get('format')!r}") from exc
    if fmt > FORMAT:
        raise HilError(
            f"recording format {fmt} (written by spirob-teleop {meta.get('version', '?')}) is newer than "
            f"this replay reads (format {FORMAT}, spirob-teleop {package_version()}): upgrade spirob-teleop"
        )


def replay(path: str | Path, progress: Callable[[int], None] | None = None) -> ReplayResult:
    """Replay ``path`` through a fresh firmware and compare its outputs.

    Recordings of every format up to :data:`hil.recording.FORMAT` replay (format 1 files included).

    Raises:
        HilError: the file is not a lockstep recording of a virtual board, or a newer format.
    """
    if not is_mcap(path):
        raise HilError("not an MCAP file")
    meta = read_metadata(path)
    if not meta:
        raise HilError("no spirob metadata: not a recording made by 'spirob-hil run --record'")
    if meta.get("kind") == KIND_PORT:
        raise HilError(
            "this records a run against a port (the link as the host saw it): only a lockstep "
            "recording can be replayed (spirob-hil run ... --record without --port)"
        )
    if meta.get("source", "").startswith(HOST_SOURCE):
        raise HilError(
            "a spirob-host recording holds the board link as the host saw it, not the board's CAN and "
            "DBUS inputs nor its ticks: the board cannot replay it (play it with spirob-host --replay FILE)"
        )
    _check_format(meta)
    config, rc_kind = _firmware_from(meta)
    bus = ReplayBus(config.motor.current_limit_raw, config.motor_count)
    link = WireEnd()
    uart: MemoryUart | None = None
    rc: RcSource
    if rc_kind == "radio":
        uart = MemoryUart()
        rc = DbusSerialSource(uart)
    else:
        rc = LinkRcSource()
    poses: list[Any] = []
    fw = Firmware(
        config,
        bus,
        rc,
        link,
        poses=lambda: poses.pop(0) if poses else None,
        exec_timer_ns=zero_ns,
    )

    # Outputs are compared as soon as both sides have them, so only what one side is ahead by is held.
    produced: deque[tuple[int, str, bytes]] = deque()
    expected: deque[tuple[int, str, bytes]] = deque()
    ticks = 0
    pairs = compared = mismatches = 0
    first: str | None = None

    def compare(got: tuple[int, str, bytes] | None, want: tuple[int, str, bytes] | None) -> None:
        nonlocal pairs, compared, mismatches, first
        pairs += 1
        compared += want is not None
        if got != want:
            mismatches += 1
            if first is None:
                first = f"output #{pairs - 1}: recorded {_describe(want)}, replay produced {_describe(got)}"

    def compare_ready() -> None:
        while produced and expected:
            compare(produced.popleft(), expected.popleft())

    def feed(rec: Record) -> None:
        topic = rec.topic
        if topic in _OUTPUTS:
            expected.append((rec.time_us, topic, rec.data))
        elif topic == recording.DBUS_RX:
            if uart is None:
                raise HilError("recording has DBUS bytes but its board took RC from the link")
            uart.feed(rec.data)
        elif topic == recording.CAN_RX:
            bus.inbox.append(recording.unpack_can(rec.data))
        elif topic == recording.LINK_RX:
            link.inbox += rec.data

    def run_tick(t_us: int, segment: list[Record]) -> None:
        nonlocal ticks
        # Poses are pulled by the firmware during this tick, so they were recorded after its mark.
        poses.clear()
        poses.extend(
            pose_messages(r.time_us, *recording.unpack_poses(r.data), config.arm_count)
            for r in segment
            if r.topic == recording.POSES
        )
        fw.run_due(t_us)
        produced.extend((t_us, recording.CAN_TX, frame) for frame in bus.sent)
        bus.sent.clear()
        if link.outbox:
            produced.append((t_us, recording.LINK_TX, bytes(link.outbox)))
            link.outbox.clear()
        ticks += 1
        if progress is not None and ticks % 500 == 0:
            progress(ticks)

    # One pass over the file: the records between two tick marks (one segment) are held until the next
    # mark, then the tick runs with its poses and the segment's inputs are fed after it, as they arrived.
    # Each record is touched a bounded number of times, so the replay is linear in the recording's length.
    # A segment is bounded (a file without tick marks is not a lockstep recording, however long it is).
    tick_us: int | None = None
    segment: list[Record] = []
    segment_bytes = 0
    for rec in read_records(path, topics=_INPUTS | _OUTPUTS | {recording.TICK}):
        if rec.topic != recording.TICK:
            if tick_us is None and rec.topic in _OUTPUTS:
                # The board emits only from a tick, after its mark: outputs before any mark were not
                # recorded in lockstep (a host's or a port run's file without its metadata).
                raise HilError(
                    f"{rec.topic} output before any {recording.TICK} mark: not a lockstep recording, "
                    "the board cannot replay it"
                )
            segment.append(rec)
            segment_bytes += len(rec.data)
            if len(segment) > MAX_SEGMENT_RECORDS or segment_bytes > MAX_SEGMENT_BYTES:
                raise HilError(
                    f"more than {MAX_SEGMENT_RECORDS} records or {MAX_SEGMENT_BYTES >> 20} MiB between two "
                    f"tick marks (after {ticks} ticks): not a lockstep recording"
                )
            continue
        if tick_us is not None:
            run_tick(tick_us, segment)
        for held in segment:
            feed(held)
        compare_ready()
        tick_us, segment, segment_bytes = rec.time_us, [], 0
    truncated = recording.is_truncated(path)
    if truncated:
        # The last tick's segment may be cut anywhere: its outputs are not compared (nor run).
        if tick_us is not None:
            cut = tick_us
            expected = deque(e for e in expected if e[0] < cut)
    else:
        if tick_us is not None:
            run_tick(tick_us, segment)
        for held in segment:
            feed(held)
        # The board's shutdown sends zero current once after the last tick.
        bus.shutdown()
        if bus.sent:
            last_t = produced[-1][0] if produced else 0
            produced.extend((last_t, recording.CAN_TX, frame) for frame in bus.sent)
    compare_ready()
    while produced or expected:
        compare(produced.popleft() if produced else None, expected.popleft() if expected else None)
    return ReplayResult(str(path), ticks, compared, mismatches, first, truncated)


def _describe(item: tuple[int, str, bytes] | None) -> str:
    if item is None:
        return "nothing"
    t, topic, data = item
    return f"{topic} at {t} us ({len(data)} bytes: {data[:16].hex()}...)"
