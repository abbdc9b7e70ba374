"""One background thread with a stop flag: the panel's pushes, the gamepad, ``--virtual-rc`` and replay.

:meth:`Worker.start` starts it once (a second call does nothing), :meth:`Worker.stop` sets the flag and
joins it within a bounded time; both are safe to call twice. The thread is a daemon, so a thread that does
not stop in time cannot keep the program alive.
"""

from __future__ import annotations

import threading
from collections.abc import Callable

__all__ = ["Worker"]


class Worker:
    """A named daemon thread running ``target`` until :attr:`stop_event` is set.

    Args:
        name: the thread's name.
        target: its body; it returns when :attr:`stop_event` is set (wait on it, don't sleep).
        join_s: how long :meth:`stop` waits for it.
    """

    def __init__(self, name: str, target: Callable[[], None], join_s: float = 3.0) -> None:
        self.name = name
        self._target = target
        self._join_s = join_s
        self.stop_event = threading.Event()
        """Set when the thread must end."""
        self._thread: threading.Thread | None = None

    @property
    def running(self) -> bool:
        """Started and not stopped."""
        return self._thread is not None

    def start(self) -> bool:
        """Start the thread; False if it was already running."""
        if self._thread is not None:
            return False
        self.stop_event.clear()
        self._thread = threading.Thread(target=self._target, name=self.name, daemon=True)
        self._thread.start()
        return True

    def stop(self) -> None:
        """Set the flag and join the thread (bounded); safe twice."""
        self.stop_event.set()
        thread, self._thread = self._thread, None
        if thread is not None and thread is not threading.current_thread():
            thread.join(timeout=self._join_s)
