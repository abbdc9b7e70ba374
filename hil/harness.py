"""The harness around a virtual board in lockstep: a scripted host and a per-tick probe.

- :class:`ScriptedHost` is the host's side of the board link: 10 Hz heartbeats (unless a ``host-loss``
  fault blocks them), messages scheduled at given times, and every board message decoded (in batches,
  when first looked at) and kept.
The loop that drives it is :class:`hil.environment.Environment`; what a run measured goes into a
:class:`hil.record.RunRecord`.
"""

from __future__ import annotations

from controller.transport import Transport
from protocol.link import LinkParser
from protocol.messages import (
    CommandAck,
    Event,
    Heartbeat,
    Message,
    ParamValue,
    Telemetry,
    decode,
    encode,
)

from .faults import FaultSet

HEARTBEAT_PERIOD_US = 100_000
"""The host's heartbeat period (10 Hz, as spirob-host sends)."""


class ScriptedHost:
    """A host that follows a script over a lockstep link.

    Args:
        end: the host's end of the link (:attr:`hil.board.LinkWire.host`).
        faults: the run's faults (``host-loss`` blocks heartbeats).
        heartbeats: send heartbeats at all.
    """

    def __init__(self, end: Transport, faults: FaultSet | None = None, *, heartbeats: bool = True) -> None:
        self.end = end
        self.faults = faults
        self.heartbeats = heartbeats
        self.parser = LinkParser()
        self._seq = 0
        self._next_hb_us = 0
        self._hb_count = 0
        self._script: list[tuple[int, Message]] = []
        self.sent: list[tuple[int, Message]] = []
        self._received = bytearray()
        self._telemetry: list[Telemetry] = []
        self._events: list[Event] = []
        self._acks: list[CommandAck] = []
        self._params: dict[str, float] = {}
        self._other: list[Message] = []
        self._decode_errors = 0
        self.last_heartbeat_us: int | None = None

    def at(self, t_us: int, msg: Message) -> None:
        """Send ``msg`` at ``t_us``."""
        self._script.append((t_us, msg))
        self._script.sort(key=lambda item: item[0])

    def send(self, t_us: int, msg: Message) -> None:
        """Send ``msg`` now."""
        self.end.write(encode(msg, self._seq))
        self._seq = (self._seq + 1) & 0xFF
        self.sent.append((t_us, msg))

    def before_tick(self, t_us: int) -> None:
        """Write what is due by ``t_us``."""
        if self.heartbeats and t_us >= self._next_hb_us:
            self._next_hb_us = t_us + HEARTBEAT_PERIOD_US
            if self.faults is None or not self.faults.heartbeat_blocked(t_us):
                self.send(t_us, Heartbeat(t_us, self._hb_count))
                self._hb_count += 1
                self.last_heartbeat_us = t_us
        while self._script and self._script[0][0] <= t_us:
            self.send(t_us, self._script.pop(0)[1])

    def after_tick(self, t_us: int) -> None:
        """Take what the board sent; it is decoded when a received message is first looked at.

        The scripted host never reacts to what it receives, so decoding in batches changes nothing but
        the cost: a lockstep tick stays small, and the decoding runs warm (see ``docs/hil.md``).
        """
        data = self.end.read()
        if data:
            self._received += data

    def drain(self) -> None:
        """Decode everything received so far (every accessor below does this first)."""
        if not self._received:
            return
        data = bytes(self._received)
        self._received.clear()
        for frame in self.parser.feed(data):
            try:
                msg = decode(frame)
            except ValueError:
                self._decode_errors += 1
                continue
            if isinstance(msg, Telemetry):
                self._telemetry.append(msg)
            elif isinstance(msg, Event):
                self._events.append(msg)
            elif isinstance(msg, CommandAck):
                self._acks.append(msg)
            elif isinstance(msg, ParamValue):
                self._params[msg.name] = msg.value
            else:
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
        return self._params

    @property
    def other(self) -> list[Message]:
        """Every other message received (``MotorFrames``, ``RawRc``, ``SimPoses``, ``BoardStatus``...)."""
        self.drain()
        return self._other

    @property
    def decode_errors(self) -> int:
        """Intact frames whose payload did not decode."""
        self.drain()
        return self._decode_errors
