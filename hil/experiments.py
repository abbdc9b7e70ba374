"""Experiments that reproduce the paper's simulation results with the plant and the firmware (issue 8).

Each experiment is a pure function of ``(design, params, seed)`` that runs the virtual board in lockstep
(firmware + plant, :class:`hil.board.VirtualBoard`) and returns a frozen, picklable result with
``as_dict()``; a ``progress(done, total)`` callback reports how far it is. ``spirob-hil experiment NAME``
prints each number next to the paper's prediction and, with ``--report DIR``, writes a PNG.

=============  ==========================================  =============================================
name           paper                                       what runs through the firmware
=============  ==========================================  =============================================
workspace      Note S2, Fig. 2E / S4: envelope ρw          random per-cable tensions (DIRECT mode, host
                                                           commands over the board link), 2 and 3 cables,
                                                           three taper angles
packing        Note S3, Fig. S5C: packed spiral = design b one cable's tension ramped (DIRECT) until every
                                                           joint sits at its limit
strategy       Note S4, Fig. S6, Fig. 3C                   the GRASP state machine (left lever) with the
                                                           strategy on and off, objects on a grid
grasp-range    eq. (14), (15): d_min, d_max                strategy on/off grasps of cylinders of many
                                                           diameters, the best wrap angle of each
load           eq. (16), Fig. 2F: M(φ, d, F_max)           a grasp, then a growing downward load on the
                                                           object until it slips out
dynamic        Fig. S11: 0.06 s grasp, 120 ms capture      a current step on one cable (DIRECT); a thrown
                                                           object against the arm with one cable held
=============  ==========================================  =============================================

Geometry: the drone sits at (0, 0, 1) m and the arm's base (its mount) 20 mm below it; the arm hangs
along −z and cable 0 is on its +x side. Object positions are given relative to the base, in the x-z
plane (the plane cable 0 bends the arm in).
"""

from __future__ import annotations

import argparse
import dataclasses
import itertools
import json
import math
import signal
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TypeVar

import numpy as np
import numpy.typing as npt

from controller.config import FirmwareConfig, MappingConfig
from protocol.c610 import MotorFeedback
from protocol.dbus import Lever, RcFrame
from protocol.messages import Command, CommandCode, GraspState, Mode

from .board import BoardConfig, VirtualBoard
from .harness import ScriptedHost
from .mjcf import ObjectConfig
from .plant import Plant, PlantConfig
from .radio import RadioScript
from .spiral import SpiralDesign

__all__ = [
    "EXPERIMENTS",
    "SIZES",
    "DynamicParams",
    "DynamicResult",
    "Envelope",
    "Experiment",
    "GraspOutcome",
    "GraspRangeParams",
    "GraspRangeResult",
    "GraspSetup",
    "LoadParams",
    "LoadResult",
    "PackingParams",
    "PackingResult",
    "Rig",
    "StrategyParams",
    "StrategyResult",
    "WorkspaceParams",
    "WorkspaceResult",
    "add_experiment_command",
    "base_first_tip_curve",
    "configure_experiment",
    "fit_log_spiral",
    "grasp_firmware",
    "grasp_trial",
    "run_experiment",
    "run_experiment_command",
]

Progress = Callable[[int, int], None]
"""``progress(done, total)``: work units done so far (trials or simulated milliseconds)."""

T = TypeVar("T")
R = TypeVar("R")

MS = 1000
S = 1_000_000
G = 9.80665
DRONE_Z_M = 1.0
BASE_Z_M = DRONE_Z_M - 0.02  # the mount is 20 mm under the drone (DroneConfig.mount_offset_m)
FAR_M = (0.6, 0.0, 0.4)  # where an object waits, out of reach, until its trial places it
_OBJ = "target"
HELD_DROP_MM = 60.0
"""A released object counts as held if it ends up less than this below where it was let go (the wrap
settles and swings it by a few centimetres; a dropped object falls far more) ..."""
HELD_SPEED_M_S = 0.05
"""... and is not moving faster than this at the end (not slipping out)."""


def _rc(right: int = Lever.DOWN, left: int = Lever.DOWN) -> RcFrame:
    return RcFrame((0, 0, 0, 0), int(right), int(left))


# ==================================================================================================
# the rig: a virtual board in lockstep with a scripted host
# ==================================================================================================


class _ThreeMotors:
    """The C610 trio seen by the firmware when the arm has fewer cables: the spare motor idles.

    The terminal always has three M2006 motors (Note S6); on a 2-cable arm the third has no cable, so it
    answers with still feedback and its current goes nowhere.
    """

    def __init__(self, plant: Plant) -> None:
        self.plant = plant
        self._spare = MotorFeedback(0, 0, 0, 30)

    def apply_currents(self, raw: Sequence[int]) -> object:
        return self.plant.apply_currents(list(raw))

    def feedback(self) -> Sequence[MotorFeedback]:
        fb = tuple(self.plant.feedback())
        return fb + (self._spare,) * (3 - len(fb))


class Rig:
    """A virtual board (firmware + plant + radio) and a scripted host, stepped in lockstep.

    Args:
        design: the arm.
        firmware: firmware configuration.
        radio: the pilot's lever script.
        objects: objects in the scene.
        start_packed: start with the arm coiled on cable 0.
        seed: seed of the board's random choices.
    """

    def __init__(
        self,
        design: SpiralDesign,
        firmware: FirmwareConfig,
        radio: Sequence[tuple[int, RcFrame]],
        *,
        objects: Sequence[ObjectConfig] = (),
        start_packed: bool = False,
        seed: int = 0,
    ) -> None:
        plant = PlantConfig()
        if objects:
            plant = dataclasses.replace(plant, model=plant.model.with_objects(*objects))
        cfg = BoardConfig(
            design=design, plant=plant, firmware=firmware, rc="radio", seed=seed, start_packed=start_packed
        )
        self.board = VirtualBoard(cfg, radio_script=RadioScript(list(radio)))
        if design.cables < 3:
            self.board.bus.motors = _ThreeMotors(self.board.plant)
        assert self.board.wire is not None  # lockstep boards have a wire
        self.host = ScriptedHost(self.board.wire.host)
        self.plant = self.board.plant
        self.firmware = self.board.firmware

    @property
    def now_us(self) -> int:
        """Board time."""
        return self.board.now_us

    def tick(self) -> None:
        """One control period: host out, physics + firmware, host in."""
        self.host.before_tick(self.board.now_us)
        self.board.tick()
        self.host.after_tick(self.board.now_us)

    def run(self, duration_us: int, each: Callable[[Rig], bool | None] | None = None) -> None:
        """Tick for ``duration_us``; ``each(rig)`` after every tick may return True to stop early."""
        for _ in range(max(0, duration_us // self.board.period_us)):
            self.tick()
            if each is not None and each(self):
                return

    def command(self, code: CommandCode, *args: float) -> None:
        """Send a host command now (it reaches the board on the next tick)."""
        a = [*args, 0.0, 0.0, 0.0][:3]
        self.host.send(self.board.now_us, Command(code, (a[0], a[1], a[2])))

    def set_tensions(self, tensions_n: Sequence[float]) -> None:
        """DIRECT-mode cable tensions (the firmware clamps them to [pretension, tension_max])."""
        t = [*tensions_n, 0.0, 0.0, 0.0][:3]
        self.command(CommandCode.SET_TENSIONS, *t)

    def close(self) -> None:
        """Zero current and release the link."""
        self.board.close()


def _direct_rig(
    design: SpiralDesign,
    firmware: FirmwareConfig,
    *,
    objects: Sequence[ObjectConfig] = (),
    start_packed: bool = False,
    seed: int = 0,
) -> Rig:
    """A rig in DIRECT mode: lever DOWN (arm), MIDDLE at 20 ms, then the host's SET_MODE DIRECT."""
    rig = Rig(
        design,
        firmware,
        [(0, _rc()), (20 * MS, _rc(Lever.MIDDLE))],
        objects=objects,
        start_packed=start_packed,
        seed=seed,
    )
    for _ in range(200):
        rig.tick()
        if rig.firmware.mode == Mode.MANUAL:
            break
    rig.command(CommandCode.SET_MODE, float(Mode.DIRECT))
    for _ in range(50):
        rig.tick()
        if rig.firmware.mode == Mode.DIRECT:
            return rig
    raise RuntimeError("the firmware did not enter DIRECT mode")


def _map(
    fn: Callable[[T], R],
    items: Sequence[T],
    jobs: int,
    progress: Progress | None,
    done0: int = 0,
    total: int = 0,
) -> list[R]:
    """``[fn(x) for x in items]``, over ``jobs`` processes when > 1, reporting one unit per item."""
    total = total or done0 + len(items)
    out: list[R] = []
    if jobs <= 1 or len(items) <= 1:
        for i, item in enumerate(items):
            out.append(fn(item))
            if progress is not None:
                progress(done0 + i + 1, total)
        return out
    pool = ProcessPoolExecutor(max_workers=jobs, initializer=_ignore_ctrl_c)
    try:
        for i, r in enumerate(pool.map(fn, items)):
            out.append(r)
            if progress is not None:
                progress(done0 + i + 1, total)
    except BaseException:  # Ctrl-C or a failed item: drop what has not started, do not wait for it
        pool.shutdown(wait=False, cancel_futures=True)
        raise
    pool.shutdown()
    return out


def _ignore_ctrl_c() -> None:
    """Pool workers leave Ctrl-C to the parent (a terminal sends it to the whole process group)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def _world(x_m: float, z_m: float) -> tuple[float, float, float]:
    """World position of a point given relative to the arm's base in the x-z plane."""
    return (x_m, 0.0, BASE_Z_M + z_m)


def _contact_units(plant: Plant, name: str) -> set[str]:
    return {c.unit for c in plant.contacts() if c.other == name}


def _wrap_deg(plant: Plant, name: str) -> float:
    """Angular extent of the arm's contacts around an object's axis (y), in degrees (0..360).

    The largest gap between contact directions is the part not wrapped; 360° minus it is the wrap.
    """
    centre = plant.object_pose(name).pos_m
    angles = sorted(
        math.atan2(c.pos_m[2] - centre[2], c.pos_m[0] - centre[0])
        for c in plant.contacts()
        if c.other == name
    )
    if len(angles) < 2:
        return 0.0
    gaps = [b - a for a, b in itertools.pairwise(angles)] + [angles[0] + 2 * math.pi - angles[-1]]
    return math.degrees(2 * math.pi - max(gaps))


# ==================================================================================================
# one grasp: the GRASP state machine against one object
# ==================================================================================================


@dataclass(frozen=True)
class GraspSetup:
    """One grasp trial.

    Attributes:
        x_m: object centre, horizontal distance from the arm's base on cable 0's side (+x).
        z_m: object centre, height relative to the base (negative = below).
        diameter_m: cylinder diameter (axis along y).
        strategy_on: the bio-inspired strategy (packed start, reach, contact, wrap) or the plain ramp.
        mass_kg: object mass.
        length_m: cylinder length.
        hold_s: how long the object must stay after its support is removed.
        release: remove the support at HOLD (False: the object stays fixed, a pole or a branch).
        load_rate_n_per_s: if > 0, once the released object has been held for ``hold_s``, a downward
            force on it grows at this rate until it drops out (the load experiment).
        load_cap_n: the load stops growing here.
        firmware: firmware configuration (None = :func:`grasp_firmware`).
        seed: seed of the board.
    """

    x_m: float
    z_m: float
    diameter_m: float
    strategy_on: bool = True
    mass_kg: float = 0.02
    length_m: float = 0.06
    hold_s: float = 0.6
    release: bool = True
    load_rate_n_per_s: float = 0.0
    load_cap_n: float = 20.0
    firmware: FirmwareConfig | None = None
    seed: int = 0


@dataclass(frozen=True)
class GraspOutcome:
    """What one grasp trial measured.

    Attributes:
        setup: the trial.
        state: the grasp state at the end (``HOLD`` for a completed grasp).
        t_hold_s: time from the start of the grasp (REACH, or WRAP with the strategy off) to HOLD; NaN if
            never.
        contact_s: time from the start of the grasp to the detected contact (strategy on); NaN if none.
        units_at_hold: arm units touching the object when HOLD was reached.
        units_after: arm units touching it ``hold_s`` after its support was removed.
        wrap_deg: angular extent of the contacts around the object at the end.
        drop_mm: how far below its release height the object is at the end (negative: above).
        shift_mm: how far the object is from where it was released, at the end.
        held: HOLD reached, and ``hold_s`` after its support was removed the object still touches at
            least 2 units, is less than :data:`HELD_DROP_MM` below its release height and slower than
            :data:`HELD_SPEED_M_S`.
        max_current_raw: largest |current| sent to an ESC.
        load_n: with a load ramp, the extra downward force at which the object dropped out (more than
            :data:`HELD_DROP_MM` below where the ramp started, or no contact); the cap if it never did;
            NaN without a ramp or if it was not held.
    """

    setup: GraspSetup
    state: str
    t_hold_s: float
    contact_s: float
    units_at_hold: int
    units_after: int
    wrap_deg: float
    drop_mm: float
    shift_mm: float
    held: bool
    max_current_raw: int
    load_n: float = math.nan

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        d = dataclasses.asdict(self)
        d["setup"] = {k: v for k, v in d["setup"].items() if k != "firmware"}
        return d


def grasp_firmware(**changes: Any) -> FirmwareConfig:
    """The firmware of the grasp experiments: defaults, except that IDLE winds the pack up at 60 N/s
    (the trial starts packed and only has to hold it) and a reach that has run its ramp down without
    contact fails 0.6 s later instead of after 4 s."""
    base = FirmwareConfig()
    ramp_s = (base.grasp.pack_n - base.grasp.reach_n) / base.grasp.reach_rate_n_per_s
    cfg = base.replaced(grasp_pack_rate_n_per_s=60.0, grasp_reach_timeout_us=int((ramp_s + 0.6) * S))
    return cfg.replaced(**changes) if changes else cfg


def grasp_trial(setup: GraspSetup, design: SpiralDesign | None = None) -> GraspOutcome:
    """Run one grasp through the firmware's GRASP mode and measure it (pure; picklable in and out).

    Timeline: lever DOWN, then UP (GRASP mode) at 20 ms, left lever UP (grasp request) at 60 ms. The object
    waits out of reach on its support and is put at its place, still on its support, when the firmware
    starts the grasp (the drone bringing the ready arm next to it); the support is removed when the
    firmware reports HOLD; the trial ends ``hold_s`` later, or when the grasp FAILED.
    """
    design = design or SpiralDesign.paper_prototype()
    fw = setup.firmware or grasp_firmware()
    fw = fw.replaced(grasp_strategy_on=setup.strategy_on, grasp_direction_deg=0.0)
    obj = ObjectConfig(
        _OBJ, radius_m=setup.diameter_m / 2, length_m=setup.length_m, pos_m=FAR_M, mass_kg=setup.mass_kg
    )
    rig = Rig(
        design,
        fw,
        [(0, _rc()), (20 * MS, _rc(Lever.UP)), (60 * MS, _rc(Lever.UP, Lever.UP))],
        objects=(obj,),
        start_packed=setup.strategy_on,
        seed=setup.seed,
    )
    plant = rig.plant
    plant.hold_object(_OBJ)
    target = _world(setup.x_m, setup.z_m)
    t_start = -1
    t_contact = -1
    t_hold = -1
    units_at_hold = 0
    released_at = np.full(3, math.nan)
    before_end = np.full(3, math.nan)
    max_current = 0
    timeout_us = 12 * S
    end_us = timeout_us
    load_n = math.nan
    while rig.now_us < end_us:
        rig.tick()
        state = rig.firmware.grasp_state
        cur = plant.commanded_currents_raw()
        max_current = max(max_current, max(abs(c) for c in cur))
        now = rig.now_us
        if t_start < 0 and state in (GraspState.REACH, GraspState.WRAP):
            t_start = now
            plant.hold_object(_OBJ, target)
        if t_contact < 0 and state == GraspState.WRAP and setup.strategy_on:
            t_contact = now
        if t_hold < 0 and state == GraspState.HOLD:
            t_hold = now
            units_at_hold = len(_contact_units(plant, _OBJ))
            if setup.release:
                plant.release_object(_OBJ)
            released_at = plant.object_pose(_OBJ).pos_m.copy()
            end_us = now + int(setup.hold_s * S)
        if t_hold >= 0 and end_us - now == 10 * MS:
            before_end = plant.object_pose(_OBJ).pos_m.copy()
        if state == GraspState.FAILED:
            break
    units_after = len(_contact_units(plant, _OBJ)) if t_hold >= 0 else 0
    final = plant.object_pose(_OBJ).pos_m
    drop_mm = float(released_at[2] - final[2]) * 1000
    shift_mm = float(np.linalg.norm(final - released_at)) * 1000
    speed = float(np.linalg.norm(final - before_end)) / 0.010
    held = t_hold >= 0 and units_after >= 2 and drop_mm < HELD_DROP_MM and speed < HELD_SPEED_M_S
    if held and setup.release and setup.load_rate_n_per_s > 0:
        load_n = _load_ramp(rig, setup)
    out = GraspOutcome(
        setup,
        GraspState(rig.firmware.grasp_state).name,
        (t_hold - t_start) / S if t_hold >= 0 else math.nan,
        (t_contact - t_start) / S if t_contact >= 0 else math.nan,
        units_at_hold,
        units_after,
        _wrap_deg(plant, _OBJ) if t_hold >= 0 else 0.0,
        drop_mm,
        shift_mm,
        held,
        max_current,
        load_n,
    )
    rig.close()
    return out


def _load_ramp(rig: Rig, setup: GraspSetup) -> float:
    """Grow a downward force on the held object until it drops out; the force at that moment [N]."""
    plant = rig.plant
    z0 = float(plant.object_pose(_OBJ).pos_m[2])
    rate = setup.load_rate_n_per_s / S
    t0 = rig.now_us
    force = 0.0
    while force < setup.load_cap_n:
        force = min(setup.load_cap_n, rate * (rig.now_us - t0))
        plant.apply_object_force(_OBJ, (0.0, 0.0, -force))
        rig.tick()
        dropped = (z0 - float(plant.object_pose(_OBJ).pos_m[2])) * 1000 > HELD_DROP_MM
        if dropped or not _contact_units(plant, _OBJ):
            return force
    return setup.load_cap_n


# ==================================================================================================
# geometry helpers: log-spiral fit and the workspace envelope
# ==================================================================================================


def fit_log_spiral(points: npt.NDArray[np.complex128]) -> tuple[float, complex, float]:
    """Fit a discrete logarithmic spiral to planar points (complex numbers), base first.

    Consecutive points of a log spiral are related by one similarity ``z' = s·z + t`` whose fixed point is
    the pole; log ρ is then regressed on the unwrapped polar angle. Returns ``(b, pole, turn per point)``.
    """
    a = np.stack([points[:-1], np.ones(len(points) - 1)], axis=1)
    s, t = np.linalg.lstsq(a, points[1:], rcond=None)[0]
    pole = t / (1 - s)
    w = points - pole
    angle = np.unwrap(np.angle(w))
    slope = np.polyfit(angle, np.log(np.abs(w)), 1)[0]
    return abs(float(slope)), complex(pole), float(np.angle(s))


def _joint_points(plant: Plant) -> npt.NDArray[np.complex128]:
    """Joint positions and the tip in the x-z plane (x + i·z), base first."""
    pos, _ = plant.unit_poses()
    pts = np.vstack([pos, plant.tip_pose().pos_m])
    return np.asarray(pts[:, 0] + 1j * pts[:, 2], dtype=np.complex128)


def base_first_tip_curve(
    design: SpiralDesign, base_z_m: float = BASE_Z_M, steps: int = 12
) -> npt.NDArray[np.float64]:
    """The real tip's path when the joints close one at a time from the base (Fig. S4A), from the straight
    arm to the packed one: rows ``(u, z)``, u toward the curl side from the arm's axis, z the world height
    of a point on an arm whose base (mount) is at ``base_z_m``. Exact for the discretised arm; Table S1's
    ρw is the smooth involute of the same spiral unwound from the *virtual* tip (θ → −∞), so it lies
    further out by about the virtual part of the arm, s(0) = δ(0) / (2 tan(φ/2))."""
    chords = design.unit_chords_m()
    n = len(chords)
    dtheta = design.dtheta_rad
    out = []
    for k in range(1, n):
        for a in np.linspace(0.0, dtheta, steps, endpoint=k == n - 1):
            # joints 1..k-1 closed, joint k at a, the distal ones straight; heading from -z toward +u
            heading = 0.0
            u, z = 0.0, base_z_m - chords[0]
            for j in range(1, n):
                if j < k:
                    heading += dtheta
                elif j == k:
                    heading += float(a)
                u += chords[j] * math.sin(heading)
                z -= chords[j] * math.cos(heading)
            out.append((u, z))
    return np.array(out)


@dataclass(frozen=True)
class Envelope:
    """The workspace envelope ρw of one bending side, in the bending plane (u = horizontal distance from
    the arm's axis toward the packed side, z = height), as the involute of the packed central spiral
    about its pole (Table S1; the same construction as ``tests/test_plant.py``)."""

    design: SpiralDesign
    pole: complex
    base_angle: float
    sense: float
    exact_angle: tuple[float, ...] = field(default=(), repr=False)
    exact_radius: tuple[float, ...] = field(default=(), repr=False)

    @classmethod
    def of(cls, plant: Plant) -> Envelope:
        """Measure the packed spiral's pole on ``plant`` (which is left straight and at rest)."""
        plant.set_packed(0)
        pts = _joint_points(plant)
        base_z = float(plant.unit_poses()[0][0][2])
        _, pole, _ = fit_log_spiral(pts)
        w = pts - pole
        base_angle = float(np.angle(w[0]))
        sense = 1.0 if np.angle(w[1] / w[0]) < 0 else -1.0
        plant.set_straight()
        curve = base_first_tip_curve(plant.design, base_z)
        wc = curve[:, 0] + 1j * curve[:, 1] - pole
        ang = np.unwrap(np.angle(wc))
        order = np.argsort(ang)
        return cls(
            plant.design,
            pole,
            base_angle,
            sense,
            tuple(float(v) for v in ang[order]),
            tuple(float(v) for v in np.abs(wc)[order]),
        )

    def exact_ratio(self, u: float, z: float) -> float:
        """Like :meth:`ratio`, against the real tip's base-first curve (:func:`base_first_tip_curve`)."""
        w = complex(u, z) - self.pole
        phi = float(np.angle(w))
        ang = self.exact_angle
        best = 0.0
        for k in range(-4, 5):
            a = phi + 2 * math.pi * k
            if ang[0] <= a <= ang[-1]:
                best = max(best, float(np.interp(a, ang, self.exact_radius)))
        return abs(w) / best if best > 0 else math.inf

    def exact_boundary(self) -> npt.NDArray[np.float64]:
        """Points ``(u, z)`` of the real tip's base-first curve."""
        a = np.array(self.exact_angle)
        z = self.pole + np.array(self.exact_radius) * np.exp(1j * a)
        return np.stack([z.real, z.imag], axis=1)

    def radius(self, phi: float) -> float:
        """Envelope radius about the pole at polar angle ``phi`` (0 where the envelope has no point)."""
        d = self.design
        best = 0.0
        for k in range(-4, 5):
            theta = d.theta0_rad + self.sense * (phi - self.base_angle) + 2 * math.pi * k + math.pi / 2
            if 0.0 <= theta <= d.theta0_rad:
                best = max(best, d.rho_w_m(theta + math.pi / 2))
        return best

    def ratio(self, u: float, z: float) -> float:
        """Distance from the pole over the envelope radius in that direction (<= 1: inside)."""
        w = complex(u, z) - self.pole
        r = self.radius(float(np.angle(w)))
        return abs(w) / r if r > 0 else math.inf

    def boundary(self, n: int = 200) -> npt.NDArray[np.float64]:
        """Points ``(u, z)`` of the envelope curve (θ from the tip to the base)."""
        d = self.design
        out = []
        for theta in np.linspace(0.0, d.theta0_rad, n):
            phi = self.base_angle + self.sense * (theta - math.pi / 2 - d.theta0_rad)
            p = self.pole + d.rho_w_m(theta + math.pi / 2) * complex(math.cos(phi), math.sin(phi))
            out.append((p.real, p.imag))
        return np.array(out)


# ==================================================================================================
# workspace (Note S2, Fig. 2E / S4)
# ==================================================================================================


@dataclass(frozen=True)
class WorkspaceParams:
    """Attributes:
    tapers_deg: taper angles of the three designs (length, tip width and Δθ of the prototype).
    cables: cable counts to run for each taper.
    duration_s: random drive per design (one tip sample every ``sample_ms``).
    sample_ms: tip sample period.
    hold_ms: each random tension set is held for a time drawn from this range.
    tension_max_n: largest random tension (the firmware's per-cable ceiling).
    cell_m: raster cell of the coverage measure.
    drive: how a random tension set is drawn (see :func:`_random_tensions`).
    """

    tapers_deg: tuple[float, ...] = (5.0, 6.5, 9.0)
    cables: tuple[int, ...] = (2, 3)
    duration_s: float = 30.0
    sample_ms: int = 5
    hold_ms: tuple[int, int] = (50, 300)
    tension_max_n: float = 20.0
    cell_m: float = 0.004
    drive: str = "mixed"


@dataclass(frozen=True)
class WorkspaceRun:
    """One design's random drive.

    ``inside_share`` / ``coverage`` / ``envelope_area_m2`` refer to Table S1's ρw (the involute unwound from
    the virtual tip), ``*_exact`` to the real tip's base-first curve (:func:`base_first_tip_curve`);
    ``inside_share_eta`` allows ρw the discretisation tolerance 1/η. Areas: the half plane on the curl
    side (u >= 0), rastered in ``cell_m`` cells; ``covered_area_m2``: the cells the tip visited.
    """

    taper_deg: float
    cables: int
    b: float
    units: int
    samples: int
    inside_share: float
    inside_share_eta: float
    inside_share_exact: float
    coverage: float
    coverage_exact: float
    envelope_area_m2: float
    exact_area_m2: float
    covered_area_m2: float
    u_m: tuple[float, ...] = field(repr=False)
    z_m: tuple[float, ...] = field(repr=False)
    boundary: tuple[tuple[float, float], ...] = field(repr=False)
    exact_boundary: tuple[tuple[float, float], ...] = field(repr=False)


@dataclass(frozen=True)
class WorkspaceResult:
    """All designs: the share of tip samples inside ρw, and the covered share of its area."""

    params: WorkspaceParams
    seed: int
    runs: tuple[WorkspaceRun, ...]

    @property
    def inside_share(self) -> float:
        """Share of all tip samples (every design) inside the envelope."""
        n = sum(r.samples for r in self.runs)
        return sum(r.inside_share * r.samples for r in self.runs) / n if n else math.nan

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready form (without the raw samples)."""
        return {
            "experiment": "workspace",
            "seed": self.seed,
            "inside_share": self.inside_share,
            "samples": sum(r.samples for r in self.runs),
            "runs": [
                {
                    k: v
                    for k, v in dataclasses.asdict(r).items()
                    if k not in ("u_m", "z_m", "boundary", "exact_boundary")
                }
                for r in self.runs
            ],
            "params": dataclasses.asdict(self.params),
        }


def _random_tensions(rng: np.random.Generator, p: WorkspaceParams) -> npt.NDArray[np.float64]:
    """One random tension set: ``uniform`` per cable, or ``single``: one cable anywhere in the range and
    the others low (one cable at a time is what bends the arm furthest), or ``mixed`` (either, 50/50)."""
    hi = p.tension_max_n
    single = p.drive == "single" or (p.drive == "mixed" and rng.random() < 0.5)
    if not single:
        return rng.uniform(0.5, hi, 3)
    out = rng.uniform(0.5, 2.0, 3)
    out[int(rng.integers(0, 3))] = rng.uniform(0.5, hi)
    return out


def _workspace_run(args: tuple[float, int, WorkspaceParams, int]) -> WorkspaceRun:
    taper_deg, cables, p, seed = args
    base = SpiralDesign.paper_prototype()
    design = SpiralDesign.from_physical(
        length_m=0.23,
        tip_width_m=base.tip_width_m,
        taper_rad=math.radians(taper_deg),
        dtheta_rad=base.dtheta_rad,
        cables=cables,
    )
    fw = FirmwareConfig(mapping=MappingConfig(tension_max_n=p.tension_max_n))
    rig = _direct_rig(design, fw, seed=seed)
    env = Envelope.of(rig.plant)
    rng = np.random.default_rng([seed, cables, round(taper_deg * 100)])
    n = int(p.duration_s * 1000 / p.sample_ms)
    u = np.empty(n)
    z = np.empty(n)
    next_change = 0
    i = 0
    warm = 300  # ms before the first sample
    t = 0
    while i < n:
        if t >= next_change:
            tensions = _random_tensions(rng, p)
            rig.set_tensions(tensions[:cables].tolist() + [0.0] * (3 - cables))
            next_change = t + int(rng.integers(p.hold_ms[0], p.hold_ms[1] + 1))
        rig.tick()
        t += 1
        if t > warm and t % p.sample_ms == 0:
            tip = rig.plant.tip_pose().pos_m
            u[i] = abs(tip[0]) if cables < 3 else math.hypot(tip[0], tip[1])
            z[i] = tip[2]
            i += 1
    rig.close()
    ratios = np.array([env.ratio(float(a), float(b)) for a, b in zip(u, z, strict=True)])
    exact = np.array([env.exact_ratio(float(a), float(b)) for a, b in zip(u, z, strict=True)])
    # Coverage: raster cells whose centre is inside an envelope, and those a sample falls in.
    bnd = env.boundary()
    lo_u, hi_u = 0.0, float(max(bnd[:, 0].max(), u.max())) + p.cell_m
    lo_z, hi_z = (
        float(min(bnd[:, 1].min(), z.min())) - p.cell_m,
        float(max(bnd[:, 1].max(), z.max())) + p.cell_m,
    )
    nu = int((hi_u - lo_u) / p.cell_m) + 1
    nz = int((hi_z - lo_z) / p.cell_m) + 1
    in_w = np.zeros((nu, nz), bool)
    in_exact = np.zeros((nu, nz), bool)
    for a in range(nu):
        for b in range(nz):
            cu, cz = lo_u + (a + 0.5) * p.cell_m, lo_z + (b + 0.5) * p.cell_m
            in_w[a, b] = env.ratio(cu, cz) <= 1.0
            in_exact[a, b] = env.exact_ratio(cu, cz) <= 1.0
    hit = np.zeros((nu, nz), bool)
    ia = np.clip(((u - lo_u) / p.cell_m).astype(int), 0, nu - 1)
    ib = np.clip(((z - lo_z) / p.cell_m).astype(int), 0, nz - 1)
    hit[ia, ib] = True
    cell_area = p.cell_m**2

    def share(mask: npt.NDArray[np.bool_]) -> float:
        cells = int(mask.sum())
        return float((hit & mask).sum() / cells) if cells else math.nan

    return WorkspaceRun(
        taper_deg,
        cables,
        design.b,
        design.units,
        n,
        float(np.mean(ratios <= 1.0)),
        float(np.mean(ratios <= 1.0 / design.eta)),
        float(np.mean(exact <= 1.0 + 1e-9)),
        share(in_w),
        share(in_exact),
        float(in_w.sum()) * cell_area,
        float(in_exact.sum()) * cell_area,
        float(hit.sum()) * cell_area,
        tuple(float(v) for v in u),
        tuple(float(v) for v in z),
        tuple((float(a), float(b)) for a, b in bnd),
        tuple((float(a), float(b)) for a, b in env.exact_boundary()),
    )


def workspace(
    params: WorkspaceParams | None = None, seed: int = 0, progress: Progress | None = None, jobs: int = 1
) -> WorkspaceResult:
    """Random per-cable tensions through the firmware (DIRECT mode) on 2- and 3-cable arms of three
    taper angles; tip samples against the involute envelope ρw (Note S2, Fig. 2E / S4)."""
    p = params or WorkspaceParams()
    items = [(taper, c, p, seed) for taper in p.tapers_deg for c in p.cables]
    runs = _map(_workspace_run, items, jobs, progress)
    return WorkspaceResult(p, seed, tuple(runs))


# ==================================================================================================
# packing (Note S3, Fig. S5C)
# ==================================================================================================


@dataclass(frozen=True)
class PackingParams:
    """Attributes:
    tension_end_n: the ramp of cable 0's tension ends here (54 N = 3 A, the firmware's current limit).
    ramp_s: ramp duration (slow: quasi-static).
    hold_s: the end tension is held this long before the spiral is fitted.
    limit_tol_deg: a joint counts as closed within this of its limit Δθ.
    command_ms: the host sends a new tension this often.
    """

    tension_end_n: float = 54.0
    ramp_s: float = 8.0
    hold_s: float = 0.5
    limit_tol_deg: float = 1.5
    command_ms: int = 10


@dataclass(frozen=True)
class PackingResult:
    """Ramp one cable until the arm packs: the tension and current it took, the fitted spiral, the order."""

    params: PackingParams
    seed: int
    b_design: float
    b_fit: float
    turn_design_deg: float
    turn_fit_deg: float
    joints: int
    packed: bool
    pack_tension_n: float
    pack_current_a: float
    close_order: tuple[int, ...]
    close_tension_n: tuple[float, ...]
    order_correlation: float
    ramp_tension_n: tuple[float, ...] = field(repr=False)
    closed_count: tuple[int, ...] = field(repr=False)
    joint_points: tuple[tuple[float, float], ...] = field(repr=False)
    pole: tuple[float, float] = field(repr=False)

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        return {
            "experiment": "packing",
            "seed": self.seed,
            "b_design": self.b_design,
            "b_fit": self.b_fit,
            "b_error": self.b_fit / self.b_design - 1.0,
            "turn_design_deg": self.turn_design_deg,
            "turn_fit_deg": self.turn_fit_deg,
            "joints": self.joints,
            "packed": self.packed,
            "pack_tension_n": self.pack_tension_n,
            "pack_current_a": self.pack_current_a,
            "close_order": list(self.close_order),
            "close_tension_n": list(self.close_tension_n),
            "order_correlation": self.order_correlation,
            "params": dataclasses.asdict(self.params),
        }


def packing(
    design: SpiralDesign | None = None,
    params: PackingParams | None = None,
    seed: int = 0,
    progress: Progress | None = None,
) -> PackingResult:
    """Ramp cable 0's tension through the firmware (DIRECT) until every joint is at its limit Δθ; fit a
    logarithmic spiral to the joints; record in which order the joints closed (Note S3, Fig. S5C)."""
    design = design or SpiralDesign.paper_prototype()
    p = params or PackingParams()
    fw = FirmwareConfig(mapping=MappingConfig(tension_max_n=max(20.0, p.tension_end_n)))
    rig = _direct_rig(design, fw, seed=seed)
    plant = rig.plant
    limit = design.dtheta_rad - math.radians(p.limit_tol_deg)
    n_joints = design.joints
    closed_at = np.full(n_joints, math.nan)
    ramp_ms = int(p.ramp_s * 1000)
    total = ramp_ms + int(p.hold_s * 1000)
    pretension = fw.mapping.pretension_n
    ramp_t: list[float] = []
    closed_n: list[int] = []
    pack_t = math.nan
    pack_i = math.nan
    for k in range(total):
        if k % p.command_ms == 0:
            t_cmd = pretension + (p.tension_end_n - pretension) * min(1.0, k / ramp_ms)
            rig.set_tensions([t_cmd, pretension, pretension])
        rig.tick()
        commanded = rig.firmware.tensions_n[0]
        angles = np.abs(plant.joint_angles_rad())
        now_closed = angles >= limit
        newly = now_closed & np.isnan(closed_at)
        closed_at[newly] = commanded
        if k % 20 == 0:
            ramp_t.append(commanded)
            closed_n.append(int(now_closed.sum()))
        if math.isnan(pack_t) and now_closed.all():
            pack_t = commanded
            pack_i = abs(plant.commanded_currents_raw()[0]) / 1000.0
        if progress is not None and k % 100 == 0:
            progress(k, total)
    pts = _joint_points(plant)
    b_fit, pole, turn = fit_log_spiral(pts)
    rig.close()
    order = tuple(
        int(j) + 1 for j in np.argsort(np.where(np.isnan(closed_at), np.inf, closed_at), kind="stable")
    )
    valid = ~np.isnan(closed_at)
    if valid.sum() >= 3:
        ranks_t = np.argsort(np.argsort(closed_at[valid]))
        ranks_j = np.argsort(np.argsort(np.arange(n_joints)[valid]))
        corr = float(np.corrcoef(ranks_j, ranks_t)[0, 1])
    else:
        corr = math.nan
    if progress is not None:
        progress(total, total)
    return PackingResult(
        p,
        seed,
        design.b,
        b_fit,
        math.degrees(design.dtheta_rad),
        abs(math.degrees(turn)),
        n_joints,
        bool(valid.all()),
        pack_t,
        pack_i,
        order,
        tuple(float(v) for v in closed_at),
        corr,
        tuple(ramp_t),
        tuple(closed_n),
        tuple((float(z.real), float(z.imag)) for z in pts),
        (pole.real, pole.imag),
    )


# ==================================================================================================
# strategy (Note S4, Fig. S6, Fig. 3C)
# ==================================================================================================


@dataclass(frozen=True)
class StrategyParams:
    """Attributes:
    diameters_m: the three object diameters.
    xs_m: grid of horizontal distances of the object's centre from the arm's axis (target side, +x).
    zs_m: grid of heights of the object's centre relative to the base (negative = below).
    mass_kg: object mass.
    hold_s: how long a released object must stay to count as grasped.
    """

    diameters_m: tuple[float, ...] = (0.016, 0.024, 0.036)
    xs_m: tuple[float, ...] = (0.03, 0.05, 0.07, 0.09)
    zs_m: tuple[float, ...] = (-0.07, -0.10, -0.13, -0.16)
    mass_kg: float = 0.02
    hold_s: float = 0.6


@dataclass(frozen=True)
class StrategyResult:
    """Every placement grasped with the strategy on and off."""

    params: StrategyParams
    seed: int
    outcomes: tuple[GraspOutcome, ...]

    def _share(self, on: bool, d: float | None = None) -> float:
        sel = [
            o for o in self.outcomes if o.setup.strategy_on == on and (d is None or o.setup.diameter_m == d)
        ]
        return sum(o.held for o in sel) / len(sel) if sel else math.nan

    @property
    def success_on(self) -> float:
        """Share of placements grasped and held with the strategy on."""
        return self._share(True)

    @property
    def success_off(self) -> float:
        """Share of placements grasped and held with the strategy off."""
        return self._share(False)

    def per_diameter(self) -> list[dict[str, float]]:
        """Success rates per diameter."""
        return [
            {"diameter_m": d, "success_on": self._share(True, d), "success_off": self._share(False, d)}
            for d in self.params.diameters_m
        ]

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        return {
            "experiment": "strategy",
            "seed": self.seed,
            "success_on": self.success_on,
            "success_off": self.success_off,
            "trials": len(self.outcomes),
            "per_diameter": self.per_diameter(),
            "only_on": sum(
                1 for o in self.outcomes if o.setup.strategy_on and o.held and not self._twin(o).held
            ),
            "only_off": sum(
                1 for o in self.outcomes if not o.setup.strategy_on and o.held and not self._twin(o).held
            ),
            "outcomes": [o.as_dict() for o in self.outcomes],
            "params": dataclasses.asdict(self.params),
        }

    def _twin(self, o: GraspOutcome) -> GraspOutcome:
        s = o.setup
        return next(
            t
            for t in self.outcomes
            if t.setup.strategy_on != s.strategy_on
            and (t.setup.x_m, t.setup.z_m, t.setup.diameter_m) == (s.x_m, s.z_m, s.diameter_m)
        )


def _trial(args: tuple[GraspSetup, SpiralDesign]) -> GraspOutcome:
    return grasp_trial(*args)


def strategy(
    design: SpiralDesign | None = None,
    params: StrategyParams | None = None,
    seed: int = 0,
    progress: Progress | None = None,
    jobs: int = 1,
) -> StrategyResult:
    """Objects of three diameters on a grid beside the arm, grasped through the firmware's GRASP mode with
    the strategy on and off (Note S4, Fig. S6, Fig. 3C)."""
    design = design or SpiralDesign.paper_prototype()
    p = params or StrategyParams()
    setups = [
        GraspSetup(x, z, d, strategy_on=on, mass_kg=p.mass_kg, hold_s=p.hold_s, seed=seed)
        for d in p.diameters_m
        for z in p.zs_m
        for x in p.xs_m
        for on in (True, False)
    ]
    return StrategyResult(p, seed, tuple(_map(_trial, [(s, design) for s in setups], jobs, progress)))


# ==================================================================================================
# grasp-range (eq. 14, 15)
# ==================================================================================================


@dataclass(frozen=True)
class GraspRangeParams:
    """Attributes:
    diameters_m: cylinders to try.
    gaps_m: horizontal gap between the hanging arm's axis and the cylinder's near surface.
    drops_m: depth of the cylinder's top below the base.
    half_wrap_deg: the wrap that counts ("at least half way around", eq. 15).
    wrap_n: wrap tension (a geometric question: more than the grasp default, well within 3 A).
    """

    diameters_m: tuple[float, ...] = (0.004, 0.006, 0.009, 0.013, 0.018, 0.026, 0.036, 0.05, 0.07, 0.1, 0.13)
    gaps_m: tuple[float, ...] = (0.02, 0.04)
    drops_m: tuple[float, ...] = (0.06, 0.09)
    half_wrap_deg: float = 180.0
    wrap_n: float = 15.0


@dataclass(frozen=True)
class GraspRangeResult:
    """The best wrap around each diameter, and the smallest and largest wrapped half way."""

    params: GraspRangeParams
    seed: int
    d_min_paper_m: float
    d_max_paper_m: float
    outcomes: tuple[GraspOutcome, ...]

    def best_wrap_deg(self) -> list[tuple[float, float]]:
        """``(diameter, best wrap angle over placements and strategies)`` per diameter."""
        out = []
        for d in self.params.diameters_m:
            wraps = [o.wrap_deg for o in self.outcomes if o.setup.diameter_m == d and o.state == "HOLD"]
            out.append((d, max(wraps, default=0.0)))
        return out

    @property
    def d_min_sim_m(self) -> float:
        """Smallest diameter wrapped at least half way (NaN if none)."""
        ok = [d for d, w in self.best_wrap_deg() if w >= self.params.half_wrap_deg]
        return min(ok) if ok else math.nan

    @property
    def d_max_sim_m(self) -> float:
        """Largest diameter wrapped at least half way (NaN if none)."""
        ok = [d for d, w in self.best_wrap_deg() if w >= self.params.half_wrap_deg]
        return max(ok) if ok else math.nan

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        return {
            "experiment": "grasp-range",
            "seed": self.seed,
            "d_min_paper_m": self.d_min_paper_m,
            "d_max_paper_m": self.d_max_paper_m,
            "d_min_sim_m": self.d_min_sim_m,
            "d_max_sim_m": self.d_max_sim_m,
            "best_wrap_deg": [{"diameter_m": d, "wrap_deg": w} for d, w in self.best_wrap_deg()],
            "trials": len(self.outcomes),
            "outcomes": [o.as_dict() for o in self.outcomes],
            "params": dataclasses.asdict(self.params),
        }


def grasp_range(
    design: SpiralDesign | None = None,
    params: GraspRangeParams | None = None,
    seed: int = 0,
    progress: Progress | None = None,
    jobs: int = 1,
) -> GraspRangeResult:
    """Cylinders of many diameters, fixed beside the arm (held on their support throughout), grasped with
    the strategy on and off; the wrap angle of the contacts once the grasp holds, against the paper's
    d_min (eq. 14) and d_max (eq. 15)."""
    design = design or SpiralDesign.paper_prototype()
    p = params or GraspRangeParams()
    fw = grasp_firmware(grasp_wrap_n=p.wrap_n)
    setups = [
        GraspSetup(
            gap + d / 2, -(drop + d / 2), d, strategy_on=on, hold_s=0.3, release=False, firmware=fw, seed=seed
        )
        for d in p.diameters_m
        for gap in p.gaps_m
        for drop in p.drops_m
        for on in (True, False)
    ]
    outcomes = _map(_trial, [(s, design) for s in setups], jobs, progress)
    return GraspRangeResult(p, seed, design.d_min_m, design.d_max_m, tuple(outcomes))


# ==================================================================================================
# load (eq. 16, Fig. 2F)
# ==================================================================================================


@dataclass(frozen=True)
class LoadParams:
    """Attributes:
    diameters_m: object diameters.
    forces_n: wrap tensions (the cable force F_max of eq. 16).
    placements: ``(gap, depth)`` candidates: centre at ``(gap + d/2, −(depth + d/2))``; the best of them.
    load_rate_n_per_s: growth of the extra downward force.
    """

    diameters_m: tuple[float, ...] = (0.013, 0.017, 0.022, 0.03)
    forces_n: tuple[float, ...] = (5.0, 10.0)
    placements: tuple[tuple[float, float], ...] = ((0.03, 0.09), (0.02, 0.07), (0.04, 0.09))
    load_rate_n_per_s: float = 2.0


@dataclass(frozen=True)
class LoadResult:
    """The heaviest object held per diameter and wrap force, against M(φ, d, F_max)."""

    params: LoadParams
    seed: int
    outcomes: tuple[GraspOutcome, ...]
    bounds_kg: tuple[tuple[float, float, float], ...]  # (force, diameter, M bound)

    def rows(self) -> list[dict[str, float]]:
        """Per (force, diameter): the best held mass over placements (NaN: never held) and the bound."""
        out = []
        for force, d, bound in self.bounds_kg:
            held = [
                o.setup.mass_kg + o.load_n / G
                for o in self.outcomes
                if o.setup.diameter_m == d
                and o.setup.firmware is not None
                and o.setup.firmware.grasp.wrap_n == force
                and not math.isnan(o.load_n)
            ]
            best = max(held) if held else math.nan
            out.append(
                {
                    "force_n": force,
                    "diameter_m": d,
                    "held_kg": best,
                    "bound_kg": bound,
                    "ratio": best / bound if held else math.nan,
                }
            )
        return out

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        return {
            "experiment": "load",
            "seed": self.seed,
            "rows": self.rows(),
            "trials": len(self.outcomes),
            "outcomes": [o.as_dict() for o in self.outcomes],
            "params": dataclasses.asdict(self.params),
        }


def load(
    design: SpiralDesign | None = None,
    params: LoadParams | None = None,
    seed: int = 0,
    progress: Progress | None = None,
    jobs: int = 1,
) -> LoadResult:
    """Grasp (strategy on) a 20 g cylinder, remove its support, then grow a downward force on it until it
    slips out: the heaviest load held per diameter at a fixed wrap tension F, against eq. (16)."""
    design = design or SpiralDesign.paper_prototype()
    p = params or LoadParams()
    setups = []
    bounds = []
    for force in p.forces_n:
        fw = grasp_firmware(grasp_wrap_n=force)
        for d in p.diameters_m:
            bounds.append((force, d, design.max_load_kg(d, force)))
            for gap, depth in p.placements:
                setups.append(
                    GraspSetup(
                        gap + d / 2,
                        -(depth + d / 2),
                        d,
                        strategy_on=True,
                        hold_s=0.5,
                        firmware=fw,
                        load_rate_n_per_s=p.load_rate_n_per_s,
                        seed=seed,
                    )
                )
    outcomes = _map(_trial, [(s, design) for s in setups], jobs, progress)
    return LoadResult(p, seed, tuple(outcomes), tuple(bounds))


# ==================================================================================================
# dynamic (Fig. S11)
# ==================================================================================================


@dataclass(frozen=True)
class DynamicParams:
    """Attributes:
    step_tensions_n: cable 0 tension steps (54 N = 3 A, the current limit) for the pen grasp.
    pen: ``(x, z)`` of the pen's centre relative to the base (beside the hanging arm, near its tip).
    pen_diameter_m, pen_length_m, pen_mass_kg: the pen.
    throw_speeds_m_s: speeds of the thrown object (horizontal, toward the arm, from its +x side).
    throw_from: ``(x, z)`` where the thrown object starts.
    window_ms: how long each run is watched.
    """

    step_tensions_n: tuple[float, ...] = (20.0, 54.0)
    pen: tuple[float, float] = (0.02, -0.17)
    pen_diameter_m: float = 0.010
    pen_length_m: float = 0.14
    pen_mass_kg: float = 0.015
    throw_speeds_m_s: tuple[float, ...] = (1.0, 2.0, 4.0)
    throw_from: tuple[float, float] = (0.04, -0.12)
    window_ms: int = 400


@dataclass(frozen=True)
class DynamicRun:
    """One pen grasp or one throw."""

    kind: str  # "pen" or "throw"
    value: float  # step tension [N] or throw speed [m/s]
    first_contact_ms: float
    half_wrap_ms: float  # from the step (pen) or the first contact (throw) to a >= 180° wrap; NaN: never
    max_wrap_deg: float
    held_after_ms: float  # pen: released at the half wrap, still touching the arm this long after
    held: bool
    wrap_trace: tuple[float, ...] = field(repr=False)


@dataclass(frozen=True)
class DynamicResult:
    """Fig. S11: how fast a current step grasps a pen; whether a thrown object is captured passively."""

    params: DynamicParams
    seed: int
    runs: tuple[DynamicRun, ...]

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        pens = [r for r in self.runs if r.kind == "pen"]
        throws = [r for r in self.runs if r.kind == "throw"]
        fastest = min((r.half_wrap_ms for r in pens if not math.isnan(r.half_wrap_ms)), default=math.nan)
        return {
            "experiment": "dynamic",
            "seed": self.seed,
            "pen_half_wrap_ms": fastest,
            "pen_held": any(r.held for r in pens),
            "captured": sum(r.held for r in throws),
            "throws": len(throws),
            "runs": [
                {k: v for k, v in dataclasses.asdict(r).items() if k != "wrap_trace"} for r in self.runs
            ],
            "params": dataclasses.asdict(self.params),
        }


def _dynamic_run(args: tuple[str, float, DynamicParams, int]) -> DynamicRun:
    kind, value, p, seed = args
    pen = kind == "pen"
    if pen:
        obj = ObjectConfig(
            _OBJ, radius_m=p.pen_diameter_m / 2, length_m=p.pen_length_m, pos_m=FAR_M, mass_kg=p.pen_mass_kg
        )
    else:
        obj = ObjectConfig(_OBJ, radius_m=0.01, length_m=0.06, pos_m=FAR_M, mass_kg=0.01)
    # A step, not a ramp: the slew limiter opened, the ceiling at the 3 A current limit.
    fw = FirmwareConfig(mapping=MappingConfig(tension_max_n=54.0, slew_n_per_s=100_000.0))
    rig = _direct_rig(SpiralDesign.paper_prototype(), fw, objects=(obj,), seed=seed)
    plant = rig.plant
    if pen:
        plant.hold_object(_OBJ, _world(*p.pen))
        rig.run(200 * MS)
        rig.set_tensions([value, fw.mapping.pretension_n, fw.mapping.pretension_n])
    else:
        plant.hold_object(_OBJ)
        rig.run(300 * MS)
        plant.hold_object(_OBJ, _world(*p.throw_from))
        plant.release_object(_OBJ)
        plant.set_object_velocity(_OBJ, (-value, 0.0, 0.3))
    t0 = rig.now_us
    first = math.nan
    half = math.nan
    released = math.nan
    trace = []
    max_wrap = 0.0
    for _ in range(p.window_ms):
        rig.tick()
        units = _contact_units(plant, _OBJ)
        wrap = _wrap_deg(plant, _OBJ)
        trace.append(wrap)
        max_wrap = max(max_wrap, wrap)
        t = (rig.now_us - t0) / MS
        if units and math.isnan(first):
            first = t
        if math.isnan(half) and wrap >= 180.0 and len(units) >= 3:
            half = t if pen else t - first
            if pen:
                plant.release_object(_OBJ)
                released = t
    last_touch = t if _contact_units(plant, _OBJ) else math.nan
    rig.close()
    if pen:
        held_after = (last_touch - released) if not math.isnan(released) else math.nan
        held = not math.isnan(held_after)
    else:
        held_after = math.nan
        held = not math.isnan(half) and not math.isnan(last_touch)
    return DynamicRun(kind, value, first, half, max_wrap, held_after, held, tuple(trace))


def dynamic(
    params: DynamicParams | None = None, seed: int = 0, progress: Progress | None = None, jobs: int = 1
) -> DynamicResult:
    """Fig. S11: a current step on cable 0 (DIRECT) against a pen on its support beside the tip (time to
    a half wrap, then the pen is let go); objects thrown at the hanging arm (passive capture)."""
    p = params or DynamicParams()
    items: list[tuple[str, float, DynamicParams, int]] = [("pen", t, p, seed) for t in p.step_tensions_n]
    items += [("throw", v, p, seed) for v in p.throw_speeds_m_s]
    return DynamicResult(p, seed, tuple(_map(_dynamic_run, items, jobs, progress)))


# ==================================================================================================
# the catalogue: sizes, the paper's numbers next to ours, figures
# ==================================================================================================

SIZES = ("tiny", "default", "large")
"""``tiny``: a smoke test of seconds; ``default``: the documented run (< 5 min on 2 cores); ``large``."""

Row = tuple[str, str, str]
"""``(quantity, ours, the paper's)``."""


def _pct(x: float) -> str:
    return "n/a" if math.isnan(x) else f"{100 * x:.0f} %"


def _mm(x: float) -> str:
    return "none" if math.isnan(x) else f"{1000 * x:.1f} mm"


@dataclass(frozen=True)
class Experiment:
    """One experiment of the catalogue.

    Attributes:
        name: the CLI word.
        summary: one line.
        run: ``run(design, size, seed, progress, jobs)`` -> result.
        rows: the result's numbers next to the paper's.
        samples: the result's sample counts, in words.
        plot: writes the figure, returns its path.
    """

    name: str
    summary: str
    run: Callable[[SpiralDesign, str, int, Progress | None, int], Any]
    rows: Callable[[Any], list[Row]]
    samples: Callable[[Any], str]
    plot: Callable[[Any, Path], Path]


def _sized(size: str, tiny: T, default: T, large: T) -> T:
    if size not in SIZES:
        raise ValueError(f"size must be one of {', '.join(SIZES)}, got {size!r}")
    return {"tiny": tiny, "default": default, "large": large}[size]


# --- workspace


def _run_workspace(design: SpiralDesign, size: str, seed: int, progress: Progress | None, jobs: int) -> Any:
    p = _sized(
        size,
        WorkspaceParams(tapers_deg=(6.5,), cables=(2,), duration_s=0.5),
        WorkspaceParams(),
        WorkspaceParams(duration_s=40.0),
    )
    return workspace(p, seed, progress, jobs)


def _rows_workspace(r: WorkspaceResult) -> list[Row]:
    n = sum(x.samples for x in r.runs)
    exact = sum(x.inside_share_exact * x.samples for x in r.runs) / n if n else math.nan
    rows: list[Row] = [
        ("tip samples inside ρw (all designs)", _pct(r.inside_share), "reachable points lie inside ρw"),
        ("  inside the real tip's base-first curve", _pct(exact), "(ρw is for the virtual tip)"),
    ]
    for run in r.runs:
        rows.append(
            (
                f"taper {run.taper_deg:g}° (b = {run.b:.3f}), {run.cables} cables: area inside ρw / exact",
                f"{run.envelope_area_m2 * 1e4:.0f} / {run.exact_area_m2 * 1e4:.0f} cm²",
                "shrinks as b grows",
            )
        )
        rows.append(
            (
                "  share of that area the tip reached (ρw / exact)",
                f"{_pct(run.coverage)} / {_pct(run.coverage_exact)} ({run.covered_area_m2 * 1e4:.0f} cm²)",
                "every point inside is reachable",
            )
        )
    return rows


def _samples_workspace(r: WorkspaceResult) -> str:
    return (
        f"{len(r.runs)} designs x {r.params.duration_s:g} s of random tensions, "
        f"{sum(x.samples for x in r.runs)} tip samples (every {r.params.sample_ms} ms)"
    )


def _plot_workspace(r: WorkspaceResult, out: Path) -> Path:
    plt = _pyplot()
    cables = sorted({x.cables for x in r.runs})
    tapers = sorted({x.taper_deg for x in r.runs})
    fig, axes = plt.subplots(
        len(cables), len(tapers), figsize=(3.6 * len(tapers), 4.2 * len(cables)), squeeze=False
    )
    for run in r.runs:
        ax = axes[cables.index(run.cables)][tapers.index(run.taper_deg)]
        b = np.array(run.boundary)
        ax.plot(np.array(run.u_m) * 1000, (np.array(run.z_m) - BASE_Z_M) * 1000, ".", ms=1.2, alpha=0.5)
        ax.plot(b[:, 0] * 1000, (b[:, 1] - BASE_Z_M) * 1000, "r-", lw=1.2, label="ρw (Table S1)")
        e = np.array(run.exact_boundary)
        ax.plot(e[:, 0] * 1000, (e[:, 1] - BASE_Z_M) * 1000, "g-", lw=1.0, label="real tip, base first")
        ax.plot([0], [0], "k^", ms=6, label="base")
        ax.set_title(
            f"taper {run.taper_deg:g}°, b={run.b:.3f}, {run.cables} cables\n"
            f"inside ρw {_pct(run.inside_share)}, exact {_pct(run.inside_share_exact)}; "
            f"reached {_pct(run.coverage_exact)} of the exact area",
            fontsize=8,
        )
        ax.set_aspect("equal")
        ax.set_xlim(-20, 280)
        ax.grid(alpha=0.3)
        ax.set_xlabel("distance from the arm's axis [mm]", fontsize=7)
        ax.set_ylabel("height above the base [mm]", fontsize=7)
        ax.tick_params(labelsize=7)
    axes[0][0].legend(fontsize=7, loc="lower right")
    fig.suptitle("workspace: tip samples under random cable tensions vs. the envelope ρw", fontsize=10)
    return _save(fig, out / "workspace.png")


# --- packing


def _run_packing(design: SpiralDesign, size: str, seed: int, progress: Progress | None, jobs: int) -> Any:
    p = _sized(size, PackingParams(ramp_s=1.5, hold_s=0.1), PackingParams(), PackingParams(ramp_s=16.0))
    return packing(design, p, seed, progress)


def _rows_packing(r: PackingResult) -> list[Row]:
    order = (
        "tip first" if r.order_correlation < -0.8 else "base first" if r.order_correlation > 0.8 else "mixed"
    )
    return [
        (
            "fitted spiral b of the packed joints",
            f"{r.b_fit:.4f} (design {r.b_design:.4f}, {100 * (r.b_fit / r.b_design - 1):+.1f} %)",
            "packed = the design's log spiral (Fig. S5)",
        ),
        ("turn per joint when packed", f"{r.turn_fit_deg:.1f}°", f"Δθ = {r.turn_design_deg:g}°"),
        ("every joint at its limit", "yes" if r.packed else "no", "yes (tight packing)"),
        (
            "cable 0 tension / current that packed it",
            f"{r.pack_tension_n:.1f} N / {r.pack_current_a:.2f} A",
            "a minimum force exists (Fig. S3C; no value for this arm)",
        ),
        (
            "curl order (rank correlation joint index vs. closing tension)",
            f"{order} ({r.order_correlation:+.2f})",
            "curls from the tip (Fig. S5C, Note S4)",
        ),
    ]


def _samples_packing(r: PackingResult) -> str:
    return f"1 ramp of {r.params.ramp_s:g} s to {r.params.tension_end_n:g} N, {r.joints} joints"


def _plot_packing(r: PackingResult, out: Path) -> Path:
    plt = _pyplot()
    fig, (a, b) = plt.subplots(1, 2, figsize=(10, 4.5))
    pts = np.array(r.joint_points)
    pole = complex(*r.pole)
    a.plot((pts[:, 0]) * 1000, (pts[:, 1] - BASE_Z_M) * 1000, "o-", ms=3, label="joints (packed)")
    w = pts[:, 0] + 1j * pts[:, 1] - pole
    ang = np.unwrap(np.angle(w))
    th = np.linspace(ang.min(), ang.max(), 300)
    r0 = abs(w[0])
    for bb, style, lab in ((r.b_design, "r--", "design b"), (r.b_fit, "g:", "fitted b")):
        rho = r0 * np.exp(bb * np.sign(ang[0] - ang[-1]) * (th - ang[0]))
        z = pole + rho * np.exp(1j * th)
        a.plot(z.real * 1000, (z.imag - BASE_Z_M) * 1000, style, lw=1, label=f"{lab} = {bb:.4f}")
    a.set_aspect("equal")
    a.grid(alpha=0.3)
    a.legend(fontsize=7)
    a.set_title("packed arm vs. the design spiral", fontsize=9)
    a.set_xlabel("x [mm]", fontsize=8)
    a.set_ylabel("z above the base [mm]", fontsize=8)
    b.plot(r.ramp_tension_n, r.closed_count, "-", lw=1.2)
    b.set_xlabel("cable 0 tension [N]", fontsize=8)
    b.set_ylabel("joints at their limit", fontsize=8)
    b2 = b.twinx()
    joints = np.arange(1, r.joints + 1)
    b2.plot(r.close_tension_n, joints, "r.", ms=5)
    b2.set_ylabel("joint (1 = base) by the tension that closed it", fontsize=8, color="r")
    b.set_title(
        f"packs at {r.pack_tension_n:.1f} N ({r.pack_current_a:.2f} A), curling from the tip", fontsize=9
    )
    b.grid(alpha=0.3)
    return _save(fig, out / "packing.png")


# --- strategy


def _run_strategy(design: SpiralDesign, size: str, seed: int, progress: Progress | None, jobs: int) -> Any:
    p = _sized(
        size,
        StrategyParams(diameters_m=(0.02,), xs_m=(0.04,), zs_m=(-0.11,)),
        StrategyParams(),
        StrategyParams(
            xs_m=(0.02, 0.035, 0.05, 0.065, 0.08, 0.095),
            zs_m=(-0.06, -0.08, -0.1, -0.12, -0.14, -0.16, -0.18),
        ),
    )
    return strategy(design, p, seed, progress, jobs)


def _rows_strategy(r: StrategyResult) -> list[Row]:
    d = r.as_dict()
    rows: list[Row] = [
        (
            "placements grasped and held, strategy on",
            _pct(r.success_on),
            "wider range than off (Fig. S6, 3C)",
        ),
        ("placements grasped and held, strategy off", _pct(r.success_off), "only objects near the tip"),
        ("held only with the strategy on / only off", f"{d['only_on']} / {d['only_off']}", "on > off"),
    ]
    for row in r.per_diameter():
        rows.append(
            (
                f"  diameter {row['diameter_m'] * 1000:g} mm: on / off",
                f"{_pct(row['success_on'])} / {_pct(row['success_off'])}",
                "",
            )
        )
    return rows


def _samples_strategy(r: StrategyResult) -> str:
    p = r.params
    return (
        f"{len(p.diameters_m)} diameters x {len(p.xs_m) * len(p.zs_m)} placements x 2 strategies = "
        f"{len(r.outcomes)} grasps ({1000 * p.mass_kg:g} g objects, held {p.hold_s:g} s after release)"
    )


def _plot_strategy(r: StrategyResult, out: Path) -> Path:
    plt = _pyplot()
    ds = r.params.diameters_m
    fig, axes = plt.subplots(1, len(ds), figsize=(3.8 * len(ds), 4.6), squeeze=False)
    for ax, d in zip(axes[0], ds, strict=True):
        for o in r.outcomes:
            s = o.setup
            if s.diameter_m != d or not s.strategy_on:
                continue
            twin = r._twin(o)
            on, off = o.held, twin.held
            marker, colour = (
                ("o", "tab:green")
                if on and off
                else ("^", "tab:blue")
                if on
                else ("v", "tab:orange")
                if off
                else ("x", "0.6")
            )
            ax.plot(s.x_m * 1000, s.z_m * 1000, marker=marker, color=colour, ms=9, ls="")
            ax.add_patch(plt.Circle((s.x_m * 1000, s.z_m * 1000), d * 500, fill=False, color=colour, lw=0.6))
        ax.plot([0, 0], [0, -223], "k-", lw=3, alpha=0.3)
        ax.set_title(
            f"d = {d * 1000:g} mm: on {_pct(r._share(True, d))}, off {_pct(r._share(False, d))}", fontsize=9
        )
        ax.set_aspect("equal")
        ax.set_xlim(-15, 125)
        ax.set_ylim(-235, 10)
        ax.grid(alpha=0.3)
        ax.set_xlabel("object centre from the arm's axis [mm]", fontsize=8)
        ax.set_ylabel("object centre below the base [mm]", fontsize=8)
    handles = [
        plt.Line2D([], [], marker=m, color=c, ls="", label=lab)
        for m, c, lab in (
            ("o", "tab:green", "both"),
            ("^", "tab:blue", "strategy on only"),
            ("v", "tab:orange", "strategy off only"),
            ("x", "0.6", "neither"),
        )
    ]
    axes[0][0].legend(handles=handles, fontsize=7, loc="lower left")
    fig.suptitle("grasp-range map: grasped and held against gravity (hanging arm in grey)", fontsize=10)
    return _save(fig, out / "strategy.png")


# --- grasp-range


def _run_grasp_range(design: SpiralDesign, size: str, seed: int, progress: Progress | None, jobs: int) -> Any:
    p = _sized(
        size,
        GraspRangeParams(diameters_m=(0.013,), gaps_m=(0.02,), drops_m=(0.06,)),
        GraspRangeParams(),
        GraspRangeParams(gaps_m=(0.015, 0.03, 0.045), drops_m=(0.0, 0.04, 0.07, 0.1)),
    )
    return grasp_range(design, p, seed, progress, jobs)


def _rows_grasp_range(r: GraspRangeResult) -> list[Row]:
    rows: list[Row] = [
        (
            "smallest diameter wrapped >= half way",
            _mm(r.d_min_sim_m),
            f"d_min = {_mm(r.d_min_paper_m)} (eq. 14)",
        ),
        (
            "largest diameter wrapped >= half way",
            _mm(r.d_max_sim_m),
            f"d_max = {_mm(r.d_max_paper_m)} (eq. 15)",
        ),
    ]
    for d, w in r.best_wrap_deg():
        rows.append(
            (f"  best wrap around {d * 1000:g} mm", f"{w:.0f}°", "" if d > r.d_min_paper_m else "< d_min")
        )
    return rows


def _samples_grasp_range(r: GraspRangeResult) -> str:
    p = r.params
    return (
        f"{len(p.diameters_m)} diameters x {len(p.gaps_m) * len(p.drops_m)} placements x 2 strategies = "
        f"{len(r.outcomes)} grasps of fixed cylinders at {p.wrap_n:g} N"
    )


def _plot_grasp_range(r: GraspRangeResult, out: Path) -> Path:
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(6.5, 4.2))
    for on, marker in ((True, "^"), (False, "v")):
        xs = [o.setup.diameter_m * 1000 for o in r.outcomes if o.setup.strategy_on == on]
        ys = [o.wrap_deg for o in r.outcomes if o.setup.strategy_on == on]
        ax.plot(xs, ys, marker, ls="", alpha=0.5, label=f"strategy {'on' if on else 'off'} (each placement)")
    best = r.best_wrap_deg()
    ax.plot([d * 1000 for d, _ in best], [w for _, w in best], "k-", lw=1.2, label="best")
    ax.axhline(r.params.half_wrap_deg, color="r", ls="--", lw=1, label="half way (eq. 15)")
    ax.axvline(r.d_min_paper_m * 1000, color="g", ls=":", label=f"d_min = {r.d_min_paper_m * 1000:.1f} mm")
    ax.axvline(r.d_max_paper_m * 1000, color="m", ls=":", label=f"d_max = {r.d_max_paper_m * 1000:.0f} mm")
    ax.set_xscale("log")
    ax.set_xlabel("cylinder diameter [mm]")
    ax.set_ylabel("wrap angle of the contacts [°]")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=7)
    ax.set_title("grasp range: how far the arm wraps around fixed cylinders", fontsize=10)
    return _save(fig, out / "grasp-range.png")


# --- load


def _run_load(design: SpiralDesign, size: str, seed: int, progress: Progress | None, jobs: int) -> Any:
    p = _sized(
        size,
        LoadParams(diameters_m=(0.02,), forces_n=(5.0,), placements=((0.03, 0.09),)),
        LoadParams(),
        LoadParams(diameters_m=(0.013, 0.016, 0.02, 0.025, 0.03, 0.04), forces_n=(5.0, 10.0, 15.0)),
    )
    return load(design, p, seed, progress, jobs)


def _rows_load(r: LoadResult) -> list[Row]:
    rows: list[Row] = []
    for row in r.rows():
        held = row["held_kg"]
        rows.append(
            (
                f"F = {row['force_n']:g} N, d = {row['diameter_m'] * 1000:g} mm: heaviest held",
                "not held"
                if math.isnan(held)
                else f"{held * 1000:.0f} g ({_pct(row['ratio'])} of the bound)",
                f"M <= {row['bound_kg'] * 1000:.0f} g (eq. 16)",
            )
        )
    return rows


def _samples_load(r: LoadResult) -> str:
    p = r.params
    return (
        f"{len(p.forces_n)} forces x {len(p.diameters_m)} diameters x {len(p.placements)} placements = "
        f"{len(r.outcomes)} grasps, load growing at {p.load_rate_n_per_s:g} N/s"
    )


def _plot_load(r: LoadResult, out: Path, design: SpiralDesign | None = None) -> Path:
    plt = _pyplot()
    design = design or SpiralDesign.paper_prototype()
    fig, ax = plt.subplots(figsize=(6.5, 4.2))
    dd = np.linspace(0.005, max(r.params.diameters_m) * 1.3, 100)
    for k, force in enumerate(r.params.forces_n):
        colour = f"C{k}"
        ax.plot(
            dd * 1000,
            [design.max_load_kg(float(d), force) * 1000 for d in dd],
            "--",
            color=colour,
            lw=1,
            label=f"bound M(φ, d, {force:g} N)",
        )
        rows = [x for x in r.rows() if x["force_n"] == force]
        ax.plot(
            [x["diameter_m"] * 1000 for x in rows],
            [x["held_kg"] * 1000 for x in rows],
            "o-",
            color=colour,
            label=f"held in simulation, F = {force:g} N",
        )
    ax.set_xlabel("object diameter [mm]")
    ax.set_ylabel("mass held [g]")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)
    ax.set_title("load: heaviest object held vs. the bound of eq. (16)", fontsize=10)
    return _save(fig, out / "load.png")


# --- dynamic


def _run_dynamic(design: SpiralDesign, size: str, seed: int, progress: Progress | None, jobs: int) -> Any:
    p = _sized(
        size,
        DynamicParams(step_tensions_n=(54.0,), throw_speeds_m_s=(2.0,), window_ms=150),
        DynamicParams(),
        DynamicParams(
            step_tensions_n=(10.0, 20.0, 35.0, 54.0), throw_speeds_m_s=(0.5, 1.0, 2.0, 3.0, 4.0, 6.0)
        ),
    )
    return dynamic(p, seed, progress, jobs)


def _rows_dynamic(r: DynamicResult) -> list[Row]:
    rows: list[Row] = []
    for run in r.runs:
        if run.kind == "pen":
            rows.append(
                (
                    f"pen, step to {run.value:g} N: step -> half wrap",
                    "never" if math.isnan(run.half_wrap_ms) else f"{run.half_wrap_ms:.0f} ms",
                    "0.06 s to grasp (45 cm arm, Fig. S11A)",
                )
            )
            rows.append(("  pen kept once let go", "yes" if run.held else "no (thrown)", "moved to the base"))
        else:
            rows.append(
                (
                    f"object thrown at {run.value:g} m/s: contact -> half wrap",
                    "never" if math.isnan(run.half_wrap_ms) else f"{run.half_wrap_ms:.0f} ms",
                    "captured within 120 ms (Fig. S11B)",
                )
            )
            rows.append(
                ("  largest wrap, captured", f"{run.max_wrap_deg:.0f}°, {'yes' if run.held else 'no'}", "")
            )
    return rows


def _samples_dynamic(r: DynamicResult) -> str:
    pens = sum(1 for x in r.runs if x.kind == "pen")
    return f"{pens} pen steps and {len(r.runs) - pens} throws, {r.params.window_ms} ms each"


def _plot_dynamic(r: DynamicResult, out: Path) -> Path:
    plt = _pyplot()
    fig, (a, b) = plt.subplots(1, 2, figsize=(10, 4))
    for run in r.runs:
        ax = a if run.kind == "pen" else b
        t = np.arange(1, len(run.wrap_trace) + 1)
        unit = "N step" if run.kind == "pen" else "m/s"
        ax.plot(t, run.wrap_trace, lw=1, label=f"{run.value:g} {unit}")
    a.axvline(60, color="k", ls=":", label="paper: 0.06 s")
    b.axvline(120, color="k", ls=":", label="paper: 120 ms")
    for ax, title in (
        (a, "pen beside the tip: current step on cable 0"),
        (b, "object thrown at the hanging arm"),
    ):
        ax.axhline(180, color="r", ls="--", lw=0.8)
        ax.set_xlabel("time [ms]" + (" from the step" if ax is a else " from the throw"))
        ax.set_ylabel("wrap angle of the contacts [°]")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
        ax.set_title(title, fontsize=9)
    return _save(fig, out / "dynamic.png")


# --- plotting helpers


def _pyplot() -> Any:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _save(fig: Any, path: Path) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    _pyplot().close(fig)
    return path


EXPERIMENTS: dict[str, Experiment] = {
    e.name: e
    for e in (
        Experiment(
            "workspace",
            "random cable tensions on 2- and 3-cable arms of three tapers vs. the envelope ρw (Note S2)",
            _run_workspace,
            _rows_workspace,
            _samples_workspace,
            _plot_workspace,
        ),
        Experiment(
            "packing",
            "one cable's tension ramped until the arm packs: current, fitted b, curl order (Note S3)",
            _run_packing,
            _rows_packing,
            _samples_packing,
            _plot_packing,
        ),
        Experiment(
            "strategy",
            "objects on a grid grasped with the strategy on and off: success rates, range map (Note S4)",
            _run_strategy,
            _rows_strategy,
            _samples_strategy,
            _plot_strategy,
        ),
        Experiment(
            "grasp-range",
            "the smallest and largest cylinder wrapped at least half way vs. d_min, d_max (eq. 14, 15)",
            _run_grasp_range,
            _rows_grasp_range,
            _samples_grasp_range,
            _plot_grasp_range,
        ),
        Experiment(
            "load",
            "the heaviest object held per diameter at a fixed cable force vs. M(φ, d, F) (eq. 16)",
            _run_load,
            _rows_load,
            _samples_load,
            _plot_load,
        ),
        Experiment(
            "dynamic",
            "a current step grasping a pen, objects thrown at the arm (Fig. S11)",
            _run_dynamic,
            _rows_dynamic,
            _samples_dynamic,
            _plot_dynamic,
        ),
    )
}
"""Every experiment, by CLI name."""


def run_experiment(
    name: str,
    *,
    design: SpiralDesign | None = None,
    size: str = "default",
    seed: int = 0,
    progress: Progress | None = None,
    jobs: int = 1,
) -> Any:
    """Run the experiment ``name`` at ``size`` (pure; the result is frozen and picklable).

    Raises:
        KeyError: unknown experiment.
        ValueError: unknown size.
    """
    exp = EXPERIMENTS[name]
    _sized(size, 0, 0, 0)
    return exp.run(design or SpiralDesign.paper_prototype(), size, seed, progress, max(1, jobs))


# ==================================================================================================
# `spirob-hil experiment NAME`
# ==================================================================================================


def configure_experiment(p: argparse.ArgumentParser) -> None:
    """Arguments of ``spirob-hil experiment``."""
    from hil.cli import add_design_arguments, seed_arg

    p.add_argument("name", choices=list(EXPERIMENTS), metavar="NAME", help=", ".join(EXPERIMENTS))
    p.add_argument("--json", action="store_true", help="print one JSON object instead of a table")
    p.add_argument("--report", type=Path, metavar="DIR", help="write the experiment's PNG figure into DIR")
    p.add_argument("--seed", type=seed_arg, default=0, help="seed of every random choice (default 0)")
    p.add_argument(
        "--size",
        choices=SIZES,
        default="default",
        help="tiny: seconds (a smoke test); default: the documented run (< 5 min); large: denser",
    )
    p.add_argument(
        "--jobs", type=int, default=2, metavar="N", help="worker processes for independent runs (default 2)"
    )
    add_design_arguments(p)


def run_experiment_command(args: argparse.Namespace) -> int:
    """Run ``spirob-hil experiment``: progress on stderr, the table (or JSON) on stdout, a PNG with
    ``--report``."""
    import time

    from rich.console import Console
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn
    from rich.table import Table

    from hil.cli import design_from_args

    if args.jobs < 1:
        raise ValueError(f"--jobs must be >= 1, got {args.jobs}")
    design = design_from_args(args)
    exp = EXPERIMENTS[args.name]
    err = Console(stderr=True)
    t0 = time.perf_counter()
    with Progress(
        TextColumn("{task.description}"),
        BarColumn(),
        TextColumn("{task.completed:.0f}/{task.total:.0f}"),
        TimeElapsedColumn(),
        console=err,
        transient=True,
        disable=not err.is_terminal,
    ) as bar:
        task = bar.add_task(f"experiment {exp.name}", total=None)

        def progress(done: int, total: int) -> None:
            bar.update(task, completed=done, total=total)

        result = run_experiment(
            args.name, design=design, size=args.size, seed=args.seed, progress=progress, jobs=args.jobs
        )
    elapsed = time.perf_counter() - t0
    figure = None
    if args.report is not None:
        try:
            figure = exp.plot(result, args.report)
        except OSError as exc:
            raise ValueError(f"cannot write into {args.report}: {exc.strerror or exc}") from exc
    if args.json:
        out = result.as_dict()
        out["samples"] = exp.samples(result)
        out["size"] = args.size
        out["elapsed_s"] = round(elapsed, 1)
        if figure is not None:
            out["figure"] = str(figure)
        print(json.dumps(_clean(out), allow_nan=False, default=_json_default))
        return 0
    table = Table(title=f"{exp.name}: {exp.summary}", title_justify="left")
    table.add_column("quantity")
    table.add_column("this model", justify="right")
    table.add_column("paper")
    for quantity, ours, paper in exp.rows(result):
        table.add_row(quantity, ours, paper)
    console = Console()
    console.print(table)
    console.print(f"samples: {exp.samples(result)}; seed {args.seed}; size {args.size}; {elapsed:.0f} s")
    if figure is not None:
        console.print(f"figure: {figure}")
    return 0


def add_experiment_command(subparsers: Any) -> argparse.ArgumentParser:
    """Add ``experiment`` to an argparse subparsers object (for a CLI that does not use ``COMMANDS``)."""
    p: argparse.ArgumentParser = subparsers.add_parser(
        "experiment", help="reproduce a simulation result of the paper"
    )
    configure_experiment(p)
    p.set_defaults(_run=run_experiment_command)
    return p


def _clean(value: Any) -> Any:
    """JSON has no NaN or infinity: they become null."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: _clean(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_clean(v) for v in value]
    return value


def _json_default(value: object) -> object:
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, np.generic):
        return value.item()
    raise TypeError(f"not JSON serialisable: {type(value).__name__}")
