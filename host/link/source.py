"""Where the host's board messages come from: one listener fan-out for a live link and a replay alike.

A :class:`BoardSource` hands every decoded board -> host message to its listeners and tells its state
listeners when the link connects, disconnects or stops. The live board link
(:class:`host.link.client.BoardClient`) and a recording played back (:class:`host.link.replay.ReplaySource`)
are both sources, so whatever listens (the panel's board state and notices, the recorder, the drone
link, the run summary) is wired the same way to either (a recorder is just a listener; replay feeds the
same listeners).
"""

from __future__ import annotations

import enum
import logging
from collections.abc import Callable
from types import TracebackType

from protocol.messages import Message

__all__ = ["BoardSource", "LinkState", "MessageListener", "StateListener"]

_log = logging.getLogger(__name__)

MessageListener = Callable[[Message], None]
"""Called with every decoded board -> host message, on the source's thread (keep it short)."""
StateListener = Callable[["LinkState"], None]
"""Called when the link connects, disconnects or stops."""


class LinkState(enum.Enum):
    """Connection state of the board link."""

    CONNECTING = "connecting"
    CONNECTED = "connected"
    DISCONNECTED = "disconnected"
    STOPPED = "stopped"


class BoardSource:
    """Listeners and their fan-out; a subclass feeds them (:meth:`fan_out`, :meth:`set_state`).

    Listeners run on the source's thread and must be quick (store the latest value, queue work);
    exceptions they raise are logged and counted (:attr:`listener_errors`), never propagated.
    """

    def __init__(self) -> None:
        self._listeners: list[MessageListener] = []
        self._state_listeners: list[StateListener] = []
        self._state = LinkState.STOPPED
        self.listener_errors = 0
        """Exceptions raised by listeners (logged, never fatal)."""

    def add_listener(self, listener: MessageListener) -> None:
        """Receive every board -> host message (on the source's thread)."""
        self._listeners.append(listener)

    def add_state_listener(self, listener: StateListener) -> None:
        """Be told when the link connects, disconnects or stops."""
        self._state_listeners.append(listener)

    @property
    def state(self) -> LinkState:
        """Current connection state."""
        return self._state

    def start(self) -> None:
        """Start delivering messages (a subclass's job)."""
        raise NotImplementedError

    def stop(self) -> None:
        """Stop delivering; safe twice (a subclass's job)."""
        raise NotImplementedError

    def __enter__(self) -> BoardSource:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.stop()

    def fan_out(self, msg: Message) -> None:
        """Hand ``msg`` to every listener, in the order they were added."""
        for listener in self._listeners:
            try:
                listener(msg)
            except Exception:
                self.listener_errors += 1
                _log.exception("listener %r failed on %s", listener, type(msg).__name__)

    def set_state(self, state: LinkState) -> None:
        """Take ``state`` and tell every state listener."""
        self._state = state
        for listener in self._state_listeners:
            try:
                listener(state)
            except Exception:
                self.listener_errors += 1
                _log.exception("state listener failed")
