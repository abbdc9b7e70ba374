"""A rig for the firmware's unit tests: fake C610 trio, scripted radio, optional in-memory host link.

The firmware alone, on a fake bus with no plant: the product's one lockstep loop (board, plant and host
together) is :class:`hil.environment.Environment`; these tests need tick-exact control of the motors'
feedback instead. The host's end of the link is the same :class:`~protocol.session.HostSession` every
host uses (heartbeats off: tests send what they need).

Time is simulated: ``rig.tick()`` runs the firmware at ``rig.now_us`` and then advances 1 ms, so after
``tick()`` the state reflects the tick that ran at ``rig.last_us``.
"""

from __future__ import annotations

from collections.abc import Callable

from controller.config import FirmwareConfig
from controller.firmware import Firmware
from controller.motorbus import FakeMotorBus
from controller.rc import LinkRcSource, RcSource, ScriptedRcSource
from controller.transport import MemoryTransport
from protocol.dbus import Lever, RcFrame
from protocol.messages import Message, Phase
from protocol.session import HostSession

TICK_US = 1000


def frame(
    right: int = Lever.DOWN,
    left: int = Lever.DOWN,
    ch0: int = 0,
    ch1: int = 0,
    ch2: int = 0,
    ch3: int = 0,
) -> RcFrame:
    """An RC frame with the given levers and channels."""
    return RcFrame((ch0, ch1, ch2, ch3), int(right), int(left))


class Rig:
    """Firmware + fake bus + scripted RC (+ host end of a memory link) in simulated time."""

    def __init__(
        self,
        config: FirmwareConfig | None = None,
        *,
        link: bool = False,
        rc: RcSource | None = None,
        start: RcFrame | None = None,
        bus: FakeMotorBus | None = None,
    ) -> None:
        self.config = config or FirmwareConfig()
        self.bus = bus if bus is not None else FakeMotorBus()
        self.radio = ScriptedRcSource(start if start is not None else frame())
        self.rc = rc if rc is not None else self.radio
        self.host: MemoryTransport | None = None
        board = None
        if link:
            self.host, board = MemoryTransport.pair()
        self.fw = Firmware(self.config, self.bus, self.rc, board, exec_timer_ns=lambda: 0)
        self.now_us = 0
        self.last_us = -TICK_US
        self.session = HostSession(heartbeats=False)
        self.received: list[Message] = []

    @property
    def currents(self) -> tuple[int, ...]:
        return self.fw.commanded_currents

    def tick(self, n: int = 1) -> None:
        for _ in range(n):
            self.fw.run_due(self.now_us)
            self.last_us = self.now_us
            self.now_us += TICK_US

    def until(self, pred: Callable[[], bool], max_ticks: int) -> int:
        """Tick until ``pred()`` holds after a tick; return the time of that tick. Fails if it never does."""
        for _ in range(max_ticks):
            self.tick()
            if pred():
                return self.last_us
        raise AssertionError(f"condition not met within {max_ticks} ticks (now {self.now_us} us)")

    def arm(self) -> None:
        """Pass the start-up gate with the right lever DOWN."""
        self.radio.set_frame(frame())
        self.until(lambda: self.fw.phase == Phase.OK, 50)

    def set_rc(self, rc_frame: RcFrame | None) -> None:
        self.radio.set_frame(rc_frame)

    # --- host side ---------------------------------------------------------------------------------

    def send(self, msg: Message) -> int:
        """Send a host -> board message; return its seq."""
        assert self.host is not None
        seq = self.session.send(msg, self.now_us)
        self.host.write(self.session.data_to_send() + self.session.rc_to_send())
        return seq

    def drain(self) -> list[Message]:
        """Board -> host messages received since the last drain (also appended to ``received``)."""
        assert self.host is not None
        out = self.session.receive_data(self.host.read(), self.now_us)
        self.received += out
        return out


def link_rc_rig(config: FirmwareConfig | None = None) -> Rig:
    """A rig whose RC comes from the host's VirtualRc frames (the radio object is unused)."""
    return Rig(config, link=True, rc=LinkRcSource())
