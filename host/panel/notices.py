"""What the panel tells people: notices (toasts, to everyone or one tab) and the event console.

:class:`Notices` listens to the board (failsafe phases, events, command answers), to the link's state
(disconnect, reconnect) and to every message the host sends (``BoardClient`` sent listener: the console
lists commands and parameter sets with who sent them: ``Tab 3``, ``host`` for the command line,
``MAVLink``). The control arbiter adds its own notices (refusals, hand-overs, E-stop) through
:meth:`Notices.notify`. The panel shows each notice once (:meth:`Notices.notices_after`).
"""

from __future__ import annotations

import collections
import threading
from dataclasses import dataclass

from host.link.source import LinkState
from host.panel.console import EventConsole
from protocol.messages import (
    AckResult,
    Command,
    CommandAck,
    CommandCode,
    Event,
    EventKind,
    Message,
    ParamSet,
    Phase,
    Telemetry,
)

__all__ = ["Notice", "Notices"]

_PHASE_NOTICES = {
    Phase.OK: ("info", "Failsafe cleared", "phase OK: current may flow"),
    Phase.GATE: ("info", "Start-up gate", "waiting for valid RC with the right lever DOWN"),
    Phase.RC_LOST: ("warning", "RC lost", "no valid RC frame for 30 ms: zero current"),
    Phase.MOTOR_FAULT: ("error", "Motor fault", "a motor went silent: all currents zero (latched)"),
    Phase.HOST_LOST: ("warning", "Host lost", "host heartbeat timed out: zero current"),
    Phase.ESTOP: ("error", "E-STOP", "emergency stop latched: clear it and re-arm through SAFE"),
}


@dataclass(frozen=True, slots=True)
class Notice:
    """Something to tell people in the panel (failsafe, fault, control hand-over, link state).

    Attributes:
        seq: increasing number (the panel shows each notice once).
        level: ``info``, ``warning`` or ``error``.
        title: short title.
        body: one line.
        client: only this client (None: everybody).
    """

    seq: int
    level: str
    title: str
    body: str
    client: int | None = None


def _args_text(args: tuple[float, ...]) -> str:
    """A command's non-zero arguments for a console line (``" (1, 2.5)"``; empty when all are 0)."""
    shown = [f"{a:g}" for a in args if a != 0.0]
    return f" ({', '.join(shown)})" if shown else ""


class Notices:
    """Notices for the panel and the event console; thread-safe.

    Args:
        keep: notices kept (the oldest go first).
    """

    def __init__(self, keep: int = 100) -> None:
        self.events = EventConsole()
        """The event console (board events, failsafes, acks, commands sent)."""
        self._lock = threading.Lock()
        self._notices: collections.deque[Notice] = collections.deque(maxlen=keep)
        self._seq = 0
        self._board_time_us: int | None = None
        self._last_phase: Phase | None = None
        self._link_state = LinkState.CONNECTING

    # ------------------------------------------------------------------ notices and console

    def notify(self, level: str, title: str, body: str, client: int | None = None) -> None:
        """Tell everybody (``client`` None) or one tab."""
        with self._lock:
            self._seq += 1
            self._notices.append(Notice(self._seq, level, title, body, client))

    def notices_after(self, seq: int) -> list[Notice]:
        """Notices newer than ``seq``, oldest first."""
        with self._lock:
            return [n for n in self._notices if n.seq > seq]

    def log(self, source: str, level: str, text: str, *, board_time_us: int | None = None) -> None:
        """Add a line to the event console (at the newest telemetry's board time unless given)."""
        if board_time_us is None:
            board_time_us = self._board_time_us
        self.events.add(board_time_us, source, level, text)

    # ------------------------------------------------------------------ listeners

    def on_board_message(self, msg: Message) -> None:
        """Listener: failsafe phase changes, board events and command answers become lines and notices."""
        if isinstance(msg, Telemetry):
            self._board_time_us = msg.time_us
            phase = msg.phase
            if phase != self._last_phase:
                if self._last_phase is not None:
                    self._phase_notice(phase)
                self._last_phase = phase
        elif isinstance(msg, Event):
            self._on_event(msg)
        elif isinstance(msg, CommandAck):
            code = msg.command
            name = code.name if isinstance(code, CommandCode) else f"command {code}"
            ok = msg.result in (AckResult.ACCEPTED, AckResult.IN_PROGRESS)
            why = f": {msg.text}" if msg.text else ""
            self.log("ack", "info" if ok else "warning", f"{name} {msg.result.name}{why}")

    def _phase_notice(self, phase: Phase) -> None:
        self.log("failsafe", "info" if phase in (Phase.OK, Phase.GATE) else "warning", f"phase {phase.name}")
        self.notify(*_PHASE_NOTICES[phase])

    def _on_event(self, e: Event) -> None:
        level = "error" if e.kind == EventKind.FAULT else "info"
        self.log("board", level, f"{e.kind.name}: {e.text or e.code}", board_time_us=e.time_us)
        if e.kind == EventKind.FAULT:
            self.notify("error", "Fault", e.text or f"fault code {e.code}")
        elif e.kind == EventKind.GRASP:
            self.notify("info", "Grasp", e.text or f"grasp state {e.code}")
        elif e.kind == EventKind.BOOT:
            self.notify("info", "Board started", e.text or "boot")

    def on_link_state(self, state: LinkState) -> None:
        """State listener: say when the board goes away and comes back."""
        with self._lock:
            prev, self._link_state = self._link_state, state
        if state is LinkState.DISCONNECTED and prev is not LinkState.DISCONNECTED:
            self.notify("error", "Board disconnected", "retrying; the board holds zero current")
        elif state is LinkState.CONNECTED and prev is LinkState.DISCONNECTED:
            self.notify("info", "Board reconnected", "levers reset to SAFE (right lever DOWN)")

    def on_sent(self, msg: Message, origin: str) -> None:
        """Sent listener (``BoardClient.add_sent_listener``): commands and parameter sets, with who sent
        them."""
        if isinstance(msg, Command):
            code = CommandCode(msg.code)
            level = "error" if code == CommandCode.ESTOP else "info"
            self.log(origin, level, f"{code.name}{_args_text(msg.args)}")
        elif isinstance(msg, ParamSet):
            self.log(origin, "info", f"set {msg.name} = {msg.value:g}")
