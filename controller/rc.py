"""RC input sources: the DR16's DBUS UART, the board link's virtual RC frames, or a script.

Every source returns decoded :class:`~protocol.dbus.RcFrame` objects *as received*, valid or not: the
control task's :class:`RcInput` decides (``RcFrame.is_valid``), rejects and counts. ``poll(now_us)`` is
called on every control tick and never blocks.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable, Iterable
from types import TracebackType
from typing import Protocol

from controller.errors import PortError
from protocol.dbus import FRAME_PERIOD_US, IDLE_GAP_US, DbusFramer, RcFrame

__all__ = ["DbusSerialSource", "LinkRcSource", "RcInput", "RcSource", "ScriptedRcSource", "Uart"]

DBUS_BAUDRATE = 100_000
"""DR16 DBUS: 100 000 baud, 8 data bits, even parity, 1 stop bit (inverted in hardware on the C-board)."""


class Uart(Protocol):
    """A UART's receive side as :class:`DbusSerialSource` reads it (the part of pyserial's ``Serial`` used).

    A pyserial port satisfies it as it is; other implementations (an in-memory UART for a simulated
    board) subclass it to say so.
    """

    @property
    def in_waiting(self) -> int:
        """Bytes received and not read yet."""
        ...

    def read(self, n: int, /) -> bytes:
        """Take up to ``n`` received bytes.

        Raises:
            OSError: the port failed (pyserial's ``SerialException`` is one).
        """
        ...

    def close(self) -> None:
        """Release the port."""
        ...


RAW_RC_QUEUE = 16
"""DBUS frames held for ``RawRc`` between telemetry ticks (14 ms apart: 1 normally)."""


class RcInput:
    """The control task's RC intake: valid frames accepted, invalid ones counted and never acted on.

    Args:
        on_valid: told ``(now_us, right_lever)`` of every valid frame (the failsafe's RC event).
        keep_raw: keep every frame, valid or not, for ``RawRc`` (with a host link).

    Attributes:
        frame: the last valid frame (None before the first).
        frames_ok: valid frames accepted.
        rejected: invalid frames rejected.
        raw: ``(now_us, frame)`` of frames received since the telemetry task last sent them (at most
            :data:`RAW_RC_QUEUE`, oldest dropped).
    """

    def __init__(self, on_valid: Callable[[int, int], None], *, keep_raw: bool) -> None:
        """Nothing received yet."""
        self._on_valid = on_valid
        self._keep_raw = keep_raw
        self.frame: RcFrame | None = None
        self.frames_ok = 0
        self.rejected = 0
        self.raw: list[tuple[int, RcFrame]] = []

    def take(self, now_us: int, frames: list[RcFrame]) -> None:
        """Accept or reject the frames a source returned at ``now_us``."""
        keep_raw = self._keep_raw
        for f in frames:
            if keep_raw:
                q = self.raw
                if len(q) >= RAW_RC_QUEUE:
                    del q[0]
                q.append((now_us, f))
            if f.is_valid():
                self.frames_ok += 1
                self.frame = f
                self._on_valid(now_us, f.right_lever)
            else:
                self.rejected += 1


class RcSource(ABC):
    """Where RC frames come from."""

    @abstractmethod
    def poll(self, now_us: int) -> list[RcFrame]:
        """Frames completed since the last call (usually none, at most a few); never blocks."""

    @property
    def bytes_dropped(self) -> int:
        """Raw bytes discarded by this source's framer (0 for sources without one)."""
        return 0

    def discard_pending(self) -> int:
        """Drop what arrived before the loop started (bytes dropped; 0 for sources without a port).

        A UART buffers the receiver's frames from the moment it is opened; the loop starts later (the
        other ports open, a CAN adapter settles), and its first read would take that backlog as one
        burst: frames seconds old, counted as a burst that was not 18 bytes."""
        return 0

    def close(self) -> None:  # noqa: B027 - optional hook
        """Release the source's port, if any (safe twice)."""

    def __enter__(self) -> RcSource:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()


class DbusSerialSource(RcSource):
    """A DR16 receiver on a UART (USB-serial adapter with an inverter), framed on idle gaps.

    Bytes are read without blocking on every poll and fed to a :class:`~protocol.dbus.DbusFramer` with
    the poll time as their arrival time; the framer closes a frame after ``idle_gap_us`` of silence.
    """

    def __init__(self, port: str | Uart, *, idle_gap_us: int = IDLE_GAP_US) -> None:
        """Open ``port`` (path or pyserial URL) at 100000 8E1, or read from an open :class:`Uart`.

        Raises:
            PortError: the port cannot be opened.
        """
        self._serial: Uart
        if isinstance(port, str):
            import serial

            try:
                self._serial = serial.serial_for_url(
                    port,
                    baudrate=DBUS_BAUDRATE,
                    bytesize=serial.EIGHTBITS,
                    parity=serial.PARITY_EVEN,
                    stopbits=serial.STOPBITS_ONE,
                    timeout=0,
                    exclusive=True,  # a second reader would steal bytes: busy is an error
                )
            except (serial.SerialException, OSError, ValueError) as exc:
                raise PortError(f"cannot open RC port {port}: {exc}") from exc
        else:
            # No timeout to set: poll reads only what in_waiting reports, so a read never waits.
            self._serial = port
        self.framer = DbusFramer(idle_gap_us)
        self.read_errors = 0
        self._closed = False

    @property
    def bytes_dropped(self) -> int:
        """Bytes of bursts that were not 18 bytes long."""
        return self.framer.bytes_dropped

    def discard_pending(self) -> int:
        """Read and drop what the UART holds, unframed (see :meth:`RcSource.discard_pending`)."""
        dropped = 0
        if not self._closed:
            try:
                for _ in range(64):  # bounded: a receiver sends 1.3 KB/s, a UART buffers a few KB
                    n = self._serial.in_waiting
                    if not n:
                        break
                    dropped += len(self._serial.read(n))
            except OSError:  # serial.SerialException is an OSError (unplugged adapter)
                self.read_errors += 1
        return dropped

    def poll(self, now_us: int) -> list[RcFrame]:
        """Read what the UART holds and return the frames the idle gap has closed."""
        data = b""
        if not self._closed:
            try:
                n = self._serial.in_waiting
                if n:
                    data = self._serial.read(n)
            except OSError:  # serial.SerialException is an OSError (unplugged adapter)
                self.read_errors += 1
        return self.framer.feed(data, now_us)

    def close(self) -> None:
        """Close the port (safe twice)."""
        if not self._closed:
            self._closed = True
            self._serial.close()


class LinkRcSource(RcSource):
    """RC frames that the host sends as ``VirtualRc`` over the board link (the browser's sticks).

    The link task pushes the 18 DBUS bytes; they are decoded by the same ``RcFrame.unpack`` as the
    radio's frames and judged by the same validity rule. The link has already delimited the frame, so no
    idle-gap framing (and none of its 2.5 ms latency) is needed.
    """

    def __init__(self, capacity: int = 8) -> None:
        """Create an empty source that holds at most ``capacity`` unpolled frames (oldest dropped)."""
        self._frames: list[RcFrame] = []
        self._capacity = capacity
        self.frames_dropped = 0

    def push(self, data: bytes, now_us: int) -> None:
        """Queue the 18 bytes of one DBUS frame received at ``now_us`` (wrong length: dropped, counted)."""
        if len(data) != 18:
            self.frames_dropped += 1
            return
        if len(self._frames) >= self._capacity:
            del self._frames[0]
            self.frames_dropped += 1
        self._frames.append(RcFrame.unpack(data))

    def poll(self, now_us: int) -> list[RcFrame]:
        """Frames pushed since the last poll."""
        if not self._frames:
            return []
        out = self._frames
        self._frames = []
        return out


class ScriptedRcSource(RcSource):
    """Frames from a script, at the DR16's 14 ms cadence (tests, scenarios, examples).

    The current frame (:meth:`set_frame`) repeats every ``period_us``; ``None`` is silence (the radio
    switched off). :meth:`schedule` changes the frame at given times; :meth:`inject` sends one extra
    frame on the next poll (e.g. an invalid one).
    """

    def __init__(
        self,
        frame: RcFrame | None = None,
        *,
        period_us: int = FRAME_PERIOD_US,
        schedule: Iterable[tuple[int, RcFrame | None]] = (),
    ) -> None:
        """Start with ``frame`` (None = silent) and an optional ``(time_us, frame)`` schedule.

        Raises:
            ValueError: ``period_us`` <= 0.
        """
        if period_us <= 0:
            raise ValueError(f"period_us must be > 0, got {period_us}")
        self.period_us = period_us
        self._frame = frame
        self._next_us: int | None = None
        self._schedule = sorted(schedule, key=lambda item: item[0])
        self._extra: list[RcFrame] = []
        self.frames_sent = 0

    @property
    def frame(self) -> RcFrame | None:
        """The frame now repeating (None = silent)."""
        return self._frame

    def set_frame(self, frame: RcFrame | None) -> None:
        """Repeat ``frame`` from the next poll on (None = silence)."""
        self._frame = frame

    def schedule(self, time_us: int, frame: RcFrame | None) -> None:
        """Switch to ``frame`` at ``time_us``."""
        self._schedule.append((time_us, frame))
        self._schedule.sort(key=lambda item: item[0])

    def inject(self, frame: RcFrame) -> None:
        """Deliver ``frame`` once on the next poll, in addition to the repeating one."""
        self._extra.append(frame)

    def poll(self, now_us: int) -> list[RcFrame]:
        """The scripted frames due at ``now_us``."""
        while self._schedule and self._schedule[0][0] <= now_us:
            self._frame = self._schedule.pop(0)[1]
        out: list[RcFrame] = []
        if self._extra:
            out, self._extra = self._extra, []
        if self._frame is not None:
            nxt = self._next_us
            if nxt is None or now_us >= nxt:
                out.append(self._frame)
                self._next_us = (
                    now_us + self.period_us if nxt is None else _next_grid(nxt, now_us, self.period_us)
                )
        else:
            self._next_us = None
        self.frames_sent += len(out)
        return out


def _next_grid(last_us: int, now_us: int, period_us: int) -> int:
    """Next point of the ``last_us + k * period_us`` grid after ``now_us``."""
    return last_us + ((now_us - last_us) // period_us + 1) * period_us
