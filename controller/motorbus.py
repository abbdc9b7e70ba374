"""The motor bus: one interface, many back ends (python-can's ``BusABC`` pattern).

Public methods do the bookkeeping — clamping, packing the C610 frame, decoding feedback, counting
errors — over two tiny private hooks that a back end implements:

- ``_send_frame(can_id, data)``: put one standard CAN frame on the wire (raise ``BusError`` or
  ``OSError`` on failure; the caller counts it).
- ``_recv_frames() -> list[(can_id, data)]``: every frame received since the last call, never blocking.

Back ends: :class:`CanMotorBus` (any python-can bus: ``socketcan`` (``can0``), ``gs_usb`` (candleLight),
``slcan`` over a serial port such as /dev/ttyACM0, ``virtual``; python-can's ``interface`` name picks the
driver; 1 Mbit/s, receive filters for the feedback ids, an optional ``can.Logger`` of every frame) and
:class:`FakeMotorBus` (an in-process fake C610 set, no threads). The simulated back end lives in ``hil``
(``hil.canbus.SimMotorBus``), which builds it around its plant.

Facts: C610 command id 0x200 carries motors 1-4 as big-endian int16, -10000..10000 = -10..10 A, and id
0x1FF motors 5-8 in the same layout; motor n answers on 0x200 + n at about 1 kHz (DJI ``CAN_receive.c``).
CAN bus at 1 Mbit/s. A bus of up to four motors sends one 0x200 frame per tick (a three-motor arm's
frames are those it has always sent), of five to eight a 0x200 and then a 0x1FF frame.
"""

from __future__ import annotations

import functools
import os
import time
from abc import ABC, abstractmethod
from collections.abc import Sequence
from types import TracebackType
from typing import TYPE_CHECKING, Any, ClassVar

from controller.config import CONTROL_PERIOD_US
from controller.errors import BusError, PortError
from protocol.c610 import (
    COMMAND_ID_HIGH,
    COMMAND_ID_LOW,
    CURRENT_RAW_MAX,
    FEEDBACK_ID_BASE,
    MOTORS_MAX,
    MOTORS_PER_COMMAND,
    MotorFeedback,
    command_frames,
    pack_currents,
)
from protocol.errors import DecodeError

if TYPE_CHECKING:
    from controller.fake_c610 import FakeC610Set

__all__ = [
    "CanMotorBus",
    "FakeMotorBus",
    "MotorBus",
    "feedback_filters",
]

CAN_BITRATE = 1_000_000
"""C610s talk at 1 Mbit/s."""
_RECV_BURST_MAX = 64
"""Most frames drained per ``read_feedback`` call (a flooded bus cannot stall the control tick)."""


class MotorBus(ABC):
    """C610/M2006 motors 1..n (n = 1..8; three by default): commands on 0x200 (motors 1-4) and, above
    four motors, 0x1FF (motors 5-8); feedback on 0x201..0x200+n.

    Attributes:
        motor_count: motors on this bus (1..8).
        can_errors: failed sends/receives and undecodable feedback frames.
        frames_sent: command frames sent (two per :meth:`send_currents` above four motors).
        frames_ignored: received frames that are not feedback from our motors.
        last_send_ok: every command frame of the last :meth:`send_currents` went out.
        simulated: True for back ends driving a simulated plant (reported in telemetry).
    """

    simulated: ClassVar[bool] = False

    def __init__(self, *, current_limit_raw: int = CURRENT_RAW_MAX, motor_count: int = 3) -> None:
        """Set the bookkeeping up.

        Args:
            current_limit_raw: |current| never sent above this (raw, 1000 per amp; at most 10000).
            motor_count: motors 1..n (1..8): 1-4 on command id 0x200, 5-8 on 0x1FF.

        Raises:
            ValueError: a bad limit or motor count.
        """
        if not 1 <= motor_count <= MOTORS_MAX:
            raise ValueError(f"motor_count must be 1..{MOTORS_MAX}, got {motor_count}")
        self.motor_count = motor_count
        self.current_limit_raw = current_limit_raw
        self.can_errors = 0
        self.frames_sent = 0
        self.frames_ignored = 0
        self.last_send_ok = False
        self._sent = [0] * motor_count
        self._two_frames = motor_count > MOTORS_PER_COMMAND
        # the empty slots of the last frame (0x200 up to four motors, 0x1FF above), sent as 0
        self._unused_slots = (0,) * (-motor_count % MOTORS_PER_COMMAND)
        self._is_shutdown = False

    @property
    def current_limit_raw(self) -> int:
        """|current| limit applied by :meth:`send_currents` (raw units)."""
        return self._limit_raw

    @current_limit_raw.setter
    def current_limit_raw(self, value: int) -> None:
        if not 0 <= value <= CURRENT_RAW_MAX:
            raise ValueError(f"current_limit_raw must be 0..{CURRENT_RAW_MAX}, got {value}")
        self._limit_raw = int(value)

    @property
    def is_shutdown(self) -> bool:
        """:meth:`shutdown` has been called."""
        return self._is_shutdown

    def send_currents(self, currents_raw: Sequence[int]) -> tuple[int, ...]:
        """Clamp and send the current command frames for motors 1..n: 0x200, then 0x1FF above four.

        Args:
            currents_raw: one raw setpoint per motor (1000 per amp); floats are rounded.

        Returns:
            The setpoints put in the frames after clamping to ±``current_limit_raw``. If the back end
            failed to send a frame, the error is counted and ``last_send_ok`` is False (the other frame
            is still sent).

        Raises:
            ValueError: wrong number of setpoints.
            BusError: the bus has been shut down.
        """
        if self._is_shutdown:
            raise BusError("send_currents on a bus that has been shut down")
        n = self.motor_count
        if len(currents_raw) != n:
            raise ValueError(f"expected {n} currents, got {len(currents_raw)}")
        lim = self._limit_raw
        out = self._sent
        for i in range(n):
            v = currents_raw[i]
            if type(v) is not int:
                v = round(v)
            out[i] = lim if v > lim else -lim if v < -lim else v
        # The clamp above leaves ints within ±10000, so the frames are packed by the unchecked packer, without
        # current_command's per-value validation (command_frames' bytes; this runs every control tick).
        if self._two_frames:
            data = pack_currents(out[0], out[1], out[2], out[3])
        else:
            data = pack_currents(*out, *self._unused_slots)
        try:
            self._send_frame(COMMAND_ID_LOW, data)
        except (BusError, OSError):
            self.can_errors += 1
            self.last_send_ok = False
        else:
            self.frames_sent += 1
            self.last_send_ok = True
        if self._two_frames:
            data = pack_currents(*out[MOTORS_PER_COMMAND:], *self._unused_slots)
            try:
                self._send_frame(COMMAND_ID_HIGH, data)
            except (BusError, OSError):
                self.can_errors += 1
                self.last_send_ok = False
            else:
                self.frames_sent += 1
        return tuple(out)

    def read_feedback(self) -> list[tuple[int, MotorFeedback]]:
        """Drain the feedback received since the last call: ``(motor 1..n, MotorFeedback)`` in order.

        Never raises for bad frames: undecodable ones count as ``can_errors``, foreign ids as
        ``frames_ignored``.
        """
        if self._is_shutdown:
            return []
        try:
            frames = self._recv_frames()
        except (BusError, OSError):
            self.can_errors += 1
            return []
        out: list[tuple[int, MotorFeedback]] = []
        if not frames:
            return out
        n = self.motor_count
        for can_id, data in frames:
            motor = can_id - FEEDBACK_ID_BASE
            if 1 <= motor <= n:
                try:
                    out.append((motor, MotorFeedback.unpack(data)))
                except DecodeError:
                    self.can_errors += 1
            else:
                self.frames_ignored += 1
        return out

    def shutdown(self) -> None:
        """Send zero current once on every command frame (if the bus still works) and release the back
        end. Safe twice."""
        if self._is_shutdown:
            return
        try:
            for can_id, data in command_frames([0] * self.motor_count):
                try:
                    self._send_frame(can_id, data)
                except (BusError, OSError):
                    self.can_errors += 1
        finally:
            self._is_shutdown = True
            self._shutdown_backend()

    def __enter__(self) -> MotorBus:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.shutdown()

    @abstractmethod
    def _send_frame(self, can_id: int, data: bytes) -> None:
        """Back end: send one standard CAN frame (raise ``BusError`` / ``OSError`` on failure)."""

    @abstractmethod
    def _recv_frames(self) -> list[tuple[int, bytes]]:
        """Back end: every ``(can_id, data)`` received since the last call, without blocking."""

    def _shutdown_backend(self) -> None:  # noqa: B027 - optional hook
        """Back end: release resources (called once)."""


def feedback_filters(motor_count: int = 3) -> list[dict[str, int | bool]]:
    """python-can ``can_filters`` that pass only the feedback of motors 1..``motor_count`` (0x201-0x20n).

    Interfaces that filter in the kernel or the adapter (SocketCAN, PCAN, Kvaser, ...) then never wake
    the control loop for other traffic; the others (slcan, gs_usb, virtual) filter inside python-can,
    before :meth:`MotorBus.read_feedback` sees a frame.
    """
    return [
        {"can_id": FEEDBACK_ID_BASE + motor, "can_mask": 0x7FF, "extended": False}
        for motor in range(1, motor_count + 1)
    ]


@functools.cache  # one class, made on first use (python-can's slcan only when slcan is asked for)
def _slcan_bus_class() -> type[Any]:
    """python-can's slcan bus, reading what the adapter has sent in one call instead of byte by byte.

    python-can 4.6's ``slcanBus._read`` reads one byte per ``read(1)`` call (a ``select`` each) and, with
    nothing waiting, blocks for the port's time-out (1 ms) even when ``recv(timeout=0)`` was asked. A
    1 kHz loop that drains three feedback frames per tick then spends 1-3 ms per tick reading and falls
    behind (measured over a pty: 1296 of 2000 ticks in 2 s; ``bench/slcan.py``). Its ``_write`` also
    drains the port (``tcdrain``) after every frame, which waits for the adapter to take the bytes: over
    USB, up to a bus frame (1 ms) per command. This bus takes every byte waiting in one read, returns at
    once when none is and ``timeout`` is 0 (otherwise it waits as python-can does), and writes without
    waiting: what the kernel does not take now is kept, in order, for the next frame (pyserial's own
    timed write selects after every write and raised "Write timeout" on frames already written). Same
    lines, same terminators (``\\r`` ok, ``\\a`` error), same errors.
    """
    import serial
    from can.exceptions import CanOperationError, error_check
    from can.interfaces.slcan import slcanBus

    class BulkSlcanBus(slcanBus):  # type: ignore[misc]
        _tx: bytearray | None = None

        def _write(self, string: str) -> None:
            data = string.encode() + self.LINE_TERMINATOR
            port = self.serialPortOrig
            fd = getattr(port, "fd", None)
            if not isinstance(fd, int):  # a URL port (socket://...): python-can's write, less the drain
                with error_check("Could not write to serial device"):
                    port.write(data)
                return
            # The port's descriptor is non-blocking (pyserial opens it so): write what the kernel takes
            # now and keep the rest, in order, for the next frame; never wait, never select.
            if self._tx is None:
                self._tx = bytearray()
            tx = self._tx
            tx += data
            try:
                n = os.write(fd, tx)
            except BlockingIOError:
                n = 0
            except OSError as exc:
                raise CanOperationError("Could not write to serial device") from exc
            del tx[:n]
            if len(tx) > _SLCAN_TX_PENDING_MAX:
                tx.clear()
                raise CanOperationError(
                    f"the adapter took no bytes for {_SLCAN_TX_PENDING_MAX} bytes: dropped"
                )

        def _read(self, timeout: float | None) -> str | None:
            port = self.serialPortOrig
            buf: bytearray = self._buffer
            expiry = serial.Timeout(timeout)
            with error_check("Could not read from serial device"):
                while True:
                    ends = [i for i in (buf.find(self._OK), buf.find(self._ERROR)) if i >= 0]
                    if ends:
                        end = min(ends) + 1
                        line = buf[:end].decode()
                        del buf[:end]
                        return line
                    waiting = port.in_waiting
                    if waiting:
                        buf.extend(port.read(waiting))
                        continue
                    if expiry.expired():
                        return None
                    buf.extend(port.read(1))  # waits up to the port's time-out for the next byte

    return BulkSlcanBus


_SLCAN_TX_PENDING_MAX = 4096
"""Bytes of slcan commands an adapter may leave untaken (about 180 command frames) before it is an error."""


class CanMotorBus(MotorBus):
    """The motors on any python-can bus (``socketcan``, ``gs_usb``, ``slcan``, ``pcan``, ``virtual``, ...).

    Attributes:
        bus: the python-can bus.
        feedback_timestamps_s: python-can's receive timestamp (the driver's or the adapter's, in
            seconds) of the latest feedback frame of each motor, 0.0 before the first.
        log_file: where every frame sent and received is logged (None: not logged).
        log_errors: frames the log file failed to take (a full disk); the bus keeps going.
    """

    def __init__(
        self,
        channel: str | None = None,
        interface: str | None = None,
        *,
        bus: Any = None,
        bitrate: int = CAN_BITRATE,
        log_file: str | os.PathLike[str] | None = None,
        send_timeout_s: float = 0.001,
        current_limit_raw: int = CURRENT_RAW_MAX,
        motor_count: int = 3,
        **kwargs: Any,
    ) -> None:
        """Open a python-can bus, or wrap one (``bus=``, then owned: shut down with this object).

        An opened bus gets ``bitrate`` (whatever the interface: python-can's own default is 500 kbit/s,
        at which a C610 is never heard) and the :func:`feedback_filters` as its ``can_filters``.

        Args:
            channel: python-can channel (``can0``, ``/dev/ttyACM0`` for slcan, any name for virtual).
            interface: python-can interface name (``socketcan``, ``gs_usb``, ``slcan``, ``virtual``, ...).
            bus: an open ``can.BusABC`` to use instead of opening one (its filters are left as they are).
            bitrate: CAN bitrate in bit/s (SocketCAN ignores it: the kernel's ``ip link`` sets it).
            log_file: log every frame, with its timestamp, through python-can's ``can.Logger``: the
                suffix picks the format (``.log`` candump, ``.blf`` Vector BLF, ``.asc``, ``.csv``).
            send_timeout_s: longest a send may wait for room in the adapter's queue.
            current_limit_raw: see :class:`MotorBus`.
            motor_count: see :class:`MotorBus` (the feedback filters pass 0x201..0x200+n).
            **kwargs: passed to ``can.Bus`` (e.g. ``sleep_after_open=0`` for slcan on a pty).

        Raises:
            PortError: the channel cannot be opened, or the log file cannot be written.
        """
        super().__init__(current_limit_raw=current_limit_raw, motor_count=motor_count)
        import can

        self._can = can
        if bus is None:
            if channel is None or interface is None:
                raise ValueError("give channel and interface, or bus")
            kwargs.setdefault("bitrate", bitrate)
            kwargs.setdefault("can_filters", feedback_filters(self.motor_count))
            try:
                if interface == "slcan":
                    bus = _slcan_bus_class()(channel=channel, **kwargs)
                else:
                    bus = can.Bus(channel=channel, interface=interface, **kwargs)
            except (can.CanError, OSError, ValueError, ImportError) as exc:
                raise PortError(f"cannot open CAN {interface} channel {channel}: {exc}") from exc
        self.bus = bus
        self.send_timeout_s = send_timeout_s
        self.feedback_timestamps_s = [0.0] * self.motor_count
        self.log_file = log_file
        self.log_errors = 0
        self._logger: Any = None
        if log_file is not None:
            try:
                self._logger = can.Logger(log_file)
            except (OSError, ValueError, ImportError) as exc:
                bus.shutdown()
                raise PortError(f"cannot log CAN frames to {log_file}: {exc}") from exc
        # One command message, refilled every tick (the drivers copy or serialize it in send()).
        self._command = can.Message(
            arbitration_id=COMMAND_ID_LOW,
            data=bytes(8),
            is_extended_id=False,
            is_rx=False,
            channel=channel,
        )

    def _send_frame(self, can_id: int, data: bytes) -> None:
        can = self._can
        msg = self._command
        msg.arbitration_id = can_id
        msg.data[:] = data
        msg.dlc = len(data)
        msg.timestamp = time.time()
        try:
            self.bus.send(msg, timeout=self.send_timeout_s)
        except can.CanError as exc:
            raise BusError(str(exc)) from exc
        if self._logger is not None:
            self._log(msg)

    def _log(self, msg: Any) -> None:
        """Hand ``msg`` to the logger; a failing log file is counted, never taken for a bus failure."""
        try:
            self._logger.on_message_received(msg)
        except (OSError, ValueError):
            self.log_errors += 1

    def _recv_frames(self) -> list[tuple[int, bytes]]:
        can = self._can
        out: list[tuple[int, bytes]] = []
        recv = self.bus.recv
        logger = self._logger is not None
        stamps = self.feedback_timestamps_s
        n = self.motor_count
        for _ in range(_RECV_BURST_MAX):
            try:
                msg = recv(timeout=0)
            except can.CanError as exc:
                raise BusError(str(exc)) from exc
            if msg is None:
                break
            if logger:
                self._log(msg)
            if msg.is_error_frame:
                self.can_errors += 1
            elif msg.is_extended_id or msg.is_remote_frame:
                self.frames_ignored += 1
            else:
                can_id = msg.arbitration_id
                motor = can_id - FEEDBACK_ID_BASE
                if 1 <= motor <= n:
                    stamps[motor - 1] = msg.timestamp
                out.append((can_id, bytes(msg.data)))
        return out

    def _shutdown_backend(self) -> None:
        try:
            self.bus.shutdown()
        except (self._can.CanError, OSError):
            self.can_errors += 1
        if self._logger is not None:
            try:
                self._logger.stop()
            except OSError:
                self.can_errors += 1


class FakeMotorBus(MotorBus):
    """An in-process fake C610 set, stepped synchronously: each tick's commands advance it by ``dt_us``.

    The set steps on the tick's last command frame (0x200, or 0x1FF above four motors), so every motor
    runs this tick's current. Feedback produced by a command is returned by the next :meth:`read_feedback`
    — the order of a real bus, where the answers arrive after the command. Faults:
    ``bus.c610s.silent.add(2)`` stops motor 2.
    """

    def __init__(
        self,
        c610s: FakeC610Set | None = None,
        *,
        dt_us: int = CONTROL_PERIOD_US,
        current_limit_raw: int = CURRENT_RAW_MAX,
    ) -> None:
        """Create the bus around ``c610s`` (default: a fresh ``FakeC610Set()``, three motors); the bus has
        as many motors as the set."""
        if c610s is None:
            from controller.fake_c610 import FakeC610Set

            c610s = FakeC610Set()
        super().__init__(current_limit_raw=current_limit_raw, motor_count=len(c610s.motors))
        self.c610s = c610s
        self.dt_us = dt_us
        self._step_id = COMMAND_ID_HIGH if self.motor_count > MOTORS_PER_COMMAND else COMMAND_ID_LOW
        self._pending: list[tuple[int, bytes]] = []

    def _send_frame(self, can_id: int, data: bytes) -> None:
        self.c610s.handle_frame(can_id, data)
        if can_id == self._step_id:
            self._pending.extend(self.c610s.step(self.dt_us))

    def _recv_frames(self) -> list[tuple[int, bytes]]:
        if not self._pending:
            return []
        out = self._pending
        self._pending = []
        return out
