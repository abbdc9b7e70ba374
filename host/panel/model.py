"""The teleop panel's model: latest board state, plot history, health, and who holds control.

Everything the panel shows is read from here and everything a browser does is written here: panel
callbacks only call :class:`UiModel` methods, which check who is asking, clamp every value again on the
server side, and forward commands to the board through the ``send`` callable. The board client calls
:meth:`UiModel.on_board_message` (a listener like any other) and :meth:`UiModel.virtual_rc_frame` every
14 ms to get the DBUS frame to send (None when nobody holds control: then no RC is sent and the board
falls to zero current after its 30 ms RC timeout).

Control ownership: exactly one client (a browser tab, or the command line for ``--virtual-rc``) holds
control. Anyone may ask for it; if nobody holds it the request is granted, otherwise the holder is asked
and must grant it (or release it) — a second tab never takes control silently. Whoever receives control
starts from SAFE (right lever DOWN, sticks centred). E-stop is open to every authorised client.
"""

from __future__ import annotations

import collections
import enum
import math
import secrets
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field

from host.link.client import LinkState, LinkStats
from host.panel.console import EventConsole
from host.panel.history import PLOT_COLUMNS, RingBuffer
from host.panel.param_table import PARAM_NAMES, ParamStatus, param_check
from protocol.dbus import CH_LIMIT, Lever, RcFrame
from protocol.messages import (
    HOLD_HERE,
    HOLD_RELEASE,
    HOLD_UNCHANGED,
    PARAM_LIST_ALL,
    AckResult,
    BoardStatus,
    Command,
    CommandAck,
    CommandCode,
    Event,
    EventKind,
    Message,
    Mode,
    ParamRequest,
    ParamSet,
    ParamValue,
    Phase,
    SimPoses,
    Telemetry,
)

__all__ = ["CLI_CLIENT", "ControlLimits", "ControlResult", "Notice", "PoseSource", "UiModel", "new_token"]

CLI_CLIENT = -1
"""Client id of the command line itself (``--virtual-rc``)."""

SendFn = Callable[[Message], bool]

_RAW_PER_AMP = 1000.0  # C610: 1000 raw units per amp
_ACK_OWNER_S = 5.0
"""An answer to a command code a tab sent that long ago or less goes to that tab."""


def new_token() -> str:
    """A fresh URL-safe access token (128 bits)."""
    return secrets.token_urlsafe(16)


class PoseSource(enum.Enum):
    """Where the arm's drawn shape comes from (the value is what the panel says)."""

    NONE = "no pose source"
    SIMULATION = "simulation (SimPoses)"
    """The plant of a virtual board, over the board link."""
    SHADOW = "shadow plant (measured currents)"
    """A local plant driven by a real board's measured motor currents (``host.shadow``)."""


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
        tension_max_n: per-cable tension ceiling for DIRECT mode (the firmware's ``tension_max_n``).
    """

    channel_limit: int = CH_LIMIT
    tension_max_n: float = 20.0


@dataclass(frozen=True, slots=True)
class Notice:
    """Something to tell people in the panel (failsafe, fault, control hand-over, link state).

    Attributes:
        seq: increasing number (the panel shows each notice once).
        level: ``info``, ``warning`` or ``error``.
        title: short title.
        body: one line.
        client: only this client (None: everybody).
    """

    seq: int
    level: str
    title: str
    body: str
    client: int | None = None


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


class UiModel:
    """Latest board state, history, health and control ownership; thread-safe.

    Args:
        send: forwards a host -> board message (``BoardClient.send``); None = nowhere (replay).
        limits: server-side clamps.
        history_s: seconds of telemetry kept for the plots.
        telemetry_hz: expected telemetry rate (sizes the history).
        token: access token; None = every client is authorised (loopback).
    """

    def __init__(
        self,
        send: SendFn | None = None,
        *,
        limits: ControlLimits | None = None,
        history_s: float = 20.0,
        telemetry_hz: float = 100.0,
        token: str | None = None,
    ) -> None:
        self._send = send
        self.limits = limits or ControlLimits()
        self.token = token
        self._lock = threading.RLock()
        self.history_s = history_s
        """Seconds of telemetry kept for the plots."""
        self.history = RingBuffer(max(10, int(history_s * telemetry_hz)), len(PLOT_COLUMNS))
        self.telemetry: Telemetry | None = None
        self.telemetry_count = 0
        self.poses: SimPoses | None = None
        self.poses_count = 0
        self.poses_event = threading.Event()
        """Set whenever new poses arrive (the panel waits on it)."""
        self.pose_source = PoseSource.NONE
        """Where :attr:`poses` came from."""
        self.sim_poses_count = 0
        """``SimPoses`` received from the board (after the first, shadow poses are ignored)."""
        self.status: BoardStatus | None = None
        self.params: dict[str, float] = {}
        self.last_ack: CommandAck | None = None
        self.link_state = LinkState.CONNECTING
        self.link_stats: LinkStats | None = None
        self.link_stats_fn: Callable[[], LinkStats] | None = None
        self.source_label = "board"
        self._op = _Operator()
        self._holder: int | None = None
        self._pending: int | None = None
        self._authorised: set[int] = set()
        self._notices: collections.deque[Notice] = collections.deque(maxlen=100)
        self._notice_seq = 0
        self._last_phase: Phase | None = None
        self._control_version = 0
        self.commands_sent = 0
        self.commands_refused = 0
        self._rc_changed_us = 0
        self.events = EventConsole()
        """The event console (board events, failsafes, acks, commands)."""
        self._ack_owner: dict[int, tuple[int, float]] = {}
        """Command code -> (client, host time s) of the last panel command with that code."""
        self.param_status: dict[str, ParamStatus] = {}
        """Parameter name -> the last value a tab asked for and what the board read back."""
        self.params_count = 0
        """How many parameters the board says it has (0 until the first ``ParamValue``)."""

    # ------------------------------------------------------------------ board side (listeners)

    def on_board_message(self, msg: Message) -> None:
        """Listener: keep the latest of each message, extend the history, raise notices."""
        if isinstance(msg, Telemetry):
            self._on_telemetry(msg)
        elif isinstance(msg, SimPoses):
            with self._lock:
                self.poses = msg
                self.poses_count += 1
                self.sim_poses_count += 1
                self.pose_source = PoseSource.SIMULATION
            self.poses_event.set()
        elif isinstance(msg, Event):
            self._on_event(msg)
        elif isinstance(msg, BoardStatus):
            with self._lock:
                self.status = msg
        elif isinstance(msg, ParamValue):
            self._on_param(msg)
        elif isinstance(msg, CommandAck):
            self._on_ack(msg)

    def _on_param(self, msg: ParamValue) -> None:
        with self._lock:
            self.params[msg.name] = msg.value
            self.params_count = msg.count
            # The wire name (controller.config.PARAMS): the DIRECT sliders' ceiling follows the board's.
            if msg.name == "TENSION_MAX_N" and msg.value > 0:
                self.limits = ControlLimits(self.limits.channel_limit, float(msg.value))
            pending = self.param_status.get(msg.name)
            if pending is not None and pending.confirmed is None:
                self.param_status[msg.name] = ParamStatus(
                    pending.requested, pending.sent_s, msg.value, pending.note
                )

    def _on_ack(self, ack: CommandAck) -> None:
        code = ack.command
        name = code.name if isinstance(code, CommandCode) else f"command {code}"
        now_s = time.monotonic()
        with self._lock:
            self.last_ack = ack
            owner = self._ack_owner.get(int(code))
        client = owner[0] if owner is not None and now_s - owner[1] <= _ACK_OWNER_S else None
        result = ack.result
        ok = result in (AckResult.ACCEPTED, AckResult.IN_PROGRESS)
        why = f": {ack.text}" if ack.text else ""
        self.log("ack", "info" if ok else "warning", f"{name} {result.name}{why}")
        if not ok:
            # Every refusal is said, with the board's reason, to the tab that asked (else to everyone:
            # a command from MAVLink or a tab that left).
            self._notify("warning", f"Board refused {name}", ack.text or result.name.lower(), client=client)

    def on_shadow_poses(self, poses: SimPoses) -> bool:
        """Poses of the shadow plant (``host.shadow``); ignored once the board itself sent ``SimPoses``.

        Returns:
            True if they became the poses shown.
        """
        with self._lock:
            if self.sim_poses_count:
                return False
            self.poses = poses
            self.poses_count += 1
            self.pose_source = PoseSource.SHADOW
        self.poses_event.set()
        return True

    def _on_telemetry(self, t: Telemetry) -> None:
        row = (
            *t.tension_target_n,
            *t.tension_est_n,
            *(c / _RAW_PER_AMP for c in t.commanded_current),
            *(c / _RAW_PER_AMP for c in t.motor_current),
            *(x * 1000.0 for x in t.cable_length_m),
        )
        with self._lock:
            prev = self.telemetry
            if prev is not None and t.time_us < prev.time_us:
                self.history.clear()  # the board restarted
            self.telemetry = t
            self.telemetry_count += 1
            self.history.append(t.time_us / 1e6, row)
            phase = t.phase
            if phase != self._last_phase:
                if self._last_phase is not None:
                    self._phase_notice(phase)
                self._last_phase = phase

    def _phase_notice(self, phase: Phase) -> None:
        self.log("failsafe", "info" if phase in (Phase.OK, Phase.GATE) else "warning", f"phase {phase.name}")
        text = {
            Phase.OK: ("info", "Failsafe cleared", "phase OK: current may flow"),
            Phase.GATE: ("info", "Start-up gate", "waiting for valid RC with the right lever DOWN"),
            Phase.RC_LOST: ("warning", "RC lost", "no valid RC frame for 30 ms: zero current"),
            Phase.MOTOR_FAULT: ("error", "Motor fault", "a motor went silent: all currents zero (latched)"),
            Phase.HOST_LOST: ("warning", "Host lost", "host heartbeat timed out: zero current"),
            Phase.ESTOP: ("error", "E-STOP", "emergency stop latched: clear it and re-arm through SAFE"),
        }[phase]
        self._notify(*text)

    def _on_event(self, e: Event) -> None:
        level = "error" if e.kind == EventKind.FAULT else "info"
        self.log("board", level, f"{e.kind.name}: {e.text or e.code}", board_time_us=e.time_us)
        if e.kind == EventKind.PARAM and e.text.startswith("rejected") and 0 <= e.code < len(PARAM_NAMES):
            with self._lock:
                name = PARAM_NAMES[e.code]
                pending = self.param_status.get(name)
                if pending is not None:
                    self.param_status[name] = ParamStatus(
                        pending.requested, pending.sent_s, pending.confirmed, e.text
                    )
        if e.kind == EventKind.FAULT:
            self._notify("error", "Fault", e.text or f"fault code {e.code}")
        elif e.kind == EventKind.GRASP:
            self._notify("info", "Grasp", e.text or f"grasp state {e.code}")
        elif e.kind == EventKind.BOOT:
            self._notify("info", "Board started", e.text or "boot")

    def on_link_state(self, state: LinkState) -> None:
        """State listener: show the link state; after a reconnect every lever starts DOWN again."""
        with self._lock:
            prev = self.link_state
            self.link_state = state
            if state is LinkState.CONNECTED:
                self._reset_operator()
        if state is LinkState.DISCONNECTED and prev is not LinkState.DISCONNECTED:
            self._notify("error", "Board disconnected", "retrying; the board holds zero current")
        elif state is LinkState.CONNECTED and prev is LinkState.DISCONNECTED:
            self._notify("info", "Board reconnected", "levers reset to SAFE (right lever DOWN)")

    def refresh_link_stats(self) -> LinkStats | None:
        """Pull a fresh snapshot from the board client (the panel calls this at its own rate)."""
        fn = self.link_stats_fn
        if fn is not None:
            stats = fn()
            with self._lock:
                self.link_stats = stats
        return self.link_stats

    # ------------------------------------------------------------------ notices

    def _notify(self, level: str, title: str, body: str, client: int | None = None) -> None:
        with self._lock:
            self._notice_seq += 1
            self._notices.append(Notice(self._notice_seq, level, title, body, client))

    def notices_after(self, seq: int) -> list[Notice]:
        """Notices newer than ``seq``, oldest first."""
        with self._lock:
            return [n for n in self._notices if n.seq > seq]

    def log(self, source: str, level: str, text: str, *, board_time_us: int | None = None) -> None:
        """Add a line to the event console (see :class:`ConsoleEntry`)."""
        with self._lock:
            if board_time_us is None and self.telemetry is not None:
                board_time_us = self.telemetry.time_us
        self.events.add(board_time_us, source, level, text)

    def on_host_command(self, msg: Message, source: str) -> None:
        """Log a command another part of the host sends to the board (the drone link: ``MAVLink``)."""
        if isinstance(msg, Command):
            self.log(source, "info", f"{CommandCode(msg.code).name}{_args_text(msg.args)}")
        elif isinstance(msg, ParamSet):
            self.log(source, "info", f"set {msg.name} = {msg.value:g}")

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

    @property
    def control_version(self) -> int:
        """Increments whenever the holder or the pending request changes."""
        return self._control_version

    def _reset_operator(self) -> None:
        self._op = _Operator()
        self._rc_changed_us = time.monotonic_ns() // 1000

    def _set_holder(self, client: int | None) -> None:
        self._holder = client
        self._pending = None
        self._reset_operator()
        self._control_version += 1

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
            self._control_version += 1
            holder = self._holder
        who = "The command line" if client == CLI_CLIENT else f"Tab {client}"
        self._notify(
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
                self._control_version += 1
        if grant:
            self._notify("info", "Control handed over", "you hold control (SAFE)", client=requester)
        else:
            self._notify("warning", "Control refused", "the holder kept control", client=requester)
        return grant

    def cancel_request(self, client: int) -> None:
        """Withdraw ``client``'s pending request."""
        with self._lock:
            if self._pending == client:
                self._pending = None
                self._control_version += 1

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
                self._control_version += 1

    def has_control(self, client: int) -> bool:
        """True if ``client`` holds control."""
        return self._holder is not None and self._holder == client

    # ------------------------------------------------------------------ operator input (holder only)

    def set_stick(self, client: int, channel: int, value: float) -> bool:
        """Set DBUS channel 0..3 (clamped to ±660); ignored unless ``client`` holds control."""
        if not 0 <= channel <= 3:
            raise ValueError(f"channel must be 0..3, got {channel}")
        lim = self.limits.channel_limit
        v = round(min(max(_finite(value), -lim), lim))
        with self._lock:
            if not self.has_control(client):
                self.commands_refused += 1
                return False
            if self._op.sticks[channel] != v:
                self._op.sticks[channel] = v
                self._rc_changed_us = time.monotonic_ns() // 1000
        return True

    def centre_sticks(self, client: int) -> bool:
        """All sticks back to the centre."""
        ok = True
        for ch in range(4):
            ok = self.set_stick(client, ch, 0) and ok
        return ok

    def set_lever(self, client: int, which: str, lever: Lever | int | str) -> bool:
        """Move the ``"right"`` or ``"left"`` lever to UP / MIDDLE / DOWN (holder only)."""
        if which not in ("right", "left"):
            raise ValueError(f"lever must be 'right' or 'left', got {which!r}")
        try:
            value = Lever[lever.upper()] if isinstance(lever, str) else Lever(int(lever))
        except (KeyError, ValueError):
            with self._lock:
                self.commands_refused += 1
            return False
        with self._lock:
            if not self.has_control(client):
                self.commands_refused += 1
                return False
            if which == "right":
                self._op.right_lever = value
            else:
                self._op.left_lever = value
            self._rc_changed_us = time.monotonic_ns() // 1000
        return True

    def operator_input(self) -> tuple[tuple[int, int, int, int], Lever, Lever, tuple[float, float, float]]:
        """Current sticks, right lever, left lever and DIRECT tensions (for display)."""
        with self._lock:
            op = self._op
            s = op.sticks
            d = op.direct_tensions_n
            return (s[0], s[1], s[2], s[3]), op.right_lever, op.left_lever, (d[0], d[1], d[2])

    @property
    def rc_changed_us(self) -> int:
        """Host time (µs, monotonic) of the last change of the virtual RC state."""
        return self._rc_changed_us

    def virtual_rc_frame(self) -> RcFrame | None:
        """The DBUS frame to send now (board client calls it every 14 ms); None when nobody holds control."""
        with self._lock:
            if self._holder is None:
                return None
            op = self._op
            return RcFrame(
                (op.sticks[0], op.sticks[1], op.sticks[2], op.sticks[3]),
                int(op.right_lever),
                int(op.left_lever),
            )

    # ------------------------------------------------------------------ commands

    def _forward(self, msg: Message, client: int | None = None) -> bool:
        send = self._send
        if send is None:
            self._refused(client, "no board to send it to (replay)")
            return False
        if isinstance(msg, Command):
            with self._lock:
                self._ack_owner[int(msg.code)] = (CLI_CLIENT if client is None else client, time.monotonic())
        ok = send(msg)
        with self._lock:
            if ok:
                self.commands_sent += 1
        if not ok:
            self._refused(client, "the board link is down")
        return ok

    def _refused(self, client: int | None, why: str) -> None:
        with self._lock:
            self.commands_refused += 1
        if client is not None and client != CLI_CLIENT:
            self._notify("warning", "Not sent", why, client=client)

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
            self._refused(client, f"{code.name}: this tab does not hold control")
            return False
        a = tuple(_finite(x) for x in args)
        if code == CommandCode.HOLD_LENGTHS:
            a = tuple(float(x) for x in args)  # NaN (unchanged) and ±inf (hold here / release) mean something
        elif code == CommandCode.SET_MODE:
            try:
                Mode(int(a[0]))
            except ValueError:
                self._refused(client, f"SET_MODE: no mode {a[0]:g}")
                return False
            a = (float(int(a[0])), 0.0, 0.0)
        elif code == CommandCode.SET_TENSIONS:
            hi = self.limits.tension_max_n
            a = tuple(min(max(x, 0.0), hi) for x in a)
        elif code == CommandCode.REQUIRE_HOST:
            a = (1.0 if a[0] else 0.0, 0.0, 0.0)
        else:
            a = (0.0, 0.0, 0.0)
        who = "the host" if client == CLI_CLIENT else f"Tab {client}"
        self.log("panel", "info", f"{code.name}{_args_text(a)} by {who}")
        return self._forward(Command(code, (a[0], a[1], a[2])), client)

    def estop(self, client: int) -> bool:
        """Emergency stop: any authorised client may press it; the levers also go to SAFE."""
        if not self.is_authorised(client):
            with self._lock:
                self.commands_refused += 1
            return False
        with self._lock:
            self._op.right_lever = Lever.DOWN
            self._op.sticks = [0, 0, 0, 0]
            self._rc_changed_us = time.monotonic_ns() // 1000
        ok = self._forward(Command(CommandCode.ESTOP), client)
        self._notify("error", "E-STOP pressed", f"by Tab {client}" if client != CLI_CLIENT else "by the host")
        self.log("panel", "error", "ESTOP by " + (f"Tab {client}" if client != CLI_CLIENT else "the host"))
        return ok

    def set_direct_tension(self, client: int, cable: int, tension_n: float) -> bool:
        """Set one cable's DIRECT-mode tension (clamped) and send all three (holder only)."""
        if not 0 <= cable <= 2:
            raise ValueError(f"cable must be 0..2, got {cable}")
        hi = self.limits.tension_max_n
        v = min(max(_finite(tension_n), 0.0), hi)
        with self._lock:
            if not self.has_control(client):
                self.commands_refused += 1
                return False
            self._op.direct_tensions_n[cable] = v
            t = tuple(self._op.direct_tensions_n)
        return self._forward(Command(CommandCode.SET_TENSIONS, (t[0], t[1], t[2])), client)

    def set_length_hold(self, client: int, cable: int, hold: bool) -> bool:
        """Hold one cable at its present length, or release it (``HOLD_LENGTHS``; holder only).

        The other cables are left as they are. The board refuses it in SAFE and drops every hold on a
        mode change; ``TelemetryFlags.HOLD_1..3`` tell which cables it holds.
        """
        if not 0 <= cable <= 2:
            raise ValueError(f"cable must be 0..2, got {cable}")
        if not self.has_control(client):
            with self._lock:
                self.commands_refused += 1
            return False
        args = [HOLD_UNCHANGED, HOLD_UNCHANGED, HOLD_UNCHANGED]
        args[cable] = HOLD_HERE if hold else HOLD_RELEASE
        return self._forward(Command(CommandCode.HOLD_LENGTHS, (args[0], args[1], args[2])), client)

    # ------------------------------------------------------------------ parameters

    def request_params(self) -> bool:
        """Ask the board for every parameter (it answers with one ``ParamValue`` each)."""
        send = self._send
        return send is not None and send(ParamRequest(PARAM_LIST_ALL))

    def set_param(self, client: int, name: str, value: float) -> str | None:
        """Ask the board to take ``value`` for parameter ``name`` (holder only); the board reads it back.

        Checked here first against the firmware's bounds (``controller.config``), so an out-of-range
        value is refused with its reason before it travels.

        Returns:
            None if sent (watch :attr:`param_status` for the board's answer), else why not.
        """
        if name not in PARAM_NAMES:
            return f"unknown parameter {name!r}"
        if not self.has_control(client):
            return "this tab does not hold control"
        v = float(value)
        with self._lock:
            values = dict(self.params)
        why = param_check(values, name, v)
        if why is not None:
            return why
        with self._lock:
            self.param_status[name] = ParamStatus(v, time.monotonic())
        who = "the host" if client == CLI_CLIENT else f"Tab {client}"
        self.log("panel", "info", f"set {name} = {v:g} by {who}")
        if not self._forward(ParamSet(name, v), client):
            with self._lock:
                self.param_status.pop(name, None)
            return "the board link is down"
        return None


def _args_text(args: tuple[float, ...]) -> str:
    shown = [f"{a:g}" for a in args if a != 0.0]
    return f" ({', '.join(shown)})" if shown else ""
