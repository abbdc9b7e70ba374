"""Recording started and stopped from the panel, mid-run.

:class:`RecordingSwitch` sits on the board client once (a byte tap and a listener, like any recorder)
and forwards to a :class:`host.link.recording.LinkRecording` only while one is open; the panel's buttons
open one in a new file and close it. A recording started mid-run begins mid-stream: its first bytes
may be the tail of a frame, which the reader's parser skips and counts (it resynchronises on the next
frame), so the file replays like any other.
"""

from __future__ import annotations

import datetime
import threading
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import viser

from host.errors import HostError
from host.link.recording import LinkRecording
from host.panel.arbiter import ControlArbiter
from host.panel.notices import Notices
from protocol.messages import Message

__all__ = ["RecordHandles", "RecordingSwitch", "build_record_panel", "refresh_record"]

_ORDER_RECORD = 150.0  # after Plots (100), before Health (200)


class RecordingSwitch:
    """A recorder that can be switched on and off while the board link runs; thread-safe.

    Args:
        directory: where new recordings go (created on the first start).
        metadata: stored in every file.
    """

    def __init__(self, directory: Path, metadata: dict[str, str]) -> None:
        self.directory = directory
        self._metadata = metadata
        self._lock = threading.Lock()
        self._rec: LinkRecording | None = None
        self.last_path: Path | None = None
        """The file being written, or the last one closed."""

    @property
    def recording(self) -> bool:
        """True while a file is open."""
        return self._rec is not None

    def start(self) -> Path:
        """Open a new file named after the local time; returns its path (already recording: that one).

        Raises:
            HostError: the directory or the file cannot be created.
        """
        with self._lock:
            if self._rec is not None:
                return self._rec.path
            stamp = datetime.datetime.now().strftime("%Y%m%d-%H%M%S")
            try:
                self.directory.mkdir(parents=True, exist_ok=True)
            except OSError as exc:
                raise HostError(f"cannot create {self.directory}: {exc.strerror or exc}") from exc
            path = self.directory / f"spirob-{stamp}.mcap"
            n = 1
            while path.exists():
                n += 1
                path = self.directory / f"spirob-{stamp}-{n}.mcap"
            self._rec = LinkRecording(path, self._metadata)
            self.last_path = path
            return path

    def stop(self) -> Path | None:
        """Close the file (safe when none is open); returns its path."""
        with self._lock:
            rec, self._rec = self._rec, None
        if rec is None:
            return None
        rec.close()
        return rec.path

    def tap(self, direction: str, data: bytes, t_us: int) -> None:
        """Byte tap of ``BoardClient`` (forwarded while recording)."""
        rec = self._rec
        if rec is not None:
            rec.tap(direction, data, t_us)

    def on_board_message(self, msg: Message) -> None:
        """Listener of ``BoardClient`` (forwarded while recording)."""
        rec = self._rec
        if rec is not None:
            rec.on_board_message(msg)

    def write_json(self, topic: str, obj: Mapping[str, Any], schema: Mapping[str, Any]) -> None:
        """A message of the host's own (``LinkRecording.write_json``), while recording."""
        rec = self._rec
        if rec is not None:
            rec.write_json(topic, obj, schema)

    def write_event(self, text: str, *, warning: bool = False) -> None:
        """A line of the host's own on the event channel (``LinkRecording.write_event``), while recording."""
        rec = self._rec
        if rec is not None:
            rec.write_event(text, warning=warning)


@dataclass
class RecordHandles:
    """The shared Recording folder."""

    start: Any
    stop: Any
    status: Any
    shown: str = ""


def build_record_panel(
    server: viser.ViserServer, switch: RecordingSwitch, arbiter: ControlArbiter, notices: Notices
) -> RecordHandles:
    """Build the shared Recording folder (any authorised tab may start or stop a recording; the event
    console says so)."""
    gui = server.gui
    with gui.add_folder("Recording", order=_ORDER_RECORD, expand_by_default=False):
        start = gui.add_button("Start recording", color="red", hint=f"A new MCAP file in {switch.directory}")
        stop = gui.add_button("Stop recording", disabled=True)
        status = gui.add_markdown("")
    h = RecordHandles(start, stop, status)

    def allowed(event: Any) -> bool:
        return event.client_id is not None and arbiter.is_authorised(event.client_id)

    @start.on_click
    def _(event: Any) -> None:
        if not allowed(event):
            return
        try:
            path = switch.start()
        except HostError as exc:
            event.client.add_notification(
                "Recording not started", str(exc), color="red", auto_close_seconds=10.0
            )
            return
        notices.log("host", "info", f"recording to {path}")
        refresh_record(h, switch)

    @stop.on_click
    def _(event: Any) -> None:
        if not allowed(event):
            return
        path = switch.stop()
        if path is not None:
            notices.log("host", "info", f"recording closed: {path}")
        refresh_record(h, switch)

    refresh_record(h, switch)
    return h


def refresh_record(h: RecordHandles, switch: RecordingSwitch) -> None:
    """Show whether a recording runs and where."""
    on = switch.recording
    path = switch.last_path
    if on:
        text = f"**Recording** to `{path}`"
    elif path is not None:
        text = f"Not recording. Last file: `{path}`"
    else:
        text = f"Not recording (files go to `{switch.directory}`)"
    if text != h.shown:
        h.shown = text
        h.status.content = text
        h.start.disabled = on
        h.stop.disabled = not on
