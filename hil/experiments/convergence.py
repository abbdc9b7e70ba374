"""convergence: the plant's headline numbers at 1, 0.5 and 0.25 ms physics steps, side by side.

Each number is measured on the bare plant (currents straight to the drives, no firmware), so only the
physics step differs between the columns:

- **packing**: cable 0's current ramped slowly; the tension at which every joint reaches its limit.
- **pen**: a 5 mm-radius pen on its support beside the tip, a 3 A (54 N) step on cable 0: time to a half
  wrap, the largest penetration while wrapping (the first 300 ms) and while pressing (the rest).
- **throw**: a 10 mm-radius object thrown at the hanging arm at each speed: the largest penetration.
- **random**: random currents up to the limit, each held 50-300 ms: the largest tension and limit overshoot.

If the 1 ms column agrees with the 0.25 ms one, figures measured at the default step can be trusted.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from hil.experiments.base import Conditions, Experiment, Sizes
from hil.experiments.common import BOARD_MODEL, Row, extremes_rows, pyplot, save_figure, worst_extremes
from hil.experiments.parallel import parallel_map
from hil.sim.config import ModelConfig, ObjectConfig
from hil.sim.objects import contact_units, contact_wrap_deg
from hil.sim.plant import Plant
from hil.sim.spiral import SpiralDesign
from hil.sim.types import PhysicsExtremes, PlantConfig
from hil.trial.scene import MS, OBJ, target_object, world_m


@dataclass(frozen=True)
class ConvergenceParams:
    """Attributes:
    timesteps_s: the physics steps compared (the control period stays 1 ms).
    ramp_ms: how long cable 0's current takes to rise from 0 to ``ramp_to_a`` (packing).
    ramp_to_a: the end of the packing ramp.
    pen: ``(x, z)`` of the pen's centre relative to the base (beside the hanging arm, near its tip).
    pen_radius_m, pen_mass_kg: the pen (as in the ``dynamic`` experiment).
    step_a: the current step on cable 0 (3 A = 54 N).
    pen_ms: how long the pen run lasts; the first 300 ms are its wrap, the rest its press.
    throw_speeds_m_s: speeds of the thrown object.
    throw_ms: how long each throw is watched.
    random_ms: length of the random-current run.
    """

    timesteps_s: tuple[float, ...] = (0.001, 0.0005, 0.00025)
    ramp_ms: int = 3000
    ramp_to_a: float = 2.0
    pen: tuple[float, float] = (0.02, -0.17)
    pen_radius_m: float = 0.005
    pen_mass_kg: float = 0.015
    step_a: float = 3.0
    pen_ms: int = 600
    throw_speeds_m_s: tuple[float, ...] = (1.0, 2.0, 3.0, 4.0)
    throw_ms: int = 300
    random_ms: int = 10_000


WRAP_MS = 300
"""The first part of the pen run counts as wrapping, the rest as pressing."""


@dataclass(frozen=True)
class StepFigures:
    """The headline numbers at one physics step (NaN where the event never happened)."""

    timestep_s: float
    packing_tension_n: float
    pen_half_wrap_ms: float
    wrap_penetration_m: float
    press_penetration_m: float
    press_penetration_ratio: float
    throw_penetration_m: tuple[float, ...]
    random_tension_n: float
    random_overshoot_rad: float


@dataclass(frozen=True)
class ConvergenceResult:
    """Every step's numbers (a :class:`~hil.experiments.base.Result`)."""

    params: ConvergenceParams
    seed: int
    steps: tuple[StepFigures, ...]

    @property
    def extremes(self) -> PhysicsExtremes:
        """The worst over every step: the pen's and the throws' penetration, the random runs' tension and
        overshoot (the throws' object has a 10 mm radius)."""
        pen_r = self.params.pen_radius_m
        return worst_extremes(
            PhysicsExtremes(
                max(s.wrap_penetration_m, s.press_penetration_m, *s.throw_penetration_m),
                max(
                    s.wrap_penetration_m / pen_r,
                    s.press_penetration_ratio,
                    *(t / 0.01 for t in s.throw_penetration_m),
                ),
                s.random_tension_n,
                s.random_overshoot_rad,
            )
            for s in self.steps
        )

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready form (SI units)."""
        return {
            "experiment": "convergence",
            "seed": self.seed,
            "steps": [dataclasses.asdict(s) for s in self.steps],
            "extremes": self.extremes.as_dict(),
            "params": dataclasses.asdict(self.params),
        }

    def table_rows(self) -> list[Row]:
        """One row per number: its values at every step side by side (the paper has none of these)."""
        steps = self.steps
        head = " | ".join(f"{s.timestep_s * 1e3:g} ms" for s in steps)
        rows: list[Row] = [("physics step", head, "")]

        def row(name: str, fmt: Any, values: list[float]) -> None:
            rows.append((name, " | ".join(fmt(v) for v in values), ""))

        row("packing tension, cable 0", lambda v: f"{v:.1f} N", [s.packing_tension_n for s in steps])
        row(f"pen, {self.params.step_a:g} A step -> half wrap", _ms, [s.pen_half_wrap_ms for s in steps])
        row("pen penetration while wrapping", _mm, [s.wrap_penetration_m for s in steps])
        row("pen penetration while pressing", _mm, [s.press_penetration_m for s in steps])
        for i, v in enumerate(self.params.throw_speeds_m_s):
            row(f"throw at {v:g} m/s: penetration", _mm, [s.throw_penetration_m[i] for s in steps])
        row("random currents: largest tension", lambda v: f"{v:.0f} N", [s.random_tension_n for s in steps])
        row(
            "random currents: limit overshoot",
            lambda v: f"{math.degrees(v):.2f}°",
            [s.random_overshoot_rad for s in steps],
        )
        rows.extend(extremes_rows(self.extremes))
        return rows

    def describe_samples(self) -> str:
        """Physics steps and the runs at each, in words."""
        p = self.params
        return (
            f"{len(self.steps)} physics steps; per step a {p.ramp_ms} ms ramp, a {p.pen_ms} ms pen run, "
            f"{len(p.throw_speeds_m_s)} throws of {p.throw_ms} ms, "
            f"{p.random_ms / 1000:g} s of random currents"
        )

    def figure(self, out: Path) -> Path:
        """Penetration against the physics step (one line per measurement); returns ``convergence.png``."""
        plt = pyplot()
        fig, ax = plt.subplots(figsize=(6, 4))
        h = [s.timestep_s * 1e3 for s in self.steps]
        ax.plot(h, [s.wrap_penetration_m * 1e3 for s in self.steps], "o-", label="pen, wrapping")
        ax.plot(h, [s.press_penetration_m * 1e3 for s in self.steps], "s-", label="pen, pressing")
        for i, v in enumerate(self.params.throw_speeds_m_s):
            ax.plot(h, [s.throw_penetration_m[i] * 1e3 for s in self.steps], "^--", label=f"throw {v:g} m/s")
        ax.axhline(1.0, color="r", ls=":", lw=0.8, label="goal: 1 mm")
        ax.set_xscale("log")
        ax.set_xlabel("physics step [ms]")
        ax.set_ylabel("largest penetration [mm]")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
        return save_figure(fig, out / "convergence.png")


def _plant(model: ModelConfig, seed: int, *objects: ObjectConfig) -> Plant:
    if objects:
        model = model.with_objects(*objects)
    return Plant(SpiralDesign.paper_prototype(), PlantConfig(model=model), rng=np.random.default_rng(seed))


def _amps(plant: Plant, cable0_a: float) -> list[int]:
    return [round(cable0_a * 1000)] + [0] * (plant.cables - 1)


def packing_tension_n(p: ConvergenceParams, model: ModelConfig, seed: int) -> float:
    """Cable 0's tension when the last joint reaches its limit on a slow current ramp (NaN: never)."""
    plant = _plant(model, seed)
    limit = plant.design.dtheta_rad - math.radians(0.5)
    for k in range(p.ramp_ms):
        plant.apply_currents(_amps(plant, p.ramp_to_a * (k + 1) / p.ramp_ms))
        plant.step()
        if bool(np.all(np.abs(plant.joint_angles_rad()) >= limit)):
            return float(plant.cable_tensions_n()[0])
    return math.nan


def pen_figures(p: ConvergenceParams, model: ModelConfig, seed: int) -> tuple[float, float, float, float]:
    """Half-wrap time [ms], wrap penetration [m], press penetration [m] and its ratio to the radius."""
    pen = target_object(p.pen_radius_m, 0.14, p.pen_mass_kg)
    plant = _plant(model, seed, pen)
    plant.hold_object(OBJ, world_m(*p.pen))
    plant.run(200 * MS)
    plant.reset_extremes()
    plant.apply_currents(_amps(plant, p.step_a))
    half = math.nan
    for k in range(p.pen_ms):
        plant.step()
        if k + 1 == WRAP_MS:
            wrap = plant.extremes().penetration_m
            plant.reset_extremes()
        if math.isnan(half) and len(contact_units(plant, OBJ)) >= 3 and contact_wrap_deg(plant, OBJ) >= 180:
            half = float(k + 1)
    press = plant.extremes()
    return half, wrap, press.penetration_m, press.penetration_ratio


def throw_penetration_m(p: ConvergenceParams, model: ModelConfig, seed: int, speed_m_s: float) -> float:
    """Largest penetration of a 10 mm-radius, 10 g object thrown at the hanging arm."""
    obj = target_object(0.01, 0.06, 0.01)
    plant = _plant(model, seed, obj)
    plant.hold_object(OBJ)
    plant.run(300 * MS)
    plant.hold_object(OBJ, world_m(0.04, -0.12))
    plant.release_object(OBJ)
    plant.set_object_velocity(OBJ, (-speed_m_s, 0.0, 0.3))
    plant.reset_extremes()
    plant.run(p.throw_ms * MS)
    return plant.extremes().penetration_m


def random_extremes(p: ConvergenceParams, model: ModelConfig, seed: int) -> tuple[float, float]:
    """Largest tension [N] and limit overshoot [rad] under random currents up to the limit."""
    plant = _plant(model, seed)
    rng = np.random.default_rng(seed + 1)
    limit = round(plant.config.model.motor.current_limit_a * 1000)
    next_change = 0
    for k in range(p.random_ms):
        if k >= next_change:
            plant.apply_currents([int(v) for v in rng.integers(-limit, limit + 1, size=plant.cables)])
            next_change = k + int(rng.integers(50, 300))
        plant.step()
    e = plant.extremes()
    return e.tension_n, e.limit_overshoot_rad


def _one_step(args: tuple[ConvergenceParams, ModelConfig, float, int]) -> StepFigures:
    p, model, h, seed = args
    at_h = dataclasses.replace(model, solver=dataclasses.replace(model.solver, timestep_s=h))
    half, wrap, press, ratio = pen_figures(p, at_h, seed)
    throws = tuple(throw_penetration_m(p, at_h, seed, v) for v in p.throw_speeds_m_s)
    tension, over = random_extremes(p, at_h, seed)
    return StepFigures(h, packing_tension_n(p, at_h, seed), half, wrap, press, ratio, throws, tension, over)


def convergence(p: ConvergenceParams, on: Conditions) -> ConvergenceResult:
    """Measure the headline numbers at each physics step (one step per job) on the prototype (whatever
    ``on.design`` is: the numbers are the plant's, not a design's), on ``on.model`` with only its physics
    step changed: the constraints' time constants stay the model's."""
    items = [(p, on.model, h, on.seed) for h in p.timesteps_s]
    return ConvergenceResult(p, on.seed, tuple(parallel_map(_one_step, items, on.jobs, on.progress)))


def _ms(x: float) -> str:
    return "never" if math.isnan(x) else f"{x:.0f} ms"


def _mm(x: float) -> str:
    return f"{x * 1000:.2f} mm"


EXPERIMENT = Experiment(
    "convergence",
    "packing tension, a pen's half wrap, penetration and tension extremes at 1, 0.5, 0.25 ms steps",
    Sizes(
        ConvergenceParams(
            timesteps_s=(0.001, 0.0005),
            ramp_ms=300,
            pen_ms=WRAP_MS + 20,
            throw_speeds_m_s=(3.0,),
            throw_ms=60,
            random_ms=300,
        ),
        ConvergenceParams(),
        ConvergenceParams(throw_speeds_m_s=(1.0, 2.0, 3.0, 4.0, 6.0), random_ms=60_000),
    ),
    convergence,
    # the board's model: only the step changes between the columns, and its 2 ms constraints allow 1 ms
    BOARD_MODEL,
    own_arm="the prototype",
)
"""The convergence experiment (:mod:`hil.experiments.catalogue`)."""
