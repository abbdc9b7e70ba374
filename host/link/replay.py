"""A recording played back as a board source: the same listeners as a live link, at the recorded pace."""

from __future__ import annotations

import logging
import threading
import time
from pathlib import Path

from host.errors import HostError
from host.link.recording import replay_messages
from host.link.source import BoardSource, LinkState
from host.worker import Worker

__all__ = ["ReplaySource"]

_log = logging.getLogger(__name__)


class ReplaySource(BoardSource):
    """Feeds the board -> host messages of a recording (``/board/link_tx``) to its listeners.

    The link reads as connected while it plays; :attr:`done` is set when the file has been played, or
    could not be read (:attr:`error` says why: a record over the bounded reader's cap, a chunk bomb, a
    malformed record; what came before it was played). Ours and ``spirob-hil``'s recordings, format 1 too.

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
        self.error: str | None = None
        """Why the file could not be (wholly) read: set with :attr:`done`; the run ends on it."""
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
        # Messages are decoded as they are played (a generator over the file), never all at once: a file
        # of 300,000 records starts at once, holds one chunk in memory and stops when told to.
        t0_rec: int | None = None
        t0 = time.monotonic()
        stopped = False
        try:
            for t_us, msg in replay_messages(self.path):
                if t0_rec is None:
                    t0_rec, t0 = t_us, time.monotonic()
                due = t0 + (t_us - t0_rec) / 1e6 / self.speed
                delay = due - time.monotonic()
                if self._stop.wait(delay) if delay > 0 else self._stop.is_set():
                    stopped = True
                    break
                self.fan_out(msg)
                self.messages_n += 1
        except Exception as exc:  # any unreadable file: the run ends on it with one line (HostApp.run)
            self.error = str(exc) if isinstance(exc, HostError) else f"{type(exc).__name__}: {exc}"
            _log.debug("replay of %s stopped", self.path, exc_info=True)
        if self.error is not None:
            _log.debug("replay of %s refused after %d messages", self.path, self.messages_n)
        elif t0_rec is None:
            _log.warning("%s holds no board-link messages (/board/link_tx): nothing to replay", self.path)
        else:
            _log.info("replay %s: %d messages", "stopped" if stopped else "finished", self.messages_n)
        self.done.set()
