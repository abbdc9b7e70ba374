"""Bounded queue of board events (mode, phase, fault, grasp, parameter changes) for the link.

Events are rare (a handful per second at most), so building an ``Event`` when one happens is fine; the
queue itself is bounded: when full, the oldest event is dropped and counted, never the loop blocked.
"""

from __future__ import annotations

from collections import deque

from protocol.messages import EVENT_TEXT_MAX, Event, EventKind, truncate_utf8

__all__ = ["EventQueue"]


class EventQueue:
    """FIFO of :class:`~protocol.messages.Event` with a fixed capacity.

    Attributes:
        dropped: events pushed out by newer ones because the queue was full.
        total: events ever queued.
    """

    def __init__(self, capacity: int) -> None:
        """Create an empty queue holding at most ``capacity`` events.

        Raises:
            ValueError: ``capacity`` < 1.
        """
        if capacity < 1:
            raise ValueError(f"capacity must be >= 1, got {capacity}")
        self._q: deque[Event] = deque(maxlen=capacity)
        self.dropped = 0
        self.total = 0

    def __len__(self) -> int:
        return len(self._q)

    def push(self, time_us: int, kind: EventKind, code: int = 0, value: float = 0.0, text: str = "") -> None:
        """Queue one event stamped with board time ``time_us``."""
        if len(self._q) == self._q.maxlen:
            self.dropped += 1
        self._q.append(Event(time_us, kind, code, value, truncate_utf8(text, EVENT_TEXT_MAX)))
        self.total += 1

    def pop_all(self) -> list[Event]:
        """Remove and return every queued event, oldest first."""
        out = list(self._q)
        self._q.clear()
        return out
