"""Recording the board link from the host's side, and reading a recording back for replay."""

from __future__ import annotations

import contextlib
import threading
import time
from collections.abc import Mapping
from pathlib import Path

from host.board_client import LinkState
from host.errors import HostError
from protocol.messages import Message, SimPoses, Telemetry
from protocol.stream import MessageStream

__all__ = ["LinkRecording", "replay_messages"]


def _now_us() -> int:
    return time.monotonic_ns() // 1000


class LinkRecording:
    """Records the board link from the host's side into MCAP (``hil.recording``): a listener and a tap.

    Raw bytes go to the same topics the virtual board uses (``/board/link_tx`` = board -> host,
    ``/board/link_rx`` = host -> board), so ``--replay`` and ``spirob-hil`` read either kind of file.
    What the board reports goes to the Foxglove channels a ``spirob-hil`` recording has: telemetry in the
    same JSON layout (``/telemetry``), its poses as transforms and the arm's shape (``/tf``,
    ``/arm/scene``), and the link's state changes with the board's own as events (``/events``).
    ``publish_time`` is the host's monotonic clock, ``log_time`` the Unix time of the same instant.
    """

    def __init__(self, path: Path, metadata: Mapping[str, str]) -> None:
        """Create the file.

        Args:
            path: the file.
            metadata: the run's description (source, port, and the virtual board's ``design`` and
                ``firmware`` when the host started it: the design sizes the arm's drawing).

        Raises:
            HostError: the file cannot be created.
        """
        from hil import recording

        self._rec_mod = recording
        try:
            self._rec = recording.Recorder(
                path, metadata=metadata, clock_offset_ns=recording.monotonic_clock_offset_ns()
            )
        except OSError as exc:
            raise HostError(f"cannot record to {path}: {exc.strerror or exc}") from exc
        self._lock = threading.Lock()
        self.path = path

    def tap(self, direction: str, data: bytes, t_us: int) -> None:
        """Byte tap of :class:`BoardClient`."""
        topic = self._rec_mod.LINK_TX if direction == "rx" else self._rec_mod.LINK_RX
        with self._lock, contextlib.suppress(ValueError):
            self._rec.write_raw(topic, t_us, data)

    def on_board_message(self, msg: Message) -> None:
        """Listener: telemetry (and the events it shows) and the simulated poses."""
        if isinstance(msg, Telemetry):
            obj = self._rec_mod.telemetry_json(msg)
            with self._lock, contextlib.suppress(ValueError):
                self._rec.write_json(self._rec_mod.TELEMETRY, _now_us(), obj)
        elif isinstance(msg, SimPoses) and msg.positions_m:
            with self._lock, contextlib.suppress(ValueError):
                self._rec.write_poses(_now_us(), msg.positions_m, msg.quats_wxyz)

    def on_link_state(self, state: LinkState) -> None:
        """State listener of :class:`BoardClient`: each change of the link's state is an event."""
        warning = state is LinkState.DISCONNECTED
        with self._lock, contextlib.suppress(ValueError):
            self._rec.write_event(_now_us(), f"board link {state.value}", warning=warning)

    def close(self) -> None:
        """Finish the file (safe twice)."""
        with self._lock:
            self._rec.close()


def replay_messages(path: Path) -> list[tuple[int, Message]]:
    """Decode every board -> host message of a recording with its time (µs), in order."""
    from hil import recording

    stream = MessageStream()
    return [
        (rec.time_us, msg)
        for rec in recording.read_records(path, {recording.LINK_TX})
        for _, msg in stream.feed(rec.data)
    ]
