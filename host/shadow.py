"""The shadow plant: the arm's shape on hardware, from a local plant driven by the measured motor currents.

A real C-board sends no ``SimPoses`` (it has no plant to read them from). So that the panel still shows
the arm's shape, the host runs its own :class:`hil.sim.plant.Plant` (the default design) and drives it with
what the board measures: every ``Telemetry`` frame carries the three motors' measured currents
(``motor_current``, raw C610 units, 1000 per amp). Those are applied with
:meth:`hil.sim.plant.Plant.apply_currents` and the plant is stepped by the *board* time elapsed since the
previous frame, so the shadow follows the board's clock, not the host's.

Why measured current and not the commanded current or the tension targets: the measured current is
what the motors actually produce. It includes the C610's own current loop, the current limit, a motor
that dropped out or a failsafe that zeroed the command, so the shadow arm feels the same cable tensions
as the real one (up to the model's friction and constants). See ``docs/host.md``.

- :class:`ShadowPlant` is a listener (``on_board_message``), like the UI model and the recorder; it
  keeps only the newest telemetry and does the physics in its own thread, so neither the board client's
  dispatcher nor the viser server ever waits for MuJoCo.
- Each update applies at most ``max_step_us`` (50 ms) of board time; a longer gap (a stalled host, a
  slow machine) is skipped and counted rather than simulated in a burst. The plant runs about 3-6x real time
  on this kind of machine (3.4x measured with other jobs loading both cores, 5.8x idle), so at 100 Hz
  telemetry it keeps up; ``ShadowStats.speed_x`` reports the figure live.
- Currents are applied as a zero-order hold of the measurement: the plant covers the interval between
  two frames with the currents of the earlier one, then takes the new frame's currents.
- As soon as the board sends ``SimPoses`` (a virtual board behind ``--port``), the shadow switches off
  for good: the true shape is on the link. While telemetry says ``SIM``, it waits ``sim_grace_us`` of
  board time for those poses before building a plant at all.
- A board laid out as an array (it sends ``ArmsTelemetry``, docs/board-link.md 0x0109) switches it off
  too: the shadow plant is one arm driven by motors 1-3, which on an array are cables of different arms,
  so its shape would be a wrong one. ``ArmsTelemetry`` follows each ``Telemetry``, and the check is made
  again after the (slow) plant build, so an array's shadow never publishes a pose.
"""

from __future__ import annotations

import enum
import logging
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from types import TracebackType
from typing import Any

from protocol.messages import ArmsTelemetry, Message, SimPoses, Telemetry, TelemetryFlags

__all__ = ["ShadowConfig", "ShadowPlant", "ShadowState", "ShadowStats", "reel_in_currents"]

_log = logging.getLogger(__name__)

PosesFn = Callable[[SimPoses], object]
PlantFactory = Callable[[], Any]


class ShadowState(enum.Enum):
    """Life cycle of the shadow plant (the value is what the panel shows)."""

    IDLE = "idle (not started)"
    WAITING = "waiting for telemetry"
    RUNNING = "running"
    OFF_SIM_POSES = "off (the board sends SimPoses)"
    OFF_ARRAY = "off (the board is an array of arms: the shadow plant models one arm)"
    FAILED = "failed"
    STOPPED = "stopped"


@dataclass(frozen=True, slots=True)
class ShadowConfig:
    """Settings of the shadow plant.

    Attributes:
        max_step_us: most board time simulated per telemetry frame; the rest of a longer gap is skipped.
        sim_grace_us: board time to wait for ``SimPoses`` while telemetry carries the ``SIM`` flag,
            before building a plant anyway.
        idle_wait_s: how long the thread waits for telemetry before checking for a stop (bounded loop).
    """

    max_step_us: int = 50_000
    sim_grace_us: int = 300_000
    idle_wait_s: float = 0.1

    def __post_init__(self) -> None:
        if self.max_step_us <= 0:
            raise ValueError(f"max_step_us must be > 0, got {self.max_step_us}")
        if self.sim_grace_us < 0:
            raise ValueError(f"sim_grace_us must be >= 0, got {self.sim_grace_us}")
        if not self.idle_wait_s > 0:
            raise ValueError(f"idle_wait_s must be > 0, got {self.idle_wait_s}")


@dataclass(frozen=True, slots=True)
class ShadowStats:
    """A snapshot of the shadow plant's bookkeeping.

    Attributes:
        state: life cycle state.
        updates: telemetry frames applied.
        steps: plant control periods simulated.
        board_time_us: board time the plant has reached (0 before the first frame).
        skipped_us: board time not simulated (gaps longer than ``max_step_us``).
        resyncs: board time went backwards (board restart): the plant kept its state, the clock resynced.
        divergences: the plant diverged and was reset.
        speed_x: simulated time / wall time spent stepping (how much faster than real time it runs).
        error: the reason for :attr:`ShadowState.FAILED`.
    """

    state: ShadowState
    updates: int = 0
    steps: int = 0
    board_time_us: int = 0
    skipped_us: int = 0
    resyncs: int = 0
    divergences: int = 0
    speed_x: float = 0.0
    error: str = ""

    def describe(self) -> str:
        """One line for the panel's health area."""
        if self.state is ShadowState.RUNNING:
            return (
                f"shadow plant {self.speed_x:.1f}x real time · {self.updates} updates · skipped "
                f"{self.skipped_us / 1000:.0f} ms · resets {self.divergences}"
            )
        if self.state is ShadowState.FAILED:
            return f"shadow plant failed: {self.error}"
        return f"shadow plant {self.state.value}"


def reel_in_currents(t: Telemetry) -> tuple[int, int, int]:
    """The measured currents of ``t`` as the plant's convention wants them: positive reels the cable in.

    A motor mounted mirrored (``motor_signs = -1`` in the firmware) reels in with a negative current. The
    sign is not on the wire, but the firmware's tension estimate is ``sign x current x K``, so a current
    and an estimate of opposite signs reveal a mirrored motor. A motor the board reports offline gets 0:
    its last reading is stale, and the board zeroes every current on a motor fault anyway.
    """
    out = [0, 0, 0]
    for i in range(3):
        if not (t.motors_online >> i) & 1:
            continue
        c = int(t.motor_current[i])
        out[i] = -c if c * t.tension_est_n[i] < 0.0 else c
    return out[0], out[1], out[2]


def _default_plant() -> Any:
    from hil.sim.plant import Plant  # type: ignore[import-not-found,unused-ignore]

    return Plant()


class ShadowPlant:
    """A listener that runs a local plant on measured currents and publishes its poses.

    Args:
        on_poses: called from the shadow thread with each new pose set (drone first, then the units,
            like ``SimPoses``; ``time_us`` is the board time), e.g. ``BoardState.on_shadow_poses``.
        config: step bounds.
        plant_factory: builds the plant (in the shadow thread); default ``hil.sim.plant.Plant()``, the
            default design.

    Use as a context manager, or :meth:`start` and :meth:`stop` (safe twice).
    """

    def __init__(
        self,
        on_poses: PosesFn,
        *,
        config: ShadowConfig | None = None,
        plant_factory: PlantFactory | None = None,
    ) -> None:
        self.config = config or ShadowConfig()
        self._on_poses = on_poses
        self._factory = plant_factory or _default_plant
        self._lock = threading.Lock()
        self._wake = threading.Event()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._latest: Telemetry | None = None
        self._sim_poses = False
        self._array = False
        self._sim_since_us: int | None = None
        self._state = ShadowState.IDLE
        self._updates = 0
        self._steps = 0
        self._synced_us: int | None = None
        self._skipped_us = 0
        self._resyncs = 0
        self._divergences = 0
        self._step_wall_s = 0.0
        self._step_sim_us = 0
        self._error = ""

    # ------------------------------------------------------------------ listener (board client thread)

    def on_board_message(self, msg: Message) -> None:
        """Listener: keep the newest telemetry (cheap, never blocks); ``SimPoses`` or ``ArmsTelemetry`` switch
        the shadow off."""
        if isinstance(msg, Telemetry):
            with self._lock:
                self._latest = msg
            self._wake.set()
        elif isinstance(msg, SimPoses) and not self._sim_poses:
            self._sim_poses = True
            self._wake.set()
        elif isinstance(msg, ArmsTelemetry) and not self._array:
            self._array = True
            self._wake.set()

    # ------------------------------------------------------------------ life cycle

    @property
    def state(self) -> ShadowState:
        """Current life cycle state."""
        return self._state

    @property
    def active(self) -> bool:
        """The shadow is (or may become) the pose source: started, not switched off, not failed."""
        return self._state in (ShadowState.WAITING, ShadowState.RUNNING)

    def start(self) -> None:
        """Start the shadow thread (the plant is built there, on the first telemetry frame)."""
        if self._thread is not None:
            return
        if self._state is ShadowState.IDLE:
            self._state = ShadowState.WAITING
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, name="shadow-plant", daemon=True)
        self._thread.start()

    def stop(self, timeout_s: float = 5.0) -> None:
        """Stop the thread and release the plant; safe twice."""
        self._stop.set()
        self._wake.set()
        thread, self._thread = self._thread, None
        if thread is not None:
            thread.join(timeout_s)
        if self._state in (ShadowState.WAITING, ShadowState.RUNNING, ShadowState.IDLE):
            self._state = ShadowState.STOPPED

    def __enter__(self) -> ShadowPlant:
        self.start()
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.stop()

    def stats(self) -> ShadowStats:
        """A snapshot of the counters."""
        with self._lock:
            speed = self._step_sim_us / 1e6 / self._step_wall_s if self._step_wall_s > 0 else 0.0
            return ShadowStats(
                self._state,
                self._updates,
                self._steps,
                self._synced_us or 0,
                self._skipped_us,
                self._resyncs,
                self._divergences,
                speed,
                self._error,
            )

    # ------------------------------------------------------------------ the thread

    def _run(self) -> None:
        plant: Any = None
        try:
            while not self._stop.is_set():
                self._wake.wait(self.config.idle_wait_s)
                self._wake.clear()
                if self._stop.is_set():
                    break
                if self._off():
                    break
                with self._lock:
                    t, self._latest = self._latest, None
                if t is None:
                    continue
                if plant is None:
                    if not self._ready_to_build(t):
                        continue
                    try:
                        plant = self._factory()
                    except Exception as exc:  # no MuJoCo, a bad model: say so, never crash the host
                        self._fail(f"cannot build the plant: {exc}")
                        break
                    if self._off():  # what arrived while the plant was built
                        break
                    self._state = ShadowState.RUNNING
                self._update(plant, t)
        except Exception as exc:
            _log.exception("shadow plant failed")
            self._fail(str(exc) or type(exc).__name__)

    def _off(self) -> bool:
        """Switch off for good if the board sends its own poses or is an array; True if switched off."""
        if self._sim_poses:
            self._state = ShadowState.OFF_SIM_POSES
            _log.info("the board sends SimPoses: shadow plant off")
        elif self._array:
            self._state = ShadowState.OFF_ARRAY
            _log.info("the board is an array (ArmsTelemetry): shadow plant off, it models one arm")
        else:
            return False
        return True

    def _fail(self, reason: str) -> None:
        with self._lock:
            self._error = reason
            self._state = ShadowState.FAILED
        _log.warning("shadow plant off: %s", reason)

    def _ready_to_build(self, t: Telemetry) -> bool:
        """While the board says it simulates, give its ``SimPoses`` a chance before building a plant."""
        if not TelemetryFlags(t.flags) & TelemetryFlags.SIM:
            return True
        if self._sim_since_us is None or t.time_us < self._sim_since_us:
            self._sim_since_us = t.time_us
        return t.time_us - self._sim_since_us >= self.config.sim_grace_us

    def _update(self, plant: Any, t: Telemetry) -> None:
        """Advance ``plant`` to the board time of ``t`` (bounded), then take ``t``'s currents."""
        from hil.errors import PlantDivergedError  # type: ignore[import-not-found,unused-ignore]

        period = int(plant.control_period_us)
        synced = self._synced_us
        steps = skipped = 0
        resync = False
        wall = 0.0
        if synced is None or t.time_us < synced:
            resync = synced is not None  # board restarted: keep the arm's state, follow the new clock
            synced = t.time_us
        else:
            dt = t.time_us - synced
            if dt > self.config.max_step_us:
                skipped = dt - self.config.max_step_us
                synced += skipped
                dt = self.config.max_step_us
            n = dt // period
            t0 = time.perf_counter()
            try:
                for _ in range(n):
                    plant.step()
                    steps += 1
            except PlantDivergedError as exc:
                _log.warning("shadow plant diverged (%s): reset", exc)
                plant.reset()
                with self._lock:
                    self._divergences += 1
            wall = time.perf_counter() - t0
            synced += n * period
        plant.apply_currents(reel_in_currents(t))
        poses = plant.body_poses()
        with self._lock:
            self._synced_us = synced
            self._updates += 1
            self._steps += steps
            self._skipped_us += skipped
            self._resyncs += int(resync)
            self._step_wall_s += wall
            self._step_sim_us += steps * period
        positions = poses.positions_m.tolist()
        quats = poses.quats_wxyz.tolist()
        self._on_poses(
            SimPoses(
                t.time_us,
                tuple((p[0], p[1], p[2]) for p in positions),
                tuple((q[0], q[1], q[2], q[3]) for q in quats),
            )
        )
