"""DBUS: the 18-byte frames of a DJI DR16 receiver (DT7 radio), and an idle-gap framer.

Facts (DJI ``RoboMaster/Development-Board-C-Examples``, ``remote_control.c``; RoboRTS-Firmware):

- UART 100 000 baud, 8 data bits, even parity, 1 stop bit, signal inverted (the C-board inverts it in
  hardware). One byte on the wire is 11 bits = 110 µs; an 18-byte frame lasts 1.98 ms.
- Frames come every 14 ms (some receivers 7 ms). No sync byte, no checksum: a frame is exactly the 18
  bytes between two UART idle gaps.
- Bytes 0-5 are one 48-bit little-endian word: ch0 (right stick horizontal) bits 0-10, ch1 (right
  vertical) 11-21, ch2 (left horizontal) 22-32, ch3 (left vertical) 33-43, s[0] = right lever bits
  44-45, s[1] = left lever bits 46-47. Bytes 6-11 mouse x, y, z (int16 LE), 12 left button, 13 right
  button, 14-15 keyboard bitmask (u16 LE), 16-17 wheel (ch4; DJI reads it as int16 LE minus 1024).
- Channels are offset by 1024: raw 364..1684 = -660..+660. Levers: up 1, down 2, middle 3, 0 invalid.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass, field
from enum import IntEnum, IntFlag
from typing import ClassVar

from protocol.errors import DecodeError

__all__ = [
    "BYTE_TIME_US",
    "CH_LIMIT",
    "CH_OFFSET",
    "CH_RAW_MAX",
    "CH_RAW_MIN",
    "FRAME_LEN",
    "FRAME_PERIOD_US",
    "FRAME_TIME_US",
    "IDLE_GAP_US",
    "LEVER_INVALID",
    "WHEEL_OFFSET",
    "DbusFramer",
    "Key",
    "Lever",
    "RcFrame",
]

FRAME_LEN = 18
"""Bytes in one DBUS frame."""
CH_OFFSET = 1024
"""Raw channel value of a centred stick."""
CH_LIMIT = 660
"""Largest valid |channel| after removing the offset (raw 364..1684)."""
CH_RAW_MIN = CH_OFFSET - CH_LIMIT
CH_RAW_MAX = CH_OFFSET + CH_LIMIT
WHEEL_OFFSET = 1024
"""Subtracted from bytes 16-17 (read as int16 LE), as DJI's firmware does."""
LEVER_INVALID = 0
"""A lever value of 0 never comes from a working receiver; frames carrying it are invalid."""

BYTE_TIME_US = 110
"""One 8E1 byte at 100 kbaud: 11 bits x 10 µs."""
FRAME_TIME_US = FRAME_LEN * BYTE_TIME_US
"""1980 µs on the wire for one frame."""
FRAME_PERIOD_US = 14_000
"""DR16: a frame every 14 ms (some receivers every 7 ms)."""

IDLE_GAP_US = 2_500
"""Silence that ends a frame, measured between the arrival times of consecutive non-empty chunks.

Why 2.5 ms: inside a frame bytes are 110 µs apart, but a host reading a UART sees them in chunks whose
arrival times are quantised by its polling period (1 ms for the firmware's control task) plus scheduling
jitter (p99 < 0.1 ms, max about 0.3 ms under SCHED_FIFO), so chunks of one frame arrive at most about
1.3 ms apart. Between frames the line is silent for at least 7 - 1.98 = 5.02 ms (4 ms after polling
quantisation). 2.5 ms sits in the middle with more than 1 ms of margin on either side, and adds at most
2.5 ms (+ one poll period) of latency, well inside the 30 ms RC-lost budget.
"""

# Bit layout of the 48-bit word in bytes 0-5.
_CH_BITS = 11
_CH_MASK = (1 << _CH_BITS) - 1
_LEVER_MASK = 0x3
_RIGHT_LEVER_SHIFT = 44
_LEFT_LEVER_SHIFT = 46

_INT16_MIN = -(1 << 15)
_INT16_MAX = (1 << 15) - 1


class Lever(IntEnum):
    """Position of a DT7 three-position lever (switch) as DBUS encodes it."""

    UP = 1
    DOWN = 2
    MIDDLE = 3


class Key(IntFlag):
    """Keyboard bits of bytes 14-15, DJI order (W = bit 0 ... B = bit 15)."""

    W = 1 << 0
    S = 1 << 1
    A = 1 << 2
    D = 1 << 3
    SHIFT = 1 << 4
    CTRL = 1 << 5
    Q = 1 << 6
    E = 1 << 7
    R = 1 << 8
    F = 1 << 9
    G = 1 << 10
    Z = 1 << 11
    X = 1 << 12
    C = 1 << 13
    V = 1 << 14
    B = 1 << 15


def _check_range(name: str, value: int, lo: int, hi: int) -> None:
    if not isinstance(value, int):
        raise ValueError(f"{name} must be an int, got {type(value).__name__}")
    if not lo <= value <= hi:
        raise ValueError(f"{name} = {value} outside {lo}..{hi}")


@dataclass(frozen=True, slots=True)
class RcFrame:
    """One decoded DBUS frame.

    Every field holds exactly what the wire carries (channels and wheel with their offsets removed), so
    ``RcFrame.unpack(b).pack() == b`` for every 18 bytes ``b``, including invalid frames. Whether a frame
    may be acted on is :meth:`is_valid`.

    Attributes:
        channels: ch0 right horizontal, ch1 right vertical, ch2 left horizontal, ch3 left vertical;
            raw minus 1024, so -1024..1023 on the wire and -660..660 when valid. Positive = right / up.
        right_lever: s[0], ``Lever`` value 1 up / 3 middle / 2 down, or 0 (invalid).
        left_lever: s[1], same encoding.
        mouse_x: mouse x speed, int16.
        mouse_y: mouse y speed, int16.
        mouse_z: mouse wheel, int16.
        mouse_left: left button, 0..255 (1 = pressed).
        mouse_right: right button, 0..255 (1 = pressed).
        keys: keyboard bitmask (``Key``), 0..65535.
        wheel: the DT7 thumb wheel (ch4): bytes 16-17 as int16 LE minus 1024, so -33792..31743 on the
            wire, -660..660 from a receiver that sends it; an old receiver sends 0 there, giving -1024.
    """

    FORMAT: ClassVar[struct.Struct] = struct.Struct("<IHhhhBBHh")

    channels: tuple[int, int, int, int]
    right_lever: int
    left_lever: int
    mouse_x: int = 0
    mouse_y: int = 0
    mouse_z: int = 0
    mouse_left: int = 0
    mouse_right: int = 0
    keys: int = 0
    wheel: int = 0
    _wire: bytes | None = field(default=None, init=False, repr=False, compare=False)
    """The 18 bytes this frame was decoded from or last encoded to (``pack`` returns them again)."""

    @classmethod
    def unpack(cls, data: bytes | bytearray | memoryview) -> RcFrame:
        """Decode one 18-byte frame (never rejects a value: see :meth:`is_valid`).

        Raises:
            DecodeError: ``data`` is not exactly 18 bytes long.
        """
        if len(data) != FRAME_LEN:
            raise DecodeError(f"a DBUS frame is {FRAME_LEN} bytes, got {len(data)}")
        lo, hi, mx, my, mz, ml, mr, keys, wheel = cls.FORMAT.unpack(data)
        word = lo | (hi << 32)
        frame = cls(
            (
                (word & _CH_MASK) - CH_OFFSET,
                ((word >> 11) & _CH_MASK) - CH_OFFSET,
                ((word >> 22) & _CH_MASK) - CH_OFFSET,
                ((word >> 33) & _CH_MASK) - CH_OFFSET,
            ),
            (word >> _RIGHT_LEVER_SHIFT) & _LEVER_MASK,
            (word >> _LEFT_LEVER_SHIFT) & _LEVER_MASK,
            mx,
            my,
            mz,
            ml,
            mr,
            keys,
            wheel - WHEEL_OFFSET,
        )
        # unpack(b).pack() == b: keep b, so that re-sending a received frame (RawRc) costs nothing
        object.__setattr__(frame, "_wire", bytes(data))
        return frame

    def pack(self) -> bytes:
        """Encode to the 18 wire bytes (computed once per frame object, then returned again).

        Raises:
            ValueError: a field is outside what the wire can carry (see the attribute ranges).
        """
        if self._wire is not None:
            return self._wire
        if len(self.channels) != 4:
            raise ValueError(f"channels must hold 4 values, got {len(self.channels)}")
        word = 0
        for i, ch in enumerate(self.channels):
            _check_range(f"channels[{i}]", ch, -CH_OFFSET, _CH_MASK - CH_OFFSET)
            word |= (ch + CH_OFFSET) << (_CH_BITS * i)
        _check_range("right_lever", self.right_lever, 0, _LEVER_MASK)
        _check_range("left_lever", self.left_lever, 0, _LEVER_MASK)
        word |= int(self.right_lever) << _RIGHT_LEVER_SHIFT
        word |= int(self.left_lever) << _LEFT_LEVER_SHIFT
        _check_range("mouse_x", self.mouse_x, _INT16_MIN, _INT16_MAX)
        _check_range("mouse_y", self.mouse_y, _INT16_MIN, _INT16_MAX)
        _check_range("mouse_z", self.mouse_z, _INT16_MIN, _INT16_MAX)
        _check_range("mouse_left", self.mouse_left, 0, 0xFF)
        _check_range("mouse_right", self.mouse_right, 0, 0xFF)
        _check_range("keys", int(self.keys), 0, 0xFFFF)
        _check_range("wheel", self.wheel, _INT16_MIN - WHEEL_OFFSET, _INT16_MAX - WHEEL_OFFSET)
        wire = self.FORMAT.pack(
            word & 0xFFFF_FFFF,
            word >> 32,
            self.mouse_x,
            self.mouse_y,
            self.mouse_z,
            self.mouse_left,
            self.mouse_right,
            int(self.keys),
            self.wheel + WHEEL_OFFSET,
        )
        object.__setattr__(self, "_wire", wire)  # a frozen frame always packs to the same bytes
        return wire

    def is_valid(self) -> bool:
        """True when the frame may be acted on: every |channel| <= 660 and neither lever is 0.

        This is RoboRTS's rule (DJI's ``RC_data_is_error`` allows up to 700); the wheel and the
        mouse/keyboard bytes are not checked, as in DJI's firmware.
        """
        c0, c1, c2, c3 = self.channels
        return (
            -CH_LIMIT <= c0 <= CH_LIMIT
            and -CH_LIMIT <= c1 <= CH_LIMIT
            and -CH_LIMIT <= c2 <= CH_LIMIT
            and -CH_LIMIT <= c3 <= CH_LIMIT
            and self.right_lever != LEVER_INVALID
            and self.left_lever != LEVER_INVALID
        )

    @classmethod
    def neutral(cls, right_lever: int = Lever.DOWN, left_lever: int = Lever.DOWN) -> RcFrame:
        """A valid frame with centred sticks and wheel, no mouse or keys, and the given levers.

        Both levers default to DOWN: the safe position (right lever DOWN = SAFE mode).
        """
        return cls((0, 0, 0, 0), int(right_lever), int(left_lever))


class DbusFramer:
    """Splits a raw DBUS UART byte stream into frames on idle gaps (DJI's rule).

    Feed it every chunk read from the UART together with the time it arrived; all bytes of a chunk are
    taken to have arrived at that time. A gap is ``now_us - last_chunk_us >= idle_gap_us`` between
    non-empty chunks (or between the last chunk and a later call). A burst of bytes between two gaps is a
    frame if and only if it is exactly 18 bytes long; any other burst is dropped and counted.

    Delivery rule: a burst is closed, and returned if it is a frame, by the first call to :meth:`feed`
    (or :meth:`flush`, the same as ``feed(b"", now_us)``) whose ``now_us`` is at least ``idle_gap_us``
    after the burst's last chunk. Poll it every control tick, with an empty chunk when nothing was read,
    and a frame is returned at most ``idle_gap_us`` + one tick after its last byte. The start of the
    stream counts as a gap.

    A chunk cannot reveal a gap inside itself: a reader that stalls past a whole frame period reads two
    frames in one chunk (36 bytes) and both are dropped, exactly as DJI's DMA handler drops them.

    Counters (monotonic): ``frames_ok``, ``frames_dropped`` (bursts that were not 18 bytes),
    ``bytes_dropped`` (the bytes of those bursts).
    """

    def __init__(self, idle_gap_us: int = IDLE_GAP_US) -> None:
        """Create a framer.

        Args:
            idle_gap_us: silence that ends a burst, in µs (default :data:`IDLE_GAP_US`).

        Raises:
            ValueError: ``idle_gap_us`` is not positive.
        """
        if idle_gap_us <= 0:
            raise ValueError(f"idle_gap_us must be > 0, got {idle_gap_us}")
        self.idle_gap_us = idle_gap_us
        self.frames_ok = 0
        self.frames_dropped = 0
        self.bytes_dropped = 0
        self._buf = bytearray()
        self._burst_len = 0  # may exceed len(_buf): bytes past 18 are counted, not stored
        self._last_us: int | None = None

    @property
    def pending(self) -> int:
        """Bytes of the burst still open (not yet closed by a gap)."""
        return self._burst_len

    def feed(self, data: bytes | bytearray | memoryview, now_us: int) -> list[RcFrame]:
        """Add one chunk of UART bytes that arrived at ``now_us``; return the frames it completes.

        Args:
            data: the bytes read (may be empty: then the call only checks for a gap).
            now_us: arrival time of the chunk in integer µs (monotonic; a clock that steps backwards
                is treated as "no gap").

        Returns:
            The frame closed by a gap before ``now_us``, if it was exactly 18 bytes (zero or one frame).
        """
        out: list[RcFrame] = []
        if self._burst_len and self._last_us is not None and now_us - self._last_us >= self.idle_gap_us:
            self._close(out)
        n = len(data)
        if n:
            room = FRAME_LEN + 1 - len(self._buf)  # keep one byte past 18 to know it overflowed
            if room > 0:
                self._buf += data[:room]
            self._burst_len += n
            self._last_us = now_us
        return out

    def flush(self, now_us: int) -> list[RcFrame]:
        """Close the open burst if the gap after it has elapsed by ``now_us``: ``feed(b"", now_us)``."""
        return self.feed(b"", now_us)

    def reset(self) -> None:
        """Forget the open burst without counting it (e.g. after reopening the port)."""
        self._buf.clear()
        self._burst_len = 0
        self._last_us = None

    def _close(self, out: list[RcFrame]) -> None:
        if self._burst_len == FRAME_LEN:
            out.append(RcFrame.unpack(self._buf))
            self.frames_ok += 1
        else:
            self.frames_dropped += 1
            self.bytes_dropped += self._burst_len
        self._buf.clear()
        self._burst_len = 0
