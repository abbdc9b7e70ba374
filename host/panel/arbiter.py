"""Who may drive the arm, and what they drive it with: the control arbiter.

Everything a browser tab (or the command line: ``--virtual-rc``, ``--gamepad``) does goes through
:class:`ControlArbiter`, which checks who is asking, clamps every value again on the server side, and
forwards it to the board: the operator's radio (sticks and levers) as one DBUS frame pushed to the link
once per change (``BoardClient.set_rc``: the link process's 14 ms RC slot is the only clock that samples
it), and commands through ``BoardClient.send``.

The radio never falls silent on purpose: like a DT7 lying on the table, it transmits whether anyone holds
control or not. Nobody holding control (at start, after a release, after the holder's tab closed) means
the *idle* frame: sticks centred, the levers where they were (DOWN at start: SAFE, zero current;
docs/host.md says why a released tab's levers stay). An RC loss on the board is then a real one: a dead link
process, a host frozen past its lease (``host.link.process``), a board link that went down.

Control ownership: exactly one client holds control. Anyone authorised may ask for it; if nobody holds
it the request is granted, otherwise the holder is asked and must grant it (or release it): a second tab
never takes control silently. Whoever receives control starts from SAFE (right lever DOWN, sticks
centred), and so does everyone after the board link (re)connects. E-stop is open to every authorised
client. A board's answer refusing a command is told to the tab that sent that command code in the last
5 s (else to everybody: a command from MAVLink, or from a tab that left).
"""

from __future__ import annotations

import enum
import math
import secrets
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Protocol

from host.link.source import LinkState
from host.panel.notices import Notices
from protocol.dbus import CH_LIMIT, Lever, RcFrame
from protocol.messages import (
    HOLD_HERE,
    HOLD_RELEASE,
    HOLD_UNCHANGED,
    AckResult,
    Command,
    CommandAck,
    CommandCode,
    Message,
    Mode,
    ParamValue,
)

__all__ = [
    "CLI_CLIENT",
    "BoardSend",
    "ControlArbiter",
    "ControlLimits",
    "ControlResult",
    "RcOut",
    "new_token",
    "origin_of",
]

CLI_CLIENT = -1
"""Client id of the command line itself (``--virtual-rc``, ``--gamepad``)."""
_ACK_OWNER_S = 5.0
"""An answer to a command code a tab sent that long ago or less goes to that tab."""


class BoardSend(Protocol):
    """Sends one host -> board message (``BoardClient.send``); False if it did not go out."""

    def __call__(self, msg: Message, *, origin: str = ...) -> bool:
        """Send ``msg`` on behalf of ``origin`` (``Tab 3``, ``host``)."""


RcOut = Callable[[RcFrame | None], None]
"""Takes the operator's DBUS frame from now on (``BoardClient.set_rc``; the arbiter never passes None,
which would silence the radio)."""


def new_token() -> str:
    """A fresh URL-safe access token (128 bits)."""
    return secrets.token_urlsafe(16)


def origin_of(client: int) -> str:
    """How a client is named where the host says who did something (``Tab 3``, ``host``)."""
    return "host" if client == CLI_CLIENT else f"Tab {client}"


class ControlResult(enum.Enum):
    """Answer to a request for control."""

    GRANTED = "granted"
    PENDING = "pending"
    DENIED = "denied"


@dataclass(frozen=True, slots=True)
class ControlLimits:
    """Server-side clamps applied to every value a client sends.

    Attributes:
        channel_limit: |stick| in DBUS counts (DR16: 660).
        tension_max_n: per-cable tension ceiling for DIRECT mode (the board's ``TENSION_MAX_N``).
    """

    channel_limit: int = CH_LIMIT
    tension_max_n: float = 20.0


@dataclass
class _Operator:
    """What the control holder set (already clamped)."""

    sticks: list[int] = field(default_factory=lambda: [0, 0, 0, 0])
    right_lever: Lever = Lever.DOWN
    left_lever: Lever = Lever.DOWN
    direct_tensions_n: list[float] = field(default_factory=lambda: [0.0, 0.0, 0.0])


def _finite(value: float, default: float = 0.0) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        return default
    return v if math.isfinite(v) else default


def _lever(value: Lever | int | str) -> Lever | None:
    try:
        return Lever[value.upper()] if isinstance(value, str) else Lever(int(value))
    except (KeyError, ValueError):
        return None


class ControlArbiter:
    """Authorisation, the single control holder, the operator's clamped radio, commands; thread-safe.

    Args:
        notices: where refusals, hand-overs and E-stops are told.
        send: forwards a host -> board message (``BoardClient.send``); None = nowhere (replay).
        rc_out: takes the operator's DBUS frame whenever it changes (``BoardClient.set_rc``); None = no
            radio (replay).
        limits: server-side clamps.
        token: access token; None = every client is authorised (loopback).
    """

    def __init__(
        self,
        notices: Notices,
        send: BoardSend | None = None,
        rc_out: RcOut | None = None,
        *,
        limits: ControlLimits | None = None,
        token: str | None = None,
    ) -> None:
        self._notices = notices
        self._send = send
        self._rc_out = rc_out
        self.limits = limits or ControlLimits()
        self.token = token
        self._lock = threading.RLock()
        self._op = _Operator()
        self._holder: int | None = None
        self._pending: int | None = None
        self._authorised: set[int] = set()
        self._frame = self._op_frame()
        """The frame last given to ``rc_out``: the idle radio from the start (a link started later
        begins with it)."""
        self._ack_owner: dict[int, tuple[int, float]] = {}
        """Command code -> (client, host time s) of the last command with that code."""
        if rc_out is not None:
            rc_out(self._frame)

    # ------------------------------------------------------------------ authorisation and control

    def authorise(self, client: int, token: str | None = None) -> bool:
        """Authorise ``client`` if no token is required or ``token`` matches (constant-time compare)."""
        ok = self.token is None or (token is not None and secrets.compare_digest(token, self.token))
        if ok:
            with self._lock:
                self._authorised.add(client)
        return ok

    def is_authorised(self, client: int) -> bool:
        """True if ``client`` may act (always, when no token is required)."""
        return self.token is None or client == CLI_CLIENT or client in self._authorised

    @property
    def holder(self) -> int | None:
        """The client holding control, or None."""
        return self._holder

    @property
    def pending(self) -> int | None:
        """The client waiting for the holder to hand control over, or None."""
        return self._pending

    def has_control(self, client: int) -> bool:
        """True if ``client`` holds control."""
        return self._holder is not None and self._holder == client

    def _set_holder(self, client: int | None) -> None:
        self._holder = client
        self._pending = None
        # Whoever gets control starts from SAFE. Control given up (or its tab gone) leaves the idle
        # radio as a DT7 put down on the table: sticks centred, the levers where they were (a held
        # object stays held; docs/host.md, "The idle radio").
        old = self._op
        self._op = _Operator()
        if client is None:
            self._op.right_lever, self._op.left_lever = old.right_lever, old.left_lever
        self._publish()

    def request_control(self, client: int) -> ControlResult:
        """Ask for control: granted if free, otherwise the holder is asked (never taken silently)."""
        if not self.is_authorised(client):
            return ControlResult.DENIED
        with self._lock:
            if self._holder is None or self._holder == client:
                if self._holder != client:
                    self._set_holder(client)
                return ControlResult.GRANTED
            self._pending = client
            holder = self._holder
        who = "The command line" if client == CLI_CLIENT else f"Tab {client}"
        self._notices.notify(
            "warning", "Control requested", f"{who} asks for control: hand it over or keep it", client=holder
        )
        return ControlResult.PENDING

    def answer_request(self, holder: int, grant: bool) -> bool:
        """The holder grants or refuses the pending request; returns True if control moved."""
        with self._lock:
            if holder != self._holder or self._pending is None:
                return False
            requester = self._pending
            if grant:
                self._set_holder(requester)
            else:
                self._pending = None
        if grant:
            self._notices.notify("info", "Control handed over", "you hold control (SAFE)", client=requester)
        else:
            self._notices.notify("warning", "Control refused", "the holder kept control", client=requester)
        return grant

    def cancel_request(self, client: int) -> None:
        """Withdraw ``client``'s pending request."""
        with self._lock:
            if self._pending == client:
                self._pending = None

    def release_control(self, client: int) -> bool:
        """Give control up; a pending requester does not get it automatically (they ask again)."""
        with self._lock:
            if self._holder != client:
                return False
            self._set_holder(None)
        return True

    def client_left(self, client: int) -> None:
        """A client disconnected: drop its control or request and its authorisation."""
        with self._lock:
            self._authorised.discard(client)
            if self._holder == client:
                self._set_holder(None)
            elif self._pending == client:
                self._pending = None

    # ------------------------------------------------------------------ the operator's radio

    def _op_frame(self) -> RcFrame:
        op = self._op
        s = op.sticks
        return RcFrame((s[0], s[1], s[2], s[3]), int(op.right_lever), int(op.left_lever))

    def _publish(self, force: bool = False) -> None:
        """Hand the radio's frame to the link if it changed (called with the lock held, so frames
        reach the link in the order they were decided). With nobody holding control this is the idle
        frame (``_set_holder`` reset it), or DOWN after an E-stop."""
        frame = self._op_frame()
        if frame == self._frame and not force:
            return
        self._frame = frame
        if self._rc_out is not None:
            self._rc_out(frame)

    def set_stick(self, client: int, channel: int, value: float) -> bool:
        """Set DBUS channel 0..3 (clamped to ±660); ignored unless ``client`` holds control."""
        if not 0 <= channel <= 3:
            raise ValueError(f"channel must be 0..3, got {channel}")
        lim = self.limits.channel_limit
        v = round(min(max(_finite(value), -lim), lim))
        with self._lock:
            if not self.has_control(client):
                return False
            self._op.sticks[channel] = v
            self._publish()
        return True

    def centre_sticks(self, client: int) -> bool:
        """All sticks back to the centre (holder only)."""
        with self._lock:
            if not self.has_control(client):
                return False
            self._op.sticks = [0, 0, 0, 0]
            self._publish()
        return True

    def set_lever(self, client: int, which: str, lever: Lever | int | str) -> bool:
        """Move the ``"right"`` or ``"left"`` lever to UP / MIDDLE / DOWN (holder only)."""
        if which not in ("right", "left"):
            raise ValueError(f"lever must be 'right' or 'left', got {which!r}")
        value = _lever(lever)
        if value is None:
            return False
        with self._lock:
            if not self.has_control(client):
                return False
            if which == "right":
                self._op.right_lever = value
            else:
                self._op.left_lever = value
            self._publish()
        return True

    def set_radio(
        self, client: int, sticks: tuple[float, float, float, float], right_lever: Lever, left_lever: Lever
    ) -> bool:
        """Set every stick and both levers at once (one frame: a gamepad's whole state; holder only)."""
        lim = self.limits.channel_limit
        values = [round(min(max(_finite(v), -lim), lim)) for v in sticks]
        right, left = _lever(right_lever), _lever(left_lever)
        if right is None or left is None or len(values) != 4:
            return False
        with self._lock:
            if not self.has_control(client):
                return False
            self._op.sticks = values
            self._op.right_lever, self._op.left_lever = right, left
            self._publish()
        return True

    def operator_input(self) -> tuple[tuple[int, int, int, int], Lever, Lever, tuple[float, float, float]]:
        """Current sticks, right lever, left lever and DIRECT tensions (for display)."""
        with self._lock:
            op = self._op
            s = op.sticks
            d = op.direct_tensions_n
            return (s[0], s[1], s[2], s[3]), op.right_lever, op.left_lever, (d[0], d[1], d[2])

    def rc_frame(self) -> RcFrame:
        """The DBUS frame the link is sending: the holder's, or the idle radio's when nobody holds
        control."""
        with self._lock:
            return self._frame

    @property
    def idle(self) -> bool:
        """Nobody holds control: the radio sends the idle frame (sticks centred, the levers left where
        they were, DOWN at start)."""
        return self._holder is None

    # ------------------------------------------------------------------ commands

    def forward(self, msg: Message, client: int | None = None) -> bool:
        """Send ``msg`` on behalf of ``client`` (checked by the caller); a tab is told when it did not go.

        Returns:
            True if the message went out.
        """
        send = self._send
        if send is None:
            self._not_sent(client, "no board to send it to (replay)")
            return False
        if isinstance(msg, Command):
            with self._lock:
                self._ack_owner[int(msg.code)] = (CLI_CLIENT if client is None else client, time.monotonic())
        ok = send(msg, origin="host" if client is None else origin_of(client))
        if not ok:
            self._not_sent(client, "the board link is down")
        return ok

    def _not_sent(self, client: int | None, why: str) -> None:
        if client is not None and client != CLI_CLIENT:
            self._notices.notify("warning", "Not sent", why, client=client)

    def command(
        self, client: int, code: CommandCode, args: tuple[float, float, float] = (0.0, 0.0, 0.0)
    ) -> bool:
        """Send a command on behalf of the control holder (E-stop: any authorised client).

        Arguments are validated and clamped here again: ``SET_MODE`` must name a ``Mode``,
        ``SET_TENSIONS`` is clamped to 0..``tension_max_n``; ``HOLD_LENGTHS`` goes as given.

        Returns:
            True if the command went out.
        """
        code = CommandCode(code)
        if code == CommandCode.ESTOP:
            return self.estop(client)
        if not self.has_control(client):
            self._not_sent(client, f"{code.name}: this tab does not hold control")
            return False
        a = tuple(_finite(x) for x in args)
        if code == CommandCode.HOLD_LENGTHS:
            a = tuple(float(x) for x in args)  # NaN (unchanged) and ±inf (hold here / release) mean something
        elif code == CommandCode.SET_MODE:
            try:
                Mode(int(a[0]))
            except ValueError:
                self._not_sent(client, f"SET_MODE: no mode {a[0]:g}")
                return False
            a = (float(int(a[0])), 0.0, 0.0)
        elif code == CommandCode.SET_TENSIONS:
            hi = self.limits.tension_max_n
            a = tuple(min(max(x, 0.0), hi) for x in a)
        elif code == CommandCode.REQUIRE_HOST:
            a = (1.0 if a[0] else 0.0, 0.0, 0.0)
        else:
            a = (0.0, 0.0, 0.0)
        return self.forward(Command(code, (a[0], a[1], a[2])), client)

    def estop(self, client: int) -> bool:
        """Emergency stop: any authorised client may press it; the levers also go to SAFE."""
        if not self.is_authorised(client):
            return False
        with self._lock:
            self._op.right_lever = Lever.DOWN
            self._op.sticks = [0, 0, 0, 0]
            self._publish()
        ok = self.forward(Command(CommandCode.ESTOP), client)
        self._notices.notify(
            "error", "E-STOP pressed", "by the host" if client == CLI_CLIENT else f"by Tab {client}"
        )
        return ok

    def set_direct_tension(self, client: int, cable: int, tension_n: float) -> bool:
        """Set one cable's DIRECT-mode tension (clamped) and send all three (holder only)."""
        if not 0 <= cable <= 2:
            raise ValueError(f"cable must be 0..2, got {cable}")
        hi = self.limits.tension_max_n
        v = min(max(_finite(tension_n), 0.0), hi)
        with self._lock:
            if not self.has_control(client):
                return False
            self._op.direct_tensions_n[cable] = v
            t = tuple(self._op.direct_tensions_n)
        return self.forward(Command(CommandCode.SET_TENSIONS, (t[0], t[1], t[2])), client)

    def set_length_hold(self, client: int, cable: int, hold: bool) -> bool:
        """Hold one cable at its present length, or release it (``HOLD_LENGTHS``; holder only).

        The other cables are left as they are. The board refuses it in SAFE and drops every hold on a
        mode change; ``TelemetryFlags.HOLD_1..3`` tell which cables it holds.
        """
        if not 0 <= cable <= 2:
            raise ValueError(f"cable must be 0..2, got {cable}")
        if not self.has_control(client):
            return False
        args = [HOLD_UNCHANGED, HOLD_UNCHANGED, HOLD_UNCHANGED]
        args[cable] = HOLD_HERE if hold else HOLD_RELEASE
        return self.forward(Command(CommandCode.HOLD_LENGTHS, (args[0], args[1], args[2])), client)

    # ------------------------------------------------------------------ listeners

    def on_board_message(self, msg: Message) -> None:
        """Listener: a refusal goes to the tab that sent the command; the DIRECT ceiling follows the board."""
        if isinstance(msg, CommandAck):
            if msg.result in (AckResult.ACCEPTED, AckResult.IN_PROGRESS):
                return
            code = msg.command
            name = code.name if isinstance(code, CommandCode) else f"command {code}"
            with self._lock:
                owner = self._ack_owner.get(int(code))
            recent = owner is not None and time.monotonic() - owner[1] <= _ACK_OWNER_S
            client = owner[0] if owner is not None and recent else None
            # Every refusal is said, with the board's reason, to the tab that asked (else to everyone:
            # a command from MAVLink or a tab that left).
            body = msg.text or msg.result.name.lower()
            self._notices.notify("warning", f"Board refused {name}", body, client=client)
        elif isinstance(msg, ParamValue) and msg.name == "TENSION_MAX_N" and msg.value > 0:
            # The wire name (the firmware's parameter table): the DIRECT sliders' ceiling is the board's.
            self.limits = ControlLimits(self.limits.channel_limit, float(msg.value))

    def on_link_state(self, state: LinkState) -> None:
        """State listener: after a (re)connect every lever starts DOWN again, and the link is told so
        before it may send anything but SAFE frames (``BoardClient`` orders the two)."""
        if state is LinkState.CONNECTED:
            with self._lock:
                self._op = _Operator()
                self._publish(force=True)
