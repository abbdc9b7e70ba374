"""host.panel.model (control ownership, server-side clamps, history, notices) and host.panel.scene
geometry."""

from __future__ import annotations

import math

import numpy as np
import pytest

from host.link.client import LinkState
from host.panel.history import RingBuffer
from host.panel.model import CLI_CLIENT, ControlResult, UiModel
from host.panel.scene import ArmGeometry, DronePose, arm_drawing, default_hanging_pose, quat_mul, quat_rotate
from protocol.dbus import Lever
from protocol.messages import (
    Command,
    CommandCode,
    Event,
    EventKind,
    Message,
    Mode,
    Phase,
    Telemetry,
)


def make_model(token: str | None = None) -> tuple[UiModel, list[Message]]:
    sent: list[Message] = []

    def send(msg: Message) -> bool:
        sent.append(msg)
        return True

    return UiModel(send, token=token), sent


def test_first_client_gets_control_second_must_be_handed_it() -> None:
    m, _ = make_model()
    assert m.request_control(1) is ControlResult.GRANTED
    assert m.request_control(2) is ControlResult.PENDING
    assert m.holder == 1 and m.pending == 2
    # The requester cannot act meanwhile.
    assert not m.set_stick(2, 3, 400)
    assert not m.command(2, CommandCode.ARM)
    assert m.answer_request(1, grant=False) is False
    assert m.holder == 1 and m.pending is None
    m.request_control(2)
    assert not m.answer_request(2, grant=True)  # only the holder answers
    assert m.answer_request(1, grant=True)
    assert m.holder == 2
    assert not m.set_stick(1, 3, 400)


def test_new_holder_starts_safe_and_leaving_releases() -> None:
    m, _ = make_model()
    m.request_control(1)
    assert m.set_lever(1, "right", "MIDDLE")
    assert m.set_stick(1, 3, 500)
    m.request_control(2)
    m.answer_request(1, grant=True)
    frame = m.virtual_rc_frame()
    assert frame is not None
    assert frame.right_lever == Lever.DOWN and frame.channels == (0, 0, 0, 0)
    m.client_left(2)
    assert m.holder is None
    assert m.virtual_rc_frame() is None  # nobody holds control: no RC at all


def test_values_are_clamped_server_side() -> None:
    m, sent = make_model()
    m.request_control(1)
    m.set_stick(1, 0, 10_000)
    m.set_stick(1, 1, -10_000)
    m.set_stick(1, 2, float("nan"))
    frame = m.virtual_rc_frame()
    assert frame is not None and frame.channels[:3] == (660, -660, 0)
    assert frame.is_valid()
    assert not m.set_lever(1, "right", "SIDEWAYS")
    with pytest.raises(ValueError):
        m.set_stick(1, 7, 0)
    m.set_direct_tension(1, 0, 1e9)
    m.set_direct_tension(1, 1, -5)
    cmd = sent[-1]
    assert isinstance(cmd, Command) and cmd.code == CommandCode.SET_TENSIONS
    assert cmd.args[0] == m.limits.tension_max_n and cmd.args[1] == 0.0
    assert not m.command(1, CommandCode.SET_MODE, (42.0, 0.0, 0.0))
    assert m.command(1, CommandCode.SET_MODE, (float(Mode.DIRECT), 0.0, 0.0))
    assert m.set_length_hold(1, 2, True)
    cmd = sent[-1]
    assert isinstance(cmd, Command) and cmd.code == CommandCode.HOLD_LENGTHS
    assert math.isnan(cmd.args[0]) and math.isnan(cmd.args[1]) and cmd.args[2] == math.inf
    assert m.set_length_hold(1, 0, False)
    assert sent[-1].args[0] == -math.inf  # type: ignore[attr-defined]
    assert not m.set_length_hold(2, 0, True)  # not the holder
    with pytest.raises(ValueError):
        m.set_length_hold(1, 3, True)
    assert m.command(1, CommandCode.HOLD_LENGTHS, (math.nan, 0.05, -math.inf))
    cmd = sent[-1]
    assert isinstance(cmd, Command) and math.isnan(cmd.args[0]) and cmd.args[1:] == (0.05, -math.inf)


def test_estop_is_open_to_every_authorised_client_and_forces_safe() -> None:
    m, sent = make_model()
    m.request_control(1)
    m.set_lever(1, "right", Lever.MIDDLE)
    assert m.estop(2)
    assert isinstance(sent[-1], Command) and sent[-1].code == CommandCode.ESTOP
    frame = m.virtual_rc_frame()
    assert frame is not None and frame.right_lever == Lever.DOWN
    assert any(n.title == "E-STOP pressed" for n in m.notices_after(0))


def test_token_gates_everything_but_watching() -> None:
    m, sent = make_model(token="s3cret")
    assert not m.authorise(1, None)
    assert not m.authorise(1, "wrong")
    assert m.request_control(1) is ControlResult.DENIED
    assert not m.estop(1)
    assert not sent
    assert m.authorise(1, "s3cret")
    assert m.request_control(1) is ControlResult.GRANTED
    assert m.is_authorised(CLI_CLIENT)


def test_reconnect_resets_levers_and_notifies() -> None:
    m, _ = make_model()
    m.request_control(1)
    m.set_lever(1, "right", Lever.MIDDLE)
    m.on_link_state(LinkState.CONNECTED)
    m.on_link_state(LinkState.DISCONNECTED)
    m.on_link_state(LinkState.CONNECTED)
    frame = m.virtual_rc_frame()
    assert frame is not None and frame.right_lever == Lever.DOWN
    titles = [n.title for n in m.notices_after(0)]
    assert "Board disconnected" in titles and "Board reconnected" in titles


def test_telemetry_history_and_phase_notices() -> None:
    m, _ = make_model()
    for i in range(5):
        m.on_board_message(Telemetry(time_us=i * 10_000, phase=Phase.OK, commanded_current=(1000, 0, 0)))
    m.on_board_message(Telemetry(time_us=60_000, phase=Phase.RC_LOST))
    m.on_board_message(Event(61_000, EventKind.FAULT, 2, 0.0, "motor 2 silent"))
    data = m.history.snapshot()
    assert data.shape == (6, 16)
    assert data[0, 7] == pytest.approx(1.0)  # commanded current of motor 1 in A
    titles = [n.title for n in m.notices_after(0)]
    assert titles == ["RC lost", "Fault"]


def test_ring_buffer_keeps_newest_and_decimates() -> None:
    rb = RingBuffer(4, 1)
    for i in range(10):
        rb.append(float(i), [float(i * 2)])
    snap = rb.snapshot()
    assert snap[:, 0].tolist() == [6.0, 7.0, 8.0, 9.0]
    assert rb.snapshot(max_points=2)[:, 0].tolist() == [7.0, 9.0]
    with pytest.raises(ValueError):
        RingBuffer(0, 1)


def test_arm_drawing_of_a_hanging_arm() -> None:
    geom = ArmGeometry.default()
    pos, quat = default_hanging_pose(geom, DronePose((0.0, 0.0, 1.0)))
    d = arm_drawing(pos, quat, geom)
    n = geom.units
    assert d.unit_positions.shape == (n, 3) and d.unit_scales.shape == (n, 3)
    assert d.cable_segments.shape == (3 * (n + 1), 2, 3)
    # Hanging straight down: every unit below the previous one, the tip lowest, cables 120° apart.
    assert np.all(np.diff(d.unit_positions[:, 2]) < 0)
    assert d.tip_m[2] == pytest.approx(1.0 - 0.03 - sum(geom.unit_lengths_m), abs=1e-9)
    a, b = d.cable_segments[1, 0, :2], d.cable_segments[n + 2, 0, :2]
    angle = math.degrees(math.atan2(a[0] * b[1] - a[1] * b[0], a @ b))
    assert abs(angle) == pytest.approx(120.0, abs=1e-6)
    # Units point along the hang: each instance's +z maps to -z in the world.
    z = quat_rotate(d.unit_wxyzs, np.tile([0.0, 0.0, 1.0], (n, 1)))
    assert np.allclose(z, [0.0, 0.0, -1.0])


def test_arm_drawing_resamples_other_unit_counts() -> None:
    geom = ArmGeometry.default()
    pos, quat = default_hanging_pose(geom.resized(10))
    assert arm_drawing(pos, quat, geom).unit_positions.shape == (10, 3)
    with pytest.raises(ValueError):
        arm_drawing(pos[:1], quat[:1], geom)


def test_quaternion_helpers() -> None:
    q = np.array([math.cos(math.pi / 4), 0.0, 0.0, math.sin(math.pi / 4)])  # 90° about z
    assert np.allclose(quat_rotate(q, np.array([1.0, 0.0, 0.0])), [0.0, 1.0, 0.0])
    assert np.allclose(quat_mul(q, q), [0.0, 0.0, 0.0, 1.0])


def test_refused_command_toasts_the_tab_that_sent_it_with_the_boards_reason() -> None:
    from protocol.messages import AckResult, CommandAck

    m, sent = make_model()
    m.request_control(4)
    assert m.command(4, CommandCode.SET_MODE, (float(Mode.DIRECT), 0.0, 0.0))
    assert isinstance(sent[-1], Command)
    seq = m.notices_after(0)[-1].seq if m.notices_after(0) else 0
    m.on_board_message(CommandAck(CommandCode.SET_MODE, AckResult.REJECTED, 7, "right lever not MIDDLE"))
    (notice,) = m.notices_after(seq)
    assert notice.client == 4 and notice.title == "Board refused SET_MODE"
    assert notice.body == "right lever not MIDDLE"
    # An accepted one says nothing; both are in the event console.
    m.on_board_message(CommandAck(CommandCode.SET_MODE, AckResult.ACCEPTED, 8))
    assert m.notices_after(notice.seq) == []
    lines = [e.text for e in m.events.entries() if e.source == "ack"]
    assert lines == ["SET_MODE REJECTED: right lever not MIDDLE", "SET_MODE ACCEPTED"]
    # An answer to a command no tab sent (MAVLink) goes to everyone.
    m.on_board_message(CommandAck(CommandCode.GRASP, AckResult.DENIED, 9, "not in GRASP"))
    assert m.notices_after(notice.seq)[-1].client is None


def test_a_tab_that_cannot_act_is_told_why() -> None:
    m, _ = make_model()
    m.request_control(1)
    assert not m.command(2, CommandCode.ARM)
    notice = m.notices_after(0)[-1]
    assert notice.client == 2 and "does not hold control" in notice.body


def test_control_request_toast_names_the_tab() -> None:
    m, _ = make_model()
    m.request_control(11)
    m.request_control(12)
    notice = m.notices_after(0)[-1]
    assert notice.client == 11 and notice.body.startswith("Tab 12 asks for control")


def test_param_set_is_checked_sent_and_confirmed_by_the_board() -> None:
    from protocol.messages import ParamSet, ParamValue

    m, sent = make_model()
    assert m.set_param(1, "PRETENSION_N", 1.0) == "this tab does not hold control"
    m.request_control(1)
    assert m.set_param(1, "NOPE", 1.0) == "unknown parameter 'NOPE'"
    assert m.set_param(1, "CURRENT_LIMIT_A", 50.0) == "current_limit_a: must be in (0, 10] A (C610)"
    assert not any(isinstance(x, ParamSet) for x in sent)
    assert m.set_param(1, "PRETENSION_N", 0.75) is None
    assert sent[-1] == ParamSet("PRETENSION_N", 0.75)
    assert m.param_status["PRETENSION_N"].confirmed is None
    m.on_board_message(ParamValue(5, 44, "PRETENSION_N", 0.75))
    status = m.param_status["PRETENSION_N"]
    assert status.confirmed == 0.75 and status.accepted
    # The board keeps another value (a safety parameter outside SAFE): read back and its reason.
    assert m.set_param(1, "CURRENT_LIMIT_A", 2.0) is None
    m.on_board_message(Event(10, EventKind.PARAM, 4, 2.0, "rejected: only in SAFE"))
    m.on_board_message(ParamValue(4, 44, "CURRENT_LIMIT_A", 3.0))
    status = m.param_status["CURRENT_LIMIT_A"]
    assert status.confirmed == 3.0 and not status.accepted and status.note == "rejected: only in SAFE"
    # The DIRECT tension ceiling follows the board's TENSION_MAX_N.
    m.on_board_message(ParamValue(8, 44, "TENSION_MAX_N", 12.0))
    assert m.limits.tension_max_n == 12.0


def test_event_console_is_bounded_and_keeps_board_times() -> None:
    from host.panel.console import EventConsole, console_html

    c = EventConsole(3)
    for i in range(5):
        c.add(i * 1_000_000, "board", "info", f"e{i}")
    assert [e.text for e in c.entries()] == ["e2", "e3", "e4"] and c.seq == 5
    assert c.entries()[-1].line().split() == ["4.000", "s", "board", "e4"]
    text = console_html(c.entries(), max_lines=2)
    assert text.index("e4") < text.index("e3") and "e2" not in text
    with pytest.raises(ValueError):
        EventConsole(0)
    m, _ = make_model()
    m.on_board_message(Event(2_500_000, EventKind.FAULT, 2, 0.0, "motor 2 silent"))
    (entry,) = m.events.entries()
    assert entry.board_time_us == 2_500_000 and entry.level == "error" and "motor 2 silent" in entry.text


def test_camera_presets_follow_the_stick_axes() -> None:
    from host.panel.scene import CAMERA_PRESETS, camera_view

    drone = DronePose((0.0, 0.0, 1.0))
    centre, tip = (0.0, 0.0, 0.9), (0.0, 0.0, 0.76)
    views = {p: camera_view(p, centre, drone, tip) for p in CAMERA_PRESETS}
    # Stick view: from -y looking +y, so stick right (+x) is screen right and stick up (+y) is away.
    pos, look = views["sticks"]
    assert pos[1] < look[1] and abs(pos[0] - look[0]) < 1e-9
    assert views["top"][0][2] > 1.5 and views["tip"][1] == tip
    # Behind the drone follows its yaw: nose (body +x) turned to +y puts the camera at -y.
    yawed = DronePose((0.0, 0.0, 1.0), (math.cos(math.pi / 4), 0.0, 0.0, math.sin(math.pi / 4)))
    pos, look = camera_view("behind", centre, yawed, tip)
    assert pos[1] < look[1] - 1.0 and abs(pos[0]) < 1e-6
    with pytest.raises(ValueError, match="camera preset"):
        camera_view("nowhere", centre, drone, tip)


def test_mavlink_commands_are_logged_in_the_event_console() -> None:
    from protocol.messages import ParamSet

    m, _ = make_model()
    m.on_board_message(Telemetry(3_000_000))
    m.on_host_command(Command(CommandCode.GRASP), "MAVLink")
    m.on_host_command(ParamSet("SLEW_N_S", 40.0), "MAVLink")
    lines = [(e.source, e.text, e.board_time_us) for e in m.events.entries()]
    assert lines == [("MAVLink", "GRASP", 3_000_000), ("MAVLink", "set SLEW_N_S = 40", 3_000_000)]
