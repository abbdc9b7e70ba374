"""The parameter protocol of the drone link: the board's parameters mirrored for the drone.

``PARAM_REQUEST_LIST`` / ``PARAM_REQUEST_READ`` are answered from the mirror (the board is asked
when it is not complete); a ``PARAM_SET`` goes to the board and is answered with the value the board
confirms, or with the value in force when it does not confirm in time. A ``PARAM_SET`` that comes before
the mirror is complete goes to the board when the firmware's parameter table has its name. A list
requested before the board has answered is sent once the mirror is complete (the board is asked again
until it answers).

Values are typed by the kind column of the firmware's parameter table (``controller.params``):
booleans ``UINT8``, integers ``INT32``, the rest ``REAL32``; integers are encoded bytewise or by C cast as
the drone's autopilot does (:mod:`protocol.mavlink.param_encoding`). Runs on the link thread, under the
link's lock.
"""

from __future__ import annotations

import contextlib
import math
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import Final

from controller.params import WIRE_ROWS, Kind
from protocol import mavlink as mav
from protocol import messages as bm

__all__ = ["PARAM_TYPES", "ParamMirror"]

_PARAMS_PER_CYCLE: Final[int] = 10


_MAV_TYPES: Final[dict[Kind, mav.ParamType]] = {
    Kind.BOOL: mav.ParamType.UINT8,
    Kind.INT: mav.ParamType.INT32,
    Kind.FLOAT: mav.ParamType.REAL32,
}

PARAM_TYPES: Final[dict[str, mav.ParamType]] = {name: _MAV_TYPES[row.kind] for name, row in WIRE_ROWS.items()}
"""The MAVLink type of each firmware parameter (by wire name, from the kind column of the firmware's
parameter table); others are ``REAL32``."""


@dataclass
class _PendingParamSet:
    name: str
    deadline_us: int


class ParamMirror:
    """The board's parameters as the drone sees them.

    Args:
        confirm_timeout_us: A ``PARAM_SET`` the board has not confirmed by then is answered with the
            value in force; also the shortest interval between two "send all" requests to the board.
        send: Sends one MAVLink message.
        to_board: Sends one board-link message.
        text: Sends a ``STATUSTEXT`` (severity, text; rate limited by the link).
        count: Counts one event of the named :class:`~host.drone.state.DroneLinkCounters` field.
        clock_us: The link's monotonic clock in µs.
    """

    def __init__(
        self,
        confirm_timeout_us: int,
        send: Callable[[mav.MavMessage], None],
        to_board: Callable[[bm.Message], None],
        text: Callable[[int, str], None],
        count: Callable[[str], None],
        clock_us: Callable[[], int],
    ) -> None:
        self._confirm_timeout_us = confirm_timeout_us
        self._send = send
        self._board = to_board
        self._text = text
        self._count_event = count
        self._clock = clock_us
        self._values: dict[str, tuple[int, float]] = {}  # board name -> (index, value)
        self._by_index: dict[int, str] = {}
        self._by_upper: dict[str, str] = {}
        self._count: int | None = None
        self._tx: deque[str] = deque()
        self._pending: dict[str, _PendingParamSet] = {}
        self._list_asked_us: int | None = None
        self._list_wanted = False
        self.bytewise = True
        """Integer parameters encoded bytewise (MAVLink's default, PX4), else by C cast (ArduPilot)."""

    @property
    def count(self) -> int | None:
        """How many parameters the board has (None until it said)."""
        return self._count

    @property
    def known(self) -> int:
        """Parameters mirrored so far."""
        return len(self._values)

    def on_request_list(self, now: int) -> None:
        """Answer ``PARAM_REQUEST_LIST``: every mirrored value, or ask the board for all first.

        Args:
            now: Link-clock time in µs.
        """
        if self._count is not None and len(self._values) >= self._count:
            queued = set(self._tx)
            self._tx.extend(
                n for n, _ in sorted(self._values.items(), key=lambda kv: kv[1][0]) if n not in queued
            )
            return
        # Not all parameters mirrored yet: ask the board (again until it answers); its ParamValues are
        # forwarded as they come and the whole list is sent once the mirror is complete.
        self._list_wanted = True
        self.ask_board_for_all(now)

    def ask_board_for_all(self, now: int) -> None:
        """Ask the board for every parameter (at most once per confirmation timeout).

        Args:
            now: Link-clock time in µs.
        """
        asked = self._list_asked_us
        if asked is None or now - asked >= self._confirm_timeout_us:
            self._list_asked_us = now
            self._board(bm.ParamRequest(bm.PARAM_LIST_ALL))

    def on_request_read(self, req: mav.ParamRequestRead) -> None:
        """Answer ``PARAM_REQUEST_READ`` by index or by name (asking the board when not mirrored).

        Args:
            req: The request.
        """
        if req.param_index >= 0:
            name = self._by_index.get(req.param_index)
            if name is not None:
                self._tx.append(name)
            elif self._count is None or req.param_index < self._count:
                self._board(bm.ParamRequest(req.param_index))
            return
        name = self._by_upper.get(req.param_id.upper())
        if name is not None:
            self._tx.append(name)
        elif not self.complete:
            self.ask_board_for_all(self._clock())

    def on_set(self, req: mav.ParamSet, now: int) -> None:
        """Forward ``PARAM_SET`` to the board; its confirmation (or a timeout) answers the drone.

        Args:
            req: The request.
            now: Link-clock time in µs.
        """
        name = self._by_upper.get(req.param_id.upper())
        if name is None and not self.complete and req.param_id.upper() in WIRE_ROWS:
            # Before the board has listed its parameters (a set sent before any PARAM_REQUEST_LIST, or
            # while the board is slow to answer), a name of the firmware's table goes to the board all
            # the same: its ParamValue answers the drone and starts the mirror.
            name = req.param_id.upper()
            self.ask_board_for_all(now)
        if name is None:
            # MAVLink has no negative answer to PARAM_SET (the sender times out); say why.
            self._count_event("unexpected")
            self._text(mav.Severity.WARNING, f"param {req.param_id} unknown")
            return
        value = mav.decode_param_value(req.param_value, req.param_type, bytewise=self.bytewise)
        if not math.isfinite(value):
            self._tx.append(name)  # answer with the value in force
            return
        self._pending[name] = _PendingParamSet(name, now + self._confirm_timeout_us)
        self._board(bm.ParamSet(name, value))

    @property
    def complete(self) -> bool:
        """Every board parameter is mirrored."""
        return self._count is not None and len(self._values) >= self._count

    def send_due(self) -> None:
        """Send the next queued ``PARAM_VALUE``s (a bounded number per link cycle)."""
        for _ in range(min(_PARAMS_PER_CYCLE, len(self._tx))):
            name = self._tx.popleft()
            if name in self._pending:
                continue  # a set the board has not confirmed yet: its confirmation (or timeout) answers
            self._send_value(name)

    def _send_value(self, name: str) -> None:
        entry = self._values.get(name)
        if entry is None:
            return
        index, value = entry
        count = self._count if self._count is not None else len(self._values)
        ptype = PARAM_TYPES.get(name.upper(), mav.ParamType.REAL32)
        wire = mav.encode_param_value(value, ptype, bytewise=self.bytewise)
        self._send(mav.ParamValue(name.upper(), wire, ptype, count, index))

    def on_board_param(self, pv: bm.ParamValue) -> None:
        """Mirror a value the board confirmed and tell the drone.

        Args:
            pv: The board's ``ParamValue``.
        """
        name = pv.name
        if not name or len(name) > mav.PARAM_ID_MAX:
            self._count_event("board_unexpected")
            return
        self._values[name] = (pv.index, float(pv.value))
        self._by_index[pv.index] = name
        self._by_upper[name.upper()] = name
        self._count = pv.count
        self._pending.pop(name, None)
        # The board confirms what it took (answer to a request, a set or a change): tell the drone.
        with contextlib.suppress(ValueError):
            self._tx.remove(name)
        self._send_value(name)
        if self._list_wanted and self.complete:
            # A list asked for before the board had answered: send all of it now.
            self._list_wanted = False
            self.on_request_list(self._clock())

    def check_timeouts(self, now: int) -> None:
        """Answer each ``PARAM_SET`` the board did not confirm in time with the value in force.

        Args:
            now: Link-clock time in µs.
        """
        if self._list_wanted and not self.complete:
            self.ask_board_for_all(now)
        if self._pending:
            for name, pending in list(self._pending.items()):
                if now >= pending.deadline_us:
                    del self._pending[name]
                    self._send_value(name)  # the value in force
                    self._text(mav.Severity.WARNING, f"param {name.upper()}: board did not confirm")
