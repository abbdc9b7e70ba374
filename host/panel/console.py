"""The panel's event console: a bounded, thread-safe history of what happened, with board timestamps."""

from __future__ import annotations

import collections
import threading
from dataclasses import dataclass

__all__ = ["CONSOLE_LINES", "ConsoleEntry", "EventConsole", "console_html"]

CONSOLE_LINES = 200
"""Entries the event console keeps (the oldest go first)."""

_LEVEL_COLOURS = {"info": "#495057", "warning": "#e8590c", "error": "#c92a2a"}


@dataclass(frozen=True, slots=True)
class ConsoleEntry:
    """One line of the event console.

    Attributes:
        seq: increasing number.
        board_time_us: board time (an ``Event``'s own time; otherwise the newest telemetry's time when
            it happened; None before the first telemetry).
        source: ``board`` (board events), ``failsafe`` (phase changes), ``ack`` (command answers), or
            who sent a command to the board: ``Tab 3``, ``host`` (the command line; also the host's own
            notes, e.g. recordings), ``MAVLink`` (the drone link).
        level: ``info``, ``warning`` or ``error``.
        text: one line.
    """

    seq: int
    board_time_us: int | None
    source: str
    level: str
    text: str

    def line(self) -> str:
        """``"  12.345 s  source  text"`` (board seconds; ``-`` before the first telemetry)."""
        t = "-" if self.board_time_us is None else f"{self.board_time_us / 1e6:.3f} s"
        return f"{t:>12}  {self.source:<8}  {self.text}"


class EventConsole:
    """At most ``capacity`` entries, oldest dropped first; safe from any thread.

    Args:
        capacity: entries kept.

    Raises:
        ValueError: ``capacity`` is not positive.
    """

    def __init__(self, capacity: int = CONSOLE_LINES) -> None:
        if capacity <= 0:
            raise ValueError(f"capacity must be > 0, got {capacity}")
        self._lines: collections.deque[ConsoleEntry] = collections.deque(maxlen=capacity)
        self._seq = 0
        self._lock = threading.Lock()

    def add(self, board_time_us: int | None, source: str, level: str, text: str) -> ConsoleEntry:
        """Append one entry and return it."""
        with self._lock:
            self._seq += 1
            entry = ConsoleEntry(self._seq, board_time_us, source, level, text)
            self._lines.append(entry)
            return entry

    def entries(self) -> list[ConsoleEntry]:
        """All entries kept, oldest first."""
        with self._lock:
            return list(self._lines)

    @property
    def seq(self) -> int:
        """Number of the newest entry (0: none yet)."""
        return self._seq


def console_html(entries: list[ConsoleEntry], max_lines: int = 60) -> str:
    """The newest ``max_lines`` entries, newest first, as a scrolling monospace block."""
    import html

    rows = [
        f'<div style="color:{_LEVEL_COLOURS.get(e.level, "#495057")}">{html.escape(e.line())}</div>'
        for e in reversed(entries[-max_lines:])
    ]
    body = "".join(rows) or '<div style="color:#868e96">nothing yet</div>'
    return (
        '<div data-testid="event-console" style="font-family:monospace;font-size:0.75em;'
        f'white-space:pre;overflow:auto;max-height:14em">{body}</div>'
    )
