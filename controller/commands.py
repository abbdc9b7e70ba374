"""The command and parameter server on the board link (Betaflight's ``msp/`` counterpart).

:class:`CommandServer` runs on the ``link_rx`` task: it takes every frame the host sent since the last
tick and answers it — ``Heartbeat`` to the failsafe, ``VirtualRc`` to a link RC source, ``Command`` with
a ``CommandAck`` (same sequence number), ``ParamRequest`` / ``ParamSet`` with ``ParamValue``.
:class:`Params` holds the runtime configuration (``ParamSet`` replaces it, validated).
:class:`GraspAcks` owes the host the final acks of GRASP and RELEASE (MAVLink ``DO_GRIPPER`` waits for
them), sent with the next ``link_rx`` tick.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

from controller.cables import CableMapper
from controller.config import FirmwareConfig
from controller.errors import ConfigError
from controller.events import EventQueue
from controller.failsafe import Failsafe
from controller.grasp import GraspMachine, grasp_refusal
from controller.hostlink import BoardLink
from controller.lengthhold import LengthHold
from controller.modes import GRASP_STICK_MIN, ModeSelector
from controller.params import PARAM_FIELDS, PARAMS
from controller.rc import LinkRcSource, RcInput, RcSource
from protocol.dbus import Lever
from protocol.link import LinkFrame
from protocol.messages import (
    PARAM_INDEX_BY_NAME,
    PARAM_LIST_ALL,
    AckResult,
    Command,
    CommandAck,
    CommandCode,
    EventKind,
    GraspState,
    Heartbeat,
    Message,
    Mode,
    ParamRequest,
    ParamSet,
    ParamValue,
    Phase,
    VirtualRc,
    truncate_utf8,
)

__all__ = ["ACK_TEXT_MAX", "PARAM_VALUES_PER_TICK", "CommandServer", "GraspAcks", "Params"]

ACK_TEXT_MAX = 48
"""Longest ``CommandAck`` text the board sends (bytes)."""
PARAM_VALUES_PER_TICK = 4
"""``ParamValue`` answers to a list-all request sent per ``link_rx`` tick (the whole list in 11 ms): a
flood of list requests costs one bounded slice of each tick, as MAVLink streams its parameter list."""


class Params:
    """The runtime configuration and the one way to change it.

    A refused value leaves the old one in force (the ``ParamValue`` answer carries it) and logs a PARAM
    event ``rejected: <why>``: a value :meth:`FirmwareConfig.validate` refuses, a hardware ceiling, or a
    safety parameter (``controller.params.SAFETY_PARAMS``) set outside SAFE: the rule of
    :meth:`~controller.config.FirmwareConfig.with_param`.

    Args:
        config: the start-up configuration.
        events: where accepted and rejected changes are logged.
        apply: hands a new configuration to every component (called on each accepted change).
        safe: True while no current can flow (mode SAFE): safety parameters may change.
    """

    def __init__(
        self,
        config: FirmwareConfig,
        events: EventQueue,
        apply: Callable[[FirmwareConfig], None],
        safe: Callable[[], bool],
    ) -> None:
        """Hold ``config`` (already applied by the caller)."""
        self.config = config
        self._events = events
        self._apply = apply
        self._safe = safe
        self.refused: str | None = None
        """Why the last :meth:`set` was refused, or None if it was taken (a command acks with it)."""

    def set(self, now_us: int, name: str, value: float) -> float:
        """Set a runtime parameter (wire name) if valid and allowed now; return the value in force afterwards.

        Raises:
            ConfigError: unknown name (an invalid or refused value is not an error: the old value stays).
        """
        if name not in PARAM_FIELDS:
            raise ConfigError(f"unknown parameter {name!r}")
        try:
            new = self.config.with_param(name, value, safe=self._safe())
        except ConfigError as exc:
            self.refused = str(exc)
            self._events.push(now_us, EventKind.PARAM, PARAMS.index(name), value, f"rejected: {exc}")
            return self.config.get_param(name)
        self.refused = None
        self.config = new
        self._apply(new)
        now_value = new.get_param(name)
        self._events.push(now_us, EventKind.PARAM, PARAMS.index(name), now_value, f"{name} = {now_value:g}")
        return now_value


class GraspAcks:
    """Final acks owed for host GRASP / RELEASE commands (a :class:`~controller.modes.GraspListener`).

    Args:
        enabled: a host link exists (without one nothing is owed or queued).

    Attributes:
        pending: acks to send with the next ``link_rx`` tick.
    """

    def __init__(self, enabled: bool) -> None:
        """Owe nothing."""
        self._enabled = enabled
        self.pending: list[Message] = []
        self.grasp_seq = -1  # link seq of a host GRASP awaiting its final ack
        self.release_seq = -1

    def grasp_progress(self, state: GraspState) -> None:
        """Final acks on HOLD / FAILED / RELEASE (GRASP) and IDLE (RELEASE)."""
        if self.grasp_seq >= 0:
            if state == GraspState.HOLD:
                self._later(CommandCode.GRASP, AckResult.ACCEPTED, self.grasp_seq, "holding")
                self.grasp_seq = -1
            elif state in (GraspState.FAILED, GraspState.RELEASE):
                self._later(CommandCode.GRASP, AckResult.FAILED, self.grasp_seq, f"grasp {state.name}")
                self.grasp_seq = -1
        if self.release_seq >= 0 and state == GraspState.IDLE:
            self._later(CommandCode.RELEASE, AckResult.ACCEPTED, self.release_seq, "released")
            self.release_seq = -1

    def grasp_left(self, why: str) -> None:
        """GRASP mode was left (``why``: :func:`~controller.grasp.grasp_refusal` of the new state): both
        owed acks fail with that reason."""
        self.finish_grasp(AckResult.FAILED, why)
        if self.release_seq >= 0:
            self._later(CommandCode.RELEASE, AckResult.FAILED, self.release_seq, why)
            self.release_seq = -1

    def finish_grasp(self, result: AckResult, text: str) -> None:
        """Answer an owed GRASP ack now (superseded, released or held by another command)."""
        if self.grasp_seq >= 0:
            self._later(CommandCode.GRASP, result, self.grasp_seq, text)
            self.grasp_seq = -1

    def _later(self, code: int, result: AckResult, seq: int, text: str) -> None:
        if self._enabled:
            self.pending.append(CommandAck(code, result, seq, truncate_utf8(text, ACK_TEXT_MAX)))


class CommandServer:
    """The ``link_rx`` task's body: host messages in, answers out.

    A list-all ``ParamRequest`` is answered :data:`PARAM_VALUES_PER_TICK` values per tick, starting with
    the next tick's :meth:`serve`; a new list request restarts the list.

    Attributes:
        virtual_rc_ignored: ``VirtualRc`` frames received while the radio is the RC source.
    """

    def __init__(
        self,
        link: BoardLink,
        rc: RcSource,
        rc_input: RcInput,
        failsafe: Failsafe,
        modes: ModeSelector,
        grasp: GraspMachine,
        mapper: CableMapper,
        hold: LengthHold,
        params: Params,
        acks: GraspAcks,
        events: EventQueue,
    ) -> None:
        """Serve ``link`` with the given components (all owned by the firmware)."""
        self._hold = hold
        self.link = link
        self._rc = rc
        self._rc_input = rc_input
        self._failsafe = failsafe
        self._modes = modes
        self._grasp = grasp
        self._mapper = mapper
        self._params = params
        self._acks = acks
        self._events = events
        self.virtual_rc_ignored = 0
        self._list_next = -1  # index of the next ParamValue of a list-all answer, -1 when none is due
        self._link_changes = link.link_changes
        link.undecodable = self._unsupported_command

    def serve(self, now_us: int) -> None:
        """Send the owed acks, then answer every frame received since the last call."""
        link = self.link
        pending = self._acks.pending
        if pending:
            for msg in pending:
                link.send(msg)
            pending.clear()
        if self._list_next >= 0:
            self._list_some()
        received = link.receive()  # undecodable frames go to _unsupported_command
        if link.link_changes != self._link_changes:
            self._link_lost(now_us)
        for seq, msg in received:
            self._dispatch(link, now_us, seq, msg)

    def _link_lost(self, now_us: int) -> None:
        """A host connected or went away: nothing a host set survives it (DIRECT, its length-holds)."""
        self._link_changes = self.link.link_changes
        self._modes.reset_direct()
        self._hold.release_host()
        self._list_next = -1
        self._events.push(now_us, EventKind.INFO, 2, 0.0, "host link changed: DIRECT and holds reset")

    def _list_some(self) -> None:
        start = self._list_next
        stop = min(start + PARAM_VALUES_PER_TICK, len(PARAMS))
        config = self._params.config
        for index in range(start, stop):
            name = PARAMS[index]
            self.link.send(ParamValue(index, len(PARAMS), name, config.get_param(name)))
        self._list_next = stop if stop < len(PARAMS) else -1

    def _dispatch(self, link: BoardLink, now_us: int, seq: int, msg: Message) -> None:
        if isinstance(msg, Heartbeat):
            self._failsafe.on_heartbeat(now_us)
        elif isinstance(msg, VirtualRc):
            if isinstance(self._rc, LinkRcSource):
                self._rc.push(msg.data, now_us)
            else:
                self.virtual_rc_ignored += 1
        elif isinstance(msg, Command):
            result, text = self._command(now_us, seq, msg)
            link.send(CommandAck(msg.code, result, seq, truncate_utf8(text, ACK_TEXT_MAX)))
        elif isinstance(msg, ParamRequest):
            self._param_request(msg)
        elif isinstance(msg, ParamSet):
            if msg.name in PARAM_FIELDS:
                value = self._params.set(now_us, msg.name, msg.value)
                link.send(ParamValue(PARAMS.index(msg.name), len(PARAMS), msg.name, value))
            else:
                self._events.push(now_us, EventKind.PARAM, -1, msg.value, f"unknown parameter {msg.name}")
        # board -> host messages never get here: the board's parser refuses their ids

    def _unsupported_command(self, frame: LinkFrame) -> None:
        if frame.cmd_id == Command.CMD_ID and len(frame.payload) == Command.FORMAT.size:
            self.link.send(
                CommandAck(frame.payload[0], AckResult.UNSUPPORTED, frame.seq, "unknown command code")
            )

    def _param_request(self, req: ParamRequest) -> None:
        count = len(PARAMS)
        if req.index == PARAM_LIST_ALL:
            self._list_next = 0
            return
        names: Sequence[str]
        if req.index == PARAM_INDEX_BY_NAME:
            names = (req.name,) if req.name in PARAM_FIELDS else ()
        else:
            names = (PARAMS[req.index],) if req.index < count else ()
        config = self._params.config
        for name in names:
            self.link.send(ParamValue(PARAMS.index(name), count, name, config.get_param(name)))

    def _command(self, now_us: int, seq: int, cmd: Command) -> tuple[AckResult, str]:
        code = cmd.code
        a0, a1, a2 = cmd.args
        fs = self._failsafe
        if code == CommandCode.ESTOP:
            fs.estop(now_us)
            return AckResult.ACCEPTED, "E-stop latched"
        if code == CommandCode.CLEAR_ESTOP:
            if fs.clear_estop(now_us):
                return AckResult.ACCEPTED, "E-stop cleared: re-arm through SAFE"
            return AckResult.ACCEPTED, "no E-stop was latched"
        if code == CommandCode.ARM:
            if fs.arm():
                return AckResult.ACCEPTED, "armed: gate opens with the right lever DOWN"
            return AckResult.REJECTED, "E-stop latched: clear it first"
        if code == CommandCode.DISARM:
            fs.disarm(now_us)
            return AckResult.ACCEPTED, "disarmed"
        if code == CommandCode.REQUIRE_HOST:
            if a0 not in (0.0, 1.0):
                return AckResult.DENIED, "args[0] must be 0 or 1"
            self._params.set(now_us, "HOST_REQUIRED", a0)
            if self._params.refused is not None:  # a failsafe setting: only in SAFE, like the parameter
                return AckResult.REJECTED, self._params.refused
            return AckResult.ACCEPTED, "host required" if a0 else "host not required"
        if code == CommandCode.SET_TENSIONS:
            # one tension per cable of an arm (args beyond the arm's cables unused), every arm alike
            direct = self._modes.direct_tensions_n
            values = (a0, a1, a2)[: len(direct)]
            if not all(math.isfinite(v) and v >= 0.0 for v in values):
                return AckResult.DENIED, "tensions must be finite and >= 0"
            mapping = self._params.config.mapping
            lo, hi = mapping.pretension_n, mapping.tension_max_n
            clamped = [min(hi, max(lo, v)) for v in values]
            direct[:] = clamped
            return AckResult.ACCEPTED, "clamped" if clamped != list(values) else "ok"
        if code == CommandCode.SET_MODE:
            return self._set_mode(a0)
        if code == CommandCode.HOLD_LENGTHS:
            return self._hold_lengths(cmd.args)
        if code in (CommandCode.GRASP, CommandCode.RELEASE, CommandCode.HOLD):
            return self._grasp_command(now_us, seq, code, a0)
        return AckResult.UNSUPPORTED, "unsupported"

    def _hold_lengths(self, args: Sequence[float]) -> tuple[AckResult, str]:
        """Per cable of an arm (every arm's): NaN unchanged, -inf release, +inf hold here, finite hold at
        that length (m). Args beyond the arm's cables are unused."""
        if self._modes.mode == Mode.SAFE:
            return AckResult.REJECTED, "length-hold needs an active mode (not SAFE)"
        hold = self._hold
        config = self._params.config
        cables = config.cables_per_arm
        motors = range(0, config.motor_count, cables)  # each arm's first motor
        args = args[:cables]
        for i, value in enumerate(args):
            if math.isnan(value):
                continue
            for first in motors:
                if value == -math.inf:
                    hold.release(first + i)
                elif not hold.engage(first + i, None if value == math.inf else value):
                    return AckResult.FAILED, f"cable {i + 1}: no motor feedback yet"
        held = "".join(str(i + 1) for i in range(len(args)) if hold.held[i])
        return AckResult.ACCEPTED, f"held cables: {held or 'none'}"

    def _set_mode(self, value: float) -> tuple[AckResult, str]:
        modes = self._modes
        if value == Mode.MANUAL:
            modes.direct_requested = False
            return AckResult.ACCEPTED, "manual (sticks)"
        if value == Mode.DIRECT:
            rc = self._rc_input.frame
            if self._failsafe.phase != Phase.OK or rc is None or rc.right_lever != Lever.MIDDLE:
                return AckResult.REJECTED, "DIRECT needs phase OK and the right lever MIDDLE"
            if not self._failsafe.host_ok:
                return AckResult.REJECTED, "DIRECT needs the host heartbeat"
            modes.direct_requested = True
            return AckResult.ACCEPTED, "direct tensions"
        return AckResult.DENIED, "only MANUAL or DIRECT: the right lever selects SAFE and GRASP"

    def _grasp_command(self, now_us: int, seq: int, code: CommandCode, arg: float) -> tuple[AckResult, str]:
        fs = self._failsafe
        refusal = grasp_refusal(fs.phase, fs.armed, self._modes.mode)  # the radio is the master enable
        if refusal is not None:
            return AckResult.REJECTED, refusal
        grasp = self._grasp
        acks = self._acks
        if code == CommandCode.GRASP:
            direction = None
            rc = self._rc_input.frame
            if math.isfinite(arg):
                direction = arg
            elif rc is not None:
                direction = self._mapper.stick_direction(rc.channels, GRASP_STICK_MIN)
            result = grasp.request_grasp(now_us, direction)
            if result != AckResult.ACCEPTED:
                return result, "grasp already running"
            acks.finish_grasp(AckResult.FAILED, "superseded")
            acks.grasp_seq = seq
            return AckResult.IN_PROGRESS, "grasping"
        if code == CommandCode.RELEASE:
            grasp.request_release(now_us)
            acks.finish_grasp(AckResult.FAILED, "released")
            if grasp.state == GraspState.IDLE:
                return AckResult.ACCEPTED, "idle"
            acks.release_seq = seq
            return AckResult.IN_PROGRESS, "releasing"
        result = grasp.request_hold(now_us)
        if result == AckResult.ACCEPTED:
            acks.finish_grasp(AckResult.ACCEPTED, "holding")
            return result, "holding"
        return result, f"cannot hold in {grasp.state.name}"
