"""The virtual board: lockstep order, and the real-time board in its own process on a pty and on TCP."""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import pytest
import serial

from controller.clock import LockstepClock
from controller.config import FirmwareConfig
from controller.transport import MemoryTransport, parse_listen
from hil.board import (
    BoardConfig,
    LinkWire,
    VirtualBoard,
    VirtualBoardProcess,
    pose_messages,
    poses_message,
    realtime_board,
    run_realtime,
)
from hil.errors import HilError
from hil.harness import ScriptedHost
from hil.radio import RadioScript
from hil.sim.spiral import SpiralDesign
from protocol.dbus import Lever, RcFrame
from protocol.link import LinkParser
from protocol.messages import (
    ArmPoses,
    Event,
    EventKind,
    Heartbeat,
    Phase,
    RawRc,
    SimPoses,
    Telemetry,
    VirtualRc,
    decode,
    encode,
)
from tests.support.realtime_guard import largest_gap_s, retry_void


def test_lockstep_tick_order_and_time() -> None:
    board = VirtualBoard(radio_script=RadioScript([(0, RcFrame.neutral())]))
    assert board.wire is not None
    host = ScriptedHost(board.wire.host, board.faults)
    for _ in range(100):
        host.before_tick(board.now_us)
        board.tick()
        host.after_tick(board.now_us)
    assert board.now_us == 100_000 == board.plant.time_us
    assert board.firmware.phase == Phase.OK  # the radio showed the lever DOWN: gate passed
    assert len(host.telemetry) == 10  # 100 Hz
    assert any(isinstance(m, SimPoses) for m in host.other)
    board.close()


def _bodies(arms: int, units: int) -> tuple[np.ndarray, np.ndarray]:
    """Body poses as a plant gives them: the drone, then each arm's units; arm a's unit u at z = a + u/100."""
    z = [0.0] + [a + u / 100 for a in range(arms) for u in range(units)]
    positions = np.array([[0.0, 0.0, v] for v in z])
    quats = np.tile([1.0, 0.0, 0.0, 0.0], (len(z), 1))
    return positions, quats


def test_one_arms_poses_are_the_one_simposes_it_always_was() -> None:
    positions, quats = _bodies(1, 21)
    got = pose_messages(5, positions, quats)
    assert isinstance(got, SimPoses) and got == poses_message(5, positions, quats)
    assert got.pack() == poses_message(5, positions, quats).pack()


@pytest.mark.parametrize(("arms", "units"), [(2, 21), (4, 21), (8, 21), (3, 1)])
def test_an_arrays_poses_split_into_simposes_and_one_armposes_per_further_arm(arms: int, units: int) -> None:
    """8 arms of the 21-unit prototype (169 bodies) overflow one SimPoses (64): one ArmPoses per arm."""
    positions, quats = _bodies(arms, units)
    got = pose_messages(9, positions, quats, arms)
    assert isinstance(got, list)
    first, *rest = got
    assert isinstance(first, SimPoses) and len(first.positions_m) == 1 + units  # the drone and arm 0
    assert first.positions_m[0] == (0.0, 0.0, 0.0)
    assert first.tip_position_m[2] == pytest.approx((units - 1) / 100)
    further = [m for m in rest if isinstance(m, ArmPoses)]
    assert len(further) == len(rest)
    assert [(m.arm, m.arms, m.time_us) for m in further] == [(a, arms, 9) for a in range(1, arms)]
    for m in further:
        assert [p[2] for p in m.positions_m] == pytest.approx([m.arm + u / 100 for u in range(units)])
        m.pack()  # fits the wire


@pytest.mark.parametrize(("bodies_of", "arms"), [((2, 4), 3), ((1, 4), 0), ((1, 4), 9), ((0, 0), 2)])
def test_poses_that_do_not_split_into_the_arms_are_refused(bodies_of: tuple[int, int], arms: int) -> None:
    with pytest.raises(ValueError):
        pose_messages(0, *_bodies(*bodies_of), arms)


def test_an_array_board_sends_every_arms_poses() -> None:
    """4 arms of 2 cables: each pose tick brings SimPoses (drone + arm 0) and ArmPoses of arms 1-3, which
    are the plant's own body poses arm by arm."""
    cfg = BoardConfig(
        design=SpiralDesign.paper_prototype().with_cables(2), firmware=FirmwareConfig().with_arms(4, 2)
    )
    with VirtualBoard(cfg, radio_script=RadioScript([(0, RcFrame.neutral())])) as board:
        assert board.wire is not None
        host = ScriptedHost(board.wire.host, board.faults)
        for _ in range(40):
            host.before_tick(board.now_us)
            board.tick()
            host.after_tick(board.now_us)
        units = board.plant.units_per_arm
        sims = [m for m in host.other if isinstance(m, SimPoses)]
        arms = [m for m in host.other if isinstance(m, ArmPoses)]
        assert len(sims) == 2 and len(arms) == 3 * len(sims)  # 50 Hz, arms 1-3 after each SimPoses
        assert all(len(m.positions_m) == 1 + units for m in sims)
        assert [(m.arm, m.arms, len(m.positions_m)) for m in arms[-3:]] == [(a, 4, units) for a in (1, 2, 3)]
        assert {m.time_us for m in arms[-3:]} == {sims[-1].time_us}
        # The last ones are the plant's poses now (nothing moved since: the arms hang at rest).
        bodies = board.plant.body_poses().positions_m
        for m in arms[-3:]:
            lo = 1 + m.arm * units
            assert np.allclose(m.positions_m, bodies[lo : lo + units], atol=1e-3)


def test_control_period_mismatch_is_refused() -> None:
    with pytest.raises(ValueError, match="control period"):
        VirtualBoard(
            BoardConfig(firmware=FirmwareConfig().replaced(control_period_us=2000, link_period_us=2000))
        )


def test_link_wire_carries_both_ways() -> None:
    wire = LinkWire()
    wire.host.write(b"to board")
    wire.board.write(b"to host")
    wire.carry(0)
    assert wire.board.read() == b"to board" and wire.host.read() == b"to host"


def test_parse_listen() -> None:
    assert parse_listen("socket://127.0.0.1:5760") == ("127.0.0.1", 5760)
    for bad in ("tcp://127.0.0.1:1", "socket://127.0.0.1", "socket://:80", "socket://h:99999"):
        with pytest.raises(ValueError):
            parse_listen(bad)


@pytest.mark.parametrize("address", ["0.0.0.0", "192.168.1.5", "example.org", "[::]"])
def test_a_board_listens_beyond_loopback_only_when_allowed(address: str) -> None:
    """The CLI's rule (``--listen-any``) holds for every way to start a board, not just the command."""
    listen = f"socket://{address}:0"
    with pytest.raises(ValueError, match="add --listen-any"):
        parse_listen(listen)
    with pytest.raises(ValueError, match="add --listen-any"):
        VirtualBoardProcess(listen=listen)
    with pytest.raises(ValueError, match="add --listen-any"):
        realtime_board(BoardConfig(rc="link"), listen)  # refused before the plant is built
    assert parse_listen(listen, listen_any=True) == (address, 0)
    for loopback in ("127.0.0.1", "127.0.0.2", "localhost", "[::1]"):
        assert parse_listen(f"socket://{loopback}:0") == (loopback, 0)


def test_realtime_board_listens_on_any_address_when_allowed() -> None:
    board, url = realtime_board(BoardConfig(rc="link"), "socket://0.0.0.0:0", listen_any=True)
    try:
        assert url.startswith("socket://")
    finally:
        board.close()


RC_TIMEOUT_S = FirmwareConfig().failsafe.rc_timeout_us / 1e6
"""A host loop that sent nothing for longer than this starved the board of RC: the run is void."""


def _talk(url: str) -> tuple[list[Telemetry], int, float]:
    """Act as a host for a moment: heartbeats and virtual RC (lever DOWN, then MIDDLE + curl).

    Returns:
        The telemetry, the number of pose messages and the largest gap between two sends [s].
    """
    port = serial.serial_for_url(url, timeout=0)
    parser = LinkParser()
    telemetry: list[Telemetry] = []
    poses = 0
    sent_s: list[float] = []
    try:
        deadline = time.monotonic() + 4.0
        seq = 0
        t_start = time.monotonic()
        while time.monotonic() < deadline and len(telemetry) < 150:
            elapsed = time.monotonic() - t_start
            frame = RcFrame.neutral() if elapsed < 0.3 else RcFrame((0, 0, 0, 500), Lever.MIDDLE, Lever.DOWN)
            port.write(encode(VirtualRc(frame.pack()), seq) + encode(Heartbeat(seq, seq), seq + 1))
            sent_s.append(time.monotonic())
            seq = (seq + 2) & 0xFF
            for f in parser.feed(port.read(4096)):
                msg = decode(f)
                if isinstance(msg, Telemetry):
                    telemetry.append(msg)
                elif isinstance(msg, SimPoses):
                    poses += 1
            time.sleep(0.01)
    finally:
        port.close()
    return telemetry, poses, largest_gap_s(sent_s)


def _reached_manual(telemetry: list[Telemetry]) -> bool:
    return any(m.phase == Phase.OK and max(m.commanded_current) > 0 for m in telemetry)


def _talk_void(got: tuple[list[Telemetry], int, float]) -> str | None:
    """The run is void if it missed MANUAL while the host loop itself stalled past the RC timeout."""
    telemetry, _, gap_s = got
    if _reached_manual(telemetry) or gap_s <= RC_TIMEOUT_S:
        return None
    return f"the host loop sent nothing for {gap_s * 1e3:.0f} ms > {RC_TIMEOUT_S * 1e3:.0f} ms (void)"


@pytest.mark.realtime
@pytest.mark.parametrize("pty", [False, True], ids=["tcp", "pty"])
def test_realtime_board_process_serves_the_link(pty: bool) -> None:
    with VirtualBoardProcess(listen="socket://127.0.0.1:0", pty=pty, fifo=False) as board:
        url = board.start(timeout_s=60)
        assert url.startswith("/dev/") if pty else url.startswith("socket://127.0.0.1:")
        telemetry, poses, _ = retry_void(lambda: _talk(url), _talk_void)
        assert board.alive
    assert not board.alive
    assert len(telemetry) >= 100 and poses > 10
    # The virtual RC drove the real-time firmware through the gate into MANUAL with current flowing.
    assert _reached_manual(telemetry)
    assert telemetry[-1].time_us > telemetry[0].time_us


def test_board_process_reports_a_busy_port() -> None:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen(1)
        busy = s.getsockname()[1]
        with (
            VirtualBoardProcess(listen=f"socket://127.0.0.1:{busy}", fifo=False) as board,
            pytest.raises(HilError, match="failed to start"),
        ):
            board.start(timeout_s=60)


@dataclass
class _HeaderRun:
    """What the host saw around the long header (see the test below)."""

    telemetry: list[Telemetry] = field(default_factory=list)
    phases: list[int] = field(default_factory=list)
    raw: list[bytes] = field(default_factory=list)
    injected_at: int = -1
    sent_s: list[float] = field(default_factory=list)


def _send_long_header(url: str, header: bytes, marked: bytes) -> _HeaderRun:
    """Drive the board past the gate, send ``header`` then ``marked`` as the next RC frame; about 1 s."""
    port = serial.serial_for_url(url, timeout=0)
    parser = LinkParser()
    got = _HeaderRun()
    try:
        seq = 0
        deadline = time.monotonic() + 20.0
        while time.monotonic() < deadline:
            ok_since = next((i for i, m in enumerate(got.telemetry) if m.phase == Phase.OK), None)
            if got.injected_at < 0 and ok_since is not None and len(got.telemetry) - ok_since > 30:
                got.injected_at = len(got.telemetry)
                port.write(header)
                data = marked
            else:
                data = RcFrame.neutral().pack()
            port.write(encode(VirtualRc(data), seq) + encode(Heartbeat(seq, seq), seq + 1))
            got.sent_s.append(time.monotonic())
            seq = (seq + 2) & 0xFF
            for f in parser.feed(port.read(65536)):
                msg = decode(f)
                if isinstance(msg, Telemetry):
                    got.telemetry.append(msg)
                elif isinstance(msg, Event) and msg.kind == EventKind.PHASE:
                    got.phases.append(msg.code)
                elif isinstance(msg, RawRc):
                    got.raw.append(msg.data)
            if got.injected_at >= 0 and len(got.telemetry) > got.injected_at + 100:  # about 1 s after it
                break
            time.sleep(0.01)
    finally:
        port.close()
    return got


def _header_run_void(got: _HeaderRun) -> str | None:
    """RC_LOST is the product's failure only if the host kept sending; a stalled host loop voids the run."""
    gap_s = largest_gap_s(got.sent_s)
    if Phase.RC_LOST not in got.phases or gap_s <= RC_TIMEOUT_S:
        return None
    return f"the host loop sent nothing for {gap_s * 1e3:.0f} ms > {RC_TIMEOUT_S * 1e3:.0f} ms (void)"


@pytest.mark.realtime
def test_long_header_does_not_stall_a_realtime_board() -> None:
    """Issue 18: ``A5 F4 01 <seq> <crc8>`` (a valid header announcing 500 bytes) once froze link input for
    238 ms and latched RC_LOST. The board now refuses it as soon as it reads the id that follows."""
    from protocol.link import SOF, crc8

    head = bytes([SOF, 0xF4, 0x01, 0x33])
    header = head + bytes([crc8(head)])
    marked = RcFrame((7, 0, 0, 0), Lever.DOWN, Lever.DOWN).pack()  # the first RC frame after the header
    with VirtualBoardProcess(listen="socket://127.0.0.1:0", fifo=False) as board:
        url = board.start(timeout_s=60)
        got = retry_void(lambda: _send_long_header(url, header, marked), _header_run_void)
    assert got.injected_at >= 0, "the board never passed the gate"
    assert marked in got.raw  # the frame right after the header was taken
    assert Phase.RC_LOST not in got.phases
    assert all(m.phase == Phase.OK for m in got.telemetry[got.injected_at :])


def test_link_loss_resets_direct_on_a_tcp_board() -> None:
    """Issue 18: a new client that re-armed and only selected DIRECT got the last session's tensions."""
    import socket

    from controller.config import FirmwareConfig
    from controller.firmware import Firmware
    from controller.motorbus import FakeMotorBus
    from controller.rc import LinkRcSource
    from controller.transport import TcpServerTransport
    from protocol.messages import Command, CommandCode, Mode

    config = FirmwareConfig()
    transport = TcpServerTransport()
    fw = Firmware(config, FakeMotorBus(), LinkRcSource(), transport)
    now = [0]

    def tick(ms: int) -> None:
        for _ in range(ms):
            fw.run_due(now[0])
            now[0] += 1000

    host, port = transport.url.removeprefix("socket://").rsplit(":", 1)
    try:
        client = socket.create_connection((host, int(port)), timeout=2)
        client.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)  # no Nagle wait behind a small frame
        seq = 0

        def send(*msgs: object) -> None:
            nonlocal seq
            for msg in msgs:
                client.sendall(encode(msg, seq))  # type: ignore[arg-type]
                seq = (seq + 1) & 0xFF
            time.sleep(0.01)  # loopback delivery
            tick(1)

        send(VirtualRc(RcFrame.neutral().pack()), Heartbeat(0, 0))
        tick(5)
        middle = RcFrame((0, 0, 0, 0), Lever.MIDDLE, Lever.DOWN).pack()
        send(VirtualRc(middle), Heartbeat(1, 1))
        send(Command(CommandCode.SET_MODE, (float(Mode.DIRECT), 0.0, 0.0)))
        send(Command(CommandCode.SET_TENSIONS, (10.0, 10.0, 10.0)), VirtualRc(middle))
        assert fw.mode == Mode.DIRECT and fw.direct_tensions_n == [10.0] * 3
        client.close()
        time.sleep(0.01)
        tick(1)
        assert fw.direct_tensions_n == [config.mapping.pretension_n] * 3
        assert not fw.modes.direct_requested
        assert fw.link is not None and fw.link.link_changes == 2  # connected, then lost
    finally:
        transport.close()


class _StallingClock(LockstepClock):
    """Simulated wall time in which a sender keeps its own cadence while the board's loop is busy."""

    def __init__(self, on_ms: Callable[[int], None]) -> None:
        super().__init__()
        self.on_ms = on_ms

    def elapse_us(self, dt_us: int) -> None:
        """Let ``dt_us`` of wall time pass, 1 ms at a time, telling the sender each millisecond."""
        end = self.now_us() + dt_us
        while self.now_us() < end:
            self.advance_to(min(end, self.now_us() + 1_000))
            self.on_ms(self.now_us())

    def sleep_until_us(self, deadline_us: int) -> None:
        if deadline_us > self.now_us():
            self.elapse_us(deadline_us - self.now_us())


def test_a_slow_physics_step_is_not_an_rc_loss_when_the_link_kept_sending() -> None:
    """A frame that arrived while the plant stepped is stamped after that step, as a UART would stamp it.

    The host sends ``VirtualRc`` every 14 ms of wall time whatever the board does; one physics step takes
    40 ms (a contact-rich step on a loaded machine). Stamping what arrived during the step with the time
    the tick *began* made the next tick see a 40 ms silence: RC_LOST mid-grasp on a board whose radio
    never stopped.
    """
    host_end, board_end = MemoryTransport.pair()
    frame = RcFrame.neutral().pack()
    seq = iter(range(1 << 30))

    def host_sends(now_us: int) -> None:
        if now_us % 14_000 < 1_000:
            host_end.write(encode(VirtualRc(frame), next(seq)))
        if now_us % 100_000 < 1_000:
            host_end.write(encode(Heartbeat(now_us, now_us // 100_000), next(seq)))
        host_end.read()  # the board's telemetry: not needed here

    clock = _StallingClock(host_sends)
    board = VirtualBoard(BoardConfig(rc="link"), link=board_end)
    step = board.plant.step
    stalls = [0]

    phases: list[Phase] = []

    def slow_step() -> None:  # also notes the phase the firmware reached on the tick before
        phases.append(board.firmware.phase)
        step()
        if board.plant.time_us == 1_000_000:  # once, 1 s in
            stalls[0] += 1
            clock.elapse_us(40_000)

    board.plant.step = slow_step  # type: ignore[method-assign]
    run_realtime(board, clock, duration_us=2_000_000)
    assert stalls == [1]
    assert Phase.OK in phases
    first_ok = phases.index(Phase.OK)
    assert set(phases[first_ok:]) == {Phase.OK}, f"{phases.count(Phase.RC_LOST)} ticks RC_LOST"
    board.close()


@pytest.mark.parametrize(("stall_us", "lag_us"), [(12_000, 0), (50_000, 30_000)])
def test_after_a_late_tick_the_plant_keeps_the_wall_clocks_time(stall_us: int, lag_us: int) -> None:
    """The firmware skips a late tick's missed deadlines; the arm does not wait: the plant steps through
    them under the last command (up to PLANT_CATCH_UP_MAX periods), so its time stays the firmware's. A
    plant that lagged moved slower than the firmware's clock said (a speed dip the grasp read as a
    contact). Beyond the cap the lag is counted, not hidden."""
    from hil.board import PLANT_CATCH_UP_MAX

    host_end, board_end = MemoryTransport.pair()
    clock = _StallingClock(lambda _now_us: host_end.read())
    board = VirtualBoard(BoardConfig(rc="radio"), link=board_end)
    step = board.plant.step

    def slow_step() -> None:
        step()
        if board.plant.time_us == 500_000:  # once, half a second in
            clock.elapse_us(stall_us)

    board.plant.step = slow_step  # type: ignore[method-assign]
    run_realtime(board, clock, duration_us=1_000_000)
    period = board.period_us
    assert PLANT_CATCH_UP_MAX * period < 50_000 - period
    # The stall ended a period into its own tick's wait: 49-50 periods missed, 20 caught up.
    assert lag_us - period <= board.plant_lag_us <= lag_us
    # The plant stepped one period ahead of the firmware's last tick, less exactly the lag it counts.
    assert board.plant.time_us == board.now_us + period - board.plant_lag_us
    board.close()


def test_a_real_time_array_board_ends_with_zero_current_on_every_motor() -> None:
    """The end of a real-time run sends zero current to all the board's motors (eight here, both frames)."""
    cfg = BoardConfig(
        design=SpiralDesign.paper_prototype().with_cables(1), firmware=FirmwareConfig().with_arms(8, 1)
    )
    host_end, board_end = MemoryTransport.pair()
    with VirtualBoard(cfg, link=board_end, radio_script=RadioScript([(0, RcFrame.neutral())])) as board:
        run_realtime(board, _StallingClock(lambda _now_us: host_end.read()), duration_us=50_000)
        assert board.bus.motor_count == 8
        assert board.plant.commanded_currents_raw() == (0,) * 8
