"""A game controller as the virtual radio: a Linux joystick device mapped to the DT7's sticks and levers.

The kernel's joystick interface (``/dev/input/jsN``, ``Documentation/input/joydev/joystick-api.rst``)
delivers 8-byte ``struct js_event`` records: ``__u32 time`` (ms), ``__s16 value``, ``__u8 type``
(``JS_EVENT_BUTTON`` 0x01, ``JS_EVENT_AXIS`` 0x02, or-ed with ``JS_EVENT_INIT`` 0x80 for the state
reported right after opening), ``__u8 number``. Axes read -32767..32767 (sticks: right / down positive);
buttons 0 / 1. No extra package is needed.

What the pad sets goes where the panel's sliders go: the control arbiter
(:meth:`host.panel.arbiter.ControlArbiter.set_radio`, the whole pad in one frame) as the command
line's client, so the board receives it as the same DBUS frames (``VirtualRc`` every 14 ms). The DT7's
levers have three positions; a pad has none, so each lever is two inputs that step it up or down
(DOWN -> MIDDLE -> UP).

Default mapping (an Xbox-layout pad on the Linux ``xpad`` driver: axes 0/1 left stick, 3/4 right stick,
6/7 D-pad; buttons 0 A, 3 Y, 7 Start), overridable with :func:`parse_mapping`::

    ch0=a3,ch1=-a4,ch2=a0,ch3=-a1,right=-a7/a7,left=b3/b0,control=b7

- ``chN=[-]aK``: DBUS channel N (0 right horizontal, 1 right vertical, 2 left horizontal, 3 left
  vertical) from axis K; ``-`` inverts (a stick's Y axis reads down positive, the DT7's up positive).
- ``right=UP/DOWN`` and ``left=UP/DOWN``: the inputs that step a lever up and down: ``bK`` a button,
  ``aK`` / ``-aK`` an axis pushed past half way to its positive / negative end (the D-pad).
- ``control=bK``: ask for control (back from a browser tab that took it).

Failsafe: when the device goes away (unplugged: read error or end of file) the right lever goes DOWN
(SAFE: zero current) and the sticks to the centre at once; the device is reopened every second, and a pad
that comes back starts from right lever DOWN, like a radio switched on. It is reported back when its
events flow again, not when the device merely opens (a FIFO with no writer opens and reads end of file).
"""

from __future__ import annotations

import contextlib
import logging
import os
import re
import select
import struct
from dataclasses import dataclass
from typing import Final

from host.panel.arbiter import ControlArbiter
from host.worker import Worker
from protocol.dbus import CH_LIMIT, Lever

__all__ = [
    "AXIS_MAX",
    "DEFAULT_MAPPING",
    "JS_EVENT",
    "JS_EVENT_AXIS",
    "JS_EVENT_BUTTON",
    "JS_EVENT_INIT",
    "Gamepad",
    "GamepadMapping",
    "GamepadState",
    "Input",
    "JsEvent",
    "JsEventReader",
    "format_mapping",
    "parse_mapping",
]

_log = logging.getLogger("spirob-host")

JS_EVENT: Final = struct.Struct("<IhBB")
"""``struct js_event``: time (ms), value, type, number (x86 and ARM Linux are little-endian)."""
JS_EVENT_BUTTON: Final = 0x01
JS_EVENT_AXIS: Final = 0x02
JS_EVENT_INIT: Final = 0x80
AXIS_MAX: Final = 32767
"""Full deflection of an axis."""

_LEVER_UP_ORDER = (Lever.DOWN, Lever.MIDDLE, Lever.UP)
"""A lever's positions from the bottom: stepping up moves right along this tuple."""


@dataclass(frozen=True, slots=True)
class JsEvent:
    """One ``struct js_event``.

    Attributes:
        time_ms: the kernel's timestamp (ms, wraps).
        value: axis position or button state.
        kind: ``JS_EVENT_BUTTON`` or ``JS_EVENT_AXIS`` (without the INIT bit).
        number: axis or button number.
        init: part of the state the kernel reports right after the device is opened.
    """

    time_ms: int
    value: int
    kind: int
    number: int
    init: bool = False

    def pack(self) -> bytes:
        """The 8 bytes the kernel would deliver."""
        return JS_EVENT.pack(
            self.time_ms, self.value, self.kind | (JS_EVENT_INIT if self.init else 0), self.number
        )


class JsEventReader:
    """Splits a byte stream into :class:`JsEvent` records; never raises.

    Records are fixed 8-byte structs, so a partial one is kept for the next :meth:`feed`; a record of an
    unknown type is skipped and counted in :attr:`bad_n`.
    """

    def __init__(self) -> None:
        self._rest = b""
        self.bad_n = 0
        """Records of an unknown type skipped."""

    def feed(self, data: bytes) -> list[JsEvent]:
        """The complete records in what has arrived so far."""
        buf = self._rest + data
        n = len(buf) // JS_EVENT.size
        self._rest = buf[n * JS_EVENT.size :]
        out: list[JsEvent] = []
        for time_ms, value, kind, number in JS_EVENT.iter_unpack(buf[: n * JS_EVENT.size]):
            base = kind & ~JS_EVENT_INIT
            if base not in (JS_EVENT_BUTTON, JS_EVENT_AXIS):
                self.bad_n += 1
                continue
            out.append(JsEvent(time_ms, value, base, number, bool(kind & JS_EVENT_INIT)))
        return out


@dataclass(frozen=True, slots=True)
class Input:
    """One pad input.

    Attributes:
        kind: ``JS_EVENT_AXIS`` or ``JS_EVENT_BUTTON``.
        number: axis or button number.
        invert: an axis read with its sign flipped (a stick); for a lever step, the axis's negative end.
    """

    kind: int
    number: int
    invert: bool = False

    def text(self) -> str:
        """``aK``, ``-aK`` or ``bK``."""
        if self.kind == JS_EVENT_BUTTON:
            return f"b{self.number}"
        return f"{'-' if self.invert else ''}a{self.number}"


@dataclass(frozen=True, slots=True)
class GamepadMapping:
    """Which pad inputs drive the DT7's sticks and levers.

    Attributes:
        channels: axes of DBUS channels 0..3 (right horizontal, right vertical, left horizontal, left
            vertical).
        right_lever: the inputs stepping the right lever (mode) up and down.
        left_lever: the inputs stepping the left lever up and down.
        control: the button asking for control.
        deadzone: fraction of full deflection read as the centre (a resting stick is not exactly 0).
    """

    channels: tuple[Input, Input, Input, Input]
    right_lever: tuple[Input, Input]
    left_lever: tuple[Input, Input]
    control: Input
    deadzone: float = 0.08


def _axis(n: int, invert: bool = False) -> Input:
    return Input(JS_EVENT_AXIS, n, invert)


def _button(n: int) -> Input:
    return Input(JS_EVENT_BUTTON, n)


DEFAULT_MAPPING: Final = GamepadMapping(
    channels=(_axis(3), _axis(4, True), _axis(0), _axis(1, True)),
    right_lever=(_axis(7, True), _axis(7)),
    left_lever=(_button(3), _button(0)),
    control=_button(7),
)
"""Xbox layout on ``xpad``: right stick ch0/ch1, left stick ch2/ch3, D-pad ↑/↓ the right lever, Y/A the
left lever, Start asks for control."""

_INPUT = re.compile(r"^(-?)a(\d{1,3})$|^b(\d{1,3})$")


def _parse_input(key: str, text: str) -> Input:
    m = _INPUT.match(text.strip().lower())
    if m is None:
        raise ValueError(f"{key}={text}: an input is aK, -aK (axis K) or bK (button K)")
    if m.group(3) is not None:
        number = int(m.group(3))
        kind = JS_EVENT_BUTTON
    else:
        number = int(m.group(2))
        kind = JS_EVENT_AXIS
    if number > 255:
        raise ValueError(f"{key}={text}: input numbers are 0..255")
    return Input(kind, number, m.group(1) == "-")


def parse_mapping(text: str, base: GamepadMapping = DEFAULT_MAPPING) -> GamepadMapping:
    """``base`` with the entries of ``text`` replaced (``ch0=a3,right=-a7/a7,...``; see the module).

    Raises:
        ValueError: one line saying what is wrong.
    """
    channels = list(base.channels)
    levers = {"right": base.right_lever, "left": base.left_lever}
    control = base.control
    seen: set[str] = set()
    for item in text.split(","):
        key, eq, value = item.partition("=")
        key = key.strip().lower()
        if not eq or not key:
            raise ValueError(f"{item.strip()!r}: expected KEY=VALUE (ch0..ch3, right, left, control)")
        if key in seen:
            raise ValueError(f"{key} given twice")
        seen.add(key)
        if key in ("ch0", "ch1", "ch2", "ch3"):
            inp = _parse_input(key, value)
            if inp.kind != JS_EVENT_AXIS:
                raise ValueError(f"{key}={value}: a stick channel needs an axis (aK or -aK)")
            channels[int(key[2])] = inp
        elif key in levers:
            up, slash, down = value.partition("/")
            if not slash:
                raise ValueError(f"{key}={value}: a lever needs UP/DOWN inputs, e.g. {key}=b3/b0")
            levers[key] = (_parse_input(key, up), _parse_input(key, down))
        elif key == "control":
            control = _parse_input(key, value)
            if control.kind != JS_EVENT_BUTTON:
                raise ValueError(f"control={value}: a button (bK)")
        else:
            raise ValueError(f"unknown key {key!r} (ch0..ch3, right, left, control)")
    return GamepadMapping(
        (channels[0], channels[1], channels[2], channels[3]),
        levers["right"],
        levers["left"],
        control,
        base.deadzone,
    )


def format_mapping(mapping: GamepadMapping) -> str:
    """The text :func:`parse_mapping` reads back to ``mapping`` (same deadzone)."""
    ch = ",".join(f"ch{i}={inp.text()}" for i, inp in enumerate(mapping.channels))
    r, left = mapping.right_lever, mapping.left_lever
    return (
        f"{ch},right={r[0].text()}/{r[1].text()},left={left[0].text()}/{left[1].text()},"
        f"control={mapping.control.text()}"
    )


class GamepadState:
    """The DT7 state a pad's events produce: four channels and two levers (pure; no I/O).

    Args:
        mapping: which inputs drive what.
    """

    def __init__(self, mapping: GamepadMapping = DEFAULT_MAPPING) -> None:
        self.mapping = mapping
        self.sticks = [0, 0, 0, 0]
        """DBUS channels 0..3, -660..660."""
        self.right_lever = Lever.DOWN
        self.left_lever = Lever.DOWN
        self.control_requests = 0
        """Presses of the control button (the runner asks for control on each new one)."""
        self._axes: dict[int, int] = {}
        self._buttons: dict[int, int] = {}

    def _active(self, inp: Input) -> bool:
        if inp.kind == JS_EVENT_BUTTON:
            return self._buttons.get(inp.number, 0) != 0
        value = self._axes.get(inp.number, 0)
        return -value > AXIS_MAX // 2 if inp.invert else value > AXIS_MAX // 2

    def _channel(self, inp: Input) -> int:
        value = self._axes.get(inp.number, 0)
        if inp.invert:
            value = -value
        frac = max(-1.0, min(1.0, value / AXIS_MAX))
        dz = self.mapping.deadzone
        if abs(frac) <= dz:
            return 0
        # Rescaled past the deadzone, so full deflection is still ±660 and there is no jump at its edge.
        scaled = (abs(frac) - dz) / (1.0 - dz)
        return round(CH_LIMIT * scaled) * (1 if frac > 0 else -1)

    def apply(self, event: JsEvent) -> None:
        """Take one event. INIT events set the state without stepping a lever (a button held while the
        device opens is not a press)."""
        m = self.mapping
        steps = (*m.right_lever, *m.left_lever, m.control)
        before = [self._active(i) for i in steps]
        if event.kind == JS_EVENT_AXIS:
            self._axes[event.number] = max(-AXIS_MAX, event.value)
        else:
            self._buttons[event.number] = event.value
        for i, inp in enumerate(m.channels):
            self.sticks[i] = self._channel(inp)
        if event.init:
            return
        after = [self._active(i) for i in steps]
        pressed = [a and not b for a, b in zip(after, before, strict=True)]
        if pressed[0]:
            self.right_lever = _step(self.right_lever, +1)
        if pressed[1]:
            self.right_lever = _step(self.right_lever, -1)
        if pressed[2]:
            self.left_lever = _step(self.left_lever, +1)
        if pressed[3]:
            self.left_lever = _step(self.left_lever, -1)
        if pressed[4]:
            self.control_requests += 1

    def lost(self) -> None:
        """The device went away: right lever DOWN (SAFE), left lever DOWN, sticks centred, inputs
        forgotten (a pad that comes back starts from rest)."""
        self.sticks = [0, 0, 0, 0]
        self.right_lever = self.left_lever = Lever.DOWN
        self._axes.clear()
        self._buttons.clear()


def _step(lever: Lever, direction: int) -> Lever:
    i = _LEVER_UP_ORDER.index(lever) + direction
    return _LEVER_UP_ORDER[max(0, min(len(_LEVER_UP_ORDER) - 1, i))]


class Gamepad:
    """Reads a joystick device in a thread and drives the control arbiter's radio with it.

    Args:
        path: the device (``/dev/input/js0``), or anything that delivers ``js_event`` records (a FIFO).
        arbiter: the control arbiter whose radio it drives.
        client: the client id it drives as (the command line's).
        mapping: which inputs drive what.
        reopen_period_s: pause between attempts to reopen a device that went away.
    """

    def __init__(
        self,
        path: str,
        arbiter: ControlArbiter,
        client: int,
        mapping: GamepadMapping = DEFAULT_MAPPING,
        *,
        reopen_period_s: float = 1.0,
    ) -> None:
        self.path = path
        self.arbiter = arbiter
        self.client = client
        self.state = GamepadState(mapping)
        self.reader = JsEventReader()
        self.reopen_period_s = reopen_period_s
        self.losses_n = 0
        """Times the device went away."""
        self.backs_n = 0
        """Times it came back: events flowed again after a loss (a reopen alone is not enough)."""
        self._reopened = False
        self._fd: int | None = None
        self._worker = Worker("gamepad", self._run)
        self._stop = self._worker.stop_event
        self._requests_seen = 0
        self._pushed: tuple[tuple[int, ...], Lever, Lever] | None = None

    def start(self) -> None:
        """Open the device, take control and start reading.

        Raises:
            OSError: the device cannot be opened (the caller words it).
        """
        self._fd = os.open(self.path, os.O_RDONLY | os.O_NONBLOCK)
        self.arbiter.request_control(self.client)
        self._worker.start()

    def stop(self) -> None:
        """Stop reading and close the device; safe twice."""
        self._worker.stop()
        self._close()

    def _close(self) -> None:
        fd, self._fd = self._fd, None
        if fd is not None:
            with contextlib.suppress(OSError):
                os.close(fd)

    def _run(self) -> None:
        while not self._stop.is_set():
            fd = self._fd
            if fd is None:
                if self._stop.wait(self.reopen_period_s):
                    return
                try:
                    self._fd = os.open(self.path, os.O_RDONLY | os.O_NONBLOCK)
                except OSError:
                    continue
                # Opened is not back: a FIFO with no writer opens fine and reads end of file at once.
                # The pad is back when its events flow (a joystick device sends its state on open).
                self._reopened = True
                continue
            try:
                ready, _, _ = select.select([fd], [], [], 0.1)
                data = os.read(fd, 4096) if ready else None
            except BlockingIOError:
                data = None
            except OSError as exc:
                self._lost(str(exc.strerror or exc))
                continue
            if data == b"":
                self._lost("end of file")
                continue
            if data:
                events = self.reader.feed(data)
                for event in events:
                    self.state.apply(event)
                if events and self._reopened:
                    self._reopened = False
                    self.backs_n += 1
                    _log.warning("gamepad %s is back (right lever DOWN: step it up to drive)", self.path)
            self._push()

    def _lost(self, reason: str) -> None:
        if self._reopened:  # reopened but silent: still the same loss, said once
            self._close()
            _log.debug("gamepad %s reopened without events (%s)", self.path, reason)
            return
        self.losses_n += 1
        self._close()
        self.state.lost()
        self._push()
        _log.warning("gamepad %s lost (%s): right lever DOWN (SAFE), sticks centred", self.path, reason)

    def _push(self) -> None:
        """What the pad holds to the arbiter (only while the command line holds control)."""
        m, st, client = self.arbiter, self.state, self.client
        if st.control_requests != self._requests_seen:
            self._requests_seen = st.control_requests
            m.request_control(client)
        holds = m.has_control(client)
        if holds and m.pending is not None:
            # Nobody at the pad can click "grant": a browser tab that asks gets control (as with
            # --virtual-rc); the pad's control button asks for it back.
            _log.info("handing control to browser tab %s", m.pending)
            m.answer_request(client, grant=True)
            holds = False
        if not holds:
            # The arbiter restarts the operator from right lever DOWN whenever control moves; the pad's
            # levers wait there too, so control regained starts from SAFE and later steps count.
            self._pushed = None
            st.right_lever = st.left_lever = Lever.DOWN
            return
        now = (tuple(st.sticks), st.right_lever, st.left_lever)
        if now == self._pushed:
            return
        self._pushed = now
        s0, s1, s2, s3 = st.sticks
        m.set_radio(client, (s0, s1, s2, s3), st.right_lever, st.left_lever)
