"""The one lockstep loop: an environment that owns the virtual board, and an episode that owns the question.

In the spirit of dm_control's ``rl/control.py``: :class:`Environment` builds the virtual board (firmware,
plant, radio, wire) and the scripted host on the board link, and advances them one control period per
:meth:`Environment.step`, in this order::

    episode.before_tick   the episode acts on the world (moves an object, sends a command)
    drone                 a scripted drone motion sets the acceleration due (:mod:`hil.sim.drone_motion`)
    host.before_tick      the host writes what is due (heartbeat, scripted messages)
    board.tick            physics, delivery, the firmware's due tasks, the command to the ESCs
    host.after_tick       the host takes what the board sent
    sample                the run record samples the firmware and the plant (when one is kept)
    episode.after_tick    the episode looks at the result

An :class:`Episode` is a scenario, an experiment's trial or a benchmark: it never owns a loop (dm_control
calls it a task; here that word is the firmware scheduler's). Scenarios, experiments, the benchmark and the
tests all step through this one loop; what differs is the episode.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from types import TracebackType

from controller.rc import DbusSerialSource
from hil import foxglove_log
from hil.board import BoardConfig, VirtualBoard
from hil.faults import Fault
from hil.foxglove_log import telemetry_json
from hil.harness import ScriptedHost
from hil.radio import RadioScript
from hil.recording import Recorder
from hil.run_record import PlantSamples, RunRecord, Samples
from hil.sim.drone_motion import DroneMotion, DroneMotionPlayer
from protocol.messages import Event, Message, RawRc, Telemetry
from protocol.stream import MessageStream

__all__ = ["Environment", "Episode"]


class Episode:
    """What a run does and asks, as hooks around the loop's ticks; every hook is optional (the defaults do
    nothing)."""

    def initialize(self, env: Environment) -> None:
        """Called once, after the board is built and before the first tick."""

    def before_tick(self, env: Environment) -> None:
        """Called before every tick, at the time of the previous one."""

    def after_tick(self, env: Environment) -> None:
        """Called after every tick (and after the run record sampled it)."""


class Environment:
    """A virtual board in lockstep, a scripted host on its link, and an episode.

    Args:
        config: the board to build.
        episode: the episode whose hooks run around every tick (default: none).
        faults: faults to inject (windows in board time).
        radio: the pilot's stick and lever script (``config.rc == "radio"``).
        host_script: messages the host sends, as (time, message).
        heartbeats: the host sends heartbeats at all.
        recorder: record every byte in and out of the board (and the decoded telemetry) to MCAP.
        record_ticks: keep a :class:`~hil.run_record.RunRecord` with room for this many ticks (0: none, the
            cheapest loop, for experiments and benchmarks that measure the plant themselves).
        drone: the drone's scripted motion (its acceleration, in the plant's time; the pose is held).

    Raises:
        ValueError: the drone's motion changes between two control periods.
    """

    def __init__(
        self,
        config: BoardConfig | None = None,
        *,
        episode: Episode | None = None,
        faults: Sequence[Fault] = (),
        radio: RadioScript | None = None,
        host_script: Sequence[tuple[int, Message]] = (),
        heartbeats: bool = True,
        recorder: Recorder | None = None,
        record_ticks: int = 0,
        drone: DroneMotion | None = None,
    ) -> None:
        self.episode = episode if episode is not None else Episode()
        self.recorder = recorder
        config = config if config is not None else BoardConfig()
        # Refused before the board exists, so a bad motion leaves nothing open.
        period_us = config.plant.control_period_us
        self._drone = DroneMotionPlayer(drone, period_us) if drone is not None else None
        self.board = VirtualBoard(config, faults=tuple(faults), radio_script=radio, recorder=recorder)
        wire = self.board.wire
        if wire is None:  # a board built without a link end of its own always has a wire
            raise RuntimeError("a lockstep board has a wire")
        self.host = ScriptedHost(wire.host, self.board.faults, heartbeats=heartbeats)
        for t_us, msg in host_script:
            self.host.at(t_us, msg)
        self.samples: Samples | None = None
        self.plant_samples: PlantSamples | None = None
        self._board_tx: bytearray | None = None
        if record_ticks > 0:
            self.samples = Samples(record_ticks)
            self.plant_samples = PlantSamples(record_ticks)
            self._board_tx = wire.tx_tap = bytearray()
        self._telemetry_written = 0
        self.ticks = 0
        # Hooks the episode does not override are not called: the loop stays as lean as the board's tick.
        kind = type(self.episode)
        self._before_tick = self.episode.before_tick if kind.before_tick is not Episode.before_tick else None
        self._after_tick = self.episode.after_tick if kind.after_tick is not Episode.after_tick else None
        self.episode.initialize(self)

    # --- what episodes look at -----------------------------------------------------------------------

    @property
    def now_us(self) -> int:
        """The board's time (of the last tick)."""
        return self.board.now_us

    @property
    def period_us(self) -> int:
        """The control period: one tick."""
        return self.board.period_us

    # --- the loop ---------------------------------------------------------------------------------

    def step(self) -> None:
        """One control period (see the module's docstring for the order)."""
        board, host = self.board, self.host
        if self._before_tick is not None:
            self._before_tick(self)
        drone = self._drone
        if drone is not None and board.plant.time_us >= drone.next_us:  # work only at a change
            drone.apply(board.plant)
        host.before_tick(board.now_us)
        board.tick()
        host.after_tick(board.now_us)
        if self.samples is not None:
            self._sample()
        if self.recorder is not None:
            self._record_telemetry(self.recorder)
        self.ticks += 1
        if self._after_tick is not None:
            self._after_tick(self)

    def run(
        self,
        duration_us: int,
        *,
        until: Callable[[], bool] | None = None,
        progress: Callable[[int, int], None] | None = None,
    ) -> int:
        """Step for ``duration_us`` of simulated time, or until ``until()`` holds after a tick.

        Args:
            duration_us: how long at most.
            until: checked after every tick; the run stops when it returns True.
            progress: called as ``progress(ticks_done, ticks_total)`` every 100 ticks.

        Returns:
            The number of ticks run.
        """
        total = max(0, duration_us // self.period_us)
        for i in range(total):
            self.step()
            if progress is not None and (i + 1) % 100 == 0:
                progress(i + 1, total)
            if until is not None and until():
                return i + 1
        return total

    def _sample(self) -> None:
        s, p = self.samples, self.plant_samples
        assert s is not None and p is not None  # only called when a record is kept
        i = s.n
        if i >= s.t_us.size:
            raise IndexError(f"the run record holds {s.t_us.size} ticks")
        fw = self.board.firmware
        plant = self.board.plant
        s.t_us[i] = self.board.now_us
        s.current_raw[i] = plant.commanded_currents_raw()[:3]
        s.target_n[i] = fw.tensions_n
        s.phase[i] = fw.phase
        s.mode[i] = fw.mode
        s.grasp[i] = fw.grasp_state
        s.rc_frames_ok[i] = fw.rc_frames_ok
        rc = fw.rc
        s.rc_refused[i] = fw.rc_rejected + (
            rc.framer.frames_dropped if isinstance(rc, DbusSerialSource) else 0
        )
        link = fw.link
        s.link_crc_errors[i] = link.crc_errors if link is not None else 0
        p.tension_n[i] = plant.cable_tensions_n()
        p.tip_m[i] = plant.tip_pose().pos_m
        p.cable_m[i] = plant.cable_lengths_m()
        p.applied_a[i] = abs(plant.applied_currents_a()).max()
        s.n = i + 1

    def _record_telemetry(self, recorder: Recorder) -> None:
        telemetry = self.host.telemetry
        if len(telemetry) > self._telemetry_written:
            for msg in telemetry[self._telemetry_written :]:
                recorder.write_json(foxglove_log.TELEMETRY, msg.time_us, telemetry_json(msg))
            self._telemetry_written = len(telemetry)

    # --- the result -------------------------------------------------------------------------------

    def record(self, duration_us: int) -> RunRecord:
        """The run record of what ran so far (needs ``record_ticks``).

        Raises:
            RuntimeError: the environment keeps no record.
        """
        if self.samples is None or self.plant_samples is None or self._board_tx is None:
            raise RuntimeError("this environment keeps no run record (record_ticks=0)")
        board, host = self.board, self.host
        run = RunRecord(
            config=board.config.firmware,
            duration_us=duration_us,
            samples=self.samples.trim(),
            plant=self.plant_samples.trim(self.samples.n),
            extremes=board.plant.extremes(),
            sent=list(host.sent),
            telemetry_received_us=[m.time_us for m in host.telemetry],
            decode_errors=host.decode_errors,
        )
        run.counters = dict(board.firmware.counters)
        run.counters.update({f"injected_{k}": v for k, v in board.faults.injected.items()})
        _board_messages(run, bytes(self._board_tx))
        return run

    def close(self) -> None:
        """Zero current to the plant and release the link (safe twice)."""
        self.board.close()

    def __enter__(self) -> Environment:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()


def _board_messages(run: RunRecord, data: bytes) -> None:
    """Fill the record's board-message lists from what the board sent, before any link fault."""
    stream = MessageStream()
    for _, msg in stream.feed(data):
        if isinstance(msg, Telemetry):
            run.telemetry_sent_us.append(msg.time_us)
        elif isinstance(msg, RawRc):
            run.rc.append((msg.time_us, msg.frame))
        elif isinstance(msg, Event):
            run.events.append((msg.time_us, msg))
    # The board's own bytes, before any fault: an error here is a firmware bug, and counted as one.
    run.counters["board_output_errors"] = stream.decode_errors + stream.crc_errors
