"""``--virtual-rc``: the command line holds the virtual radio, a client of the control arbiter.

Like the gamepad (``host.gamepad``) it drives the arbiter as the command line's client: it takes
control, puts both levers DOWN (the board's start-up gate), waits until the board reports the right
lever DOWN (or 1 s), then moves the right lever to the requested position and leaves it there. A browser
tab that asks for control gets it (nobody at the command line can click "grant").
"""

from __future__ import annotations

import logging
import time

from host.panel.arbiter import CLI_CLIENT, ControlArbiter
from host.panel.board_state import BoardState
from host.worker import Worker
from protocol.dbus import Lever

__all__ = ["VirtualRcDriver"]

_log = logging.getLogger(__name__)

_GATE_WAIT_S = 1.0
"""Longest wait for the board to report the right lever DOWN before the requested lever."""
_POLL_S = 0.02
_SETTLE_S = 0.1
"""Pause after DOWN was seen, then between checks for a tab asking for control."""


class VirtualRcDriver:
    """Drives the arbiter's radio from the command line in a thread: DOWN first, then ``lever``.

    Args:
        arbiter: the control arbiter.
        board: the board's state (to see the right lever DOWN arrive).
        lever: the right lever's position to drive with (``DOWN`` = SAFE, ``MIDDLE``, ``UP``).
    """

    def __init__(self, arbiter: ControlArbiter, board: BoardState, lever: Lever) -> None:
        self.arbiter = arbiter
        self.board = board
        self.lever = lever
        self._worker = Worker("virtual-rc", self._run)
        self._stop = self._worker.stop_event

    def start(self) -> None:
        """Start the thread (it takes control first)."""
        self._worker.start()

    def stop(self) -> None:
        """Stop the thread; safe twice (control stays where it is: the arbiter's holder)."""
        self._worker.stop()

    def _run(self) -> None:
        a = self.arbiter
        a.request_control(CLI_CLIENT)
        a.set_lever(CLI_CLIENT, "right", Lever.DOWN)
        a.set_lever(CLI_CLIENT, "left", Lever.DOWN)
        # DOWN first: wait until the board reports it (or 1 s), then the requested lever.
        deadline = time.monotonic() + _GATE_WAIT_S
        while not self._stop.is_set() and time.monotonic() < deadline:
            t = self.board.telemetry
            if t is not None and t.right_lever == Lever.DOWN and t.rc_frames_ok > 0:
                break
            self._stop.wait(_POLL_S)
        self._stop.wait(_SETTLE_S)
        if not self._stop.is_set():
            a.set_lever(CLI_CLIENT, "right", self.lever)
        while not self._stop.wait(_SETTLE_S):
            # The command line hands control to a browser tab that asks for it.
            if a.holder == CLI_CLIENT and a.pending is not None:
                _log.info("handing control to browser tab %s", a.pending)
                a.answer_request(CLI_CLIENT, grant=True)
