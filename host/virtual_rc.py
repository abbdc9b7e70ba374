"""The command line holds the virtual radio, a client of the control arbiter: ``--virtual-rc`` and
``--virtual-rc-script``.

``--virtual-rc`` (:class:`VirtualRcDriver`): like the gamepad (``host.gamepad``) it drives the arbiter as
the command line's client: it takes control, puts both levers DOWN (the board's start-up gate), waits
until the board reports the right lever DOWN (or 1 s), then moves the right lever to the requested
position and leaves it there. A browser tab that asks for control gets it (nobody at the command line
can click "grant").

``--virtual-rc-script FILE`` (:class:`RadioScript`, :class:`ScriptRun`, :class:`ScriptDriver`): a
timeline of lever and stick positions in TOML, each step waiting for board time and for what the board
reports (``until = { grasp = "HOLD" }``), for headless runs that must end in a verdict: the run ends
with the script, exit 0 only if every step was reached.
"""

from __future__ import annotations

import collections
import enum
import logging
import math
import threading
import time
import tomllib
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Final

from host.panel.arbiter import CLI_CLIENT, ControlArbiter, ControlResult
from host.panel.board_state import BoardState
from host.run_summary import FAILSAFE_PHASES
from host.worker import Worker
from protocol.dbus import CH_LIMIT, Lever
from protocol.messages import GraspState, Message, Mode, Phase, Telemetry

__all__ = [
    "STICKS",
    "Condition",
    "Radio",
    "RadioScript",
    "ScriptDriver",
    "ScriptError",
    "ScriptRun",
    "ScriptState",
    "ScriptStep",
    "VirtualRcDriver",
]

_log = logging.getLogger(__name__)

_GATE_WAIT_S = 1.0
"""Longest wait for the board to report the right lever DOWN before the requested lever."""
_POLL_S = 0.02
_SETTLE_S = 0.1
"""Pause after DOWN was seen, then between checks for a tab asking for control."""


class VirtualRcDriver:
    """Drives the arbiter's radio from the command line in a thread: DOWN first, then ``lever``.

    Args:
        arbiter: the control arbiter.
        board: the board's state (to see the right lever DOWN arrive).
        lever: the right lever's position to drive with (``DOWN`` = SAFE, ``MIDDLE``, ``UP``).
    """

    def __init__(self, arbiter: ControlArbiter, board: BoardState, lever: Lever) -> None:
        self.arbiter = arbiter
        self.board = board
        self.lever = lever
        self._worker = Worker("virtual-rc", self._run)
        self._stop = self._worker.stop_event

    def start(self) -> None:
        """Start the thread (it takes control first)."""
        self._worker.start()

    def stop(self) -> None:
        """Stop the thread; safe twice (control stays where it is: the arbiter's holder)."""
        self._worker.stop()

    def _run(self) -> None:
        a = self.arbiter
        a.request_control(CLI_CLIENT)
        a.set_lever(CLI_CLIENT, "right", Lever.DOWN)
        a.set_lever(CLI_CLIENT, "left", Lever.DOWN)
        # DOWN first: wait until the board reports it (or 1 s), then the requested lever.
        deadline = time.monotonic() + _GATE_WAIT_S
        while not self._stop.is_set() and time.monotonic() < deadline:
            t = self.board.telemetry
            if t is not None and t.right_lever == Lever.DOWN and t.rc_frames_ok > 0:
                break
            self._stop.wait(_POLL_S)
        self._stop.wait(_SETTLE_S)
        if not self._stop.is_set():
            a.set_lever(CLI_CLIENT, "right", self.lever)
        while not self._stop.wait(_SETTLE_S):
            # The command line hands control to a browser tab that asks for it.
            if a.holder == CLI_CLIENT and a.pending is not None:
                _log.info("handing control to browser tab %s", a.pending)
                a.answer_request(CLI_CLIENT, grant=True)


# ---------------------------------------------------------------------- --virtual-rc-script


class ScriptError(ValueError):
    """A radio script that cannot be run (the message is one line, naming the step)."""


STICKS: Final = ("right_x", "right_y", "left_x", "left_y")
"""A script's stick names, in DBUS channel order (ch0 right horizontal .. ch3 left vertical)."""

_STEP_KEYS: Final = frozenset({"say", "right", "left", "sticks", "for_s", "until", "keep", "timeout_s"})
_CONDITION_ENUMS: Final[dict[str, type[enum.IntEnum]]] = {"mode": Mode, "phase": Phase, "grasp": GraspState}
_DEFAULT_TIMEOUT_S: Final = 30.0
"""A step's longest host time beyond its ``for_s`` unless it says ``timeout_s``."""


@dataclass(frozen=True, slots=True)
class Condition:
    """What the board must report (each field None = any): a step's ``until`` or ``keep``."""

    mode: Mode | None = None
    phase: Phase | None = None
    grasp: GraspState | None = None

    def met(self, t: Telemetry) -> bool:
        """Every given field equals the telemetry's."""
        return (
            (self.mode is None or t.mode == self.mode)
            and (self.phase is None or t.phase == self.phase)
            and (self.grasp is None or t.grasp_state == self.grasp)
        )

    def describe(self) -> str:
        """``mode GRASP, grasp HOLD``."""
        parts = [(k, getattr(self, k)) for k in _CONDITION_ENUMS]
        return ", ".join(f"{k} {v.name}" for k, v in parts if v is not None)


@dataclass(frozen=True, slots=True)
class Radio:
    """What the scripted radio sends: sticks in DBUS counts (ch0..ch3) and both levers."""

    sticks: tuple[int, int, int, int] = (0, 0, 0, 0)
    right: Lever = Lever.DOWN
    left: Lever = Lever.DOWN

    def echoed_by(self, t: Telemetry) -> bool:
        """The board reports this radio as its last accepted frame."""
        return (
            tuple(t.rc_channels) == self.sticks and t.right_lever == self.right and t.left_lever == self.left
        )


@dataclass(frozen=True, slots=True)
class ScriptStep:
    """One step of a radio script.

    Attributes:
        number: 1-based, as people count them.
        say: its label (printed when it starts).
        right: the right lever from this step on (None: unchanged).
        left: the left lever (None: unchanged).
        sticks: channel -> DBUS counts from this step on (others unchanged).
        for_s: board time the step lasts at least, from the first telemetry that shows its radio.
        until: what the board must report before the step ends (None: nothing).
        keep: what the board must report throughout the step (None: nothing).
        timeout_s: host time the step may take at most (before the load stretches it).
    """

    number: int
    say: str = ""
    right: Lever | None = None
    left: Lever | None = None
    sticks: tuple[tuple[int, int], ...] = ()
    for_s: float = 0.0
    until: Condition | None = None
    keep: Condition | None = None
    timeout_s: float = _DEFAULT_TIMEOUT_S

    def apply(self, radio: Radio) -> Radio:
        """The radio after this step's changes."""
        sticks = list(radio.sticks)
        for ch, value in self.sticks:
            sticks[ch] = value
        return Radio(
            (sticks[0], sticks[1], sticks[2], sticks[3]),
            radio.right if self.right is None else self.right,
            radio.left if self.left is None else self.left,
        )

    def allows(self, phase: Phase, grasp: GraspState) -> bool:
        """A failsafe phase or a FAILED grasp ends the script, unless this step asks for it."""
        asked = [c for c in (self.until, self.keep) if c is not None]
        bad_phase = phase in FAILSAFE_PHASES and not any(c.phase == phase for c in asked)
        bad_grasp = grasp == GraspState.FAILED and not any(c.grasp == grasp for c in asked)
        return not (bad_phase or bad_grasp)

    def describe(self) -> str:
        """``grasp: left lever UP (until grasp HOLD)``."""
        moves = []
        if self.right is not None:
            moves.append(f"right lever {self.right.name}")
        if self.left is not None:
            moves.append(f"left lever {self.left.name}")
        moves += [f"{STICKS[ch]} {v:+d}" for ch, v in self.sticks]
        what = ", ".join(moves) or "radio unchanged"
        waits = []
        if self.for_s > 0:
            waits.append(f"for {self.for_s:g} s")
        if self.until is not None:
            waits.append(f"until {self.until.describe()}")
        if self.keep is not None:
            waits.append(f"keeping {self.keep.describe()}")
        text = f"{self.say}: {what}" if self.say else what
        return f"{text} ({'; '.join(waits)})" if waits else text


@dataclass(frozen=True, slots=True)
class RadioScript:
    """A timeline of lever and stick positions for ``spirob-host --virtual-rc-script FILE`` (TOML).

    Each ``[[step]]`` sets the levers and sticks it names (the others stay as they were; the radio starts
    with sticks centred and both levers DOWN), then lasts until the board has reported its radio and
    ``for_s`` seconds of board time have passed and ``until`` holds; ``keep`` must hold on every
    telemetry of the step. See docs/host.md (*Scripted radio*).
    """

    path: str
    steps: tuple[ScriptStep, ...]

    @classmethod
    def load(cls, path: str | Path) -> RadioScript:
        """Read and check a script file.

        Raises:
            ScriptError: unreadable, not TOML, or a step that is not valid (one line, naming it).
        """
        p = Path(path)
        try:
            data = tomllib.loads(p.read_text(encoding="utf-8"))
        except FileNotFoundError:
            raise ScriptError("no such file") from None
        except OSError as exc:
            raise ScriptError(exc.strerror or str(exc)) from None
        except UnicodeDecodeError:
            raise ScriptError("not a text file") from None
        except tomllib.TOMLDecodeError as exc:
            raise ScriptError(f"not TOML: {exc}") from None
        return cls.parse(data, str(p))

    @classmethod
    def parse(cls, data: dict[str, Any], path: str = "<script>") -> RadioScript:
        """Check a script already read from TOML.

        Raises:
            ScriptError: not a valid script (one line, naming the step).
        """
        unknown = sorted(set(data) - {"step"})
        if unknown:
            raise ScriptError(f"unknown top-level key {unknown[0]!r} (a script is a list of [[step]] tables)")
        raw = data.get("step")
        if not isinstance(raw, list) or not raw:
            raise ScriptError("no [[step]] tables: a script is a list of steps")
        return cls(path, tuple(_parse_step(n, s) for n, s in enumerate(raw, start=1)))


def _parse_step(number: int, raw: object) -> ScriptStep:
    where = f"step {number}"
    if not isinstance(raw, dict):
        raise ScriptError(f"{where}: not a table")
    unknown = sorted(set(raw) - _STEP_KEYS)
    if unknown:
        raise ScriptError(f"{where}: unknown key {unknown[0]!r} (known: {', '.join(sorted(_STEP_KEYS))})")
    say = raw.get("say", "")
    if not isinstance(say, str):
        raise ScriptError(f"{where}: say must be text")
    right = _lever_of(raw.get("right"), f"{where}: right")
    left = _lever_of(raw.get("left"), f"{where}: left")
    sticks = _sticks_of(raw.get("sticks", {}), f"{where}: sticks")
    for_s = _seconds(raw.get("for_s", 0.0), f"{where}: for_s", zero_ok=True)
    until = _condition_of(raw.get("until"), f"{where}: until")
    keep = _condition_of(raw.get("keep"), f"{where}: keep")
    timeout_s = _seconds(raw.get("timeout_s", for_s + _DEFAULT_TIMEOUT_S), f"{where}: timeout_s")
    if timeout_s <= for_s:
        raise ScriptError(f"{where}: timeout_s ({timeout_s:g} s) must be longer than for_s ({for_s:g} s)")
    if right is None and left is None and not sticks and for_s == 0 and until is None:
        raise ScriptError(f"{where}: does nothing (give right, left, sticks, for_s or until)")
    return ScriptStep(number, say, right, left, sticks, for_s, until, keep, timeout_s)


def _lever_of(value: object, where: str) -> Lever | None:
    if value is None:
        return None
    if isinstance(value, str) and value.upper() in ("UP", "MIDDLE", "DOWN"):
        return Lever[value.upper()]
    raise ScriptError(f"{where}: {value!r} is not a lever position (UP, MIDDLE or DOWN)")


def _sticks_of(value: object, where: str) -> tuple[tuple[int, int], ...]:
    if not isinstance(value, dict):
        raise ScriptError(f"{where}: not a table (e.g. sticks = {{ left_y = 300 }})")
    out = []
    for name, v in value.items():
        if name not in STICKS:
            raise ScriptError(f"{where}: unknown stick {name!r} (known: {', '.join(STICKS)})")
        if isinstance(v, bool) or not isinstance(v, int) or not -CH_LIMIT <= v <= CH_LIMIT:
            raise ScriptError(f"{where}: {name} = {v!r} is not a whole number of counts in ±{CH_LIMIT}")
        out.append((STICKS.index(name), v))
    return tuple(sorted(out))


def _seconds(value: object, where: str, *, zero_ok: bool = False) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ScriptError(f"{where}: {value!r} is not a number of seconds")
    v = float(value)
    if not math.isfinite(v) or v < 0 or (v == 0 and not zero_ok) or v > 3600:
        bound = "0..3600" if zero_ok else "more than 0, at most 3600"
        raise ScriptError(f"{where}: {value!r} s is out of range ({bound})")
    return v


def _condition_of(value: object, where: str) -> Condition | None:
    if value is None:
        return None
    if not isinstance(value, dict) or not value:
        raise ScriptError(f'{where}: not a table of board states (e.g. until = {{ grasp = "HOLD" }})')
    fields: dict[str, Any] = {}
    for key, v in value.items():
        kind = _CONDITION_ENUMS.get(key)
        if kind is None:
            raise ScriptError(f"{where}: unknown key {key!r} (known: {', '.join(_CONDITION_ENUMS)})")
        names = [m.name for m in kind]
        if not isinstance(v, str) or v.upper() not in names:
            raise ScriptError(f"{where}: {key} = {v!r} is not one of {', '.join(names)}")
        fields[key] = kind[v.upper()]
    return Condition(**fields)


class ScriptState(enum.Enum):
    """Where a :class:`ScriptRun` is."""

    RUNNING = "running"
    DONE = "done"
    FAILED = "failed"


class ScriptRun:
    """A radio script played against the board's telemetry: sans-I/O, fed telemetry with the host's time.

    Call :meth:`start`, then :meth:`on_telemetry` for every telemetry and :meth:`poll` now and then (for
    the timeouts); :attr:`radio` is what the radio must send. A step's conditions are judged only on
    telemetry that shows its radio as the board's last accepted frame (earlier telemetry was sent before
    the board took the new radio), and its ``for_s`` counts board time from the first such telemetry.
    The script fails at once when the board enters a failsafe phase or the grasp FAILS (unless the
    step's ``until`` or ``keep`` names that state), when a ``keep`` does not hold, or when a step takes
    longer than its ``timeout_s`` (times ``timeout_scale``) of host time.

    Args:
        script: the script.
        timeout_scale: stretches every ``timeout_s`` (the host's load, ``load_scaled_s``).
    """

    def __init__(self, script: RadioScript, timeout_scale: float = 1.0) -> None:
        self.script = script
        self.timeout_scale = timeout_scale
        self.state = ScriptState.RUNNING
        self.radio = Radio()
        self.index = -1
        """The running step's index in ``script.steps`` (-1 before :meth:`start`)."""
        self.reason = ""
        """Why it failed (one line), or what it did."""
        self._started_s = 0.0
        self._step_started_s = 0.0
        self._echo_us: int | None = None
        self._first_us: int | None = None
        self._last: Telemetry | None = None

    @property
    def step(self) -> ScriptStep | None:
        """The running step."""
        steps = self.script.steps
        return (
            steps[self.index] if 0 <= self.index < len(steps) and self.state is ScriptState.RUNNING else None
        )

    def start(self, host_s: float) -> Radio:
        """Enter the first step; the radio to send."""
        self._started_s = host_s
        self._enter(0, host_s)
        return self.radio

    def _enter(self, index: int, host_s: float) -> None:
        self.index = index
        self._step_started_s = host_s
        self._echo_us = None
        if index >= len(self.script.steps):
            self.state = ScriptState.DONE
            span = ""
            if self._first_us is not None and self._last is not None:
                span = f" in {(self._last.time_us - self._first_us) / 1e6:.1f} s of board time"
            self.reason = f"all {len(self.script.steps)} steps done{span}"
            return
        self.radio = self.script.steps[index].apply(self.radio)

    def fail(self, why: str) -> None:
        """End the script as failed: ``why``, with the running step and what the board last reported."""
        step = self.step
        label = "script"
        if step is not None:
            label = f"step {step.number}" + (f" ({step.say})" if step.say else "")
        self.state = ScriptState.FAILED
        last = self._last
        seen = (
            "no telemetry"
            if last is None
            else f"mode {last.mode.name}, phase {last.phase.name}, grasp {last.grasp_state.name}"
        )
        self.reason = f"{label}: {why} (the board: {seen})"

    def on_telemetry(self, t: Telemetry, host_s: float) -> None:
        """One telemetry message, received at host time ``host_s``."""
        self._last = t
        if self._first_us is None:
            self._first_us = t.time_us
        step = self.step
        if step is None:
            return
        if not step.allows(t.phase, t.grasp_state):
            what = f"grasp {t.grasp_state.name}" if t.grasp_state == GraspState.FAILED else t.phase.name
            self.fail(f"the board entered {what}")
            return
        if self._echo_us is None:
            if not self.radio.echoed_by(t):
                return
            self._echo_us = t.time_us
        if step.keep is not None and not step.keep.met(t):
            self.fail(f"{step.keep.describe()} did not hold")
            return
        long_enough = t.time_us - self._echo_us >= round(step.for_s * 1e6)
        if long_enough and (step.until is None or step.until.met(t)):
            self._enter(self.index + 1, host_s)

    def poll(self, host_s: float) -> None:
        """Check the running step's timeout at host time ``host_s``."""
        step = self.step
        if step is None:
            return
        limit_s = step.timeout_s * self.timeout_scale
        if host_s - self._step_started_s > limit_s:
            if self._echo_us is None:
                self.fail(f"the board did not report this step's radio within {limit_s:.0f} s")
            elif step.until is not None:
                self.fail(f"{step.until.describe()} not reached within {limit_s:.3g} s")
            else:
                self.fail(f"{step.for_s:g} s of board time did not pass within {limit_s:.0f} s")


Say = Callable[[str, str], None]
"""Tells the operator one line: ``(level, text)``, level ``info`` or ``error``."""


class ScriptDriver:
    """Plays a :class:`RadioScript` on the arbiter's radio from a thread, as the command line's client.

    A board listener (:meth:`on_board_message`) queues telemetry; the thread takes control, feeds the
    :class:`ScriptRun`, pushes its radio (one frame per change) and says each step. It keeps control to
    the end: a browser tab that asks waits (E-stop stays open to every tab). :attr:`done` is set when the
    script ended, either way; :attr:`run` tells how.

    Args:
        arbiter: the control arbiter.
        script: the script.
        say: tells the operator one line.
        timeout_scale: stretches every step's ``timeout_s`` (the host's load).
    """

    def __init__(
        self, arbiter: ControlArbiter, script: RadioScript, say: Say, timeout_scale: float = 1.0
    ) -> None:
        self.arbiter = arbiter
        self.run = ScriptRun(script, timeout_scale)
        self._say = say
        self.done = threading.Event()
        self._inbox: collections.deque[tuple[Telemetry, float]] = collections.deque(maxlen=_INBOX_N)
        self._lock = threading.Lock()
        self._worker = Worker("virtual-rc-script", self._loop)

    def on_board_message(self, msg: Message) -> None:
        """Listener: telemetry, queued with the host's time (the thread judges it)."""
        if isinstance(msg, Telemetry):
            self._inbox.append((msg, time.monotonic()))

    def start(self) -> None:
        """Start the thread (it takes control first)."""
        self._worker.start()

    def stop(self, reason: str = "the run ended before the script did") -> ScriptState:
        """Stop the thread; a script still running fails with ``reason``. Safe twice; the final state."""
        self._worker.stop()
        with self._lock:
            if self.run.state is ScriptState.RUNNING:
                self.run.state = ScriptState.FAILED
                self.run.reason = reason
                self._say("error", f"{_NAME}: {reason}")
        self.done.set()
        return self.run.state

    def _loop(self) -> None:
        a, run, stop = self.arbiter, self.run, self._worker.stop_event
        if a.request_control(CLI_CLIENT) is not ControlResult.GRANTED:
            with self._lock:
                run.fail("a browser tab holds control")
        else:
            with self._lock:
                radio = run.start(time.monotonic())
            self._push(radio)
            index = -1
            while not stop.is_set():
                with self._lock:
                    if run.state is not ScriptState.RUNNING:
                        break
                    while self._inbox:
                        t, host_s = self._inbox.popleft()
                        run.on_telemetry(t, host_s)
                    run.poll(time.monotonic())
                    radio, step = run.radio, run.step
                if step is not None and run.index != index:
                    index = run.index
                    n = len(run.script.steps)
                    self._say("info", f"{_NAME} step {step.number}/{n}: {step.describe()}")
                if not self._push(radio):
                    with self._lock:
                        run.fail("the command line lost control of the radio")
                    break
                stop.wait(_POLL_S)
        with self._lock:
            state, reason = run.state, run.reason
        if state is ScriptState.DONE:
            self._say("info", f"{_NAME}: {reason}")
        elif state is ScriptState.FAILED:
            self._say("error", f"{_NAME}: {reason}")
        if state is not ScriptState.RUNNING:
            self.done.set()

    def _push(self, radio: Radio) -> bool:
        """Send ``radio`` (the arbiter pushes only a change); False if the command line lost control."""
        return self.arbiter.set_radio(CLI_CLIENT, radio.sticks, radio.right, radio.left)


_NAME: Final = "--virtual-rc-script"
_INBOX_N: Final = 4096
"""Telemetry held for the thread (40 s at 100 Hz: it drains every 20 ms)."""
