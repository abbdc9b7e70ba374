"""Each command's answers back to whoever sent it: the board client's routing table.

The board answers a ``Command`` with ``CommandAck`` messages carrying the link ``seq`` the command went
out with (``IN_PROGRESS`` first for one that completes later, then the final one). The host process does
not know that seq when it sends (the link process's session numbers every frame), so a command awaiting
answers gets a *ticket*; the link process reports ``(ticket, seq)`` once it has written it, and from then
on answers with that seq and code go to the command's handler. A handler whose command can no longer be
answered (the link went down, it was never written, its seq was reused 256 frames later) gets None once.

Thread-safe; handlers are returned, never called here, so the caller calls them outside any lock.
"""

from __future__ import annotations

import threading
from collections.abc import Callable

from protocol.messages import AckResult, CommandAck

__all__ = ["ACK_ROUTES_MAX", "AckHandler", "AckRoutes"]

AckHandler = Callable[[CommandAck | None], None]
"""Gets each answer to one ``Command`` (on the client's thread), or None once it can have none."""
ACK_ROUTES_MAX = 256
"""Commands awaiting answers at most (the oldest is given up first)."""


class AckRoutes:
    """Tickets and seqs of the commands whose answers someone awaits."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._tickets = 0
        self._awaiting: dict[int, tuple[int, AckHandler]] = {}
        """Ticket -> (command code, handler): written by nobody yet, seq unknown."""
        self._routes: dict[int, tuple[int, AckHandler]] = {}
        """Seq -> (command code, handler): awaiting the final answer."""

    def ticket(self, code: int, handler: AckHandler) -> int:
        """A new ticket (> 0) for a command with ``code`` about to be sent."""
        with self._lock:
            self._tickets += 1
            self._awaiting[self._tickets] = (code, handler)
            return self._tickets

    def written(self, ticket: int, seq: int) -> list[AckHandler]:
        """The command of ``ticket`` went out with ``seq``; returns the handlers that lost their chance."""
        lost: list[AckHandler] = []
        with self._lock:
            route = self._awaiting.pop(ticket, None)
            if route is None:
                return lost
            old = self._routes.pop(seq, None)
            if old is not None:
                lost.append(old[1])
            self._routes[seq] = route
            if len(self._routes) > ACK_ROUTES_MAX:
                lost.append(self._routes.pop(next(iter(self._routes)))[1])
        return lost

    def answer(self, ack: CommandAck) -> AckHandler | None:
        """The handler ``ack`` belongs to (None: nobody awaits it); a final answer ends the route."""
        with self._lock:
            route = self._routes.get(ack.request_seq)
            if route is None or route[0] != int(ack.command):
                return None
            if ack.result is not AckResult.IN_PROGRESS:
                del self._routes[ack.request_seq]
            return route[1]

    def drop(self, ticket: int) -> AckHandler | None:
        """The command of ``ticket`` was never written: its handler (to be told None), if any."""
        with self._lock:
            route = self._awaiting.pop(ticket, None)
        return None if route is None else route[1]

    def drop_all(self) -> list[AckHandler]:
        """The link went down: every handler still waiting (each to be told None)."""
        with self._lock:
            handlers = [h for _, h in self._awaiting.values()] + [h for _, h in self._routes.values()]
            self._awaiting.clear()
            self._routes.clear()
        return handlers
