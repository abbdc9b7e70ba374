"""dynamic (Fig. S11) on the paper's 45 cm 2-cable arm: a current step grasping a pen, and objects thrown at
the arm while one cable holds.

(A) A pen stands beside the arm near its tip; cable 0 is stepped to a tension (the slew limiter opened);
measured: the time from the step to a half wrap, then the pen is let go and followed (carried toward the
base or not). (B) Cable 0 (on the +x side) is pulled to ``hold_tension_n`` and the arm settles, cable 1
stays at the pretension (slack); then cable 0 is either held at that length by the firmware's length-hold
(host command ``HOLD_LENGTHS``: Fig. S11B's "cable fixed at constant length") or kept at that tension (the
stand-in used before the firmware could hold a length); both arms run at the same aims. An object is
thrown horizontally toward −x at a jittered point of the arm's upper half; captured = a half wrap within
:data:`CAPTURE_MS` of the first contact and still touching at the end of the window (Wilson 95 % interval
per arm). Every trial
reports the plant's extremes (penetration, tension, limit overshoot); the headline (the pen at the largest
step, one throw per speed) is repeated at every physics step in ``timesteps_s`` so convergence shows.

The experiment's contacts are stiffer than the plant's default and its steps finer (``contact_timeconst_s``,
``timesteps_s``): at the default 2 ms time constant the whipping tip sinks 1.1 mm (22 % of its radius) into
the pen at every step, and a thrown object enters up to ``v·h`` before its contact is detected.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import mujoco
import numpy as np

from controller.config import FirmwareConfig, MappingConfig
from hil.experiments.base import Conditions, Experiment, Sizes
from hil.experiments.common import G, Row, pyplot, save_figure, worst_extremes
from hil.experiments.parallel import parallel_map
from hil.experiments.stats import wilson_interval
from hil.sim.config import ModelConfig
from hil.sim.objects import contact_units, contact_wrap_deg
from hil.sim.plant import Plant
from hil.sim.spiral import SpiralDesign
from hil.sim.types import PhysicsExtremes
from hil.trial.arm_45cm import paper_arm_45cm, scaled_model, with_contact_timeconst, with_timestep
from hil.trial.rig import direct_rig
from hil.trial.scene import MS, OBJ, target_object, world_m
from protocol.messages import CommandCode

CAPTURE_MS = 120.0
"""A throw is captured if the half wrap comes this soon after the first contact (Fig. S11B: 120 ms)."""
HALF_WRAP_DEG = 180.0
"""A half wrap: the contacts span at least this much of the object's circumference ..."""
HALF_WRAP_UNITS = 3
"""... with at least this many units touching it."""
HOLD_ENGAGE_MS = 5
"""(B) time between the HOLD_LENGTHS command and the throw (the command reaches the board next tick)."""
CARRIED_M = 0.02
"""The pen counts as carried toward the base if, still touching the arm at the end, it is this much
closer to the base than where it was let go."""
HOLDS = ("length", "tension")
"""How cable 0 holds during a throw: at its length (the firmware's length-hold, Fig. S11B's setup) or at
``hold_tension_n`` (the tension stand-in)."""


@dataclass(frozen=True)
class DynamicParams:
    """Attributes:
    step_tensions_n: cable 0 tension steps for the pen grasp (54 N = 3 A, the firmware's current limit).
    pen_from_tip_m: the pen's height: this far up the straight arm from its tip.
    pen_gap_m: gap between the arm's surface and the pen before the step.
    pen_diameter_m, pen_length_m, pen_mass_kg: the pen.
    hold_tension_n: (B) cable 0's tension while the arm settles before the throw (the length-hold then
        freezes the length it reached; the tension stand-in keeps this tension).
    holds: (B) the arms of the throw, a subset of :data:`HOLDS`.
    settle_ms: (B) time for the arm to settle under that tension before the throw.
    throw_speeds_m_s: speeds of the thrown object (toward −x, from the held cable's side).
    throw_positions: jittered aiming points per speed.
    throw_band: the aimed unit lies in this range of the arm, as fractions of its units from the base.
    throw_offset_m: the object starts this far on the +x side of its aiming point.
    throw_jitter_m: ± uniform jitter of the aiming point's height.
    object_diameter_m, object_length_m, object_mass_kg: the thrown object.
    throw_clearance_m: the thrown object starts at least this far from every unit: if the aimed start
        is closer (the hook curled toward +x can reach past the aiming point), it moves out along +x.
    window_ms: how long each run is watched after the step or the throw.
    timesteps_s: physics steps of the convergence check (the first one runs every trial; the control
        period stays 1 ms).
    contact_timeconst_s: the contacts' ``solref`` time constant at every step (only the step changes
        between the columns); ``None``: twice the first step (the shortest :class:`ContactConfig`
        accepts there).
    """

    step_tensions_n: tuple[float, ...] = (20.0, 54.0)
    pen_from_tip_m: float = 0.12
    pen_gap_m: float = 0.008
    pen_diameter_m: float = 0.010
    pen_length_m: float = 0.14
    pen_mass_kg: float = 0.015
    hold_tension_n: float = 10.0
    holds: tuple[str, ...] = HOLDS
    settle_ms: int = 600
    throw_speeds_m_s: tuple[float, ...] = (1.0, 2.0, 3.0, 4.0)
    throw_positions: int = 6
    throw_band: tuple[float, float] = (0.25, 0.5)
    throw_offset_m: float = 0.06
    throw_jitter_m: float = 0.01
    object_diameter_m: float = 0.020
    object_length_m: float = 0.06
    object_mass_kg: float = 0.010
    throw_clearance_m: float = 0.01
    window_ms: int = 400
    timesteps_s: tuple[float, ...] = (0.00025, 0.000125, 0.0000625)
    contact_timeconst_s: float | None = None

    @property
    def contact_s(self) -> float:
        """The contacts' time constant: ``contact_timeconst_s``, or twice the first step."""
        return self.contact_timeconst_s if self.contact_timeconst_s is not None else 2 * self.timesteps_s[0]


@dataclass(frozen=True)
class DynamicRun:
    """One pen grasp or one throw.

    Attributes:
        kind: ``"pen"`` or ``"throw"``.
        value: the step tension [N] or the throw speed [m/s].
        timestep_s: the physics step it ran at.
        position: throw: the jitter index (0 for the pen).
        hold: throw: how cable 0 held (one of :data:`HOLDS`; ``""`` for the pen).
        aim: ``(x, z)`` relative to the base: the pen's centre, or the throw's aiming point.
        first_contact_ms: from the step or the throw to the first arm-object contact (NaN: none).
        half_wrap_ms: pen: from the step to a half wrap; throw: from the first contact (NaN: never).
        max_wrap_deg: largest wrap angle of the contacts.
        toward_base_m: pen: how much closer to the base it ends than where it was let go (NaN: not let go).
        touching_at_end: the object touches the arm at the end of the window.
        success: pen: carried toward the base; throw: captured.
        extremes: the plant's extremes from the step or the throw to the end.
    """

    kind: str
    value: float
    timestep_s: float
    position: int
    hold: str
    aim: tuple[float, float]
    first_contact_ms: float
    half_wrap_ms: float
    max_wrap_deg: float
    toward_base_m: float
    touching_at_end: bool
    success: bool
    extremes: PhysicsExtremes
    wrap_trace: tuple[float, ...] = field(repr=False)

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready form (without the trace)."""
        d = {k: v for k, v in dataclasses.asdict(self).items() if k not in ("wrap_trace", "extremes")}
        d.update(self.extremes.as_dict())
        d["limit_overshoot_deg"] = math.degrees(self.extremes.limit_overshoot_rad)
        return d


def worst(runs: tuple[DynamicRun, ...] | list[DynamicRun]) -> PhysicsExtremes:
    """The largest of every extreme over ``runs`` (zeros for none)."""
    return worst_extremes(r.extremes for r in runs)


@dataclass(frozen=True)
class DynamicResult:
    """Fig. S11 on the 45 cm arm: how fast a step grasps a pen, whether a thrown object is captured (a
    :class:`~hil.experiments.base.Result`)."""

    params: DynamicParams
    seed: int
    arm: dict[str, float]
    runs: tuple[DynamicRun, ...]

    def at(self, timestep_s: float, kind: str, hold: str | None = None) -> list[DynamicRun]:
        """The runs of ``kind`` at the physics step ``timestep_s`` (throws: of one ``hold`` or all)."""
        return [
            r
            for r in self.runs
            if r.kind == kind and r.timestep_s == timestep_s and (hold is None or r.hold == hold)
        ]

    def headline(self, timestep_s: float) -> dict[str, Any]:
        """The headline at one physics step: the pen at the largest step, one throw per speed."""
        top = max(self.params.step_tensions_n)
        pens = [r for r in self.at(timestep_s, "pen") if r.value == top]
        throws = [r for r in self.at(timestep_s, "throw") if r.position == 0]
        pen = pens[0] if pens else None
        return {
            "timestep_s": timestep_s,
            "pen_half_wrap_ms": pen.half_wrap_ms if pen else math.nan,
            "pen_carried": pen.success if pen else False,
            **{f"captured_{h}": sum(r.success for r in throws if r.hold == h) for h in self.params.holds},
            "throws_per_hold": sum(1 for r in throws if r.hold == self.params.holds[0]),
            **worst(pens + throws).as_dict(),
        }

    def capture(self, hold: str, speed_m_s: float | None = None) -> tuple[int, int, tuple[float, float]]:
        """Captured, thrown and the Wilson 95 % interval at the first physics step, with cable 0 held as
        ``hold`` (one of :data:`HOLDS`), at one speed or all."""
        runs = [
            r
            for r in self.at(self.params.timesteps_s[0], "throw", hold)
            if speed_m_s is None or r.value == speed_m_s
        ]
        k = sum(r.success for r in runs)
        return k, len(runs), wilson_interval(k, len(runs))

    @property
    def extremes(self) -> PhysicsExtremes:
        """The worst physics over every run."""
        return worst(self.runs)

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        base = self.params.timesteps_s[0]
        pens = self.at(base, "pen")
        fastest = min((r.half_wrap_ms for r in pens if not math.isnan(r.half_wrap_ms)), default=math.nan)
        capture: dict[str, dict[str, Any]] = {}
        for h in self.params.holds:
            k, n, (lo, hi) = self.capture(h)
            per_speed = []
            for v in self.params.throw_speeds_m_s:
                kv, nv, (lov, hiv) = self.capture(h, v)
                per_speed.append({"speed_m_s": v, "captured": kv, "throws": nv, "ci95": [lov, hiv]})
            capture[h] = {
                "captured": k,
                "throws": n,
                "rate": k / n if n else math.nan,
                "ci95": [lo, hi],
                "by_speed": per_speed,
            }
        return {
            "experiment": "dynamic",
            "seed": self.seed,
            "arm": self.arm,
            "pen_half_wrap_ms": fastest,
            "pen_carried": any(r.success for r in pens),
            "capture": capture,
            "convergence": [self.headline(ts) for ts in self.params.timesteps_s],
            "extremes": self.extremes.as_dict(),
            "runs": [r.as_dict() for r in self.runs],
            "params": dataclasses.asdict(self.params),
        }

    def table_rows(self) -> list[Row]:
        """The result's numbers next to the paper's, one row each."""
        a = self.arm
        rows: list[Row] = [
            (
                "arm (Fig. S11: 2 cables, 45 cm)",
                f"{a['units']:.0f} units, {100 * a['length_m']:.1f} cm, "
                f"tip {1000 * a['tip_width_m']:.0f} mm, "
                f"{1000 * a['mass_kg']:.0f} g, k_base {a['base_stiffness_nm_per_rad']:.1f} N·m/rad",
                "45 cm, 2 cables",
            )
        ]
        base = self.params.timesteps_s[0]
        for run in self.at(base, "pen"):
            rows.append(
                (
                    f"pen, step to {run.value:g} N: step -> half wrap",
                    _ms(run.half_wrap_ms),
                    "0.06 s to grasp and bring to the base (Fig. S11A)",
                )
            )
            carried = "n/a" if math.isnan(run.toward_base_m) else f"{1000 * run.toward_base_m:+.0f} mm"
            rows.append(
                (
                    "  pen carried toward the base once let go",
                    f"{'yes' if run.success else 'no'} ({carried})",
                    "moved to the base",
                )
            )
            rows.append(("  penetration, tension, limit overshoot", _extremes(run.extremes), ""))
        for hold in self.params.holds:
            label = _hold_label(hold, self.params)
            for v in self.params.throw_speeds_m_s:
                k, n, (lo, hi) = self.capture(hold, v)
                runs = [x for x in self.at(base, "throw", hold) if x.value == v]
                rows.append(
                    (
                        f"thrown at {v:g} m/s, {label}: captured (Wilson 95 %)",
                        _rate(k, n, lo, hi),
                        f"captured within {CAPTURE_MS:.0f} ms (Fig. S11B: cable at constant length)",
                    )
                )
                rows.append(("  worst penetration, tension, limit overshoot", _extremes(worst(runs)), ""))
            k, n, (lo, hi) = self.capture(hold)
            rows.append((f"all throws, {label}: captured (Wilson 95 %)", _rate(k, n, lo, hi), ""))
        for h in (self.headline(ts) for ts in self.params.timesteps_s):
            captured = ", ".join(f"{hold} {h['captured_' + hold]}" for hold in self.params.holds)
            rows.append(
                (
                    f"headline at a {1000 * h['timestep_s']:g} ms physics step",
                    f"pen {_ms(h['pen_half_wrap_ms'])}, captured ({captured})/{h['throws_per_hold']}, "
                    f"penetration {1000 * h['penetration_m']:.1f} mm",
                    "converged: the same at every step",
                )
            )
        return rows

    def describe_samples(self) -> str:
        """Pen steps, throws and physics steps, in words."""
        base = self.params.timesteps_s[0]
        pens, throws = len(self.at(base, "pen")), len(self.at(base, "throw"))
        steps = ", ".join(f"{1000 * ts:g}" for ts in self.params.timesteps_s)
        holds = " and ".join(self.params.holds)
        return (
            f"{pens} pen steps and {throws} throws (cable 0 held by {holds}), "
            f"{self.params.window_ms} ms each; "
            f"headline repeated at {steps} ms physics steps ({len(self.runs)} runs)"
        )

    def figure(self, out: Path) -> Path:
        """Write the figure into the directory ``out``; returns its path (``dynamic.png``)."""
        plt = pyplot()
        fig, (a, b) = plt.subplots(1, 2, figsize=(10, 4))
        base = self.params.timesteps_s[0]
        for run in self.runs:
            if run.kind == "throw" and run.timestep_s == base and run.position > 0:
                continue  # the jittered throws count in the rate; the figure shows one per speed
            ax = a if run.kind == "pen" else b
            t = np.arange(1, len(run.wrap_trace) + 1)
            what = f"{run.value:g} N step" if run.kind == "pen" else f"{run.value:g} m/s, {run.hold}"
            style = "-" if run.timestep_s == base else ":"
            ax.plot(t, run.wrap_trace, style, lw=1, label=f"{what}, {1000 * run.timestep_s:g} ms")
        a.axvline(60, color="k", ls=":", label="paper: 0.06 s")
        b.axvline(CAPTURE_MS, color="k", ls=":", label=f"paper: {CAPTURE_MS:.0f} ms")
        for ax, title in (
            (a, "pen beside the tip: current step on cable 0"),
            (b, "object thrown at the arm, cable 0 held at length or at a tension"),
        ):
            ax.axhline(HALF_WRAP_DEG, color="r", ls="--", lw=0.8)
            ax.set_xlabel("time [ms]" + (" from the step" if ax is a else " from the throw"))
            ax.set_ylabel("wrap angle of the contacts [°]")
            ax.grid(alpha=0.3)
            ax.legend(fontsize=6)
            ax.set_title(title, fontsize=9)
        return save_figure(fig, out / "dynamic.png")


_Item = tuple[str, float, float, int, str, DynamicParams, ModelConfig, int]
"""(kind, value, timestep_s, position, hold, params, model of the 45 cm arm, seed)."""


def _pen_aim(design: SpiralDesign, p: DynamicParams) -> tuple[float, float]:
    """The pen's centre beside the straight hanging arm, ``pen_from_tip_m`` up from its tip."""
    half_width = 0.5 * design.tip_width_m + p.pen_from_tip_m * math.tan(0.5 * design.taper_rad)
    return (half_width + p.pen_gap_m + 0.5 * p.pen_diameter_m, -(design.length_m - p.pen_from_tip_m))


CLEAR_STEP_M = 0.005
"""How far the thrown object's start moves out along +x per try until it clears the arm."""


def _clearance_m(plant: Plant, p: DynamicParams) -> float:
    """Distance from the object to the nearest unit (up to ``p.throw_clearance_m``; < 0: overlapping)."""
    m, d = plant.mj_model, plant.mj_data
    geom = mujoco.mjtObj.mjOBJ_GEOM
    obj = mujoco.mj_name2id(m, geom, f"{OBJ}_geom")
    units = (mujoco.mj_name2id(m, geom, f"unit_{i:02d}_geom") for i in range(plant.design.units))
    fromto = np.zeros(6)
    return float(min(mujoco.mj_geomDistance(m, d, obj, g, p.throw_clearance_m, fromto) for g in units))


def _clear_start_offset_m(plant: Plant, aim: tuple[float, float], p: DynamicParams) -> float:
    """Put the held object ``throw_offset_m`` on the +x side of ``aim``, or further out along +x until it
    is ``throw_clearance_m`` from every unit; returns the offset used.

    The hook curled toward +x can reach past the aiming point: an object started inside it is pushed out
    in one step (on the 45 cm arm: 12.6 mm deep, the limits 72° past, 510 N), which is no throw.
    """
    offset = p.throw_offset_m
    while True:
        plant.hold_object(OBJ, world_m(aim[0] + offset, aim[1]))
        if _clearance_m(plant, p) >= p.throw_clearance_m:
            return offset
        offset += CLEAR_STEP_M


def _trial(item: _Item) -> DynamicRun:
    kind, value, timestep_s, position, hold, p, arm_model, seed = item
    design = paper_arm_45cm()
    pen = kind == "pen"
    # The object's friction is the arm's: MuJoCo takes the larger of a pair's two coefficients, so a
    # contact-friction variant must change both.
    friction = arm_model.arm.geom_friction
    if pen:
        obj = target_object(p.pen_diameter_m / 2, p.pen_length_m, p.pen_mass_kg, friction)
    else:
        obj = target_object(p.object_diameter_m / 2, p.object_length_m, p.object_mass_kg, friction)
    # A step, not a ramp: the slew limiter opened, the ceiling at the 3 A current limit.
    fw = FirmwareConfig(mapping=MappingConfig(tension_max_n=54.0, slew_n_per_s=100_000.0))
    model = with_contact_timeconst(with_timestep(arm_model, timestep_s), p.contact_s)
    rig = direct_rig(design, fw, objects=(obj,), seed=seed, model=model)
    plant = rig.plant
    pre = fw.mapping.pretension_n
    base = np.array(world_m(0.0, 0.0))
    if pen:
        aim = _pen_aim(design, p)
        plant.hold_object(OBJ, world_m(*aim))
        rig.run(200 * MS)
        rig.set_tensions([value, pre, pre])
    else:
        plant.hold_object(OBJ)
        rig.set_tensions([p.hold_tension_n, pre, pre])
        rig.run(p.settle_ms * MS)
        if hold == "length":
            # +inf: hold cable 0 at the length it settled at; NaN: the others as they are.
            rig.command(CommandCode.HOLD_LENGTHS, math.inf, math.nan, math.nan)
            rig.run(HOLD_ENGAGE_MS * MS)
            if not rig.firmware.hold.held[0]:
                raise RuntimeError("the firmware did not engage the length-hold on cable 0")
        rng = np.random.default_rng((seed, position, round(value * 1000)))
        lo, hi = p.throw_band
        unit = round((lo + (hi - lo) * rng.random()) * (design.units - 1))
        target = plant.unit_poses()[0][unit]
        dz = p.throw_jitter_m * (2.0 * rng.random() - 1.0)
        aim = (float(target[0]), float(target[2] - base[2] + dz))
        offset = _clear_start_offset_m(plant, aim, p)
        plant.release_object(OBJ)
        # Upward by half the drop over the flight: the object crosses the aiming point's height.
        plant.set_object_velocity(OBJ, (-value, 0.0, 0.5 * G * offset / value))
    plant.reset_extremes()
    t0 = rig.now_us
    first = half = math.nan
    released_dist = math.nan
    trace: list[float] = []
    t = 0.0
    for _ in range(p.window_ms):
        rig.step()
        t = (rig.now_us - t0) / MS
        units = contact_units(plant, OBJ)
        wrap = contact_wrap_deg(plant, OBJ)
        trace.append(wrap)
        if units and math.isnan(first):
            first = t
        if math.isnan(half) and wrap >= HALF_WRAP_DEG and len(units) >= HALF_WRAP_UNITS:
            half = t if pen else t - first
            if pen:
                plant.release_object(OBJ)
                released_dist = float(np.linalg.norm(plant.object_pose(OBJ).pos_m - base))
    touching = bool(contact_units(plant, OBJ))
    end_dist = float(np.linalg.norm(plant.object_pose(OBJ).pos_m - base))
    extremes = plant.extremes()
    rig.close()
    toward = released_dist - end_dist
    if pen:
        success = touching and toward >= CARRIED_M
    else:
        success = not math.isnan(half) and half <= CAPTURE_MS and touching
    return DynamicRun(
        kind,
        value,
        timestep_s,
        position,
        hold if not pen else "",
        aim,
        first,
        half,
        max(trace, default=0.0),
        toward,
        touching,
        success,
        extremes,
        tuple(trace),
    )


def _items(p: DynamicParams, model: ModelConfig, seed: int) -> list[_Item]:
    """Every trial at the first physics step; the headline (largest step, throw 0 per speed) at the others."""
    items: list[_Item] = []
    top = max(p.step_tensions_n)
    for i, ts in enumerate(p.timesteps_s):
        items += [("pen", v, ts, 0, "", p, model, seed) for v in p.step_tensions_n if i == 0 or v == top]
        positions = range(p.throw_positions) if i == 0 else range(min(1, p.throw_positions))
        items += [
            ("throw", v, ts, j, h, p, model, seed)
            for h in p.holds
            for v in p.throw_speeds_m_s
            for j in positions
        ]
    return items


def arm_summary(model: ModelConfig) -> dict[str, float]:
    """The 45 cm arm's design and model figures, for the result."""
    d = paper_arm_45cm()
    return {
        "units": float(d.units),
        "length_m": d.length_m,
        "tip_width_m": d.tip_width_m,
        "base_width_m": d.base_width_m,
        "taper_deg": math.degrees(d.taper_rad),
        "mass_kg": model.arm.total_mass_kg,
        "base_stiffness_nm_per_rad": model.arm.base_stiffness_nm_per_rad,
    }


def dynamic(p: DynamicParams, on: Conditions) -> DynamicResult:
    """Fig. S11 on the paper's 45 cm 2-cable arm (:func:`~hil.trial.arm_45cm.paper_arm_45cm`), whatever
    ``on.design`` is.

    ``on.model`` is the plant model as set for the prototype (a preset or a sensitivity variant); its arm is
    scaled to the 45 cm arm (:func:`~hil.trial.arm_45cm.scaled_model`). ``on.seed`` seeds the board and the
    throws' jitter; progress counts trials.

    Raises:
        ValueError: a hold outside :data:`HOLDS`.
    """
    if not p.holds or not set(p.holds) <= set(HOLDS):
        raise ValueError(f"holds must be a non-empty subset of {HOLDS}, got {p.holds}")
    arm_model = scaled_model(on.model, paper_arm_45cm(), SpiralDesign.paper_prototype())
    runs = parallel_map(_trial, _items(p, arm_model, on.seed), on.jobs, on.progress)
    return DynamicResult(p, on.seed, arm_summary(arm_model), tuple(runs))


TINY = DynamicParams(
    step_tensions_n=(54.0,),
    throw_speeds_m_s=(2.0,),
    throw_positions=1,
    settle_ms=300,
    window_ms=150,
    timesteps_s=(0.00025, 0.000125),
)
"""The smoke-test size: one pen step, one throw per hold, at 0.25 and 0.125 ms (contacts 0.5 ms)."""

EXPERIMENT = Experiment(
    "dynamic",
    "45 cm arm: a current step grasps a pen; throws, one cable held at length or tension (Fig. S11)",
    Sizes(
        TINY,
        DynamicParams(),
        DynamicParams(
            step_tensions_n=(10.0, 20.0, 35.0, 54.0),
            throw_speeds_m_s=(0.5, 1.0, 2.0, 3.0, 4.0, 6.0),
            throw_positions=12,
        ),
    ),
    dynamic,
    own_arm="the paper's 45 cm 2-cable arm (Fig. S11)",
)
"""The dynamic experiment (:mod:`hil.experiments.catalogue`)."""


def _ms(x: float) -> str:
    return "never" if math.isnan(x) else f"{x:.0f} ms"


def _extremes(e: PhysicsExtremes) -> str:
    return (
        f"{1000 * e.penetration_m:.1f} mm ({100 * e.penetration_ratio:.0f} % of r), "
        f"{e.tension_n:.0f} N, {math.degrees(e.limit_overshoot_rad):.1f}°"
    )


def _hold_label(hold: str, p: DynamicParams) -> str:
    if hold == "length":
        return f"cable 0 held at length (settled at {p.hold_tension_n:g} N)"
    return f"cable 0 held at {p.hold_tension_n:g} N (stand-in)"


def _rate(k: int, n: int, lo: float, hi: float) -> str:
    return f"{k}/{n} (n/a)" if n == 0 else f"{k}/{n} ({100 * lo:.0f}-{100 * hi:.0f} %)"
