"""A lost wake-up in viser 1.1.1, and its repair: the panel's updates must never freeze a browser tab.

viser queues every outgoing message in an ``AsyncMessageBuffer`` and wakes the websocket's sender through
the buffer's ``asyncio.Event``. ``push`` calls that event's ``set()`` from whatever thread sent the message
(the panel's update thread), then once more through ``call_soon_threadsafe``. ``asyncio.Event`` is not
thread-safe: ``set()`` from another thread iterates the waiters while the event loop's sender appends
one. Seen in a full test run on a loaded machine: ``RuntimeError: deque mutated during iteration`` out
of a scene update, and the tab stopped answering (Playwright's clicks timed out after 30 s). Worse, the
race needs no error: if the sender finds the event unset, then the other thread sets it and finds no
waiter, then the sender parks its waiter, the event stays set with a sender asleep on it, and every later
``set()`` returns at once because the event is already set. That tab gets no message again.

:func:`install` gives every buffer an event whose ``set()`` from any thread but its loop's is handed to
the loop (``call_soon_threadsafe``): the event and its waiters are only ever touched on the loop's
thread, as asyncio requires. viser reads the event nowhere else (its own comment says the early ``set()``
is for "synchronous logic"; no such reader exists in 1.1.1), so deferring it changes nothing else.
Installed once, before the first server starts (:func:`host.panel.guard.start_guarded_server`); if a
viser release changes the buffer so the repair no longer applies, :func:`install` raises and the panel
does not start on a sender that can freeze.
"""

from __future__ import annotations

import asyncio
import contextlib
import threading
from typing import Any

from host.errors import HostError

__all__ = ["LoopSafeEvent", "install"]

_LOCK = threading.Lock()
_installed: list[bool] = []


class LoopSafeEvent(asyncio.Event):
    """An ``asyncio.Event`` that may be set from any thread: off its loop, ``set()`` is run on the loop."""

    def __init__(self, loop: asyncio.AbstractEventLoop) -> None:
        super().__init__()
        self._owner = loop

    def set(self) -> None:
        try:
            running: asyncio.AbstractEventLoop | None = asyncio.get_running_loop()
        except RuntimeError:
            running = None
        if running is self._owner:
            super().set()
            return
        with contextlib.suppress(RuntimeError):  # a closed loop: no sender is left to wake
            self._owner.call_soon_threadsafe(super().set)


def install() -> None:
    """Give every viser message buffer created from now on a :class:`LoopSafeEvent` (once per process).

    Raises:
        HostError: this viser's buffer is not the one the repair was written for.
    """
    from viser.infra import _async_message_buffer as amb

    with _LOCK:
        if _installed:
            return
        cls: Any = amb.AsyncMessageBuffer
        fields = {f.name for f in getattr(cls, "__dataclass_fields__", {}).values()}
        if not {"event_loop", "message_event"} <= fields:
            raise HostError("viser's message buffer changed: the panel's wake-up repair does not apply")
        original_init = cls.__init__

        def init(self: Any, *args: Any, **kwargs: Any) -> None:
            original_init(self, *args, **kwargs)
            self.message_event = LoopSafeEvent(self.event_loop)

        cls.__init__ = init
        _installed.append(True)
