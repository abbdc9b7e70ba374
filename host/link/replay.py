"""A recording played back as a board source: the same listeners as a live link, at the recorded pace."""

from __future__ import annotations

import logging
import threading
import time
from pathlib import Path

from host.link.recording import replay_messages
from host.link.source import BoardSource, LinkState
from host.worker import Worker

__all__ = ["ReplaySource"]

_log = logging.getLogger(__name__)


class ReplaySource(BoardSource):
    """Feeds the board -> host messages of a recording (``/board/link_tx``) to its listeners.

    The link reads as connected while it plays; :attr:`done` is set when the file has been played (or
    could not be read: one error line). Ours and ``spirob-hil``'s recordings, format 1 too.

    Args:
        path: the MCAP recording.
        speed: playback speed (2.0 = twice as fast as recorded).

    Raises:
        ValueError: ``speed`` is not positive.
    """

    def __init__(self, path: Path, speed: float = 1.0) -> None:
        super().__init__()
        if not speed > 0:
            raise ValueError(f"speed must be > 0, got {speed}")
        self.path = path
        self.speed = speed
        self.done = threading.Event()
        """Set once the whole file has been fed (or it could not be read)."""
        self.messages_n = 0
        """Messages fed so far."""
        self._worker = Worker("replay", self._run)
        self._stop = self._worker.stop_event

    def start(self) -> None:
        """Start playing in a thread."""
        if self._worker.running:
            return
        self.set_state(LinkState.CONNECTED)
        self._worker.start()

    def stop(self) -> None:
        """Stop playing; safe twice."""
        self._worker.stop()
        if self._state is not LinkState.STOPPED:
            self.set_state(LinkState.STOPPED)

    def _run(self) -> None:
        try:
            messages = replay_messages(self.path)
        except Exception as exc:
            _log.error("cannot read %s: %s", self.path, exc)
            self.done.set()
            return
        if messages:
            t0_rec = messages[0][0]
            t0 = time.monotonic()
            for t_us, msg in messages:
                due = t0 + (t_us - t0_rec) / 1e6 / self.speed
                delay = due - time.monotonic()
                if delay > 0 and self._stop.wait(delay):
                    break
                self.fan_out(msg)
                self.messages_n += 1
            _log.info("replay finished: %d messages", self.messages_n)
        else:
            _log.warning("%s holds no board-link messages (/board/link_tx): nothing to replay", self.path)
        self.done.set()
