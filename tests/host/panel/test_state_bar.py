"""host.panel.state_bar: the state bar's text for every combination the board can report.

The telemetry is not made up: each board state comes from the firmware's own failsafe
(``controller.failsafe.Failsafe``) driven through a history of RC frames, motor feedback, heartbeats and
host commands on a fake clock, with its phase, ``arm_blocker``, ``rc_ok`` and the levers of the last
frame it accepted copied into ``Telemetry`` as ``controller.telemetry`` does. Every board state is then
read by every control owner (this tab, another tab or the command line, nobody) and, in GRASP, in every
grasp state and left-lever position; each text is checked against the telemetry it came from.
"""

from __future__ import annotations

import copy
import itertools
from dataclasses import dataclass

import pytest

from controller.config import FirmwareConfig
from controller.events import EventQueue
from controller.failsafe import Failsafe
from host.link.source import LinkState
from host.panel.state_bar import KEY_HOOK_HTML, PilotState, pilot_state, state_bar_html
from protocol.dbus import Lever
from protocol.messages import ArmBlocker, GraspState, Mode, Phase, Telemetry, TelemetryFlags

OK = LinkState.CONNECTED
MS = 1000
FRAME_US = 14 * MS
"""DR16: a frame every 14 ms."""
LEVERS = (Lever.DOWN, Lever.MIDDLE, Lever.UP)
OWNERS = ("mine", "other", "nobody")


@dataclass
class Board:
    """The firmware's failsafe on a fake clock, fed like the control task feeds it."""

    fs: Failsafe
    now_us: int = 0
    right: int = 0
    left: int = int(Lever.DOWN)
    motors: bool = True
    heartbeat: bool = True

    @classmethod
    def boot(cls, *, host_required: bool = False) -> Board:
        cfg = FirmwareConfig().replaced(host_required=host_required)
        return cls(Failsafe(cfg, EventQueue(64)))

    def run(self, ms: int, *, rc: int | None = None, left: int | None = None) -> Board:
        """``ms`` of board time; RC frames with right lever ``rc`` every 14 ms (None: the radio silent)."""
        if left is not None:
            self.left = left
        end = self.now_us + ms * MS
        while self.now_us < end:
            self.now_us += MS
            if rc is not None and self.now_us % FRAME_US == 0:
                self.right = rc
                self.fs.on_rc_frame(self.now_us, rc)
            if self.motors:
                self.fs.on_motor_frames(self.now_us, [(m, None) for m in (1, 2, 3)])
            if self.heartbeat:
                self.fs.on_heartbeat(self.now_us)
            self.fs.update(self.now_us)
        return self

    def telemetry(self, grasp: GraspState = GraspState.IDLE) -> Telemetry:
        fs = self.fs
        flags = TelemetryFlags.NONE
        if fs.phase == Phase.OK:
            flags |= TelemetryFlags.ARMED
        if fs.rc_ok:
            flags |= TelemetryFlags.RC_OK
        mode = Mode.SAFE
        if fs.phase == Phase.OK:
            mode = {Lever.MIDDLE: Mode.MANUAL, Lever.UP: Mode.GRASP}.get(Lever(self.right), Mode.SAFE)
        return Telemetry(
            self.now_us,
            mode=mode,
            phase=fs.phase,
            flags=flags,
            grasp_state=grasp if mode == Mode.GRASP else GraspState.IDLE,
            right_lever=self.right,
            left_lever=self.left,
            arm_blocker=fs.arm_blocker(),
        )


def histories() -> dict[str, Board]:
    """Every way the board gets into a state, each ending with the right lever in each position."""
    out: dict[str, Board] = {"boot, no radio yet": Board.boot().run(100)}
    for lever in LEVERS:
        name = lever.name
        out[f"radio on, lever {name}"] = Board.boot().run(100, rc=lever)
        out[f"armed, then lever {name}"] = Board.boot().run(100, rc=Lever.DOWN).run(100, rc=lever)
        out[f"armed, lever {name}, radio lost"] = (
            Board.boot().run(100, rc=Lever.DOWN).run(100, rc=lever).run(100, rc=None)
        )
        out[f"radio lost, back with lever {name}"] = (
            Board.boot().run(100, rc=Lever.DOWN).run(100, rc=Lever.MIDDLE).run(100).run(100, rc=lever)
        )
        b = Board.boot().run(100, rc=Lever.DOWN).run(100, rc=Lever.MIDDLE)
        b.motors = False
        out[f"motor silent, lever {name}"] = b.run(100, rc=lever)
        b = Board.boot().run(100, rc=Lever.DOWN).run(100, rc=Lever.MIDDLE)
        b.motors = False
        b.run(100, rc=Lever.MIDDLE).motors = True
        out[f"motor back, lever {name}"] = b.run(100, rc=lever)
        b = Board.boot(host_required=True).run(100, rc=Lever.DOWN).run(100, rc=Lever.MIDDLE)
        b.heartbeat = False
        out[f"heartbeat lost, lever {name}"] = copy.deepcopy(b.run(600, rc=lever))
        b.heartbeat = True
        out[f"heartbeat back, lever {name}"] = b.run(100, rc=lever)
        b = Board.boot().run(100, rc=Lever.DOWN)
        b.fs.estop(b.now_us)
        out[f"E-stop, lever {name}"] = b.run(100, rc=lever)
        b = Board.boot().run(100, rc=Lever.DOWN)
        b.fs.estop(b.now_us)
        b.fs.clear_estop(b.now_us)
        out[f"E-stop cleared, lever {name}"] = b.run(100, rc=lever)
        b = Board.boot().run(100, rc=Lever.DOWN)
        b.fs.disarm(b.now_us)
        out[f"host disarmed, lever {name}"] = b.run(100, rc=lever)
    return out


HISTORIES = histories()


def rows() -> list[tuple[str, Telemetry, str]]:
    """(history, telemetry, owner) for every history, owner, and in GRASP every grasp state and left lever."""
    out = []
    for name, board in HISTORIES.items():
        base = board.telemetry()
        variants = [base]
        if base.mode == Mode.GRASP:
            variants = []
            for grasp, left in itertools.product(GraspState, LEVERS):
                board.left = int(left)
                variants.append(board.telemetry(grasp))
        for t, owner in itertools.product(variants, OWNERS):
            out.append((name, t, owner))
    return out


ROWS = rows()


def bar(t: Telemetry, owner: str) -> PilotState:
    return pilot_state(t, OK, mine=owner == "mine", holder_known=owner != "nobody")


def test_the_histories_reach_every_phase_and_blocker() -> None:
    """The table covers what the board can say: every phase and every arm blocker occurs."""
    phases = {t.phase for _, t, _ in ROWS}
    blockers = {t.arm_blocker for _, t, _ in ROWS}
    assert phases == set(Phase)
    assert blockers == set(ArmBlocker)
    assert {t.mode for _, t, _ in ROWS} >= {Mode.SAFE, Mode.MANUAL, Mode.GRASP}
    assert len(ROWS) > 150


@pytest.mark.parametrize(("history", "t", "owner"), ROWS, ids=lambda v: getattr(v, "name", str(v))[:40])
def test_every_text_agrees_with_the_telemetry_it_came_from(history: str, t: Telemetry, owner: str) -> None:
    s = bar(t, owner)
    step, head = s.next_step, s.headline
    flags = TelemetryFlags(t.flags)
    armed = bool(flags & TelemetryFlags.ARMED)
    where = f"{history} / {owner}: {head} | {step}"
    assert head.startswith(f"{t.phase.name} · {t.mode.name} · "), where
    assert ("ARMED" in head) == armed, where
    assert f"right lever {Lever(t.right_lever).name if t.right_lever else '-'}" in head, where
    # An RC loss is said only when the board has no valid RC (its blocker says so), never from the phase.
    if "no RC" in step or "no valid RC" in step or "waiting for valid RC" in step:
        assert t.arm_blocker == ArmBlocker.RC_INVALID and not flags & TelemetryFlags.RC_OK, where
    if "RC is back" in step:
        assert flags & TelemetryFlags.RC_OK and t.phase == Phase.RC_LOST, where
    if t.arm_blocker == ArmBlocker.RC_INVALID and owner != "other":
        assert "no RC" in step or "no valid RC" in step, where
    # "right lever DOWN" as the way to arm: only when the board's gate waits for it.
    if "right lever DOWN to" in step:
        assert t.arm_blocker == ArmBlocker.LEVER_NOT_DOWN and t.right_lever != Lever.DOWN, where
    if t.arm_blocker == ArmBlocker.LEVER_NOT_DOWN and owner == "mine":
        assert "right lever DOWN" in step, where
    if "press Arm" in step:
        assert t.arm_blocker == ArmBlocker.DISARMED and owner == "mine", where
    # The grasp's lever: "left lever UP grasps" only in GRASP and IDLE, never in HOLD.
    if "left lever UP grasps" in step:
        assert t.mode == Mode.GRASP and t.grasp_state == GraspState.IDLE, where
        assert t.left_lever != Lever.UP, where
    if t.mode == Mode.GRASP and armed and owner == "mine":
        assert f"grasp {GraspState(t.grasp_state).name}" in head, where
        if t.grasp_state == GraspState.HOLD:
            assert step.startswith("holding") and "Release" in step.title(), where
    # Whose step: a tab without control is told to take it (or that someone else drives).
    if owner == "other" and not s.estop and t.arm_blocker != ArmBlocker.MOTOR_FAULT:
        assert step.startswith("watching"), where
    if owner == "nobody" and not s.estop and t.arm_blocker != ArmBlocker.MOTOR_FAULT:
        assert "Take control" in step, where
    if owner != "mine":
        assert "driving" not in step and "press Arm" not in step, where
    # Colours: latched stops red, a drive green, zero current waiting on the pilot orange or blue.
    estop = t.phase == Phase.ESTOP or t.arm_blocker == ArmBlocker.ESTOP_LATCHED
    assert s.estop == estop, where
    if estop or t.arm_blocker == ArmBlocker.MOTOR_FAULT:
        assert s.colour == "red", where
    elif s.colour == "green":
        assert armed and t.mode != Mode.SAFE and owner == "mine", where
    html = state_bar_html(s)
    assert ("E-STOP LATCHED" in html) == estop


def find(history: str, owner: str = "mine", **want: object) -> PilotState:
    board = HISTORIES[history]
    if "left" in want:
        board.left = int(want["left"])  # type: ignore[call-overload]
    t = board.telemetry(want.get("grasp", GraspState.IDLE))  # type: ignore[arg-type]
    return bar(t, owner)


def test_the_reported_cases() -> None:
    """Issue 25: what the bar said wrongly, and what the board's own state says instead."""
    # RC back after a loss, right lever still MIDDLE: Health says RC ok, the fix is the right lever DOWN.
    s = find("radio lost, back with lever MIDDLE")
    assert s.headline.startswith("RC_LOST")
    assert s.next_step == "RC is back: move the right lever DOWN to re-arm (zero current)"
    # A real loss (the link process gone), control held: no RC reaches the board.
    s = find("armed, lever MIDDLE, radio lost")
    assert "no valid RC reaches the board" in s.next_step and s.colour == "orange"
    # Nobody holds control and the radio transmits (levers DOWN): not an RC loss; take control.
    s = find("armed, then lever DOWN", owner="nobody")
    assert s.next_step == "press Take control: this tab then becomes the radio"
    # Right after Take control the board is armed in SAFE (zero current): said so, with the step to drive.
    s = find("armed, then lever DOWN")
    assert s.headline == "OK · SAFE · ARMED · right lever DOWN" and "MIDDLE to drive" in s.next_step
    assert find("boot, no radio yet", owner="nobody").headline.endswith("not armed · right lever -")
    # HOLD: release is the next step, not "left lever UP grasps".
    s = find("armed, then lever UP", grasp=GraspState.HOLD, left=Lever.UP)
    assert s.next_step == "holding the object: left lever DOWN releases; right lever DOWN stops"
    s = find("armed, then lever UP", grasp=GraspState.HOLD, left=Lever.DOWN)
    assert s.next_step.startswith("holding the object: press Release")
    s = find("armed, then lever UP", grasp=GraspState.IDLE, left=Lever.DOWN)
    assert s.next_step.startswith("left lever UP grasps")
    assert find("host disarmed, lever DOWN").next_step == "press Arm (the host disarmed the board)"
    assert "motor is silent" in find("motor silent, lever DOWN", owner="nobody").next_step
    assert find("motor back, lever MIDDLE").next_step.startswith("every motor answers again: move the right")


def test_before_telemetry_and_without_the_board() -> None:
    assert pilot_state(None, OK, mine=True, holder_known=True).colour == "grey"
    t = HISTORIES["armed, then lever MIDDLE"].telemetry()
    assert pilot_state(t, LinkState.DISCONNECTED, mine=True, holder_known=True).colour == "red"
    assert "<script" not in KEY_HOOK_HTML and "'keydown'" in KEY_HOOK_HTML and ",true)" in KEY_HOOK_HTML
