"""Faults to inject into a virtual board, scriptable per scenario and from the command line.

A :class:`Fault` is a value (kind, time window, parameters); a :class:`FaultSet` applies a list of them
at the points where bytes and frames cross between the simulated parts:

- the radio's DBUS byte stream into the board (:meth:`FaultSet.rc_bytes`, and the radio asks
  :meth:`FaultSet.rc_override` what frame, if any, a faulty radio sends instead);
- each motor's feedback frame into the board and the command frame out (:meth:`FaultSet.feedback`,
  :meth:`FaultSet.bus_off`);
- the board link in each direction (:meth:`FaultSet.link_bytes`, :meth:`FaultSet.link_down`);
- the host's heartbeat (:meth:`FaultSet.heartbeat_blocked`);
- the firmware's tick timing (:meth:`FaultSet.tick_delay_us`).

All randomness comes from the ``numpy.random.Generator`` given to the set, so a run is a pure function
of (design, scenario, faults, seed).

Command-line form (``--fault``): ``KIND@START[-END][:key=value,...]`` with times in seconds, e.g.
``link-byte-loss@1-3:rate=0.01``, ``motor-silence@2:motor=2``, ``link-delay@0.5-1.5:delay=0.02``.
"""

from __future__ import annotations

import re
from collections import deque
from collections.abc import Iterable
from dataclasses import dataclass, field
from enum import StrEnum

import numpy as np

from protocol.c610 import ANGLE_COUNTS, MotorFeedback
from protocol.dbus import CH_OFFSET, FRAME_LEN, RcFrame


class FaultKind(StrEnum):
    """Every fault the harness can inject."""

    RC_SILENCE = "rc-silence"
    """The radio stops sending (receiver unplugged, out of range)."""
    RC_GARBAGE = "rc-garbage"
    """The UART carries random bytes instead of frames."""
    RC_FROZEN = "rc-frozen"
    """The radio keeps repeating the last frame it sent before the fault (stuck values)."""
    RC_OUT_OF_RANGE = "rc-out-of-range"
    """Well-framed frames whose channels are outside +-660."""
    DBUS_BYTE_LOSS = "dbus-byte-loss"
    """Each DBUS byte is lost with probability ``rate``."""
    DBUS_BIT_FLIP = "dbus-bit-flip"
    """Each DBUS byte has one bit flipped with probability ``rate``."""
    MOTOR_SILENCE = "motor-silence"
    """Motor ``motor`` (or all) sends no feedback."""
    MOTOR_STUCK = "motor-stuck"
    """Motor ``motor`` (or all) repeats its last feedback frame."""
    MOTOR_WRONG = "motor-wrong"
    """Motor ``motor`` (or all) reports a random angle, speed and current."""
    CAN_BUS_OFF = "can-bus-off"
    """No frame crosses the CAN bus in either direction."""
    CAN_JITTER = "can-jitter"
    """Each motor's feedback frame is one tick late with probability ``rate`` (a busy bus): the firmware
    reads that motor's previous frame again (the timing of a real CAN bus, for identification)."""
    LINK_BYTE_LOSS = "link-byte-loss"
    """Each board-link byte (both directions) is lost with probability ``rate``."""
    LINK_BIT_FLIP = "link-bit-flip"
    """Each board-link byte (both directions) has one bit flipped with probability ``rate``."""
    LINK_DELAY = "link-delay"
    """Board-link bytes (both directions) arrive ``delay`` seconds late."""
    LINK_DISCONNECT = "link-disconnect"
    """The board link is unplugged: nothing crosses; it reconnects at the end of the window."""
    HOST_LOSS = "host-loss"
    """The host stops sending heartbeats (it keeps sending everything else)."""
    LOOP_DELAY = "loop-delay"
    """Every firmware tick starts ``delay`` seconds late."""
    LOOP_JITTER = "loop-jitter"
    """Every firmware tick starts late by a uniform random 0..``delay`` seconds."""


_RATE_KINDS = {
    FaultKind.DBUS_BYTE_LOSS,
    FaultKind.DBUS_BIT_FLIP,
    FaultKind.LINK_BYTE_LOSS,
    FaultKind.LINK_BIT_FLIP,
    FaultKind.CAN_JITTER,
}
_DELAY_KINDS = {FaultKind.LINK_DELAY, FaultKind.LOOP_DELAY, FaultKind.LOOP_JITTER}
_MOTOR_KINDS = {FaultKind.MOTOR_SILENCE, FaultKind.MOTOR_STUCK, FaultKind.MOTOR_WRONG}


@dataclass(frozen=True, slots=True)
class Fault:
    """One fault, active on ``start_us <= t < end_us`` (``end_us`` None: until the end of the run).

    Attributes:
        kind: what goes wrong.
        start_us: when it starts (board time).
        end_us: when it stops, or None.
        motor: 1..3 for per-motor faults; None means every motor.
        rate: per-byte probability for loss and bit-flip faults (0 < rate <= 1).
        delay_us: delay for link-delay, loop-delay and loop-jitter (the maximum, for jitter).
    """

    kind: FaultKind
    start_us: int
    end_us: int | None = None
    motor: int | None = None
    rate: float = 0.0
    delay_us: int = 0

    def __post_init__(self) -> None:
        if self.start_us < 0:
            raise ValueError(f"{self.kind}: start must be >= 0")
        if self.end_us is not None and self.end_us <= self.start_us:
            raise ValueError(f"{self.kind}: end must be after start")
        if self.kind in _RATE_KINDS and not 0.0 < self.rate <= 1.0:
            raise ValueError(f"{self.kind}: rate must be in (0, 1], got {self.rate}")
        if self.kind in _DELAY_KINDS and self.delay_us <= 0:
            raise ValueError(f"{self.kind}: delay must be > 0")
        if self.motor is not None and (self.kind not in _MOTOR_KINDS or not 1 <= self.motor <= 3):
            raise ValueError(f"{self.kind}: motor must be 1..3 and only for motor faults")

    def active(self, t_us: int) -> bool:
        """True while the fault is in force."""
        return self.start_us <= t_us and (self.end_us is None or t_us < self.end_us)

    @classmethod
    def parse(cls, spec: str) -> Fault:
        """Parse the command-line form ``KIND@START[-END][:key=value,...]`` (seconds).

        Raises:
            ValueError: with a message naming what is wrong.
        """
        m = re.fullmatch(r"([a-z-]+)@([0-9.]+)(?:-([0-9.]+))?(?::(.*))?", spec.strip())
        if not m:
            raise ValueError(f"fault {spec!r}: expected KIND@START[-END][:key=value,...]")
        name, start, end, opts = m.groups()
        try:
            kind = FaultKind(name)
        except ValueError:
            raise ValueError(
                f"fault {spec!r}: unknown kind {name!r} (one of: {', '.join(k.value for k in FaultKind)})"
            ) from None
        kwargs: dict[str, int | float] = {}
        for item in filter(None, (opts or "").split(",")):
            key, _, value = item.partition("=")
            try:
                if key == "motor":
                    kwargs["motor"] = int(value)
                elif key == "rate":
                    kwargs["rate"] = float(value)
                elif key == "delay":
                    kwargs["delay_us"] = round(float(value) * 1e6)
                else:
                    raise ValueError(f"fault {spec!r}: unknown option {key!r} (motor, rate, delay)")
            except ValueError as exc:
                if "unknown option" in str(exc):
                    raise
                raise ValueError(f"fault {spec!r}: bad value for {key}: {value!r}") from None
        try:
            return cls(
                kind,
                round(float(start) * 1e6),
                None if end is None else round(float(end) * 1e6),
                **kwargs,  # type: ignore[arg-type]
            )
        except ValueError as exc:
            raise ValueError(f"fault {spec!r}: {exc}") from None


@dataclass
class _DelayLine:
    """Bytes held back until their due time."""

    queue: deque[tuple[int, bytes]] = field(default_factory=deque)

    def push(self, due_us: int, data: bytes) -> None:
        if data:
            self.queue.append((due_us, data))

    def pop_due(self, t_us: int) -> bytes:
        out = bytearray()
        while self.queue and self.queue[0][0] <= t_us:
            out += self.queue.popleft()[1]
        return bytes(out)


class FaultSet:
    """Applies a list of faults; one instance per run (it keeps the per-run state of stuck values).

    Every method is cheap when no fault of its kind is configured.
    """

    def __init__(self, faults: Iterable[Fault], rng: np.random.Generator) -> None:
        self.faults = tuple(faults)
        self.rng = rng
        self._kinds = {f.kind for f in self.faults}
        self._stuck: dict[int, MotorFeedback] = {}
        self._previous: dict[int, MotorFeedback] = {}
        self._frozen_frame: RcFrame | None = None
        self._link_delay = {"rx": _DelayLine(), "tx": _DelayLine()}
        self.injected: dict[str, int] = {}

    def _count(self, what: str, n: int = 1) -> None:
        self.injected[what] = self.injected.get(what, 0) + n

    def _active(self, kind: FaultKind, t_us: int, motor: int | None = None) -> Fault | None:
        if kind not in self._kinds:
            return None
        for f in self.faults:
            if f.kind is kind and f.active(t_us) and (motor is None or f.motor in (None, motor)):
                return f
        return None

    # --- radio -------------------------------------------------------------------------------------

    def rc_override(self, t_us: int, frame: RcFrame) -> RcFrame | bytes | None:
        """What a faulty radio sends instead of ``frame`` at a frame slot.

        Returns the frame to send (possibly altered), raw garbage bytes, or None for silence.
        """
        if self._active(FaultKind.RC_SILENCE, t_us):
            self._count("rc_silent_frames")
            return None
        if self._active(FaultKind.RC_GARBAGE, t_us):
            self._count("rc_garbage_bursts")
            # Framing noise: bursts of any length but 18. DBUS has no checksum, so an 18-byte burst of
            # plausible values *is* a frame to any receiver; that case is rc-out-of-range's, not ours.
            n = int(self.rng.integers(1, 39))
            n += n >= FRAME_LEN
            return self.rng.integers(0, 256, n, dtype=np.uint8).tobytes()
        if self._active(FaultKind.RC_FROZEN, t_us):
            if self._frozen_frame is None:
                self._frozen_frame = frame
            self._count("rc_frozen_frames")
            return self._frozen_frame
        self._frozen_frame = None
        if self._active(FaultKind.RC_OUT_OF_RANGE, t_us):
            self._count("rc_out_of_range_frames")
            ch = int(self.rng.integers(0, 4))
            channels = list(frame.channels)
            channels[ch] = int(self.rng.choice([-1, 1])) * int(self.rng.integers(661, CH_OFFSET))
            return RcFrame(
                (channels[0], channels[1], channels[2], channels[3]), frame.right_lever, frame.left_lever
            )
        return frame

    def rc_bytes(self, t_us: int, data: bytes) -> bytes:
        """DBUS bytes as the board's UART receives them (byte loss, bit flips)."""
        return self._corrupt(t_us, data, FaultKind.DBUS_BYTE_LOSS, FaultKind.DBUS_BIT_FLIP, "dbus")

    # --- motors and CAN ----------------------------------------------------------------------------

    def bus_off(self, t_us: int) -> bool:
        """True while the CAN bus carries nothing."""
        return self._active(FaultKind.CAN_BUS_OFF, t_us) is not None

    def feedback(self, t_us: int, motor: int, frame: MotorFeedback) -> MotorFeedback | None:
        """Motor ``motor``'s feedback frame as the board receives it (None: nothing arrives)."""
        if self.bus_off(t_us) or self._active(FaultKind.MOTOR_SILENCE, t_us, motor):
            self._count("feedback_suppressed")
            return None
        if self._active(FaultKind.MOTOR_STUCK, t_us, motor):
            stuck = self._stuck.setdefault(motor, frame)
            self._count("feedback_stuck")
            return stuck
        self._stuck.pop(motor, None)
        jitter = self._active(FaultKind.CAN_JITTER, t_us)
        if jitter is not None:
            previous = self._previous.get(motor)
            self._previous[motor] = frame
            if previous is not None and self.rng.random() < jitter.rate:
                self._count("feedback_late")
                return previous
        if self._active(FaultKind.MOTOR_WRONG, t_us, motor):
            self._count("feedback_wrong")
            return MotorFeedback(
                angle=int(self.rng.integers(0, ANGLE_COUNTS)),
                speed_rpm=int(self.rng.integers(-20000, 20000)),
                current=int(self.rng.integers(-10000, 10001)),
                temperature=frame.temperature,
            )
        return frame

    # --- board link --------------------------------------------------------------------------------

    def link_down(self, t_us: int) -> bool:
        """True while the board link is unplugged."""
        return self._active(FaultKind.LINK_DISCONNECT, t_us) is not None

    def link_bytes(self, t_us: int, data: bytes, direction: str) -> bytes:
        """Board-link bytes as the far end receives them at ``t_us``.

        Args:
            t_us: now.
            data: bytes just written by the near end (may be empty: delayed bytes still come out).
            direction: ``"rx"`` (host to board) or ``"tx"`` (board to host).
        """
        line = self._link_delay[direction]
        if self.link_down(t_us):
            # Unplugged: what was written and what was in flight is gone.
            lost = len(data) + sum(len(d) for _, d in line.queue)
            line.queue.clear()
            if lost:
                self._count("link_bytes_disconnected", lost)
            return b""
        data = self._corrupt(t_us, data, FaultKind.LINK_BYTE_LOSS, FaultKind.LINK_BIT_FLIP, "link")
        delay = self._active(FaultKind.LINK_DELAY, t_us)
        if delay is not None or line.queue:
            line.push(t_us + (delay.delay_us if delay else 0), data)
            return line.pop_due(t_us)
        return data

    # --- host and timing ---------------------------------------------------------------------------

    def heartbeat_blocked(self, t_us: int) -> bool:
        """True while the host's heartbeats are not sent."""
        return self._active(FaultKind.HOST_LOSS, t_us) is not None

    def tick_delay_us(self, t_us: int) -> int:
        """How late the firmware tick due at ``t_us`` starts."""
        f = self._active(FaultKind.LOOP_DELAY, t_us)
        if f is not None:
            return f.delay_us
        f = self._active(FaultKind.LOOP_JITTER, t_us)
        if f is not None:
            return int(self.rng.integers(0, f.delay_us + 1))
        return 0

    # --- helpers -----------------------------------------------------------------------------------

    def _corrupt(self, t_us: int, data: bytes, loss: FaultKind, flip: FaultKind, what: str) -> bytes:
        if not data:
            return data
        f_loss = self._active(loss, t_us)
        f_flip = self._active(flip, t_us)
        if f_loss is None and f_flip is None:
            return data
        arr = np.frombuffer(data, dtype=np.uint8).copy()
        if f_flip is not None:
            hit = self.rng.random(arr.size) < f_flip.rate
            if hit.any():
                bits = self.rng.integers(0, 8, int(hit.sum()))
                arr[hit] ^= (1 << bits).astype(np.uint8)
                self._count(f"{what}_bits_flipped", int(hit.sum()))
        if f_loss is not None:
            keep = self.rng.random(arr.size) >= f_loss.rate
            self._count(f"{what}_bytes_lost", int(arr.size - keep.sum()))
            arr = arr[keep]
        return arr.tobytes()
