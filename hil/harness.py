"""The host's side of a lockstep board link: a scripted host.

- :class:`ScriptedHost` is the host's side of the board link: 10 Hz heartbeats (unless a ``host-loss``
  fault blocks them), messages scheduled at given times, and every board message decoded (in batches,
  when first looked at) and kept.
The loop that drives it is :class:`hil.environment.Environment`; what a run measured goes into a
:class:`hil.run_record.RunRecord`.
"""

from __future__ import annotations

from controller.transport import Transport
from hil.faults import FaultSet
from protocol.messages import (
    CommandAck,
    Event,
    Message,
    ParamValue,
    Telemetry,
)
from protocol.session import HostSession

__all__ = ["ScriptedHost"]


class ScriptedHost:
    """A host that follows a script over a lockstep link: a :class:`~protocol.session.HostSession`'s shell.

    Args:
        end: the host's end of the link (:attr:`hil.board.LinkWire.host`).
        faults: the run's faults (``host-loss`` blocks heartbeats).
        heartbeats: send heartbeats at all.
    """

    def __init__(self, end: Transport, faults: FaultSet | None = None, *, heartbeats: bool = True) -> None:
        self.end = end
        self.faults = faults
        blocked = faults.heartbeat_blocked if faults is not None else None
        self.session = HostSession(
            heartbeats=heartbeats,
            heartbeat_allowed=None if blocked is None else lambda t_us: not blocked(t_us),
        )
        self._script: list[tuple[int, Message]] = []
        self._idle_until_us = -1
        """Nothing periodic is due before this (the session's next deadline): most ticks return at once."""
        self._received = bytearray()
        self._received_us = 0
        self._telemetry: list[Telemetry] = []
        self._events: list[Event] = []
        self._acks: list[CommandAck] = []
        self._other: list[Message] = []

    @property
    def sent(self) -> list[tuple[int, Message]]:
        """``(t_us, msg)`` of every message sent, in order."""
        return self.session.sent

    @property
    def last_heartbeat_us(self) -> int | None:
        """When the last heartbeat was sent (None before any)."""
        return self.session.last_heartbeat_us

    def at(self, t_us: int, msg: Message) -> None:
        """Send ``msg`` at ``t_us``."""
        self._script.append((t_us, msg))
        self._script.sort(key=lambda item: item[0])

    def send(self, t_us: int, msg: Message) -> None:
        """Send ``msg`` now."""
        self.session.send(msg, t_us)
        self.end.write(self.session.data_to_send())

    def before_tick(self, t_us: int) -> None:
        """Write what is due by ``t_us``: the heartbeat, then the scripted messages."""
        script = self._script
        if t_us < self._idle_until_us and not (script and script[0][0] <= t_us):
            return  # the common lockstep tick: the heartbeat is 100 ticks apart
        session = self.session
        session.poll(t_us)
        while script and script[0][0] <= t_us:
            session.send(script.pop(0)[1], t_us)
        data = session.data_to_send()
        if data:
            self.end.write(data)
        deadline = session.next_deadline_us()
        self._idle_until_us = (1 << 62) if deadline is None else deadline

    def after_tick(self, t_us: int) -> None:
        """Take what the board sent; it is decoded when a received message is first looked at.

        The scripted host never reacts to what it receives, so decoding in batches changes nothing but
        the cost: a lockstep tick stays small, and the decoding runs warm (see ``docs/hil.md``).
        """
        data = self.end.read()
        if data:
            self._received += data
            self._received_us = t_us

    def drain(self) -> None:
        """Decode everything received so far (every accessor below does this first)."""
        if not self._received:
            return
        data = bytes(self._received)
        self._received.clear()
        for msg in self.session.receive_data(data, self._received_us):
            if isinstance(msg, Telemetry):
                self._telemetry.append(msg)
            elif isinstance(msg, Event):
                self._events.append(msg)
            elif isinstance(msg, CommandAck):
                self._acks.append(msg)
            elif not isinstance(msg, ParamValue):  # parameters: the session's table
                self._other.append(msg)

    @property
    def telemetry(self) -> list[Telemetry]:
        """Every ``Telemetry`` received, in order."""
        self.drain()
        return self._telemetry

    @property
    def events(self) -> list[Event]:
        """Every ``Event`` received, in order."""
        self.drain()
        return self._events

    @property
    def acks(self) -> list[CommandAck]:
        """Every ``CommandAck`` received, in order."""
        self.drain()
        return self._acks

    @property
    def params(self) -> dict[str, float]:
        """The last value received for each parameter (``ParamValue``)."""
        self.drain()
        return self.session.params

    @property
    def other(self) -> list[Message]:
        """Every other message received (``MotorFrames``, ``RawRc``, ``SimPoses``, ``BoardStatus``...)."""
        self.drain()
        return self._other

    @property
    def decode_errors(self) -> int:
        """Intact frames whose payload did not decode."""
        self.drain()
        return self.session.stream.decode_errors
