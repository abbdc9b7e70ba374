"""The DO_GRIPPER server of the drone link: the job in progress and its ACK sequence.

The command protocol of docs/mavlink.md: ``IN_PROGRESS`` then ``ACCEPTED`` / ``FAILED``;
``TEMPORARILY_REJECTED`` while busy; ``DENIED`` for bad params or when the radio does not allow it;
``UNSUPPORTED`` for other commands addressed to us; the final ACK carries no progress. A retransmitted
command is answered again, never carried out twice. The servo follower (``host.drone.servo``) takes
the same path through :meth:`GripperServer.request`, without ACKs.

The board decides, once: whether the radio allows the command is the firmware's rule
(:func:`controller.grasp.grasp_refusal`), asked here of the latest telemetry only to answer ``DENIED``
at once; the board applies the same rule to the command itself. When a job ends is the board's word
too: its final ``CommandAck`` for our command (routed back by the board client, ``send_to_board``'s
``on_ack``) ends the job, ``ACCEPTED`` or ``FAILED`` with the board's reason; telemetry only feeds the
progress figures. Runs on the link thread, under the link's lock.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Final, Protocol

from controller.grasp import grasp_refusal
from host.drone.config import DroneLinkConfig
from host.drone.state import GripperCommand
from protocol import mavlink as mav
from protocol import messages as bm

__all__ = ["AnswerHandler", "BoardCommand", "BoardPort", "GripperServer", "gripper_denial"]

_US_PER_S: Final[int] = 1_000_000
_ACK_REPLAY_WINDOW_US: Final[int] = 3 * _US_PER_S
_BUSY_STATES: Final = frozenset({bm.GraspState.REACH, bm.GraspState.WRAP, bm.GraspState.RELEASE})
_PROGRESS_PCT: Final[dict[bm.GraspState, int]] = {
    bm.GraspState.REACH: 30,
    bm.GraspState.RELEASE: 50,
    bm.GraspState.WRAP: 70,
}
"""Progress figures of the states a job passes through (its end is the board's final answer)."""

AnswerHandler = Callable[[bm.CommandAck | None, int], None]
"""Gets each board answer to one command on the link thread with the link-clock time (None: the command
can have no answer, e.g. the board link went down)."""
BoardCommand = Callable[[bm.Command, AnswerHandler], bool]
"""Sends one command to the board with the handler of its answers; False if it did not go out."""


class BoardPort(Protocol):
    """The board as the drone link sends to it (``BoardClient.send``)."""

    def __call__(
        self,
        msg: bm.Message,
        *,
        origin: str = ...,
        on_ack: Callable[[bm.CommandAck | None], None] | None = ...,
    ) -> bool:
        """Send ``msg`` (``origin``: who sends it); a ``Command``'s answers go to ``on_ack`` (None: it
        can have none). False if it did not go out."""


def gripper_denial(telemetry: bm.Telemetry | None, age_us: int, stale_us: int) -> str | None:
    """Why a DO_GRIPPER must be refused given the latest board telemetry, or None if it may act.

    The board's own rule (:func:`controller.grasp.grasp_refusal`: armed, phase OK, right lever UP)
    applied to its telemetry, so the commander gets ``DENIED`` without a round trip to the board.

    Args:
        telemetry: Latest board telemetry (None if none yet).
        age_us: How old it is.
        stale_us: Older than this counts as no telemetry.

    Returns:
        A short reason (fits one STATUSTEXT), or None.
    """
    if telemetry is None or age_us > stale_us:
        return "gripper denied: no board telemetry"
    armed = bool(telemetry.flags & bm.TelemetryFlags.ARMED)
    why = grasp_refusal(telemetry.phase, armed, telemetry.mode)
    return None if why is None else f"gripper denied: {why}"


_ACTION_TO_BOARD: Final = {
    mav.GripperAction.GRAB: (bm.CommandCode.GRASP, bm.GraspState.HOLD),
    mav.GripperAction.RELEASE: (bm.CommandCode.RELEASE, bm.GraspState.IDLE),
    mav.GripperAction.HOLD: (bm.CommandCode.HOLD, bm.GraspState.HOLD),
}


@dataclass
class _GripperJob:
    """A DO_GRIPPER being carried out (mutable, link thread only)."""

    number: int
    """Tells this job's board answers from a finished job's."""
    action: mav.GripperAction
    code: bm.CommandCode
    target: bm.GraspState
    requester: tuple[int, int] | None
    """The commander to answer (None for the servo follower, which gets no ACKs)."""
    deadline_us: int
    last_state: bm.GraspState = bm.GraspState.IDLE


def _gripper_action(value: float) -> mav.GripperAction | None:
    if not math.isfinite(value) or value != int(value):
        return None
    try:
        return mav.GripperAction(int(value))
    except ValueError:
        return None


class GripperServer:
    """Carries out ``MAV_CMD_DO_GRIPPER`` on the board, one job at a time.

    Args:
        config: The link's configuration (``compid``, ``board_stale_us``, ``grasp_timeout_us``).
        send: Sends one MAVLink message.
        to_board: Sends one board command with the handler of its answers (see :data:`BoardCommand`).
        text: Sends a ``STATUSTEXT`` (severity, text; rate limited by the link).
        count: Counts one event of the named :class:`~host.drone.state.DroneLinkCounters` field.
    """

    def __init__(
        self,
        config: DroneLinkConfig,
        send: Callable[[mav.MavMessage], None],
        to_board: BoardCommand,
        text: Callable[[int, str], None],
        count: Callable[[str], None],
    ) -> None:
        self.config = config
        self._send = send
        self._board = to_board
        self._text = text
        self._count = count
        self._numbers = itertools.count(1)
        self._job: _GripperJob | None = None
        self._last_final: tuple[tuple[int, int], int, int, int] | None = None  # requester, action, result, t
        self._last_command: GripperCommand | None = None
        self._settled: bm.GraspState | None = None
        """The grasp state the board's last final ACCEPTED reported, until newer telemetry arrives (the
        answer overtakes the telemetry that will show it: the board sends both in order)."""

    @property
    def busy(self) -> bool:
        """A job is in progress."""
        return self._job is not None

    @property
    def last_command(self) -> GripperCommand | None:
        """The latest command handled (None before any)."""
        return self._last_command

    def on_command(
        self,
        cmd: mav.CommandLong,
        requester: tuple[int, int],
        now: int,
        telemetry: bm.Telemetry | None,
        telemetry_at_us: int,
    ) -> None:
        """Answer a ``COMMAND_LONG`` addressed to us; a DO_GRIPPER that may act starts a job.

        Args:
            cmd: The command.
            requester: Commander's (system, component).
            now: Link-clock time in µs.
            telemetry: Latest board telemetry (None before any).
            telemetry_at_us: Link-clock time it arrived.
        """
        if cmd.command != mav.MAV_CMD_DO_GRIPPER:
            if cmd.target_component == mav.MAV_COMP_ID_ALL:
                # A broadcast command we do not implement is for someone else: stay silent (MAVLink
                # command protocol: only components that support a broadcast command answer it).
                self._count("unexpected")
                return
            self._ack(requester, cmd.command, mav.MavResult.UNSUPPORTED, -1, now, "unsupported command")
            return
        instance, action_f = cmd.params[0], cmd.params[1]
        action = _gripper_action(action_f)
        if not (math.isfinite(instance) and instance in (0.0, float(self.config.compid))) or action is None:
            why = f"gripper denied: bad params {instance:g} {action_f:g}"
            self._ack(requester, cmd.command, mav.MavResult.DENIED, -1, now, why)
            self._text(mav.Severity.WARNING, why)
            return
        job = self._job
        if job is not None:
            if cmd.confirmation > 0 and job.requester == requester and job.action == action:
                # A retransmission of the command we are carrying out: it is still in progress.
                self._ack(requester, cmd.command, mav.MavResult.IN_PROGRESS, int(action), now, "")
            else:
                self._ack(
                    requester, cmd.command, mav.MavResult.TEMPORARILY_REJECTED, int(action), now, "busy"
                )
            return
        last = self._last_final
        if (
            cmd.confirmation > 0
            and last is not None
            and last[0] == requester
            and last[1] == int(action)
            and now - last[3] <= _ACK_REPLAY_WINDOW_US
        ):
            # Our final ACK was lost and the commander retransmits: repeat it, do not act twice.
            self._ack(requester, cmd.command, last[2], int(action), now, "repeated")
            return
        self._start(action, requester, now, telemetry, telemetry_at_us)

    def request(
        self, action: mav.GripperAction, now: int, telemetry: bm.Telemetry | None, telemetry_at_us: int
    ) -> mav.MavResult:
        """Carry out an action the servo follower asks for: the DO_GRIPPER path without MAVLink ACKs.

        The same radio gate and board commands as a ``DO_GRIPPER``; refusals and results are told in
        ``STATUSTEXT`` only.

        Args:
            action: Grab or release.
            now: Link-clock time in µs.
            telemetry: Latest board telemetry (None before any).
            telemetry_at_us: Link-clock time it arrived.

        Returns:
            ``TEMPORARILY_REJECTED`` while busy (the caller may ask again), else the first answer
            (``IN_PROGRESS``, ``ACCEPTED`` when nothing was to do, ``DENIED``).
        """
        if self._job is not None:
            return mav.MavResult.TEMPORARILY_REJECTED
        return self._start(action, None, now, telemetry, telemetry_at_us)

    def _start(
        self,
        action: mav.GripperAction,
        requester: tuple[int, int] | None,
        now: int,
        telemetry: bm.Telemetry | None,
        telemetry_at_us: int,
    ) -> mav.MavResult:
        cmd_id = mav.MAV_CMD_DO_GRIPPER
        tel = telemetry
        denial = gripper_denial(tel, now - telemetry_at_us, self.config.board_stale_us)
        if denial is not None or tel is None:
            reason = denial or "gripper denied: no board telemetry"
            self._ack(requester, cmd_id, mav.MavResult.DENIED, int(action), now, reason)
            self._text(mav.Severity.WARNING, reason)
            return mav.MavResult.DENIED
        state = self._settled if self._settled is not None else bm.GraspState(tel.grasp_state)
        if state in _BUSY_STATES:
            result = mav.MavResult.TEMPORARILY_REJECTED
            self._ack(requester, cmd_id, result, int(action), now, f"busy: grasp {state.name}")
            return result
        code, target = _ACTION_TO_BOARD[action]
        if state == target:
            # Nothing to do (already holding, already released): done.
            self._final(requester, int(action), mav.MavResult.ACCEPTED, now, f"gripper: already {state.name}")
            return mav.MavResult.ACCEPTED
        job = _GripperJob(
            next(self._numbers), action, code, target, requester, now + self.config.grasp_timeout_us, state
        )
        self._job = job
        verb = action.name.lower()
        if not self._board(bm.Command(code), lambda ack, at: self._on_answer(job.number, ack, at)):
            self._finish_job(mav.MavResult.FAILED, f"gripper: {verb} failed: the board link is down", now)
            return mav.MavResult.FAILED
        self._ack(requester, cmd_id, mav.MavResult.IN_PROGRESS, int(action), now, "", progress=0)
        by = "" if requester is not None else " (autopilot servo)"
        self._text(mav.Severity.INFO, f"gripper: {verb} started{by}")
        return mav.MavResult.IN_PROGRESS

    def _ack(
        self,
        requester: tuple[int, int] | None,
        command: int,
        result: int,
        action: int,
        now: int,
        text: str,
        *,
        progress: int = 0,
    ) -> None:
        # Target = the commander, so a GCS recognises the reply as its own (MAVProxy only prints ACKs
        # targeted at its own ids or at 0). The servo follower (no requester) gets no ACK.
        src = requester or (0, 0)
        if requester is not None:
            self._send(mav.CommandAck(command, int(result), progress, 0, src[0], src[1]))
        self._last_command = GripperCommand(now, src[0], src[1], command, action, int(result), text)

    def _final(
        self, requester: tuple[int, int] | None, action: int, result: int, now: int, text: str
    ) -> None:
        # MAVLink's command protocol: progress belongs to IN_PROGRESS only; a final ACK carries 0.
        self._ack(requester, mav.MAV_CMD_DO_GRIPPER, result, action, now, text)
        if requester is not None:
            self._last_final = (requester, action, int(result), now)
        severity = mav.Severity.INFO if result == mav.MavResult.ACCEPTED else mav.Severity.WARNING
        self._text(severity, text)

    def _finish_job(self, result: int, text: str, now: int) -> None:
        job, self._job = self._job, None
        if job is not None:
            self._final(job.requester, int(job.action), result, now, text)

    def _on_answer(self, number: int, ack: bm.CommandAck | None, now: int) -> None:
        """The board's answer to job ``number``'s command: its final one ends the job."""
        job = self._job
        if job is None or job.number != number:
            return  # a job that already ended (timeout): the board's late word changes nothing
        verb = job.action.name.lower()
        if ack is None:
            self._finish_job(mav.MavResult.FAILED, f"gripper: {verb} failed: board link lost", now)
        elif ack.result == bm.AckResult.ACCEPTED:
            self._settled = job.target
            self._finish_job(mav.MavResult.ACCEPTED, f"gripper: {verb} done, {job.target.name}", now)
        elif ack.result != bm.AckResult.IN_PROGRESS:
            why = ack.text or bm.AckResult(ack.result).name
            self._finish_job(mav.MavResult.FAILED, f"gripper: {verb} failed: {why}", now)

    def on_telemetry(self, tel: bm.Telemetry, now: int) -> None:
        """Progress of the job in progress: an ``IN_PROGRESS`` with a figure per grasp state it passes.

        Args:
            tel: The board telemetry.
            now: Link-clock time in µs.
        """
        self._settled = None
        job = self._job
        if job is None or tel.grasp_state == job.last_state:
            return
        try:
            state = bm.GraspState(tel.grasp_state)
        except ValueError:
            return
        job.last_state = state
        progress = _PROGRESS_PCT.get(state)
        if progress is not None:
            self._ack(
                job.requester,
                mav.MAV_CMD_DO_GRIPPER,
                mav.MavResult.IN_PROGRESS,
                int(job.action),
                now,
                "",
                progress=progress,
            )

    def check_timeout(self, now: int) -> None:
        """Fail the job in progress once its deadline has passed.

        Args:
            now: Link-clock time in µs.
        """
        job = self._job
        if job is not None and now >= job.deadline_us:
            self._finish_job(mav.MavResult.FAILED, f"gripper: {job.action.name.lower()} failed: timeout", now)
