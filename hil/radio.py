"""A virtual DT7 radio and DR16 receiver: stick states in, DBUS bytes into the board's UART, simulated time.

The receiver sends one 18-byte frame every 14 ms (DR16: 14 ms between frames; some receivers 7 ms).
At 100 000 baud 8E1 a byte takes 110 µs on the wire, so a frame is a 1.98 ms burst followed by a
12 ms idle gap: :meth:`VirtualRadio.read` returns exactly the bytes that have finished arriving by
``t_us``, so the board's idle-gap framer sees the same chunking a real UART read loop would.
"""

from __future__ import annotations

from bisect import bisect_right
from collections.abc import Sequence

from controller.rc import Uart
from hil.faults import FaultSet
from protocol.dbus import BYTE_TIME_US, FRAME_PERIOD_US, RcFrame


class MemoryUart(Uart):
    """The board's DBUS UART in lockstep: the virtual radio feeds it, :class:`DbusSerialSource` reads it."""

    def __init__(self) -> None:
        self._buf = bytearray()

    def feed(self, data: bytes) -> None:
        """Bytes that arrived on the wire."""
        self._buf += data

    @property
    def in_waiting(self) -> int:
        """Bytes ready to read."""
        return len(self._buf)

    def read(self, n: int) -> bytes:
        """Take up to ``n`` bytes."""
        data = bytes(self._buf[:n])
        del self._buf[:n]
        return data

    def close(self) -> None:
        """Nothing to release."""


class RadioScript:
    """Stick and lever states over time: a step function of ``(t_us, frame)`` pairs.

    Before the first step the radio sends nothing (receiver not yet bound).
    """

    def __init__(self, steps: Sequence[tuple[int, RcFrame]]) -> None:
        times = [t for t, _ in steps]
        if times != sorted(times):
            raise ValueError("radio script steps must be in time order")
        self._times = times
        self._frames = [f for _, f in steps]

    def at(self, t_us: int) -> RcFrame | None:
        """The state the radio sends at ``t_us`` (None before the first step)."""
        i = bisect_right(self._times, t_us) - 1
        return self._frames[i] if i >= 0 else None


class VirtualRadio:
    """The radio side of the DBUS UART.

    Args:
        script: what the pilot does; replace the state later with :meth:`set`.
        faults: faults applied to what is sent and to the bytes on the wire.
        period_us: time between frames.
        phase_us: time of the first frame slot.
    """

    def __init__(
        self,
        script: RadioScript | None = None,
        faults: FaultSet | None = None,
        period_us: int = FRAME_PERIOD_US,
        phase_us: int = 0,
    ) -> None:
        if period_us <= 0:
            raise ValueError("period_us must be > 0")
        self.script = script
        self.faults = faults
        self.period_us = period_us
        self._next_slot_us = phase_us
        self._burst = b""
        self._burst_start_us = 0
        self._sent = 0
        self._live: RcFrame | None = None
        self.frames_sent = 0
        self.uart = MemoryUart()
        """The board's UART receive side, which this radio's wire ends in."""

    def set(self, frame: RcFrame | None) -> None:
        """Overrides the script from now on (None: back to the script)."""
        self._live = frame

    def transmit(self, t_us: int) -> bytes:
        """Put the bytes that finished arriving by ``t_us`` into :attr:`uart`; return them (to record)."""
        if self._sent >= len(self._burst) and self._next_slot_us > t_us:
            return b""  # the common tick, as in read(): no call on the lockstep hot path
        data = self.read(t_us)
        if data:
            self.uart.feed(data)
        return data

    def read(self, t_us: int) -> bytes:
        """The bytes that finished arriving at the board's UART since the previous call."""
        if self._sent >= len(self._burst) and self._next_slot_us > t_us:
            return b""  # the common tick: the last burst is all in, the next slot not yet due
        out = bytearray()
        while True:
            if self._sent < len(self._burst):
                done = min(len(self._burst), (t_us - self._burst_start_us) // BYTE_TIME_US)
                if done > self._sent:
                    out += self._burst[self._sent : done]
                    self._sent = done
                if self._sent < len(self._burst):
                    break
            if self._next_slot_us > t_us:
                break
            self._start_burst(self._next_slot_us)
            self._next_slot_us += self.period_us
        return bytes(out)

    def _start_burst(self, slot_us: int) -> None:
        frame = self._live if self._live is not None else (self.script.at(slot_us) if self.script else None)
        payload: bytes = b""
        if frame is not None:
            sent: RcFrame | bytes | None = frame
            if self.faults is not None:
                sent = self.faults.rc_override(slot_us, frame)
            if isinstance(sent, RcFrame):
                payload = sent.pack()
                self.frames_sent += 1
            elif sent is not None:
                payload = sent
            if self.faults is not None:
                payload = self.faults.rc_bytes(slot_us, payload)
        self._burst = payload
        self._burst_start_us = slot_us
        self._sent = 0
