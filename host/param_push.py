"""``spirob-host --params FILE``: a firmware parameter file's values sent to the board as ``ParamSet`` s each
time the link comes up.

The file is read with the firmware's own loader (``controller.param_file``: unknown keys, wrong types and
values out of range are refused before anything starts). The host can only send the run-time parameters
(those with a wire name, ``docs/parameters.md``); a start-up setting in the file is refused with the way to
give it (``spirob-firmware --params``). The sets go out on the first telemetry after the link comes up; a
SAFE-only parameter waits until the board reports itself disarmed (the board's own rule: it refuses one set
while current may flow). Each set is read back from the board's ``ParamValue``; a refusal (the board's
``PARAM`` event) is reported with the board's reason. Nothing is sent more than once per link-up.
"""

from __future__ import annotations

import logging
import math
import struct
import threading
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path

from controller.errors import ConfigError
from controller.param_file import load_param_file
from controller.params import FIELD_ROWS, PARAMS, SAFETY_PARAMS
from host.errors import HostError
from host.link.source import LinkState
from protocol.messages import Event, EventKind, Message, ParamSet, ParamValue, Telemetry, TelemetryFlags

__all__ = ["ParamPush", "PushStatus", "wire_values"]

_log = logging.getLogger("spirob-host")


def wire_values(path: Path) -> dict[str, float]:
    """A parameter file's values by wire name, as ``ParamSet`` carries them (bools as 0 / 1).

    Raises:
        HostError: one line: the file is unreadable or refused by the firmware's rules, or it holds a
            start-up setting the host cannot send.
    """
    try:
        values = load_param_file(path)
    except ConfigError as exc:
        raise HostError(f"--params: {exc}") from None
    out: dict[str, float] = {}
    for name, value in values.items():
        wire = FIELD_ROWS[name].wire
        if wire is None:
            raise HostError(
                f"--params {path}: {name} is a start-up setting the host cannot send "
                "(give the file to spirob-firmware --params)"
            )
        out[wire] = float(value)
    return out


def _f32(x: float) -> float:
    """``x`` as the float32 the link carries."""
    out: float = struct.unpack("<f", struct.pack("<f", x))[0]
    return out


@dataclass(frozen=True)
class PushStatus:
    """The fate of one value of the file.

    Attributes:
        requested: the file's value.
        sent: a ``ParamSet`` went out since the link came up.
        confirmed: the value the board read back after it (None: no answer yet).
        refused: the board's reason for refusing it (None: not refused).
    """

    requested: float
    sent: bool = False
    confirmed: float | None = None
    refused: str | None = None

    @property
    def taken(self) -> bool:
        """The board reads back the requested value (to float32)."""
        return self.confirmed is not None and math.isclose(self.confirmed, _f32(self.requested), rel_tol=1e-6)


class ParamPush:
    """Sends a parameter file's values to the board at every link-up (a board listener; thread-safe).

    Args:
        values: wire name -> value (:func:`wire_values`), sent in the board's index order.
        send: sends one message to the board (the control arbiter's ``forward``); False when not sent.
        say: also tell the operator here (level ``info`` / ``warning``, text), e.g. the panel's event
            console; every line goes to the ``spirob-host`` log as well.
    """

    def __init__(
        self,
        values: Mapping[str, float],
        send: Callable[[Message], bool],
        say: Callable[[str, str], None] | None = None,
    ) -> None:
        order = {name: i for i, name in enumerate(PARAMS)}
        self._values = dict(sorted(values.items(), key=lambda kv: order[kv[0]]))
        self._send = send
        self._also = say
        self._lock = threading.Lock()
        self._up = False
        self.status: dict[str, PushStatus] = {n: PushStatus(v) for n, v in self._values.items()}
        """Wire name -> the fate of its value since the link last came up."""

    def on_link_state(self, state: LinkState) -> None:
        """Listener: a link that comes up gets every value again."""
        with self._lock:
            self._up = state == LinkState.CONNECTED
            if self._up:
                self.status = {n: PushStatus(v) for n, v in self._values.items()}

    @property
    def done(self) -> bool:
        """Every value was taken or refused since the link came up."""
        with self._lock:
            return all(s.taken or s.refused is not None for s in self.status.values())

    def on_board_message(self, msg: Message) -> None:
        """Listener: send on telemetry (SAFE-only values while disarmed); read back the answers."""
        if isinstance(msg, Telemetry):
            self._on_telemetry(msg)
        elif isinstance(msg, ParamValue):
            with self._lock:
                st = self.status.get(msg.name)
                if st is None or not st.sent or st.confirmed is not None:
                    return
                self.status[msg.name] = PushStatus(st.requested, True, msg.value, st.refused)
                all_done = all(s.taken or s.refused is not None for s in self.status.values())
            if all_done:
                taken = sum(s.taken for s in self.status.values())
                self._say("info", f"--params: the board took {taken} of {len(self.status)} value(s)")
        elif isinstance(msg, Event) and msg.kind == EventKind.PARAM and msg.text.startswith("rejected"):
            if not 0 <= msg.code < len(PARAMS):
                return
            name = PARAMS[msg.code]
            with self._lock:
                st = self.status.get(name)
                if st is None or not st.sent or st.refused is not None:
                    return
                self.status[name] = PushStatus(st.requested, True, st.confirmed, msg.text)
            self._say("warning", f"--params: the board refused {name} = {st.requested:g}: {msg.text}")

    def _say(self, level: str, text: str) -> None:
        _log.log(logging.WARNING if level == "warning" else logging.INFO, "%s", text)
        if self._also is not None:
            self._also(level, text)

    def _on_telemetry(self, t: Telemetry) -> None:
        armed = bool(t.flags & TelemetryFlags.ARMED)
        with self._lock:
            if not self._up:
                return
            todo = [n for n, s in self.status.items() if not s.sent and not (armed and n in SAFETY_PARAMS)]
            for name in todo:
                self.status[name] = PushStatus(self.status[name].requested, True)
        for name in todo:
            if not self._send(ParamSet(name, self._values[name])):
                with self._lock:  # the link went down under it: the next link-up sends it again
                    self.status[name] = PushStatus(self._values[name])
