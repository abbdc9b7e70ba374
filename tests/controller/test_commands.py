"""The command and parameter server: runtime parameters, owed grasp acks, host messages answered."""

from __future__ import annotations

import pytest

from controller.cables import CableMapper, MotorModel, TensionSlew
from controller.commands import CommandServer, GraspAcks, Params
from controller.config import FirmwareConfig
from controller.errors import ConfigError
from controller.events import EventQueue
from controller.failsafe import Failsafe
from controller.grasp import GraspMachine
from controller.hostlink import BoardLink
from controller.lengthhold import LengthHold
from controller.modes import ModeSelector
from controller.params import PARAMS, SAFETY_PARAMS, WIRE_ROWS, Kind
from controller.rc import RcInput, ScriptedRcSource
from controller.transport import MemoryTransport
from protocol.dbus import Lever
from protocol.link import LinkParser, encode_frame
from protocol.messages import (
    AckResult,
    Command,
    CommandAck,
    CommandCode,
    Event,
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
    decode,
    encode,
)
from tests.support.controller_harness import Rig, frame


def test_params_set_applies_valid_values_and_keeps_the_old_one_otherwise() -> None:
    events = EventQueue(16)
    applied: list[FirmwareConfig] = []
    params = Params(FirmwareConfig(), events, applied.append, lambda: True)
    assert params.set(5, "PRETENSION_N", 1.0) == 1.0
    assert params.config.mapping.pretension_n == 1.0 and applied == [params.config]
    assert params.set(6, "PRETENSION_N", -1.0) == 1.0  # rejected: the old value stays
    assert len(applied) == 1
    texts = [e.text for e in events.pop_all() if e.kind == EventKind.PARAM]
    assert texts[0] == "PRETENSION_N = 1" and texts[1].startswith("rejected")
    with pytest.raises(ConfigError):
        params.set(7, "NO_SUCH_PARAM", 1.0)


def test_grasp_acks_final_answers_and_nothing_without_a_link() -> None:
    acks = GraspAcks(True)
    acks.grasp_seq, acks.release_seq = 4, 9
    acks.grasp_progress(GraspState.HOLD)
    acks.grasp_progress(GraspState.IDLE)
    assert [(m.command, m.result, m.request_seq) for m in acks.pending if isinstance(m, CommandAck)] == [
        (CommandCode.GRASP, AckResult.ACCEPTED, 4),
        (CommandCode.RELEASE, AckResult.ACCEPTED, 9),
    ]
    acks.grasp_seq = 11
    acks.grasp_left("failsafe RC_LOST")
    last = acks.pending[-1]
    assert isinstance(last, CommandAck) and (last.request_seq, last.result) == (11, AckResult.FAILED)
    assert last.text == "failsafe RC_LOST"  # the radio's reason travels to the host (DO_GRIPPER FAILED)
    acks.grasp_seq = 12
    acks.grasp_progress(GraspState.FAILED)
    assert acks.pending[-1] == CommandAck(CommandCode.GRASP, AckResult.FAILED, 12, "grasp FAILED")
    silent = GraspAcks(False)
    silent.grasp_seq = 1
    silent.grasp_left("mode SAFE, lever not UP")
    assert silent.pending == [] and silent.grasp_seq == -1


class Server:
    def __init__(self) -> None:
        config = FirmwareConfig()
        self.events = EventQueue(64)
        self.failsafe = Failsafe(config, self.events)
        self.host, board = MemoryTransport.pair()
        grasp = GraspMachine(config, self.events)
        mapper = CableMapper(config)
        self.acks = GraspAcks(True)
        motors = MotorModel(config)
        self.hold = LengthHold(config, motors, TensionSlew(config))
        self.modes = ModeSelector(
            config, self.failsafe, grasp, mapper, motors, self.hold, self.events, self.acks
        )
        self.params = Params(config, self.events, lambda c: None, lambda: self.modes.mode == Mode.SAFE)
        rc_input = RcInput(self.failsafe.on_rc_frame, keep_raw=False)
        self.server = CommandServer(
            BoardLink(board),
            ScriptedRcSource(None),
            rc_input,
            self.failsafe,
            self.modes,
            grasp,
            mapper,
            self.hold,
            self.params,
            self.acks,
            self.events,
        )
        self._parser = LinkParser()
        self._seq = 0

    def send(self, msg: Message) -> int:
        seq = self._seq
        self.host.write(encode(msg, seq))
        self._seq += 1
        return seq

    def replies(self) -> list[Message]:
        return [decode(f) for f in self._parser.feed(self.host.read())]


def test_commands_are_acked_with_their_seq() -> None:
    s = Server()
    seq = s.send(Command(CommandCode.ESTOP))
    s.send(Heartbeat(0, 0))
    s.server.serve(1_000)
    (ack,) = s.replies()
    assert isinstance(ack, CommandAck) and (ack.command, ack.result, ack.request_seq) == (
        CommandCode.ESTOP,
        AckResult.ACCEPTED,
        seq,
    )
    assert s.failsafe.phase == Phase.ESTOP and s.failsafe.estop_latched
    s.send(Command(CommandCode.SET_TENSIONS, (100.0, 0.0, 2.0)))
    s.server.serve(2_000)
    (ack,) = s.replies()
    assert isinstance(ack, CommandAck) and ack.text == "clamped"
    assert s.modes.direct_tensions_n == [20.0, 0.5, 2.0]


def test_parameters_and_virtual_rc_from_a_radio_board() -> None:
    s = Server()
    s.send(ParamRequest(PARAMS.index("SLEW_N_S")))
    s.send(ParamSet("SLEW_N_S", 25.0))
    s.send(VirtualRc(bytes(18)))
    s.server.serve(1_000)
    got = s.replies()
    assert [(m.name, m.value) for m in got if isinstance(m, ParamValue)] == [
        ("SLEW_N_S", 50.0),
        ("SLEW_N_S", 25.0),
    ]
    assert s.server.virtual_rc_ignored == 1


@pytest.mark.parametrize(
    ("phase", "lever", "why"),
    [
        (None, Lever.UP, "start-up gate (lever DOWN first)"),
        (Phase.RC_LOST, Lever.UP, "failsafe RC_LOST"),
        (Phase.OK, Lever.MIDDLE, "mode MANUAL, lever not UP"),
        (Phase.OK, Lever.UP, None),
    ],
)
def test_grasp_commands_obey_the_radios_one_rule(phase: Phase | None, lever: Lever, why: str | None) -> None:
    from controller.grasp import grasp_refusal

    s = Server()
    if phase is not None:
        s.failsafe.phase = phase
        s.modes.select(1_000, phase, frame(right=lever))
    for code in (CommandCode.GRASP, CommandCode.RELEASE, CommandCode.HOLD):
        s.send(Command(code))
    s.server.serve(2_000)
    acks = [m for m in s.replies() if isinstance(m, CommandAck)]
    assert len(acks) == 3
    # The board answers with the rule the host's pre-check uses (host.drone.gripper), word for word.
    assert why == grasp_refusal(s.failsafe.phase, s.failsafe.armed, s.modes.mode)
    if why is None:
        assert acks[0].result == AckResult.IN_PROGRESS
    else:
        assert [(a.result, a.text) for a in acks] == [(AckResult.REJECTED, why)] * 3


def test_grasp_refusal_names_unknown_values() -> None:
    from controller.grasp import grasp_refusal

    assert grasp_refusal(99, True, Mode.GRASP) == "failsafe 99"
    assert grasp_refusal(Phase.OK, False, Mode.GRASP) == "arm not armed"
    assert grasp_refusal(Phase.OK, True, 42) == "mode 42, lever not UP"
    assert grasp_refusal(Phase.OK, True, Mode.GRASP) is None


def test_owed_acks_go_out_first_and_unknown_codes_are_unsupported() -> None:
    s = Server()
    s.acks.grasp_seq = 3
    s.acks.grasp_progress(GraspState.FAILED)
    payload = bytearray(Command(CommandCode.ARM).pack())
    payload[0] = 200  # no such command code
    s.host.write(encode_frame(Command.CMD_ID, bytes(payload), 7))
    s.server.serve(1_000)
    first, second = s.replies()
    assert isinstance(first, CommandAck) and (first.request_seq, first.result) == (3, AckResult.FAILED)
    assert isinstance(second, CommandAck) and (second.request_seq, second.result) == (
        7,
        AckResult.UNSUPPORTED,
    )
    assert s.server.link.decode_errors == 1


# --- issue 18: safety parameters only in SAFE; DIRECT starts from rest after every disarm and loss ------


def _live(rig: Rig, ms: int) -> None:
    """Tick ``ms`` ms with a host heartbeat every 100 ms (DIRECT needs it)."""
    for k in range(ms):
        if k % 100 == 0:
            rig.send(Heartbeat(rig.now_us, k))
        rig.tick()


def _direct(rig: Rig) -> None:
    rig.arm()
    rig.set_rc(frame(right=Lever.MIDDLE))
    _live(rig, 20)
    rig.send(Command(CommandCode.SET_MODE, (float(Mode.DIRECT), 0.0, 0.0)))
    _live(rig, 5)
    assert rig.fw.mode == Mode.DIRECT


def test_armed_param_sets_cannot_raise_the_current() -> None:
    """The issue's sequence: CURRENT_LIMIT_A=10, TENSION_MAX_N=100, SPOOL_RADIUS_M=0.05 while armed, then
    SET_TENSIONS(100, 100, 100) once sent 10000 raw to every motor."""
    rig = Rig(link=True)
    _direct(rig)
    rig.drain()
    for name, value in (("CURRENT_LIMIT_A", 10.0), ("TENSION_MAX_N", 100.0), ("SPOOL_RADIUS_M", 0.05)):
        rig.send(ParamSet(name, value))
    rig.send(Command(CommandCode.SET_TENSIONS, (100.0, 100.0, 100.0)))
    peak = 0
    for k in range(1000):
        if k % 100 == 0:
            rig.send(Heartbeat(rig.now_us, k))
        rig.tick()
        peak = max(peak, *(abs(c) for c in rig.currents))
    assert rig.fw.mode == Mode.DIRECT and peak > 0
    assert peak <= 3000  # the documented 3 A
    msgs = rig.drain()
    echoed = {v.name: v.value for v in msgs if isinstance(v, ParamValue)}
    assert echoed == {"CURRENT_LIMIT_A": 3.0, "TENSION_MAX_N": 20.0, "SPOOL_RADIUS_M": pytest.approx(0.01)}
    reasons = [e.text for e in msgs if isinstance(e, Event) and e.kind == EventKind.PARAM]
    assert reasons == ["rejected: safety parameter: only in SAFE"] * 3
    # in SAFE the same values are taken (the current limit up to the C610's 10 A, the operator's call)
    rig.set_rc(frame(right=Lever.DOWN))
    _live(rig, 20)
    assert rig.fw.mode == Mode.SAFE
    rig.send(ParamSet("CURRENT_LIMIT_A", 10.0))
    rig.send(ParamSet("CURRENT_LIMIT_A", 10.5))
    rig.send(ParamSet("TORQUE_K_NM_A", 0.05))
    rig.send(ParamSet("PAYIN_MAX_M_S", 2.0))
    rig.tick(20)
    echoed_list = [(v.name, v.value) for v in rig.drain() if isinstance(v, ParamValue)]
    assert echoed_list == [
        ("CURRENT_LIMIT_A", 10.0),
        ("CURRENT_LIMIT_A", 10.0),
        ("TORQUE_K_NM_A", pytest.approx(0.18)),
        ("PAYIN_MAX_M_S", pytest.approx(0.1)),
    ]


def _another_valid_value(name: str) -> float:
    """A value the board takes in SAFE for parameter ``name``: its default moved a little (a bool flipped)."""
    row = WIRE_ROWS[name]
    default = float(row.default)
    if row.kind is Kind.BOOL:
        value = 1.0 - default
    elif row.kind is Kind.INT:
        value = float(round(default * 0.9))
    else:
        value = default * 0.9
    FirmwareConfig().with_param(name, value, safe=True)  # valid: only the SAFE rule can refuse it
    return value


@pytest.mark.parametrize("name", sorted(SAFETY_PARAMS))
def test_every_safety_parameter_is_refused_while_armed_and_taken_in_safe(name: str) -> None:
    """Every row of the table flagged SAFE-only, not only the ones an incident named."""
    rig = Rig(link=True)
    _direct(rig)
    rig.drain()
    before = rig.fw.config.get_param(name)
    value = _another_valid_value(name)
    rig.send(ParamSet(name, value))
    _live(rig, 200)  # the events go out at their own rate
    msgs = rig.drain()
    assert [(v.name, v.value) for v in msgs if isinstance(v, ParamValue)] == [(name, pytest.approx(before))]
    reasons = [e.text for e in msgs if isinstance(e, Event) and e.kind == EventKind.PARAM]
    assert reasons == ["rejected: safety parameter: only in SAFE"]
    assert rig.fw.mode == Mode.DIRECT and rig.fw.config.get_param(name) == before
    rig.set_rc(frame(right=Lever.DOWN))
    _live(rig, 20)
    assert rig.fw.mode == Mode.SAFE
    rig.send(ParamSet(name, value))
    rig.tick(5)
    assert rig.fw.config.get_param(name) == pytest.approx(value)


@pytest.mark.parametrize("name", sorted(WIRE_ROWS))
def test_an_armed_param_set_follows_its_row(name: str) -> None:
    """Every row of the table, armed in DIRECT: refused (value kept) exactly when the row says SAFE-only,
    taken otherwise. Which rows are SAFE-only is pinned by ``test_the_safety_parameters_are_the_documented_
    seven`` (tests/controller/test_params.py): the table is both the rule and this test's expectation, so a
    row whose flag is dropped is caught there, not here."""
    rig = Rig(link=True)
    _direct(rig)
    rig.drain()
    before = rig.fw.config.get_param(name)
    value = _another_valid_value(name)
    for other in (value, 0.5, 1.0, 0.1, 10.0):  # a default of 0 moved by 10 % is still 0
        try:
            FirmwareConfig().with_param(name, other, safe=True)
        except ConfigError:
            continue
        if other != before:
            value = other
            break
    assert value != before, name
    rig.send(ParamSet(name, value))
    _live(rig, 20)
    assert rig.fw.mode == Mode.DIRECT
    if WIRE_ROWS[name].safety:
        assert rig.fw.config.get_param(name) == before
    else:
        assert rig.fw.config.get_param(name) == pytest.approx(value)


def test_non_safety_params_still_change_while_armed() -> None:
    rig = Rig(link=True)
    _direct(rig)
    rig.send(ParamSet("SLEW_N_S", 80.0))
    _live(rig, 5)
    assert rig.fw.config.mapping.slew_n_per_s == 80.0


@pytest.mark.parametrize("loss", ["disarm", "rc", "heartbeat"])
def test_direct_tensions_do_not_survive_a_disarm_or_a_loss(loss: str) -> None:
    rig = Rig(link=True)
    _direct(rig)
    rig.send(Command(CommandCode.SET_TENSIONS, (10.0, 10.0, 10.0)))
    _live(rig, 500)
    driven = max(rig.currents)
    assert driven > 0
    if loss == "disarm":
        rig.send(Command(CommandCode.DISARM, (0.0, 0.0, 0.0)))
        _live(rig, 5)
        rig.send(Command(CommandCode.ARM, (0.0, 0.0, 0.0)))
    elif loss == "rc":
        rig.set_rc(None)
        _live(rig, 50)
    else:
        rig.tick(600)  # no heartbeat: DIRECT ends
    assert rig.fw.direct_tensions_n == [rig.config.mapping.pretension_n] * 3
    rig.set_rc(frame(right=Lever.DOWN))
    _live(rig, 20)
    _direct(rig)  # a new session only selects DIRECT
    _live(rig, 500)
    pre = rig.config.mapping.pretension_n
    raw = round(pre * rig.config.motor.spool_radius_m / rig.config.motor.torque_constant_nm_per_a * 1000)
    assert max(rig.currents) <= raw < driven


def test_the_host_requirement_changes_only_in_safe() -> None:
    """Dropping the host requirement while the arm moves would silence the host-loss failsafe."""
    rig = Rig(link=True)
    rig.send(Heartbeat(rig.now_us, 0))
    rig.send(Command(CommandCode.REQUIRE_HOST, (1.0, 0.0, 0.0)))  # SAFE: taken
    _direct(rig)
    assert rig.fw.config.failsafe.host_required
    rig.drain()
    rig.send(Command(CommandCode.REQUIRE_HOST, (0.0, 0.0, 0.0)))
    rig.send(ParamSet("HOST_REQUIRED", 0.0))
    _live(rig, 200)  # the events go out at their own rate
    msgs = rig.drain()
    acks = [m for m in msgs if isinstance(m, CommandAck) and m.command == CommandCode.REQUIRE_HOST]
    assert [(a.result, a.text) for a in acks] == [(AckResult.REJECTED, "safety parameter: only in SAFE")]
    assert [(v.name, v.value) for v in msgs if isinstance(v, ParamValue)] == [("HOST_REQUIRED", 1.0)]
    reasons = [e.text for e in msgs if isinstance(e, Event) and e.kind == EventKind.PARAM]
    assert reasons == ["rejected: safety parameter: only in SAFE"] * 2
    assert rig.fw.mode == Mode.DIRECT and rig.fw.config.failsafe.host_required
    rig.set_rc(frame(right=Lever.DOWN))
    _live(rig, 20)
    assert rig.fw.mode == Mode.SAFE
    rig.send(Command(CommandCode.REQUIRE_HOST, (0.0, 0.0, 0.0)))
    _live(rig, 5)
    acks = [m for m in rig.drain() if isinstance(m, CommandAck) and m.command == CommandCode.REQUIRE_HOST]
    assert [a.result for a in acks] == [AckResult.ACCEPTED]
    assert not rig.fw.config.failsafe.host_required
