"""``--excite``: play an excitation profile on the board in DIRECT mode, for identifying the arm.

A lab records its arm while the host plays a profile (``hil.identify.excitation``: ramps, steps and a
multisine per cable) as ``SET_TENSIONS`` commands, then fits the plant to the recording (``spirob-hil
identify``). The board stays in charge of every limit (clamp, slew, pay-in governor, current limit) and
the pilot's right lever is the enable:

- the excitation waits for the board to report the right lever MIDDLE with phase OK, after having seen
  it elsewhere (DOWN, or no RC yet): a lever already MIDDLE when the host starts must go DOWN and back,
  so the arm never starts moving from a command typed at a desk. Meanwhile one line says what to do;
- then it asks for DIRECT (``SET_MODE``) and starts the profile when telemetry shows DIRECT; a refusal,
  or no DIRECT within :attr:`ExciteConfig.direct_wait_s`, ends it with the board's reason;
- it stops at once (no further command) when the lever goes DOWN, the board enters any failsafe phase,
  the board leaves DIRECT, the link goes down or telemetry stops; one line says why and the run fails;
- at the end it asks for MANUAL again, so the board returns to the sticks.

:class:`Excitation` is the logic, a sans-I/O state machine fed telemetry, link states and the answer to
its ``SET_MODE`` with the host's time, and polled for the commands to send (tests drive it in simulated
time); :class:`ExcitationDriver` is its thread, a board listener like the recorder: it sends through the
board client, writes the start into the recordings and says what happens.

The rate is :data:`COMMAND_RATE_HZ` (50 Hz), each command carrying the profile's tensions at the instant
it is sent. Faster would buy nothing: the firmware slews every target at 50 N/s (``SLEW_N_S``) on its
1 kHz tick, so between two commands 20 ms apart a cable's tension moves at most 1 N and the staircase of
commands reaches the cables as ramps; the multisine's fastest line (5 Hz) gets ten commands per period.
And the fit reads what the board commanded (``Telemetry.commanded_current``, 100 Hz), not what the host
sent, so a command a busy host sends late changes the excitation slightly, never the data's truth. Every
command is acknowledged and listed in the panel's event console, which a higher rate would only flood.
"""

from __future__ import annotations

import collections
import enum
import threading
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Final, Protocol

from controller.cli_kit import error_line
from host.link.source import LinkState
from host.options import PROG
from host.panel.notices import Notices
from host.worker import Worker
from protocol.dbus import Lever
from protocol.messages import AckResult, Command, CommandAck, CommandCode, Message, Mode, Phase, Telemetry

if TYPE_CHECKING:
    from hil.identify.excitation import Profile

__all__ = [
    "COMMAND_RATE_HZ",
    "EXCITATION_SCHEMA",
    "BoardClock",
    "Excitation",
    "ExcitationDriver",
    "ExciteConfig",
    "ExciteOutcome",
    "ExciteState",
    "ExciteStep",
    "Recorder",
    "operator_lines",
]

COMMAND_RATE_HZ: Final = 50.0
"""``SET_TENSIONS`` commands per second while the profile plays (module notes: why 50)."""

EXCITATION_SCHEMA: Final[dict[str, Any]] = {
    "$schema": "https://json-schema.org/draft/2020-12/schema",
    "title": "spirob.Excitation",
    "description": "the excitation profile the host played on the board (spirob-host --excite) and the "
    "board time at which it began",
    "type": "object",
    "properties": {
        "name": {"type": "string", "description": "the profile's name"},
        "duration_s": {"type": "number"},
        "rest_n": {"type": "number", "description": "tension on every cable at rest"},
        "peak_n": {"type": "number", "description": "the largest tension asked for"},
        "multisine_band_hz": {"type": "array", "items": {"type": "number"}, "minItems": 2, "maxItems": 2},
        "segments": {
            "type": "array",
            "description": "[kind, start_s, end_s, [cables]] in time order, seconds since the start",
            "items": {"type": "array", "minItems": 4, "maxItems": 4},
        },
        "start_us": {"type": "integer", "description": "board time (Telemetry.time_us) at the start"},
        "command_rate_hz": {"type": "number", "description": "SET_TENSIONS commands per second"},
    },
    "required": ["name", "duration_s", "rest_n", "peak_n", "segments", "start_us"],
    "additionalProperties": False,
}
"""The JSON schema of the start's message (``hil.identify.motor_data.EXCITATION_TOPIC``, where the fit
reads it): ``Profile.describe()`` plus the start."""


@dataclass(frozen=True, slots=True)
class ExciteConfig:
    """The driver's timing.

    Attributes:
        command_rate_hz: ``SET_TENSIONS`` per second.
        direct_wait_s: longest wait for telemetry to show DIRECT after asking for it.
        enable_wait_s: longest wait for the right lever MIDDLE (the operator's enable).
        telemetry_wait_s: longest wait for the first telemetry.
        telemetry_gap_s: a gap in telemetry this long while the profile plays stops it.
        progress_every_s: a progress line this often.
        guidance_after_s: what the operator must do is said once it has held this long (a radio on
            its way to MIDDLE, such as ``--virtual-rc manual``, gets no line).
    """

    command_rate_hz: float = COMMAND_RATE_HZ
    direct_wait_s: float = 2.0
    enable_wait_s: float = 120.0
    telemetry_wait_s: float = 10.0
    telemetry_gap_s: float = 1.0
    progress_every_s: float = 2.0
    guidance_after_s: float = 1.0

    def __post_init__(self) -> None:
        for name in ("command_rate_hz", "direct_wait_s", "enable_wait_s", "telemetry_wait_s"):
            if not getattr(self, name) > 0.0:
                raise ValueError(f"{name} must be > 0, got {getattr(self, name)}")
        if not (self.telemetry_gap_s > 0.0 and self.progress_every_s > 0.0 and self.guidance_after_s >= 0.0):
            raise ValueError("telemetry_gap_s and progress_every_s must be > 0, guidance_after_s >= 0")

    @property
    def period_us(self) -> int:
        """Microseconds between two commands."""
        return round(1e6 / self.command_rate_hz)


class ExciteState(enum.Enum):
    """Where an excitation is."""

    WAITING = "waiting for the right lever MIDDLE"
    ASKING = "asking for DIRECT"
    RUNNING = "playing the profile"
    COMPLETED = "completed"
    STOPPED = "stopped"
    FAILED = "did not start"


@dataclass(frozen=True, slots=True)
class ExciteOutcome:
    """How an excitation ended.

    Attributes:
        completed: the whole profile was played.
        state: ``COMPLETED``, ``STOPPED`` (it had begun) or ``FAILED`` (it never began).
        text: the final line.
    """

    completed: bool
    state: ExciteState
    text: str


@dataclass(slots=True)
class ExciteStep:
    """What one :meth:`Excitation.poll` (or another input) asks of its shell.

    Attributes:
        commands: to send, in order.
        lines: ``(level, text)`` to tell the operator: ``progress`` (the command line only), ``info``,
            ``error`` (the final line of an excitation that did not play to its end).
        started: the start's message (:data:`EXCITATION_SCHEMA`) when the profile began in this step.
        outcome: set in the step in which the excitation ended.
    """

    commands: list[Command] = field(default_factory=list)
    lines: list[tuple[str, str]] = field(default_factory=list)
    started: dict[str, Any] | None = None
    outcome: ExciteOutcome | None = None


class BoardClock:
    """The board's time on the host's clock, from the telemetry's stamps and arrival times.

    The offset (arrival minus board time) is the link's transit plus any host stall; its smallest value
    over the last ``window`` messages is the one with the least delay, so ``host - offset`` is the
    board's time now (short by the minimum transit, about a millisecond on USB). The window follows a
    board clock that drifts against the host's; a board restart (time going back) starts it again.

    Args:
        window: telemetry messages kept (128: about 1.3 s at 100 Hz).
    """

    def __init__(self, window: int = 128) -> None:
        self._offsets: collections.deque[int] = collections.deque(maxlen=window)
        self._last_us: int | None = None

    def on_telemetry(self, time_us: int, host_us: int) -> None:
        """One telemetry stamp and the host time it arrived."""
        if self._last_us is not None and time_us < self._last_us:
            self._offsets.clear()
        self._last_us = time_us
        self._offsets.append(host_us - time_us)

    def board_us(self, host_us: int) -> int | None:
        """The board's time at host time ``host_us`` (None before any telemetry)."""
        return host_us - min(self._offsets) if self._offsets else None


_NOT_OK: Final = {
    Phase.GATE: "right lever DOWN (the start-up gate)",
    Phase.RC_LOST: "no RC (RC_LOST): the radio on (or control taken in the panel), right lever DOWN",
    Phase.HOST_LOST: "host heartbeat lost (HOST_LOST): right lever DOWN to re-arm",
    Phase.MOTOR_FAULT: "motor fault latched (MOTOR_FAULT): check the motors, right lever DOWN to re-arm",
    Phase.ESTOP: "E-stop latched: clear it, right lever DOWN to re-arm",
}
"""The first step the operator must take in each phase but OK."""


def _guidance(t: Telemetry, armed: bool) -> str:
    """What the operator must do before the excitation can start."""
    if t.phase is not Phase.OK:
        first = _NOT_OK.get(t.phase, f"phase {t.phase.name}: right lever DOWN")
        return f"{first}, then MIDDLE to start the excitation"
    if t.right_lever == Lever.MIDDLE and not armed:
        return "the right lever is already MIDDLE: put it DOWN, then MIDDLE, to start the excitation"
    return "right lever MIDDLE starts the excitation (DOWN stops it)"


def _not_ready(t: Telemetry) -> str:
    """Why the board is not ready for DIRECT: the lever DOWN (first: it is the pilot's own stop), a
    failsafe phase, or the lever elsewhere."""
    if t.right_lever == Lever.DOWN:
        return "right lever DOWN (SAFE)"
    if t.phase is not Phase.OK:
        return f"failsafe phase {t.phase.name}"
    return "right lever UP (GRASP)" if t.right_lever == Lever.UP else "the right lever left MIDDLE"


def _stop_reason(t: Telemetry) -> str | None:
    """Why telemetry ends a running excitation: lever DOWN, a failsafe phase, or the board left DIRECT."""
    if t.right_lever == Lever.DOWN or t.phase is not Phase.OK:
        return _not_ready(t)
    if t.mode is not Mode.DIRECT:
        return f"the board left DIRECT (mode {t.mode.name})"
    return None


class Excitation:
    """The excitation's logic, without I/O: inputs with the host's time in µs, :meth:`poll` for output.

    Not thread-safe (:class:`ExcitationDriver` serialises the calls).

    Args:
        profile: the profile to play (``hil.identify.excitation.Profile``).
        config: timing.
        start_us: host time of creation (the waits count from it).
    """

    def __init__(self, profile: Profile, config: ExciteConfig | None = None, *, start_us: int = 0) -> None:
        self.profile = profile
        self.config = config or ExciteConfig()
        self.state = ExciteState.WAITING
        self.outcome: ExciteOutcome | None = None
        self.clock = BoardClock()
        self._created_us = start_us
        self._telemetry: Telemetry | None = None
        self._telemetry_host_us = 0
        self._armed = False
        """Telemetry has shown the board not ready (lever not MIDDLE or phase not OK) since creation."""
        self._said = ""
        self._guidance = ""
        self._guidance_since_us = 0
        self._asked_us = 0
        self._refusal: str | None = None
        self._stop: str | None = None
        self._started_host_us = 0
        self._next_progress_us = 0
        self._direct_seen = False
        self._link_down = False

    # ------------------------------------------------------------------ inputs

    @property
    def done(self) -> bool:
        """It ended (:attr:`outcome` says how)."""
        return self.outcome is not None

    def on_telemetry(self, t: Telemetry, host_us: int) -> None:
        """One telemetry message, arrived at host time ``host_us``."""
        self.clock.on_telemetry(t.time_us, host_us)
        self._telemetry = t
        self._telemetry_host_us = host_us
        if self.state is ExciteState.WAITING:
            if not (t.phase is Phase.OK and t.right_lever == Lever.MIDDLE):
                self._armed = True
        elif self.state is ExciteState.ASKING:
            if t.right_lever != Lever.MIDDLE or t.phase is not Phase.OK:
                self._stop = self._stop or _not_ready(t)
            elif t.mode is Mode.DIRECT and host_us >= self._asked_us:
                self._direct_seen = True
        elif self.state is ExciteState.RUNNING and self._stop is None:
            self._stop = _stop_reason(t)

    def on_link_state(self, state: LinkState) -> None:
        """The board link's state: down ends an excitation that has begun."""
        if state is LinkState.DISCONNECTED and self.state in (ExciteState.ASKING, ExciteState.RUNNING):
            self._link_down = True
            self._stop = self._stop or "the board link went down"

    def on_mode_ack(self, ack: CommandAck | None) -> None:
        """The board's answer to the ``SET_MODE DIRECT`` request (None: the link lost it)."""
        if self.state is not ExciteState.ASKING:
            return
        if ack is None:
            self._refusal = "the board link went down before the board answered"
        elif ack.result not in (AckResult.ACCEPTED, AckResult.IN_PROGRESS):
            self._refusal = f"the board refused DIRECT: {ack.text or ack.result.name.lower()}"

    def finish(self, reason: str, now_us: int) -> ExciteStep:
        """End it from outside (the run is over: ``--duration``, Ctrl-C); nothing if it already ended."""
        step = ExciteStep()
        if self.outcome is None:
            self._end(step, now_us, reason, hand_back=True)
        return step

    # ------------------------------------------------------------------ output

    def poll(self, now_us: int) -> ExciteStep:
        """Advance to host time ``now_us``: the commands to send and the lines to say."""
        step = ExciteStep()
        if self.state is ExciteState.WAITING:
            self._poll_waiting(step, now_us)
        elif self.state is ExciteState.ASKING:
            self._poll_asking(step, now_us)
        elif self.state is ExciteState.RUNNING:
            self._poll_running(step, now_us)
        return step

    def _poll_waiting(self, step: ExciteStep, now_us: int) -> None:
        t, cfg = self._telemetry, self.config
        waited_s = (now_us - self._created_us) / 1e6
        if t is None:
            if waited_s > cfg.telemetry_wait_s:
                self._fail(step, f"no telemetry from the board within {cfg.telemetry_wait_s:g} s")
            return
        if self._armed and t.phase is Phase.OK and t.right_lever == Lever.MIDDLE:
            self.state = ExciteState.ASKING
            self._asked_us = now_us
            # The first tensions before the mode: DIRECT starts at the profile's rest, not the pretension.
            step.commands.append(Command(CommandCode.SET_TENSIONS, self.profile.tensions_n(0.0)))
            step.commands.append(Command(CommandCode.SET_MODE, (float(Mode.DIRECT), 0.0, 0.0)))
            return
        text = _guidance(t, self._armed)
        if text != self._guidance:
            self._guidance, self._guidance_since_us = text, now_us
        if waited_s > cfg.enable_wait_s:
            self._fail(step, f"the board did not reach DIRECT within {cfg.enable_wait_s:g} s ({text})")
        elif text != self._said and now_us - self._guidance_since_us >= cfg.guidance_after_s * 1e6:
            self._said = text
            step.lines.append(("info", f"excitation {self.profile.name}: {text}"))

    def _poll_asking(self, step: ExciteStep, now_us: int) -> None:
        cfg = self.config
        if self._stop is not None:
            self._fail(step, self._stop)
        elif self._refusal is not None:
            self._fail(step, self._refusal)
        elif self._direct_seen:
            self._begin(step, now_us)
        elif now_us - self._asked_us > cfg.direct_wait_s * 1e6:
            self._fail(step, f"the board did not enter DIRECT within {cfg.direct_wait_s:g} s of the request")

    def _begin(self, step: ExciteStep, now_us: int) -> None:
        p = self.profile
        self.state = ExciteState.RUNNING
        self._started_host_us = now_us
        self._next_progress_us = now_us + round(self.config.progress_every_s * 1e6)
        board_us = self.clock.board_us(now_us)
        started = dict(p.describe())
        started["start_us"] = int(board_us if board_us is not None else 0)
        started["command_rate_hz"] = self.config.command_rate_hz
        step.started = started
        step.commands.append(Command(CommandCode.SET_TENSIONS, p.tensions_n(0.0)))
        step.lines.append(
            (
                "info",
                f"excitation {p.name} started: {p.duration_s:g} s, {len(p.segments)} segments "
                "(right lever DOWN stops it)",
            )
        )

    def _poll_running(self, step: ExciteStep, now_us: int) -> None:
        cfg, p = self.config, self.profile
        if self._stop is not None:  # the board stopped it (it has dropped DIRECT) or the link went down
            self._end(step, now_us, self._stop, hand_back=False)
            return
        if now_us - self._telemetry_host_us > cfg.telemetry_gap_s * 1e6:
            self._end(step, now_us, f"no telemetry for {cfg.telemetry_gap_s:g} s", hand_back=True)
            return
        t_s = (now_us - self._started_host_us) / 1e6
        if t_s >= p.duration_s:
            step.commands.append(Command(CommandCode.SET_TENSIONS, p.tensions_n(p.duration_s)))
            step.commands.append(Command(CommandCode.SET_MODE, (float(Mode.MANUAL), 0.0, 0.0)))
            self._set_outcome(
                step,
                ExciteOutcome(
                    True,
                    ExciteState.COMPLETED,
                    f"excitation {p.name} completed: {p.duration_s:g} s played; DIRECT handed back (MANUAL)",
                ),
            )
            return
        step.commands.append(Command(CommandCode.SET_TENSIONS, p.tensions_n(t_s)))
        if now_us >= self._next_progress_us:
            self._next_progress_us += round(cfg.progress_every_s * 1e6)
            step.lines.append(("progress", f"excitation {p.name}: {self.progress(t_s)}"))

    def progress(self, t_s: float) -> str:
        """``43 % · segment 4/7 steps (cable 2) · 8.3 s left`` at ``t_s`` seconds into the profile."""
        p = self.profile
        left_s = max(0.0, p.duration_s - t_s)
        return f"{100.0 * min(1.0, t_s / p.duration_s):.0f} % · {self.where(t_s)} · {left_s:.1f} s left"

    def where(self, t_s: float) -> str:
        """``segment 4/7 steps (cable 2)``: the segment playing ``t_s`` seconds into the profile."""
        p = self.profile
        seg = p.segment_at(t_s)
        if seg is None:
            return "after the last segment" if t_s >= p.duration_s else "before the first segment"
        cables = ", ".join(str(c + 1) for c in seg.cables)
        label = "cable" if len(seg.cables) == 1 else "cables"
        what = f"{seg.kind} ({label} {cables})" if seg.cables else seg.kind
        return f"segment {p.segments.index(seg) + 1}/{len(p.segments)} {what}"

    # ------------------------------------------------------------------ endings

    def _fail(self, step: ExciteStep, why: str) -> None:
        if self.state is ExciteState.ASKING:
            step.commands.append(Command(CommandCode.SET_MODE, (float(Mode.MANUAL), 0.0, 0.0)))
        text = f"excitation {self.profile.name} did not start: {why}"
        self._set_outcome(step, ExciteOutcome(False, ExciteState.FAILED, text))

    def _end(self, step: ExciteStep, now_us: int, why: str, *, hand_back: bool) -> None:
        """Stop a running excitation (or fail one that never began); ``hand_back``: ask a board that may
        still hold our tensions (its last telemetry said DIRECT) to return to the sticks. A stop the board
        caused (lever DOWN, failsafe, another mode) sends nothing: the board has dropped DIRECT itself."""
        if self.state is not ExciteState.RUNNING:
            self._fail(step, why)
            return
        t = self._telemetry
        if hand_back and not self._link_down and t is not None and t.mode is Mode.DIRECT:
            step.commands.append(Command(CommandCode.SET_MODE, (float(Mode.MANUAL), 0.0, 0.0)))
        p = self.profile
        t_s = (now_us - self._started_host_us) / 1e6
        text = f"excitation {p.name} stopped after {t_s:.1f} of {p.duration_s:g} s ({self.where(t_s)}): {why}"
        self._set_outcome(step, ExciteOutcome(False, ExciteState.STOPPED, text))

    def _set_outcome(self, step: ExciteStep, outcome: ExciteOutcome) -> None:
        self.state = outcome.state
        self.outcome = step.outcome = outcome
        step.lines.append(("info" if outcome.completed else "error", outcome.text))


class Recorder(Protocol):
    """Where the excitation's start and end are written (``LinkRecording``, the panel's switch)."""

    def write_json(self, topic: str, obj: Mapping[str, Any], schema: Mapping[str, Any]) -> None:
        """Record one JSON message on ``topic`` now."""

    def write_event(self, text: str, *, warning: bool = False) -> None:
        """Record one line on the recording's event channel now."""


SendFn = Callable[[Message, Callable[[CommandAck | None], None] | None], bool]
"""Sends one message to the board with an answer handler for a command (``BoardClient.send``)."""
SayFn = Callable[[str, str], None]
"""Tells the operator one line: ``(level, text)``."""


def operator_lines(notices: Notices | None = None) -> SayFn:
    """Lines for the operator: ``progress`` to stdout only; ``info`` to stdout, ``error`` as the command
    line's one error line on stderr, both also in the panel (event console and a notification)."""

    def say(level: str, text: str) -> None:
        if level == "error":
            error_line(PROG, text)
        else:
            print(f"{PROG}: {text}", flush=True)
        if notices is not None and level != "progress":
            notices.log("excite", level, text)
            notices.notify("error" if level == "error" else "info", "Excitation", text)

    return say


def _host_us() -> int:
    return time.monotonic_ns() // 1000


class ExcitationDriver:
    """Plays an :class:`Excitation` on the board from a thread: a listener of the board client.

    Args:
        profile: the profile.
        send: sends a message (``BoardClient.send`` with this driver's origin and an answer handler).
        say: tells the operator one line (the command line and the panel's notices).
        recorders: where the start and the end are recorded (``--record``'s file, the panel's switch,
            which writes only while it records).
        config: timing.
        clock_us: the host's clock in µs (tests pass their own).
    """

    def __init__(
        self,
        profile: Profile,
        send: SendFn,
        say: SayFn,
        recorders: Sequence[Recorder] = (),
        *,
        config: ExciteConfig | None = None,
        clock_us: Callable[[], int] = _host_us,
    ) -> None:
        self._send = send
        self._say = say
        self._recorders = tuple(recorders)
        self._clock_us = clock_us
        self._lock = threading.Lock()
        self.excitation = Excitation(profile, config, start_us=clock_us())
        self.done = threading.Event()
        """Set when the excitation has ended (:attr:`outcome`)."""
        self._worker = Worker("excite", self._run)

    @property
    def outcome(self) -> ExciteOutcome | None:
        """How it ended (None while it runs)."""
        return self.excitation.outcome

    def start(self) -> None:
        """Start the thread."""
        self._worker.start()

    def stop(self, reason: str = "the run ended before the profile did") -> ExciteOutcome | None:
        """End it (if it has not ended: ``reason`` is why) and stop the thread; safe twice."""
        self._worker.stop()
        with self._lock:
            step = self.excitation.finish(reason, self._clock_us())
        self._carry_out(step)
        return self.outcome

    # ------------------------------------------------------------------ listeners (board client thread)

    def on_board_message(self, msg: Message) -> None:
        """Listener: telemetry feeds the state machine."""
        if isinstance(msg, Telemetry):
            now = self._clock_us()
            with self._lock:
                self.excitation.on_telemetry(msg, now)

    def on_link_state(self, state: LinkState) -> None:
        """State listener: a link going down ends a running excitation."""
        with self._lock:
            self.excitation.on_link_state(state)

    def _on_mode_ack(self, ack: CommandAck | None) -> None:
        if ack is not None and ack.result is AckResult.IN_PROGRESS:
            return
        with self._lock:
            self.excitation.on_mode_ack(ack)

    # ------------------------------------------------------------------ the thread

    def _run(self) -> None:
        stop = self._worker.stop_event
        period_us = self.excitation.config.period_us
        deadline = self._clock_us()
        while not stop.is_set():
            now = self._clock_us()
            with self._lock:
                step = self.excitation.poll(now)
            self._carry_out(step)
            if self.excitation.done:
                return
            # Absolute deadlines; a late pass skips the missed ones (each command carries the profile's
            # value at its own instant, so nothing is owed).
            deadline += period_us
            now = self._clock_us()
            if deadline < now:
                deadline = now + period_us - (now - deadline) % period_us
            stop.wait((deadline - now) / 1e6)

    def _carry_out(self, step: ExciteStep) -> None:
        if step.started is not None:
            # The topic the fit reads (hil is imported by the host only where it is used).
            from hil.identify.motor_data import EXCITATION_TOPIC  # type: ignore[import-not-found,unused-ignore]

            board_s = step.started["start_us"] / 1e6
            for rec in self._recorders:
                rec.write_json(EXCITATION_TOPIC, step.started, EXCITATION_SCHEMA)
                rec.write_event(f"excitation {step.started['name']} started at board time {board_s:.3f} s")
        for cmd in step.commands:
            on_ack = self._on_mode_ack if cmd.code == CommandCode.SET_MODE and self._asking() else None
            if not self._send(cmd, on_ack) and cmd.code == CommandCode.SET_TENSIONS:
                with self._lock:
                    self.excitation.on_link_state(LinkState.DISCONNECTED)
                break
        for level, text in step.lines:
            self._say(level, text)
        if step.outcome is not None:
            for rec in self._recorders:
                rec.write_event(step.outcome.text, warning=not step.outcome.completed)
            self.done.set()

    def _asking(self) -> bool:
        return self.excitation.state is ExciteState.ASKING
