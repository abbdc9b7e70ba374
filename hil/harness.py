"""The harness around a virtual board in lockstep: a scripted host and a per-tick probe.

- :class:`ScriptedHost` is the host's side of the board link: 10 Hz heartbeats (unless a ``host-loss``
  fault blocks them), messages scheduled at given times, and every board message decoded (in batches,
  when first looked at) and kept.
- :class:`Probe` samples what matters for the checks once per tick into preallocated arrays: the
  currents the ESCs received, the firmware's phase, mode and grasp state, the plant's true tensions and
  tip position.

Both only observe and write bytes; a scenario's checks are computed from the probe afterwards, in
simulated time.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from controller.transport import Transport
from protocol.link import LinkParser
from protocol.messages import (
    HEARTBEAT_PERIOD_US,
    CommandAck,
    Event,
    Heartbeat,
    Message,
    ParamValue,
    Telemetry,
    decode,
    encode,
)

from .board import VirtualBoard
from .faults import FaultSet


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


@dataclass
class Probe:
    """Per-tick samples of a run (preallocated for ``ticks`` ticks).

    Attributes:
        t_us: firmware time of each tick.
        current_raw: currents the ESCs received (after the firmware's clamp), shape (n, 3).
        target_n: the firmware's target tensions, shape (n, 3).
        phase, mode, grasp: the firmware's state after the tick.
        tension_n: the plant's true cable tensions, shape (n, 3).
        tip_m: the plant's tip position, shape (n, 3).
        cable_m: the plant's cable lengths from spool to tip, shape (n, 3).
        rc_rejected: the firmware's count of rejected RC frames.
    """

    ticks: int
    n: int = 0
    t_us: npt.NDArray[np.int64] = field(init=False)
    current_raw: npt.NDArray[np.int32] = field(init=False)
    target_n: npt.NDArray[np.float64] = field(init=False)
    phase: npt.NDArray[np.int8] = field(init=False)
    mode: npt.NDArray[np.int8] = field(init=False)
    grasp: npt.NDArray[np.int8] = field(init=False)
    tension_n: npt.NDArray[np.float64] = field(init=False)
    tip_m: npt.NDArray[np.float64] = field(init=False)
    cable_m: npt.NDArray[np.float64] = field(init=False)
    rc_rejected: npt.NDArray[np.int64] = field(init=False)

    def __post_init__(self) -> None:
        n = self.ticks
        self.t_us = np.zeros(n, np.int64)
        self.current_raw = np.zeros((n, 3), np.int32)
        self.target_n = np.zeros((n, 3))
        self.phase = np.zeros(n, np.int8)
        self.mode = np.zeros(n, np.int8)
        self.grasp = np.zeros(n, np.int8)
        self.tension_n = np.zeros((n, 3))
        self.tip_m = np.zeros((n, 3))
        self.cable_m = np.zeros((n, 3))
        self.rc_rejected = np.zeros(n, np.int64)

    def sample(self, board: VirtualBoard) -> None:
        """Record the state after one tick."""
        i = self.n
        if i >= self.ticks:
            raise IndexError("probe is full")
        fw = board.firmware
        plant = board.plant
        self.t_us[i] = board.now_us
        self.current_raw[i] = plant.commanded_currents_raw()[:3]
        self.target_n[i] = fw.tensions_n
        self.phase[i] = fw.phase
        self.mode[i] = fw.mode
        self.grasp[i] = fw.grasp_state
        self.tension_n[i] = plant.cable_tensions_n()
        self.tip_m[i] = plant.tip_pose().pos_m
        self.cable_m[i] = plant.cable_lengths_m()
        self.rc_rejected[i] = fw.rc_rejected
        self.n = i + 1

    def window(self, start_us: int, end_us: int | None = None) -> npt.NDArray[np.bool_]:
        """Mask of the ticks with ``start_us <= t < end_us``."""
        t = self.t_us[: self.n]
        mask = t >= start_us
        if end_us is not None:
            mask &= t < end_us
        return mask

    def first_time(self, mask: npt.NDArray[np.bool_]) -> int | None:
        """Time of the first tick where ``mask`` holds (None if never)."""
        idx = np.flatnonzero(mask[: self.n])
        return int(self.t_us[idx[0]]) if idx.size else None

    def abs_current(self) -> npt.NDArray[np.int32]:
        """Largest |current| over the three motors, per tick."""
        out: npt.NDArray[np.int32] = np.abs(self.current_raw[: self.n]).max(axis=1)
        return out
