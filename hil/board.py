"""The virtual board: the firmware emulator driving the MuJoCo plant, with a virtual radio and a host link.

One :class:`VirtualBoard` is the C-board, its three C610/M2006 motors, the arm and (optionally) the
DT7/DR16 radio, all in one process. Two ways to drive it:

- **lockstep** (:meth:`VirtualBoard.tick`, scenarios and experiments): every control period, in this
  order, on simulated time and without reading any clock:

  1. physics: the plant advances one control period (a whole number of MuJoCo steps);
  2. delivery: the radio's DBUS bytes reach the board's UART, the motors' feedback frames reach its CAN
     receive queue, the host's bytes reach its link (each through the fault set, each recorded);
  3. the firmware runs every task due at the new time (:meth:`controller.firmware.Firmware.run_due`);
  4. the command frame it sent reaches the ESCs, and its link bytes reach the host.

  Same inputs and seed, same bytes out: a run is a pure function of (design, scenario, faults, seed).

- **real time** (:func:`run_realtime`, ``spirob-hil board``): the same tick paced by
  :class:`controller.clock.RealTimeClock` (absolute deadlines, SCHED_FIFO when permitted), with the
  link on a pty or a TCP socket that speaks exactly what the real board speaks on /dev/ttyACM0.
  :class:`VirtualBoardProcess` runs it in a child process, so nothing in the host can stall its loop.
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import logging
import multiprocessing as mp
import multiprocessing.connection
import signal
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from types import TracebackType
from typing import Any, Literal

import numpy as np

from controller.clock import Clock, RealTimeClock, monotonic_ns, run_periodic, zero_ns
from controller.config import FirmwareConfig
from controller.firmware import Firmware
from controller.rc import DbusSerialSource, LinkRcSource, RcSource
from controller.transport import Transport, parse_listen
from hil import recording
from hil.canbus import SimMotorBus
from hil.errors import HilError
from hil.faults import Fault, FaultSet
from hil.radio import RadioScript, VirtualRadio
from hil.recording import Recorder
from hil.sim.plant import Plant
from hil.sim.spiral import SpiralDesign
from hil.sim.types import PlantConfig, RingConfig
from protocol.dbus import RcFrame
from protocol.messages import ARMS_MOTORS_MAX, ArmPoses, Message, SimPoses

_log = logging.getLogger(__name__)

RcInput = Literal["radio", "link"]


# --- lockstep byte pipes --------------------------------------------------------------------------


class WireEnd(Transport):
    """One end of a lockstep board link: writes collect in :attr:`outbox`, reads drain :attr:`inbox`."""

    def __init__(self, tx_capacity: int = 1 << 20) -> None:
        super().__init__(tx_capacity)
        self.inbox = bytearray()
        self.outbox = bytearray()

    def _read(self) -> bytes:
        if not self.inbox:
            return b""
        data = bytes(self.inbox)
        self.inbox.clear()
        return data

    def _write(self, data: bytearray) -> int:
        self.outbox += data
        return len(data)


class LinkWire:
    """The USB cable between a scripted host and the board in lockstep, with faults on it.

    :meth:`carry` moves what each end wrote to the other end. What the board receives is recorded on
    ``/board/link_rx`` after the faults; what the board sent on ``/board/link_tx`` before them, so a
    replay compares the board's own output.
    """

    def __init__(self, faults: FaultSet | None = None, recorder: Recorder | None = None) -> None:
        self.host = WireEnd()
        self.board = WireEnd()
        self.faults = faults
        self.recorder = recorder
        self.tx_tap: bytearray | None = None
        """When set, collects every byte the board sends, before any link fault (the run record reads the
        board's own messages from it)."""

    def carry(self, t_us: int) -> None:
        """Deliver everything written so far (subject to faults)."""
        self.to_board(t_us)
        self.to_host(t_us)

    def to_board(self, t_us: int) -> None:
        """Host -> board."""
        outbox = self.host.outbox
        faulty = self.faults is not None and bool(self.faults.faults)
        if not outbox and not faulty:
            return  # nothing written, nothing delayed in flight (only a fault delays bytes)
        data = bytes(outbox)
        outbox.clear()
        if faulty:
            assert self.faults is not None
            data = self.faults.link_bytes(t_us, data, "rx")
        if data:
            self.board.inbox += data
            if self.recorder is not None:
                self.recorder.write_raw(recording.LINK_RX, t_us, data)

    def to_host(self, t_us: int) -> None:
        """Board -> host."""
        outbox = self.board.outbox
        faulty = self.faults is not None and bool(self.faults.faults)
        if not outbox and not faulty:
            return  # nothing written, nothing delayed in flight (only a fault delays bytes)
        data = bytes(outbox)
        outbox.clear()
        if data:
            if self.recorder is not None:
                self.recorder.write_raw(recording.LINK_TX, t_us, data)
            if self.tx_tap is not None:
                self.tx_tap += data
        if faulty:
            assert self.faults is not None
            data = self.faults.link_bytes(t_us, data, "tx")
        if data:
            self.host.inbox += data


# --- the board ------------------------------------------------------------------------------------


@dataclass(frozen=True)
class BoardConfig:
    """Everything that makes up one virtual board (picklable; units in names).

    Attributes:
        design: the arm's spiral design (default: the paper's 3-cable prototype).
        plant: plant configuration (model, solver, control period).
        firmware: firmware configuration.
        rc: ``"radio"``: a virtual DT7/DR16 on the DBUS UART (scenarios); ``"link"``: the host's virtual
            RC frames over the board link are the radio (the browser panel).
        seed: seed of every random choice (encoder offsets, faults).
        start_packed: start with the arm coiled on its first cable (the grasp strategy's start pose).
    """

    design: SpiralDesign = field(default_factory=SpiralDesign.paper_prototype)
    plant: PlantConfig = field(default_factory=PlantConfig)
    firmware: FirmwareConfig = field(default_factory=FirmwareConfig)
    rc: RcInput = "radio"
    seed: int = 0
    start_packed: bool = False

    def describe(self) -> dict[str, str]:
        """String pairs for a recording's metadata (enough to rebuild the board for replay)."""
        return {
            "design": json.dumps(dataclasses.asdict(self.design)),
            "firmware": json.dumps(self.firmware.to_dict()),
            "rc": self.rc,
            "seed": str(self.seed),
            "start_packed": str(self.start_packed),
        }


def board_plant_config(cfg: BoardConfig) -> PlantConfig:
    """The plant a board drives: an array of the firmware's arms when it lays itself out as one.

    A firmware of N > 1 arms drives ``RingConfig(arms=N)`` unless ``cfg.plant.ring`` says where they hang;
    every arm is ``cfg.design``, whose cables must be the firmware's cables per arm.

    Raises:
        ValueError: the firmware's layout and the plant's differ.
    """
    fw, plant = cfg.firmware, cfg.plant
    ring = plant.ring
    if ring is None and fw.arm_count > 1:
        ring = RingConfig(arms=fw.arm_count)
    if ring is None:
        return plant
    if ring.arms != fw.arm_count or cfg.design.cables != fw.cables_per_arm:
        raise ValueError(
            f"the firmware drives {fw.arm_count} arm(s) of {fw.cables_per_arm} cable(s); the plant has "
            f"{ring.arms} arm(s) of {cfg.design.cables}"
        )
    return dataclasses.replace(plant, ring=ring)


class VirtualBoard:
    """Firmware + plant + radio + link, advanced one control period at a time.

    Args:
        config: what to build.
        faults: faults to inject (windows in board time).
        radio_script: the pilot's stick and lever states over time (``rc="radio"``).
        link: the board's end of the host link; default a :class:`LinkWire` end for a scripted host.
        recorder: record every byte in and out (and decoded telemetry) to MCAP.
        exec_timer_ns: the scheduler's execution-time timer. Lockstep runs keep the default constant
            (execution times read 0) so that two runs produce byte-identical telemetry; real-time runs
            pass :func:`controller.clock.monotonic_ns`.
    """

    def __init__(
        self,
        config: BoardConfig | None = None,
        *,
        faults: list[Fault] | tuple[Fault, ...] = (),
        radio_script: RadioScript | None = None,
        link: Transport | None = None,
        recorder: Recorder | None = None,
        exec_timer_ns: Callable[[], int] = zero_ns,
    ) -> None:
        self.config = cfg = config if config is not None else BoardConfig()
        rng = np.random.default_rng(cfg.seed)
        plant_rng, fault_rng = rng.spawn(2)
        self.faults = FaultSet(faults, fault_rng)
        self.recorder = recorder
        self.plant = Plant(cfg.design, board_plant_config(cfg), plant_rng)
        self.plant_lag_us = 0
        """Real time only: physics a late tick could not catch up (:data:`PLANT_CATCH_UP_MAX`), by which the
        plant lags the firmware's clock."""
        if cfg.start_packed:
            self.plant.set_packed(0)
        self.period_us = cfg.plant.control_period_us
        if cfg.firmware.control_period_us != self.period_us:
            raise ValueError(
                f"firmware control period {cfg.firmware.control_period_us} us differs from the plant's "
                f"{self.period_us} us"
            )
        self.now_us = 0
        self.bus = SimMotorBus(
            self.plant,
            lambda: self.now_us,
            faults=self.faults,
            recorder=recorder,
            current_limit_raw=cfg.firmware.motor.current_limit_raw,
            motor_count=cfg.firmware.motor_count,
        )
        self.radio: VirtualRadio | None = None
        rc: RcSource
        if cfg.rc == "radio":
            self.radio = VirtualRadio(radio_script, self.faults)
            rc = DbusSerialSource(self.radio.uart)
        elif cfg.rc == "link":
            rc = LinkRcSource()
        else:
            raise ValueError(f"rc must be 'radio' or 'link', got {cfg.rc!r}")
        self.rc = rc
        self.wire: LinkWire | None = None
        if link is None:
            self.wire = LinkWire(self.faults, recorder)
            link = self.wire.board
        self.link = link
        self.firmware = Firmware(
            cfg.firmware,
            self.bus,
            rc,
            link,
            poses=self._poses,
            exec_timer_ns=exec_timer_ns,
        )
        self.ticks = 0
        if recorder is not None:
            recorder.write_json("/board/config", 0, cfg.describe())

    def _poses(self) -> SimPoses | list[Message]:
        # Every body: SimPoses carries the drone and arm 0 (an array's arms do not fit one message), one
        # ArmPoses each further arm (pose_messages; docs/board-link.md, 0x010A).
        poses = self.plant.body_poses()
        positions, quats = poses.positions_m, poses.quats_wxyz
        arms = self.plant.arms
        if self.recorder is not None:  # an input of the firmware like any other: replay needs it
            data = recording.pack_poses(positions, quats)
            # The Foxglove view draws one chain: an array's drone and arm 0.
            view = None if arms == 1 else 1 + self.plant.units_per_arm
            self.recorder.write_raw(recording.POSES, self.now_us, data, view_bodies=view)
        return pose_messages(self.now_us, positions, quats, arms)

    def tick(self, now_us: int | None = None) -> None:
        """One control period in lockstep order: physics, delivery, firmware, command delivery.

        Args:
            now_us: the firmware's time for this tick; default the plant's time. Loop-delay faults shift
                the firmware's time, never the physics.
        """
        self.plant.step()
        self.firmware_tick(self.plant.time_us if now_us is None else now_us)

    def firmware_tick(self, t: int) -> None:
        """The tick after its physics step: sensors and link delivered, firmware at ``t``, commands out.

        Real time calls it at the deadline and steps the plant for the next tick right after it
        (:func:`run_realtime`), so what arrived while the plant stepped is taken in at the deadline, as a
        UART stamps a frame on arrival, never at a time read before a long physics step.
        """
        if self.faults.faults:
            t += self.faults.tick_delay_us(t)
        self.now_us = t
        rec = self.recorder
        if self.radio is not None:
            data = self.radio.transmit(t)  # into the board's UART, where the firmware's RC source reads
            if data and rec is not None:
                rec.write_raw(recording.DBUS_RX, t, data)
        self.bus.deliver_feedback()
        if self.wire is not None:
            self.wire.to_board(t)
        if rec is not None:
            rec.write_raw(recording.TICK, t, b"")
        self.firmware.run_due(t)
        self.bus.deliver_command()
        if self.wire is not None:
            self.wire.to_host(t)
        self.ticks += 1

    def run(self, duration_us: int, on_tick: Callable[[VirtualBoard], None] | None = None) -> None:
        """Lockstep for ``duration_us`` of simulated time, calling ``on_tick`` after every tick."""
        for _ in range(max(0, duration_us // self.period_us)):
            self.tick()
            if on_tick is not None:
                on_tick(self)

    def close(self) -> None:
        """Zero current to the plant and release the link (safe twice)."""
        if not self.bus.is_shutdown:
            self.bus.shutdown()
        self.link.close()

    def __enter__(self) -> VirtualBoard:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()


def poses_message(time_us: int, positions_m: Any, quats_wxyz: Any) -> SimPoses:
    """A ``SimPoses`` from (n, 3) positions and (n, 4) quaternions, built without per-element conversions."""
    return SimPoses(
        time_us,
        tuple(map(tuple, np.asarray(positions_m).tolist())),
        tuple(map(tuple, np.asarray(quats_wxyz).tolist())),
    )


def pose_messages(time_us: int, positions_m: Any, quats_wxyz: Any, arms: int = 1) -> SimPoses | list[Message]:
    """What the poses task sends for the plant's body poses (the drone, then each arm's units, arm after arm).

    One arm: the one ``SimPoses`` it always was (byte-identical). An array: ``SimPoses`` with the drone and
    arm 0 (what a host that predates arrays draws), then one ``ArmPoses`` for each further arm
    (docs/board-link.md, 0x010A), all stamped ``time_us``.

    Raises:
        ValueError: ``arms`` is not 1-8, or the units do not split into ``arms`` equal arms.
    """
    if not 1 <= arms <= ARMS_MOTORS_MAX:
        raise ValueError(f"{arms} arms: 1-{ARMS_MOTORS_MAX}")
    if arms == 1:
        return poses_message(time_us, positions_m, quats_wxyz)
    positions = np.asarray(positions_m).tolist()
    quats = np.asarray(quats_wxyz).tolist()
    units, rest = divmod(len(positions) - 1, arms)
    if rest or units < 1 or len(quats) != len(positions):
        raise ValueError(f"{len(positions)} body poses are not a drone and {arms} arms of as many units")
    msgs: list[Message] = [
        SimPoses(time_us, tuple(map(tuple, positions[: 1 + units])), tuple(map(tuple, quats[: 1 + units])))
    ]
    for arm in range(1, arms):
        lo, hi = 1 + arm * units, 1 + (arm + 1) * units
        msgs.append(
            ArmPoses(time_us, arm, arms, tuple(map(tuple, positions[lo:hi])), tuple(map(tuple, quats[lo:hi])))
        )
    return msgs


# --- real time ------------------------------------------------------------------------------------


@dataclass(frozen=True)
class BoardStall:
    """A board that stalls itself (fault injection): its control task sleeps ``for_s`` every ``every_s``
    of its own clock, as a firmware blocked on a flash write or a lock would. What the harness's tests
    use to prove that a stalled board fails its checks and is never excused as a starved machine."""

    every_s: float
    for_s: float


PLANT_CATCH_UP_MAX = 20
"""Control periods of physics a late real-time tick steps through at most (about 2 ms of CPU for the
prototype); beyond it the plant lags the wall clock and :attr:`VirtualBoard.plant_lag_us` counts it."""


def run_realtime(
    board: VirtualBoard,
    clock: Clock,
    duration_us: int | None = None,
    stop: threading.Event | None = None,
    stall: BoardStall | None = None,
) -> None:
    """Drive ``board`` in real time: one tick per control period on absolute deadlines.

    A late tick's missed deadlines are skipped by the firmware, never caught up in a burst, while the
    plant is stepped through them under the last command (up to :data:`PLANT_CATCH_UP_MAX` periods a
    tick), as a real arm keeps moving while its board is late and its C610s hold the last current. A
    plant that lagged instead would move slower than the firmware's clock says: one CI run's arm, 28
    ticks late early in a reach, unrolled with a speed dip the grasp took for a contact, and declared
    HOLD on nothing. Zero current on the way out. ``stall`` makes the control task stall itself
    (:class:`BoardStall`).
    """
    period = board.period_us
    offset = 0  # clock time minus plant time, fixed at the start
    deadline = 0

    def begin(start_us: int) -> int:
        nonlocal offset, deadline
        board.firmware.clock_kind = clock.kind
        board.plant.step()  # the first tick's physics (each tick steps the next one's: see step)
        offset = start_us - (board.plant.time_us - period)
        deadline = start_us + period
        if not board.firmware.scheduler.started:
            board.firmware.start(deadline - offset)  # the firmware's task grid is this loop's grid
        return deadline

    next_stall_us = None if stall is None else clock.now_us() + int(stall.every_s * 1e6)

    def step(now_us: int) -> int:
        nonlocal deadline, next_stall_us
        if stall is not None and next_stall_us is not None and now_us >= next_stall_us:
            time.sleep(stall.for_s)  # the injected stall, inside the control task
            next_stall_us = now_us + int(stall.every_s * 1e6)
        board.firmware_tick(now_us - offset)
        # The next tick's physics now, not after the wake-up: the firmware runs at its deadline and takes
        # in what arrived meanwhile at that time (stamped before a long step, a 40 ms step read as 40 ms of
        # radio silence). The plant still steps [t, t + period] under the command of time t, as in lockstep.
        board.plant.step()
        done_us = clock.now_us()
        deadline += period
        if done_us - deadline >= period:  # more than a whole period late: skip, do not burst
            missed = (done_us - deadline) // period
            deadline += missed * period
            # The arm does not wait for a late board: its physics through the skipped periods, under the
            # command in force (bounded, so that a machine that cannot keep up does not fall further).
            catch_up = min(missed, PLANT_CATCH_UP_MAX)
            for _ in range(catch_up):
                board.plant.step()
            board.plant_lag_us += (missed - catch_up) * period
        return deadline

    try:
        run_periodic(clock, step, begin=begin, duration_us=duration_us, stop=stop)
    finally:
        board.bus.send_currents((0,) * board.bus.motor_count)
        board.bus.deliver_command()


# --- a board in its own process -------------------------------------------------------------------


def realtime_board(
    config: BoardConfig, listen: str | None = None, *, listen_any: bool = False
) -> tuple[VirtualBoard, str]:
    """A board for real time with its link endpoint open; returns it and the URL a host connects to.

    Args:
        config: the board; with ``rc="radio"`` the virtual radio holds both levers DOWN (SAFE).
        listen: ``socket://HOST:PORT`` for TCP, or None for a pty.
        listen_any: allow a ``listen`` address other than loopback (whoever reaches it can drive the arm).

    Raises:
        ValueError: ``listen`` is not ``socket://HOST:PORT``, or not loopback without ``listen_any``.
        OSError: the endpoint cannot be opened (port in use, ...).
    """
    from controller.transport import TcpServerTransport
    from hil.transports import PtyTransport

    transport: PtyTransport | TcpServerTransport
    if listen is None:
        transport = PtyTransport()
    else:
        host, port = parse_listen(listen, listen_any=listen_any)
        transport = TcpServerTransport(host, port)
    script = RadioScript([(0, RcFrame.neutral())]) if config.rc == "radio" else None
    board = VirtualBoard(config, link=transport, radio_script=script, exec_timer_ns=monotonic_ns)
    return board, transport.url


def _child_main(
    conn: multiprocessing.connection.Connection,
    config: BoardConfig,
    listen: str | None,
    listen_any: bool,
    fifo: bool,
    stall: BoardStall | None = None,
) -> None:
    """Entry of the board process: open the endpoint, report its URL, run until told to stop."""
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        board, url = realtime_board(config, listen, listen_any=listen_any)
    except Exception as exc:  # reported to the parent as one line
        conn.send(("error", f"{type(exc).__name__}: {exc}"))
        conn.close()
        return
    conn.send(("ok", url))

    def watch_parent() -> None:
        with contextlib.suppress(EOFError, OSError):
            conn.recv()  # anything, or EOF when the parent dies
        stop.set()

    threading.Thread(target=watch_parent, name="parent-watch", daemon=True).start()
    try:
        run_realtime(board, RealTimeClock(fifo=fifo), stop=stop, stall=stall)
    finally:
        board.close()


class VirtualBoardProcess:
    """A real-time virtual board in a child process; :meth:`start` returns the URL to connect to.

    Args:
        config: the board to build (default: the prototype arm, RC from the host link).
        listen: ``socket://127.0.0.1:PORT`` (port 0 picks a free one), or None for a pty.
        listen_any: allow a ``listen`` address other than loopback, as the CLI's ``--listen-any``.
        pty: serve on a pty (the default when ``listen`` is None).
        fifo: ask for SCHED_FIFO in the child (it says so in its log when refused).
        stall: make the board's control task stall itself (fault injection, :class:`BoardStall`).

    Raises:
        ValueError: ``listen`` is malformed, or not loopback without ``listen_any``.
    """

    def __init__(
        self,
        config: BoardConfig | None = None,
        *,
        listen: str | None = "socket://127.0.0.1:0",
        listen_any: bool = False,
        pty: bool = False,
        fifo: bool = True,
        stall: BoardStall | None = None,
    ) -> None:
        self.config = config if config is not None else BoardConfig(rc="link")
        self.stall = stall
        self.listen = None if pty else listen
        self.listen_any = listen_any
        if self.listen is not None:
            parse_listen(self.listen, listen_any=listen_any)
        self.fifo = fifo
        self.url: str | None = None
        self._proc: mp.process.BaseProcess | None = None
        self._conn: multiprocessing.connection.Connection | None = None

    def start(self, timeout_s: float = 30.0) -> str:
        """Start the board; returns its pyserial URL or pty path.

        Raises:
            HilError: the board did not come up (the reason in one line).
        """
        if self._proc is not None:
            raise HilError("virtual board already started")
        ctx = mp.get_context("spawn")
        parent, child = ctx.Pipe()
        proc = ctx.Process(
            target=_child_main,
            args=(child, self.config, self.listen, self.listen_any, self.fifo, self.stall),
            name="virtual-board",
        )
        proc.start()
        child.close()
        self._proc, self._conn = proc, parent
        if not parent.poll(timeout_s):
            self.stop()
            raise HilError(f"virtual board did not start within {timeout_s:g} s")
        try:
            status, value = parent.recv()
        except EOFError:
            self.stop()
            raise HilError("virtual board exited during start-up") from None
        if status != "ok":
            self.stop()
            raise HilError(f"virtual board failed to start: {value}")
        self.url = str(value)
        return self.url

    @property
    def alive(self) -> bool:
        """The board process is running."""
        return self._proc is not None and self._proc.is_alive()

    def stop(self, timeout_s: float = 5.0) -> None:
        """Stop the board (zero current first); safe twice."""
        proc, conn = self._proc, self._conn
        self._proc = self._conn = None
        if conn is not None:
            with contextlib.suppress(OSError, ValueError):
                conn.send("stop")
            conn.close()
        if proc is not None:
            proc.join(timeout_s)
            if proc.is_alive():
                proc.terminate()
                proc.join(timeout_s)
            if proc.is_alive():
                proc.kill()
                proc.join(timeout_s)

    def __enter__(self) -> VirtualBoardProcess:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.stop()
