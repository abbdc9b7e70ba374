"""Recording the board link from the host's side, and reading a recording back for replay."""

from __future__ import annotations

import contextlib
import threading
import time
from pathlib import Path

from host.errors import HostError
from protocol.messages import Message, Telemetry
from protocol.stream import MessageStream

__all__ = ["LinkRecording", "replay_messages"]


class LinkRecording:
    """Records the board link from the host's side into MCAP (``hil.recording``): a listener and a tap.

    Raw bytes go to the same topics the virtual board uses (``/board/link_tx`` = board -> host,
    ``/board/link_rx`` = host -> board), so ``--replay`` and ``spirob-hil`` read either kind of file.
    Decoded telemetry goes to ``/telemetry`` as JSON for plotting tools. Times are host µs (monotonic).
    """

    def __init__(self, path: Path, metadata: dict[str, str]) -> None:
        """Create the file.

        Raises:
            HostError: the file cannot be created.
        """
        from hil import recording

        self._rec_mod = recording
        try:
            self._rec = recording.Recorder(path, metadata=metadata)
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
        """Listener: decoded telemetry as JSON."""
        if not isinstance(msg, Telemetry):
            return
        obj = {
            "time_us": msg.time_us,
            "mode": msg.mode.name,
            "phase": msg.phase.name,
            "grasp_state": msg.grasp_state.name,
            "flags": int(msg.flags),
            "tension_target_n": list(msg.tension_target_n),
            "tension_est_n": list(msg.tension_est_n),
            "commanded_current": list(msg.commanded_current),
            "motor_current": list(msg.motor_current),
            "cable_length_m": list(msg.cable_length_m),
        }
        with self._lock, contextlib.suppress(ValueError):
            self._rec.write_json(self._rec_mod.TELEMETRY, time.monotonic_ns() // 1000, obj)

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
