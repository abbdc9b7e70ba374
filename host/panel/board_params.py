"""The board's parameters in the panel: the values it reported, and the fate of each value a tab set.

:class:`BoardParams` listens for the board's ``ParamValue`` answers and its ``PARAM`` events, asks for
the whole list, and sets a value on behalf of the control holder after the host-side check
(``host.panel.param_table``: the firmware's own bounds), through the control arbiter like every
command. The per-tab editor (``host.panel.params``) reads it.
"""

from __future__ import annotations

import threading
import time

from host.panel.arbiter import ControlArbiter
from host.panel.param_table import PARAM_NAMES, ParamStatus, param_check
from protocol.messages import PARAM_LIST_ALL, Event, EventKind, Message, ParamRequest, ParamSet, ParamValue

__all__ = ["BoardParams"]


class BoardParams:
    """Parameter values the board reported and the status of each set; thread-safe.

    Args:
        arbiter: who may set them, and the way to the board.
    """

    def __init__(self, arbiter: ControlArbiter) -> None:
        self._arbiter = arbiter
        self._lock = threading.Lock()
        self.params: dict[str, float] = {}
        """Parameter name -> the value the board last reported."""
        self.params_count = 0
        """How many parameters the board says it has (0 until the first ``ParamValue``)."""
        self.param_status: dict[str, ParamStatus] = {}
        """Parameter name -> the last value a tab asked for and what the board read back."""

    def has_control(self, client: int) -> bool:
        """True if ``client`` may set parameters (it holds control)."""
        return self._arbiter.has_control(client)

    def on_board_message(self, msg: Message) -> None:
        """Listener: the board's values, read back into the status of a pending set, and its refusals."""
        if isinstance(msg, ParamValue):
            with self._lock:
                self.params[msg.name] = msg.value
                self.params_count = msg.count
                pending = self.param_status.get(msg.name)
                if pending is not None and pending.confirmed is None:
                    self.param_status[msg.name] = ParamStatus(
                        pending.requested, pending.sent_s, msg.value, pending.note
                    )
        elif (
            isinstance(msg, Event)
            and msg.kind == EventKind.PARAM
            and msg.text.startswith("rejected")
            and 0 <= msg.code < len(PARAM_NAMES)
        ):
            with self._lock:
                name = PARAM_NAMES[msg.code]
                pending = self.param_status.get(name)
                if pending is not None:
                    self.param_status[name] = ParamStatus(
                        pending.requested, pending.sent_s, pending.confirmed, msg.text
                    )

    def request_params(self) -> bool:
        """Ask the board for every parameter (it answers with one ``ParamValue`` each)."""
        return self._arbiter.forward(ParamRequest(PARAM_LIST_ALL))

    def set_param(self, client: int, name: str, value: float) -> str | None:
        """Ask the board to take ``value`` for parameter ``name`` (holder only); the board reads it back.

        Checked here first against the firmware's bounds, so an out-of-range value is refused with its
        reason before it travels.

        Returns:
            None if sent (watch :attr:`param_status` for the board's answer), else why not.
        """
        if name not in PARAM_NAMES:
            return f"unknown parameter {name!r}"
        if not self._arbiter.has_control(client):
            return "this tab does not hold control"
        v = float(value)
        with self._lock:
            values = dict(self.params)
        why = param_check(values, name, v)
        if why is not None:
            return why
        with self._lock:
            self.param_status[name] = ParamStatus(v, time.monotonic())
        if not self._arbiter.forward(ParamSet(name, v), client):
            with self._lock:
                self.param_status.pop(name, None)
            return "the board link is down"
        return None
