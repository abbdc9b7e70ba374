"""A fake C610/M2006 trio for tests and examples (no hardware, no MuJoCo).

Each fake motor winds a cable against a linear spring (a stand-in for the arm): the C610's current loop
is taken as ideal (measured current = command), the output shaft integrates
``J dω/dt = K_t I - r T_cable - b ω`` with ``T_cable = k · max(0, paid-in length)``. Feedback frames
carry the wrapped rotor angle (8192 counts per rotor turn, 36 rotor turns per output turn), the rotor
speed in rpm and the current, byte for byte as ``protocol.c610`` defines them.

Three ways to use it:

- stepped synchronously: :class:`~controller.motorbus.FakeMotorBus` (or :meth:`FakeC610Trio.step`);
- on a python-can bus in a thread: :class:`C610TrioServer` answers every 0x200 with 0x201-0x203;
- behind a fake USB-CAN adapter speaking slcan on a pty: :class:`SlcanAdapterEmulator`, so that
  ``CanMotorBus(interface="slcan", channel=<pty slave>)`` is tested end to end.
"""

from __future__ import annotations

import contextlib
import math
import os
import select
import struct
import threading
from collections.abc import Iterable
from types import TracebackType
from typing import Any

from controller.config import CONTROL_PERIOD_US
from protocol.c610 import (
    ANGLE_COUNTS,
    COMMAND_ID_LOW,
    FEEDBACK_ID_BASE,
    M2006_GEAR_RATIO,
    RAW_PER_AMP,
    MotorFeedback,
)

__all__ = ["C610TrioServer", "FakeC610", "FakeC610Trio", "SlcanAdapterEmulator"]

_COMMAND = struct.Struct(">hhhh")
_INT16_MAX = 32767


class FakeC610:
    """One M2006 P36 behind a C610, winding a cable against a spring.

    Attributes:
        angle_out_rad: output shaft angle (positive = cable reeled in).
        speed_out_rad_s: output shaft speed.
        current_raw: current command in force (raw, 1000 per amp).
    """

    def __init__(
        self,
        *,
        spool_radius_m: float = 0.010,
        torque_constant_nm_per_a: float = 0.18,
        spring_n_per_m: float = 200.0,
        inertia_kg_m2: float = 2e-4,
        damping_nm_s: float = 0.02,
        start_angle_counts: int = 0,
    ) -> None:
        """Create a motor at rest with the cable just taut."""
        self.r = spool_radius_m
        self.kt = torque_constant_nm_per_a
        self.k = spring_n_per_m
        self.j = inertia_kg_m2
        self.b = damping_nm_s
        self.angle_out_rad = 0.0
        self.speed_out_rad_s = 0.0
        self.current_raw = 0
        self._angle0_counts = start_angle_counts

    @property
    def cable_tension_n(self) -> float:
        """Tension in the cable (0 when slack)."""
        paid_in = self.r * self.angle_out_rad
        return self.k * paid_in if paid_in > 0.0 else 0.0

    def step(self, dt_s: float) -> None:
        """Advance the dynamics by ``dt_s`` (semi-implicit Euler)."""
        torque = self.kt * self.current_raw / RAW_PER_AMP - self.r * self.cable_tension_n
        self.speed_out_rad_s += (torque - self.b * self.speed_out_rad_s) / self.j * dt_s
        self.angle_out_rad += self.speed_out_rad_s * dt_s

    def feedback(self) -> MotorFeedback:
        """The C610 feedback frame for the present state."""
        rotor_counts = round(self.angle_out_rad * ANGLE_COUNTS * M2006_GEAR_RATIO / (2.0 * math.pi))
        rpm = round(self.speed_out_rad_s * 60.0 * M2006_GEAR_RATIO / (2.0 * math.pi))
        rpm = max(-_INT16_MAX, min(_INT16_MAX, rpm))
        return MotorFeedback((self._angle0_counts + rotor_counts) % ANGLE_COUNTS, rpm, self.current_raw, 30)


class FakeC610Trio:
    """Three fake motors on C610 ids 1..3 (command 0x200, feedback 0x201-0x203).

    Attributes:
        motors: the three motors.
        silent: motor numbers (1..3) that stop answering (fault injection).
        commands: 0x200 frames handled.
    """

    def __init__(self, start_angles_counts: Iterable[int] = (0, 0, 0), **motor_kwargs: Any) -> None:
        """Create the trio; ``motor_kwargs`` go to each :class:`FakeC610`."""
        self.motors = [FakeC610(start_angle_counts=a, **motor_kwargs) for a in start_angles_counts]
        self.silent: set[int] = set()
        self.commands = 0

    def handle_frame(self, can_id: int, data: bytes) -> None:
        """Take a frame from the bus; only 8-byte 0x200 commands matter."""
        if can_id != COMMAND_ID_LOW or len(data) != 8:
            return
        self.commands += 1
        values = _COMMAND.unpack(data)
        for motor, raw in zip(self.motors, values, strict=False):
            motor.current_raw = raw

    def step(self, dt_us: int) -> list[tuple[int, bytes]]:
        """Advance every motor by ``dt_us``; return the feedback frames of the motors that answer."""
        dt_s = dt_us / 1e6
        out: list[tuple[int, bytes]] = []
        for n, motor in enumerate(self.motors, start=1):
            motor.step(dt_s)
            if n not in self.silent:
                out.append((FEEDBACK_ID_BASE + n, motor.feedback().pack()))
        return out


class _Worker:
    """A worker thread with a stop flag, joined by :meth:`stop` (safe twice; daemon, so a failed test
    cannot hang the interpreter)."""

    def __init__(self, name: str) -> None:
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._loop, name=name, daemon=True)
        self.error: BaseException | None = None

    def start(self) -> None:
        """Start serving."""
        self._thread.start()

    def stop(self) -> None:
        """Stop serving and join the thread (safe twice)."""
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout=5.0)

    def _loop(self) -> None:
        try:
            while not self._stop.is_set():
                self._poll()
        except BaseException as exc:
            self.error = exc

    def _poll(self) -> None:
        raise NotImplementedError


class C610TrioServer(_Worker):
    """Answers each 0x200 command on a python-can bus with the trio's 0x201-0x203 feedback (a thread).

    Use as a context manager; the bus given is shut down on exit.
    """

    def __init__(self, bus: Any, trio: FakeC610Trio | None = None, *, dt_us: int = CONTROL_PERIOD_US) -> None:
        """Serve ``trio`` (default: a fresh one) on the python-can ``bus``; each command steps ``dt_us``."""
        super().__init__("c610-trio")
        import can

        self._can = can
        self.bus = bus
        self.trio = trio if trio is not None else FakeC610Trio()
        self.dt_us = dt_us

    def __enter__(self) -> C610TrioServer:
        self.start()
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.stop()
        self.bus.shutdown()

    def _poll(self) -> None:
        msg = self.bus.recv(timeout=0.01)
        if msg is None or msg.arbitration_id != COMMAND_ID_LOW or msg.is_extended_id:
            return
        self.trio.handle_frame(msg.arbitration_id, bytes(msg.data))
        for can_id, data in self.trio.step(self.dt_us):
            self.bus.send(self._can.Message(arbitration_id=can_id, data=data, is_extended_id=False))


class SlcanAdapterEmulator(_Worker):
    """A USB-CAN adapter speaking the slcan (Lawicel) ASCII protocol on a pty master, trio behind it.

    Answers ``S<n>``, ``O``, ``C``, ``L``, ``V``, ``v``, ``N`` with ``\\r`` (version queries with a
    version), and each ``t200 8 ...`` command with three ``t20n8...`` feedback lines. Use as a context
    manager; ``fd`` (the pty master) is closed on exit.

    Attributes:
        lines: slcan lines received (for assertions).
        is_open: the host sent ``O`` (and not ``C`` since).
    """

    def __init__(self, fd: int, trio: FakeC610Trio | None = None, *, dt_us: int = CONTROL_PERIOD_US) -> None:
        """Serve on the pty master ``fd``."""
        super().__init__("slcan-adapter")
        self.fd = fd
        self.trio = trio if trio is not None else FakeC610Trio()
        self.dt_us = dt_us
        self.lines: list[str] = []
        self.is_open = False
        self._buf = bytearray()

    def __enter__(self) -> SlcanAdapterEmulator:
        self.start()
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.stop()
        with contextlib.suppress(OSError):
            os.close(self.fd)

    def _poll(self) -> None:
        ready, _, _ = select.select([self.fd], [], [], 0.01)
        if not ready:
            return
        try:
            data = os.read(self.fd, 4096)
        except OSError:  # the slave side closed: nothing more to serve
            self._stop.wait(0.01)
            return
        self._buf += data
        while True:
            end = self._buf.find(b"\r")
            if end < 0:
                break
            line = self._buf[:end].decode("ascii", errors="replace")
            del self._buf[: end + 1]
            self._handle(line)

    def _handle(self, line: str) -> None:
        self.lines.append(line)
        if not line:
            return
        cmd = line[0]
        reply = b"\r"
        if cmd == "O" or cmd == "L":
            self.is_open = True
        elif cmd == "C":
            self.is_open = False
        elif cmd == "V":
            reply = b"V1013\r"
        elif cmd == "v":
            reply = b"v1013\r"
        elif cmd == "N":
            reply = b"NA123\r"
        elif cmd == "t" and len(line) >= 5:
            can_id = int(line[1:4], 16)
            dlc = int(line[4])
            data = bytes.fromhex(line[5 : 5 + 2 * dlc])
            self.trio.handle_frame(can_id, data)
            reply = b"\r" if not self.is_open else b""
            if can_id == COMMAND_ID_LOW and self.is_open:
                for fid, fdata in self.trio.step(self.dt_us):
                    reply += f"t{fid:03X}8{fdata.hex().upper()}\r".encode("ascii")
        self._write(reply)

    def _write(self, data: bytes) -> None:
        view = memoryview(data)
        while view:
            try:
                n = os.write(self.fd, view)
            except BlockingIOError:
                select.select([], [self.fd], [], 0.01)
                continue
            view = view[n:]
