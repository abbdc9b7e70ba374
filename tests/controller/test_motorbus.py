"""MotorBus: clamping, packing, feedback decoding, shutdown; python-can's options (bit rate, receive filters,
timestamps, ``can.Logger``); loopback over python-can's virtual bus and over a real pty pair (slcan adapter
emulator with a fake C610 trio behind it)."""

from __future__ import annotations

import contextlib
import os
import time
from collections.abc import Iterator
from pathlib import Path

import can
import cantools
import pytest

from controller import motorbus
from controller.errors import BusError, PortError
from controller.fake_c610 import FakeC610Set
from controller.motorbus import CAN_BITRATE, CanMotorBus, FakeMotorBus, MotorBus, feedback_filters
from protocol.c610 import DBC_PATH, MotorFeedback, command_frames, current_command
from tests.support.c610_rigs import C610SetServer, SlcanAdapterEmulator


class RecordingBus(MotorBus):
    """A back end that records frames and serves scripted ones."""

    def __init__(self, **kwargs: int) -> None:
        super().__init__(**kwargs)
        self.sent: list[tuple[int, bytes]] = []
        self.inbox: list[tuple[int, bytes]] = []
        self.fail_send = False
        self.closed = 0

    def _send_frame(self, can_id: int, data: bytes) -> None:
        if self.fail_send:
            raise BusError("bus off")
        self.sent.append((can_id, data))

    def _recv_frames(self) -> list[tuple[int, bytes]]:
        out, self.inbox = self.inbox, []
        return out

    def _shutdown_backend(self) -> None:
        self.closed += 1


def test_send_clamps_packs_and_returns_what_was_sent() -> None:
    bus = RecordingBus(current_limit_raw=3000)
    sent = bus.send_currents([5000, -20000, 1234.4])  # type: ignore[list-item]
    assert sent == (3000, -3000, 1234)
    assert bus.sent == [(0x200, bytes.fromhex("0bb8f448 04d2 0000".replace(" ", "")))]
    with pytest.raises(ValueError):
        bus.send_currents([1, 2])


def test_send_packs_the_same_bytes_as_current_command() -> None:
    for motors in (1, 2, 3, 4):
        bus = RecordingBus(motor_count=motors)
        for values in ([10000, -10000, 0, 1], [1, -2, 3, -4], [-1, 32, 9999, -9999]):
            bus.send_currents(values[:motors])
            assert bus.sent[-1] == current_command(values[:motors])


def test_every_motor_count_sends_the_frames_of_command_frames() -> None:
    """1-4 motors: one 0x200 frame; 5-8: 0x200 then 0x1FF, byte for byte ``protocol.c610``'s layout."""
    values = [10000, -10000, 0, 1, -1, 2000, -2000, 9999]
    for motors in range(1, 9):
        bus = RecordingBus(motor_count=motors)
        assert bus.send_currents(values[:motors]) == tuple(values[:motors])
        assert bus.sent == command_frames(values[:motors])
        assert [can_id for can_id, _ in bus.sent] == ([0x200] if motors <= 4 else [0x200, 0x1FF])
        assert bus.frames_sent == len(bus.sent) and bus.last_send_ok


def test_eight_motors_golden_frames() -> None:
    bus = RecordingBus(motor_count=8)
    bus.send_currents([1, -2, 3, -4, 5, -6, 7, -8])
    assert bus.sent == [
        (0x200, bytes.fromhex("0001fffe0003fffc")),
        (0x1FF, bytes.fromhex("0005fffa0007fff8")),
    ]


def test_the_clamp_applies_to_motors_5_to_8() -> None:
    bus = RecordingBus(current_limit_raw=3000, motor_count=8)
    sent = bus.send_currents([0, 0, 0, 0, 5000, -20000, 2999.6, -3001])  # type: ignore[list-item]
    assert sent == (0, 0, 0, 0, 3000, -3000, 3000, -3000)
    assert bus.sent[1] == (0x1FF, bytes.fromhex("0bb8f4480bb8f448"))
    with pytest.raises(ValueError):
        bus.send_currents([0] * 7)


@pytest.mark.parametrize("motors", [0, 9])
def test_a_bus_has_one_to_eight_motors(motors: int) -> None:
    with pytest.raises(ValueError, match=r"motor_count must be 1\.\.8"):
        RecordingBus(motor_count=motors)


def test_a_failed_high_frame_is_counted_and_the_low_one_still_goes() -> None:
    class HighFails(RecordingBus):
        def _send_frame(self, can_id: int, data: bytes) -> None:
            if can_id == 0x1FF:
                raise BusError("bus off")
            super()._send_frame(can_id, data)

    bus = HighFails(motor_count=6)
    bus.send_currents([1, 2, 3, 4, 5, 6])
    assert [can_id for can_id, _ in bus.sent] == [0x200]
    assert bus.can_errors == 1 and bus.frames_sent == 1 and not bus.last_send_ok


def test_eight_motors_feedback_and_shutdown() -> None:
    bus = RecordingBus(motor_count=8)
    bus.inbox = [(0x200 + m, MotorFeedback(m, 0, 0).pack()) for m in range(1, 10)]
    got = bus.read_feedback()
    assert [motor for motor, _ in got] == list(range(1, 9)) and got[6][1].angle == 7
    assert bus.frames_ignored == 1  # 0x209: not one of ours
    bus.shutdown()
    assert bus.sent == [(0x200, bytes(8)), (0x1FF, bytes(8))]
    assert {f["can_id"] for f in feedback_filters(8)} == set(range(0x201, 0x209))


def test_fake_bus_of_eight_motors_drives_motors_5_to_8() -> None:
    bus = FakeMotorBus(FakeC610Set.of(8))
    assert bus.motor_count == 8
    bus.send_currents([0, 0, 0, 0, 0, 0, 0, 700])
    assert [m.current_raw for m in bus.c610s.motors] == [0] * 7 + [700]
    assert bus.c610s.commands == 2
    fb = dict(bus.read_feedback())
    assert set(fb) == set(range(1, 9)) and fb[8].current == 700  # stepped once, after 0x1FF
    for _ in range(50):
        bus.send_currents([0, 0, 0, 0, 0, 0, 0, 700])
    fb = dict(bus.read_feedback())
    assert fb[8].speed_rpm > 0 and fb[1].speed_rpm == 0
    assert len(bus.read_feedback()) == 0
    trio = FakeC610Set()
    trio.handle_frame(0x1FF, bytes.fromhex("0001000200030004"))  # motors 5-8: not in a trio
    assert trio.commands == 0 and [m.current_raw for m in trio.motors] == [0, 0, 0]


def test_send_failure_is_counted_not_raised() -> None:
    bus = RecordingBus()
    bus.fail_send = True
    assert bus.send_currents([1, 2, 3]) == (1, 2, 3)
    assert bus.can_errors == 1 and not bus.last_send_ok


def test_read_feedback_decodes_ours_and_counts_the_rest() -> None:
    bus = RecordingBus()
    bus.inbox = [
        (0x202, MotorFeedback(8191, -120, 300, 40).pack()),
        (0x201, bytes(7)),  # truncated
        (0x205, bytes(8)),  # motor 5: not ours
        (0x203, MotorFeedback(1, 2, 3).pack()),
    ]
    got = bus.read_feedback()
    assert got == [(2, MotorFeedback(8191, -120, 300, 40)), (3, MotorFeedback(1, 2, 3, 0))]
    assert bus.can_errors == 1 and bus.frames_ignored == 1
    assert bus.read_feedback() == []


def test_shutdown_sends_zero_once_and_is_safe_twice() -> None:
    with RecordingBus() as bus:
        bus.send_currents([100, 100, 100])
    bus.shutdown()
    assert bus.sent[-1] == (0x200, bytes(8))
    assert len(bus.sent) == 2 and bus.closed == 1
    with pytest.raises(BusError):
        bus.send_currents([0, 0, 0])
    assert bus.read_feedback() == []


def test_fake_bus_feedback_follows_commands() -> None:
    bus = FakeMotorBus()
    bus.c610s.silent.add(3)
    bus.send_currents([500, 0, 0])
    fb = dict(bus.read_feedback())
    assert set(fb) == {1, 2}
    for _ in range(50):
        bus.send_currents([500, 0, 0])
    assert dict(bus.read_feedback())[1].speed_rpm > 0  # motor 1 winds in


def _drain(bus: MotorBus, want: int, timeout_s: float = 5.0) -> dict[int, MotorFeedback]:
    got: dict[int, MotorFeedback] = {}
    deadline = time.monotonic() + timeout_s
    while len(got) < want and time.monotonic() < deadline:
        got.update(bus.read_feedback())
        time.sleep(0.001)
    return got


def test_loopback_over_python_can_virtual_bus() -> None:
    channel = f"test-motorbus-{os.getpid()}"
    trio = FakeC610Set(start_angles_counts=(8000, 100, 4000))
    with C610SetServer(can.Bus(interface="virtual", channel=channel), trio) as server:
        with CanMotorBus(channel, "virtual") as bus:
            bus.send_currents([300, -300, 0])
            got = _drain(bus, 3)
            assert set(got) == {1, 2, 3}
            assert server.c610s.motors[0].current_raw == 300 and server.c610s.motors[1].current_raw == -300
            assert got[1].current == 300 and got[2].current == -300
        assert server.error is None
    assert trio.motors[0].current_raw == 0  # shutdown sent zero current


@pytest.fixture
def pty_adapter() -> Iterator[tuple[str, SlcanAdapterEmulator]]:
    master, slave = os.openpty()
    name = os.ttyname(slave)
    emulator = SlcanAdapterEmulator(master)
    with emulator:
        yield name, emulator
    os.close(slave)


def test_loopback_over_a_pty_with_an_slcan_adapter(pty_adapter: tuple[str, SlcanAdapterEmulator]) -> None:
    name, adapter = pty_adapter
    with CanMotorBus(name, "slcan", sleep_after_open=0) as bus:
        assert adapter_open(adapter)
        assert "S8" in adapter.lines  # 1 Mbit/s
        for _ in range(3):
            bus.send_currents([1000, 0, -1000])
            got = _drain(bus, 3)
            assert set(got) == {1, 2, 3}
        assert got[1].current == 1000 and got[3].current == -1000
        assert bus.can_errors == 0
    # The adapter is a thread reading the pty: give it (bounded) time to take shutdown's zero frame.
    deadline = time.monotonic() + 5.0
    while adapter.c610s.motors[0].current_raw != 0 and time.monotonic() < deadline:
        time.sleep(0.001)
    assert adapter.c610s.motors[0].current_raw == 0
    assert adapter.error is None


def adapter_open(adapter: SlcanAdapterEmulator) -> bool:
    deadline = time.monotonic() + 5.0
    while not adapter.is_open and time.monotonic() < deadline:
        time.sleep(0.001)
    return adapter.is_open


def test_eight_motors_loopback_over_python_can_virtual_bus() -> None:
    channel = f"test-motorbus8-{os.getpid()}"
    c610s = FakeC610Set((8000, 100, 4000, 1, 2, 3, 4, 5))
    with C610SetServer(can.Bus(interface="virtual", channel=channel), c610s) as server:
        with CanMotorBus(channel, "virtual", motor_count=8) as bus:
            bus.send_currents([300, -300, 0, 0, 500, -500, 1000, -1000])
            got = _drain(bus, 8)
            assert set(got) == set(range(1, 9))
            assert [m.current_raw for m in c610s.motors] == [300, -300, 0, 0, 500, -500, 1000, -1000]
            assert got[5].current == 500 and got[8].current == -1000
            assert len(bus.feedback_timestamps_s) == 8 and all(bus.feedback_timestamps_s)
        # shutdown sends zero current on both frames; the server thread takes them (bounded wait)
        deadline = time.monotonic() + 5.0
        while any(m.current_raw for m in c610s.motors) and time.monotonic() < deadline:
            time.sleep(0.001)
        assert server.error is None
    assert all(m.current_raw == 0 for m in c610s.motors)


def test_missing_can_port_is_a_port_error() -> None:
    with pytest.raises(PortError, match="ttyDOESNOTEXIST"):
        CanMotorBus("/dev/ttyDOESNOTEXIST", "slcan", sleep_after_open=0)


def test_every_interface_gets_1_mbit_and_the_feedback_filters(monkeypatch: pytest.MonkeyPatch) -> None:
    opened: list[dict[str, object]] = []
    real_bus = can.Bus

    def fake_bus(**kwargs: object) -> can.BusABC:
        opened.append(kwargs)
        return real_bus(interface="virtual", channel=f"test-opened-{os.getpid()}")

    monkeypatch.setattr(can, "Bus", fake_bus)
    # slcan opens python-can's slcanBus class with a faster reader and writer (same arguments).
    monkeypatch.setattr(motorbus, "_slcan_bus_class", lambda: lambda **kw: fake_bus(interface="slcan", **kw))
    for interface in ("gs_usb", "socketcan", "slcan", "pcan"):
        CanMotorBus("0", interface).shutdown()
    assert [k["interface"] for k in opened] == ["gs_usb", "socketcan", "slcan", "pcan"]
    assert all(k["bitrate"] == CAN_BITRATE == 1_000_000 for k in opened)
    assert all(k["can_filters"] == feedback_filters(3) for k in opened)
    assert {f["can_id"] for f in feedback_filters(3)} == {0x201, 0x202, 0x203}


def test_receive_filters_keep_other_traffic_away() -> None:
    channel = f"test-filters-{os.getpid()}"
    peer = can.Bus(interface="virtual", channel=channel)
    with CanMotorBus(channel, "virtual") as bus:
        for can_id in (0x100, 0x1FF, 0x204, 0x205, 0x202):
            peer.send(
                can.Message(arbitration_id=can_id, data=MotorFeedback(10, 0, 0).pack(), is_extended_id=False)
            )
        got = _drain(bus, 1)
        assert set(got) == {2}
        assert bus.read_feedback() == [] and bus.frames_ignored == 0  # the filter dropped them, not we
    peer.shutdown()


def test_feedback_timestamps_are_the_frames_own(monkeypatch: pytest.MonkeyPatch) -> None:
    channel = f"test-stamps-{os.getpid()}"
    peer = can.Bus(interface="virtual", channel=channel, preserve_timestamps=True)
    with CanMotorBus(channel, "virtual") as bus:
        assert bus.feedback_timestamps_s == [0.0, 0.0, 0.0]
        for motor, stamp in ((1, 1000.25), (3, 1000.5)):
            data = MotorFeedback(motor, 0, 0).pack()
            peer.send(
                can.Message(timestamp=stamp, arbitration_id=0x200 + motor, data=data, is_extended_id=False)
            )
        assert set(_drain(bus, 2)) == {1, 3}
        assert bus.feedback_timestamps_s == [1000.25, 0.0, 1000.5]
    peer.shutdown()


def _c610_db() -> cantools.database.can.Database:
    db = cantools.database.load_file(str(DBC_PATH))
    assert isinstance(db, cantools.database.can.Database)
    return db


@pytest.mark.parametrize("suffix", [".log", ".blf"])
def test_hardware_path_logs_every_frame_for_python_can_and_the_dbc(tmp_path: Path, suffix: str) -> None:
    """CanMotorBus over python-can's virtual interface with a C610 trio: the log reads back with python-can,
    holds both directions with their timestamps, and the shipped DBC decodes every frame to our values."""
    channel = f"test-canlog-{os.getpid()}-{suffix[1:]}"
    log = tmp_path / f"run{suffix}"
    trio = FakeC610Set(start_angles_counts=(8000, 100, 4000))
    feedback: list[tuple[int, MotorFeedback]] = []
    with C610SetServer(can.Bus(interface="virtual", channel=channel), trio) as server:
        with CanMotorBus(channel, "virtual", log_file=log) as bus:
            for _ in range(5):
                bus.send_currents([1500, -700, 0])
                got = _drain(bus, 3)
                assert set(got) == {1, 2, 3}
                feedback += sorted(got.items())
            stamps = list(bus.feedback_timestamps_s)
        assert server.error is None
        assert bus.log_errors == 0
    frames = list(can.LogReader(log))
    sent = [m for m in frames if m.arbitration_id == 0x200]
    received = [m for m in frames if m.arbitration_id != 0x200]
    assert len(sent) == 6  # five commands and shutdown's zero frame
    assert len(received) == len(feedback) == 15
    db = _c610_db()
    for msg in sent[:5]:
        assert db.decode_message(msg.arbitration_id, bytes(msg.data)) == pytest.approx(
            {"Motor1_Current": 1.5, "Motor2_Current": -0.7, "Motor3_Current": 0.0, "Motor4_Current": 0.0}
        )
    assert all(v == 0 for v in db.decode_message(0x200, bytes(sent[5].data)).values())
    for msg, (motor, fb) in zip(received, feedback, strict=True):
        assert msg.arbitration_id == 0x200 + motor
        decoded = db.decode_message(msg.arbitration_id, bytes(msg.data))
        assert decoded == {
            "Angle": fb.angle,
            "Speed": fb.speed_rpm,
            "Current": pytest.approx(fb.current / 1000),
            "Temperature": fb.temperature,
        }
    # the timestamps are the frames' own, in order, and the last feedback of each motor is the bus's
    times = [m.timestamp for m in frames]
    assert all(t > 1e9 for t in times) and times == sorted(times)
    assert [received[-3 + i].timestamp for i in range(3)] == pytest.approx(stamps, abs=1e-6)


# --- what the mutation benchmark found untested --------------------------------------------------


def test_the_current_limit_takes_only_what_a_c610_can_do() -> None:
    from protocol.c610 import CURRENT_RAW_MAX

    bus = RecordingBus()
    bus.current_limit_raw = CURRENT_RAW_MAX
    bus.current_limit_raw = 0
    for bad in (CURRENT_RAW_MAX + 1, -1):
        with pytest.raises(ValueError, match="current_limit_raw must be"):
            bus.current_limit_raw = bad
    assert bus.current_limit_raw == 0


def test_the_clamp_holds_at_its_bound_on_both_sides() -> None:
    bus = RecordingBus(current_limit_raw=3000)
    assert bus.send_currents([3001, -3001, 3000]) == (3000, -3000, 3000)
    assert bus.send_currents([-3000, 2999, -2999]) == (-3000, 2999, -2999)


def test_another_nodes_command_frames_are_never_taken_as_feedback() -> None:
    """0x200 (motors 1-4's command, e.g. from a second controller on the bus) and 0x1FF are not motor
    0's or any motor's answer: a silent motor must not look alive from someone else's traffic."""
    bus = RecordingBus()
    bus.inbox = [(0x200, MotorFeedback(1, 2, 3, 4).pack()), (0x1FF, bytes(8)), (0x204, bytes(8))]
    assert bus.read_feedback() == []
    assert bus.frames_ignored == 3 and bus.can_errors == 0


class _FailingBus(RecordingBus):
    def __init__(self, error: Exception) -> None:
        super().__init__()
        self.error = error

    def _recv_frames(self) -> list[tuple[int, bytes]]:
        raise self.error

    def _send_frame(self, can_id: int, data: bytes) -> None:
        raise self.error


@pytest.mark.parametrize("error", [OSError("adapter unplugged"), BusError("bus off")], ids=["os", "bus"])
def test_a_failing_back_end_is_counted_and_the_bus_still_shuts_down(error: Exception) -> None:
    bus = _FailingBus(error)
    assert bus.read_feedback() == [] and bus.can_errors == 1
    bus.shutdown()  # the zero-current frame fails too: counted, and the bus is shut down anyway
    assert bus.can_errors == 2 and bus.is_shutdown and bus.closed == 1


def test_an_slcan_adapter_that_takes_no_bytes_is_a_bus_error_not_a_blocked_loop() -> None:
    """Nobody reads the pty's far end: writes never wait (the loop is never blocked); once the kernel's
    buffer and our bounded queue of untaken commands are full, each send fails and is counted."""
    master, slave = os.openpty()
    try:
        with CanMotorBus(os.ttyname(slave), "slcan", sleep_after_open=0) as bus:
            for _ in range(100_000):  # bounded: the kernel buffers some 64 KB of a pty
                bus.send_currents([0, 0, 0])
                if not bus.last_send_ok:
                    break
            assert bus.can_errors == 1 and bus.frames_sent > 100
            with pytest.raises(BusError, match="adapter took no bytes"):  # the reason a log would carry
                for _ in range(100_000):  # the untaken queue was dropped with the error: fill it again
                    bus._send_frame(0x200, bytes(8))
    finally:
        for fd in (master, slave):
            with contextlib.suppress(OSError):
                os.close(fd)
