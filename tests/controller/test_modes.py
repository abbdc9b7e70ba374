"""Mode selection on its own: the phase and the right lever own the mode, the host only MANUAL/DIRECT."""

from __future__ import annotations

from controller.cables import CableMapper, MotorModel, TensionSlew
from controller.config import FirmwareConfig
from controller.events import EventQueue
from controller.failsafe import Failsafe
from controller.grasp import GraspMachine
from controller.lengthhold import LengthHold
from controller.modes import ModeSelector
from protocol.dbus import Lever, RcFrame
from protocol.messages import EventKind, GraspState, Mode, Phase


class Listener:
    def __init__(self) -> None:
        self.progress: list[GraspState] = []
        self.left = 0
        self.why: list[str] = []

    def grasp_progress(self, state: GraspState) -> None:
        self.progress.append(state)

    def grasp_left(self, why: str) -> None:
        self.left += 1
        self.why.append(why)


class Parts:
    def __init__(self) -> None:
        config = FirmwareConfig()
        self.events = EventQueue(64)
        self.failsafe = Failsafe(config, self.events)
        self.grasp = GraspMachine(config, self.events)
        self.listener = Listener()
        motors = MotorModel(config)
        self.modes = ModeSelector(
            config,
            self.failsafe,
            self.grasp,
            CableMapper(config),
            motors,
            LengthHold(config, motors, TensionSlew(config)),
            self.events,
            self.listener,
        )


def _selector() -> tuple[ModeSelector, Failsafe, EventQueue, Listener]:
    p = Parts()
    return p.modes, p.failsafe, p.events, p.listener


def _rc(right: int, left: int = Lever.DOWN) -> RcFrame:
    return RcFrame((0, 0, 0, 0), int(right), int(left))


def test_safe_unless_phase_ok_and_a_frame() -> None:
    modes, _, _, _ = _selector()
    assert modes.select(0, Phase.GATE, _rc(Lever.MIDDLE)) is Mode.SAFE
    assert modes.select(0, Phase.OK, None) is Mode.SAFE
    assert modes.direct_tensions_n == [FirmwareConfig().mapping.pretension_n] * 3


def test_right_lever_picks_safe_manual_grasp_and_logs_each_change() -> None:
    modes, _, events, listener = _selector()
    assert modes.select(1, Phase.OK, _rc(Lever.DOWN)) is Mode.SAFE
    assert modes.select(2, Phase.OK, _rc(Lever.MIDDLE)) is Mode.MANUAL
    assert modes.select(3, Phase.OK, _rc(Lever.UP)) is Mode.GRASP
    assert modes.select(4, Phase.OK, _rc(Lever.MIDDLE)) is Mode.MANUAL
    assert listener.left == 1  # leaving GRASP tells the listener (owed acks fail)
    assert listener.why == ["mode MANUAL, lever not UP"]  # with the radio's reason (grasp_refusal)
    assert modes.select(5, Phase.OK, _rc(Lever.UP)) is Mode.GRASP
    assert modes.select(6, Phase.RC_LOST, _rc(Lever.UP)) is Mode.SAFE
    assert listener.why[-1] == "failsafe RC_LOST"
    got = [(e.time_us, e.code) for e in events.pop_all() if e.kind == EventKind.MODE]
    assert got == [(2, Mode.MANUAL), (3, Mode.GRASP), (4, Mode.MANUAL), (5, Mode.GRASP), (6, Mode.SAFE)]


def test_direct_needs_the_request_and_the_heartbeat() -> None:
    modes, fs, events, _ = _selector()
    modes.direct_requested = True
    fs.host_ok = True
    assert modes.select(0, Phase.OK, _rc(Lever.MIDDLE)) is Mode.DIRECT
    fs.host_ok = False
    assert modes.select(1, Phase.OK, _rc(Lever.MIDDLE)) is Mode.MANUAL
    assert not modes.direct_requested
    assert any(e.text == "DIRECT ended: no host heartbeat" for e in events.pop_all())


def test_leaving_middle_drops_the_direct_request() -> None:
    modes, fs, _, _ = _selector()
    fs.host_ok = True
    modes.direct_requested = True
    modes.select(0, Phase.OK, _rc(Lever.MIDDLE))
    modes.select(1, Phase.OK, _rc(Lever.DOWN))
    assert not modes.direct_requested


def test_grasp_targets_follow_left_lever_edges() -> None:
    p = Parts()
    modes, grasp = p.modes, p.grasp
    modes.select(0, Phase.OK, _rc(Lever.UP, Lever.DOWN))
    targets = modes.grasp_targets(1_000, 1_000, _rc(Lever.UP, Lever.DOWN))
    assert len(targets) == 3
    assert not grasp.pending  # the lever that was DOWN on entry is no edge
    modes.grasp_targets(2_000, 1_000, _rc(Lever.UP, Lever.UP))  # left lever UP: grasp requested
    assert grasp.pending
    modes.grasp_targets(3_000, 1_000, _rc(Lever.UP, Lever.DOWN))  # left lever DOWN: released
    assert not grasp.pending
