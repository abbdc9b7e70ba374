"""Benchmark of the MuJoCo plant (hil.sim.plant) at a 1 ms control period; prints its figures.

For the default 3-cable prototype and the authors' 24-unit design, with the stiff contacts and
stretching cable of issue 13 (wedge units, the default, and capsules) and with the old parameters
(``OLD_MODEL``): control periods per second and the real-time factor free-swinging, fully packed (every
joint limit active) and wrapping a cylinder; then a stability run of random cable currents up to the
current limit (no divergence allowed).

Arrays (issue 27): 1, 4 and 8 prototypes on a ring (``hil.sim.array``, the drives as MuJoCo dc motors,
the 1 ms step), hanging and with every cable pulled, against the lone arm in the same form; and the
project's ``Plant`` of 1, 2, 4, 6 and 8 one-cable arms (the Python drives, live capstan friction, feedback
frames), as a board for an array steps it, against its one arm.

Targets on a 2-core machine: free-swinging >= 10x real time, packed >= 3x (issue 3); with the stiff
contacts of issue 13, free-swinging >= 5x. Wall-clock figures depend on what else the machine runs, so the
CPU-time factor (this process only) is printed beside them.

Usage: ``.venv/bin/python bench/plant.py [--seconds 5] [--stability-seconds 60] [--seed 0] [--arrays]``
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

# Run as a script, this file's directory comes first on sys.path, where bench/protocol.py would shadow
# the protocol package; benchmarks import the project only.
_HERE = Path(__file__).resolve().parent
sys.path[:] = [p for p in sys.path if Path(p or ".").resolve() != _HERE]

import numpy as np  # noqa: E402

from hil.errors import PlantDivergedError  # noqa: E402
from hil.sim.config import ArmConfig, ContactConfig, ModelConfig, ObjectConfig  # noqa: E402
from hil.sim.plant import Plant  # noqa: E402
from hil.sim.spiral import SpiralDesign  # noqa: E402
from hil.sim.types import PlantConfig  # noqa: E402

OLD_MODEL = ModelConfig(
    arm=ArmConfig(cable_timeconst_s=0.002, unit_shape="capsule"),
    contact=ContactConfig(timeconst_s=0.02, damping_ratio=1.0, solimp=(0.9, 0.95, 0.001, 0.5, 2.0)),
)
"""The plant before issue 13: capsule units, MuJoCo's default contact (20 ms, solimp 0.9-0.95) and a
time-constant cable."""
CAPSULE_MODEL = ModelConfig(arm=ArmConfig(unit_shape="capsule"))
"""The stiff contacts and stretching cable with capsule units (the default has wedge-shaped units)."""
MODELS = (("stiff, wedge (default)", ModelConfig()), ("stiff, capsule", CAPSULE_MODEL), ("old", OLD_MODEL))


@dataclass(frozen=True)
class Figure:
    """One measured scenario."""

    label: str
    periods: int
    wall_s: float
    cpu_s: float
    sim_s: float
    mean_constraints: float

    @property
    def rtf_wall(self) -> float:
        return self.sim_s / self.wall_s

    @property
    def rtf_cpu(self) -> float:
        return self.sim_s / self.cpu_s


def measure(label: str, plant: Plant, seconds: float, each: Callable[[int], None] | None = None) -> Figure:
    """Step ``plant`` for ``seconds`` of simulated time, timing wall clock and CPU time."""
    periods = round(seconds * 1e6 / plant.control_period_us)
    data = plant.mj_data
    nefc = 0
    wall0, cpu0 = time.perf_counter(), time.process_time()
    for k in range(periods):
        if each is not None:
            each(k)
        plant.step()
        nefc += data.nefc
    wall, cpu = time.perf_counter() - wall0, time.process_time() - cpu0
    return Figure(label, periods, wall, cpu, periods * plant.control_period_us * 1e-6, nefc / periods)


def pole_of_packed_spiral(plant: Plant) -> tuple[float, float]:
    """(x, z) of the centre the arm curls around when cable 0 packs it (similarity fixed point)."""
    plant.set_packed(0)
    pos, _ = plant.unit_poses()
    pts = np.vstack([pos, plant.tip_pose().pos_m])
    z = pts[:, 0] + 1j * pts[:, 2]
    a = np.stack([z[:-1], np.ones(len(z) - 1)], axis=1)
    s, t = np.linalg.lstsq(a, z[1:], rcond=None)[0]
    pole = t / (1 - s)
    plant.reset()
    return float(pole.real), float(pole.imag)


def scenarios(name: str, design: SpiralDesign, seconds: float, model: ModelConfig) -> list[Figure]:
    config = PlantConfig(model=model)
    figures = []
    # Free-swinging: no current; released from the packed pose, the arm springs open and keeps swinging
    # under a drone that sways 10 cm at 1 Hz (pose and acceleration updated at 100 Hz, like a MAVLink feed).
    plant = Plant(design, config)
    plant.set_packed(0)
    home = plant.drone_pose().pos_m
    omega = 2 * math.pi * 1.0

    def sway(k: int) -> None:
        if k % 10 == 0:
            t = k * plant.control_period_us * 1e-6
            x = 0.1 * math.sin(omega * t)
            plant.set_drone_pose((home[0] + x, home[1], home[2]), accel_m_s2=(-omega * omega * x, 0.0, 0.0))

    figures.append(measure(f"{name}: free-swinging (swaying drone)", plant, seconds, sway))

    # Fully packed: one cable at 2.5 A curls the arm until every joint sits on its limit.
    plant = Plant(design, config)
    plant.apply_currents([2500] + [0] * (design.cables - 1))
    plant.run(1_000_000)
    limits = int(np.sum(np.abs(plant.joint_angles_rad()) > design.dtheta_rad - math.radians(0.5)))
    fig = measure(f"{name}: packed ({limits}/{design.joints} limits)", plant, seconds)
    figures.append(fig)

    # Wrapping a cylinder placed where the curling arm closes around it.
    probe = Plant(design, config)
    x, z = pole_of_packed_spiral(probe)
    plant = Plant(design, config)
    radius = design.d_min_m  # a cylinder twice the smallest graspable diameter
    plant.add_object(ObjectConfig("cylinder", radius_m=radius, length_m=0.1, pos_m=(x, 0.0, z)))
    plant.apply_currents([1500] + [0] * (design.cables - 1))
    plant.run(500_000)
    contacts = len(plant.contacts())
    figures.append(measure(f"{name}: wrapping a cylinder ({contacts} contacts)", plant, seconds))
    return figures


def stability(design: SpiralDesign, seconds: float, seed: int, model: ModelConfig) -> str:
    """Random setpoints up to the current limit, each held 50-300 ms; reports extremes, raises nothing."""
    plant = Plant(design, PlantConfig(model=model), rng=np.random.default_rng(seed))
    rng = np.random.default_rng(seed + 1)
    limit = round(plant.config.model.motor.current_limit_a * 1000)
    periods = round(seconds * 1e6 / plant.control_period_us)
    next_change = 0
    max_angle = 0.0
    max_tension = 0.0
    wall0 = time.perf_counter()
    try:
        for k in range(periods):
            if k >= next_change:
                plant.apply_currents([int(v) for v in rng.integers(-limit, limit + 1, size=design.cables)])
                next_change = k + int(rng.integers(50, 300))
            plant.step()
            if k % 10 == 0:
                max_angle = max(max_angle, float(np.max(np.abs(plant.joint_angles_rad()))))
                max_tension = max(max_tension, float(np.max(plant.cable_tensions_n())))
    except PlantDivergedError as exc:
        return f"DIVERGED after {exc.time_us / 1e6:.3f} s: {exc}"
    wall = time.perf_counter() - wall0
    over = math.degrees(max_angle - design.dtheta_rad)
    return (
        f"{seconds:.0f} s of random currents up to +-{limit / 1000:g} A: no divergence "
        f"({seconds / wall:.1f}x real time); largest joint angle {math.degrees(max_angle):.2f} deg "
        f"({over:+.2f} past the limit), largest cable tension {max_tension:.0f} N"
    )


def array_figures(seconds: float) -> list[str]:
    """Arrays of the prototype on a ring (``hil.sim.array``: each arm's drives as MuJoCo dc motors, the
    board physics' 1 ms step): the real-time factor hanging and with every cable pulled at 1.5 A, beside
    the lone arm's in the same model form (the baseline of the ratio)."""
    import mujoco

    from hil.sim.array import build_array_spec
    from hil.sim.types import RingConfig

    out = [f"  {'array (standalone drives, 1 ms step)':<70} {'bodies':>7} {'RTF wall':>9} {'RTF cpu':>8}"]
    base: float | None = None
    for arms in (1, 4, 8):
        m = build_array_spec(ring=RingConfig(arms=arms, ring_radius_m=0.08)).compile()
        for pulled in (False, True):
            d = mujoco.MjData(m)
            d.ctrl[:] = 1.5 if pulled else 0.0
            steps = max(1, round(seconds / m.opt.timestep))
            w0, c0 = time.perf_counter(), time.process_time()
            for _ in range(steps):
                mujoco.mj_step(m, d)
            wall, cpu = time.perf_counter() - w0, time.process_time() - c0
            rtf, rtf_cpu = steps * m.opt.timestep / wall, steps * m.opt.timestep / max(cpu, 1e-9)
            label = f"{arms} arm(s), {'every cable at 1.5 A' if pulled else 'hanging'}"
            ratio = ""
            if arms == 1 and pulled:
                base = rtf_cpu
            elif pulled and base:
                ratio = f"  (lone arm's cpu RTF / this: {base / rtf_cpu:.1f})"
            out.append(f"  {label:<70} {m.nbody:>7d} {rtf:>8.1f}x {rtf_cpu:>7.1f}x{ratio}")
    return out


def plant_array_figures(seconds: float) -> list[str]:
    """The ``Plant`` of an array of one-cable prototypes (``PlantConfig.ring``) at the board physics (1 ms),
    every cable at 1.5 A, feedback frames read every period as the board's bus does: real-time factor,
    and the cost against the one-arm ``Plant`` (the baseline, measured in the same run)."""
    import dataclasses

    from hil.sim.types import RingConfig

    design = dataclasses.replace(SpiralDesign.paper_prototype(), cables=1)
    out = [
        f"  {'Plant of one-cable arms (1 ms, board physics)':<70} {'motors':>7} {'RTF wall':>9} "
        f"{'RTF cpu':>8}"
    ]
    base: float | None = None
    for arms in (1, 2, 4, 6, 8):
        plant = Plant(design, PlantConfig(ring=RingConfig(arms=arms)))
        plant.apply_currents([1500] * arms + [0] * (-arms % 4))
        periods = max(1, round(seconds * 1000))
        w0, c0 = time.perf_counter(), time.process_time()
        for _ in range(periods):
            plant.step()
            plant.feedback_payloads()
        wall, cpu = time.perf_counter() - w0, time.process_time() - c0
        rtf, rtf_cpu = periods * 1e-3 / wall, periods * 1e-3 / max(cpu, 1e-9)
        ratio = ""
        if arms == 1:
            base = rtf_cpu
        elif base:
            ratio = f"  (one arm's cpu RTF / this: {base / rtf_cpu:.1f})"
        out.append(
            f"  {f'{arms} arm(s), every cable at 1.5 A':<70} {plant.motors:>7d} {rtf:>8.1f}x "
            f"{rtf_cpu:>7.1f}x{ratio}"
        )
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=5.0, help="simulated seconds per scenario")
    parser.add_argument("--stability-seconds", type=float, default=60.0, help="length of the stability run")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--arrays", action="store_true", help="only the arrays' figures")
    args = parser.parse_args(argv)
    if args.arrays:
        for line in array_figures(args.seconds) + plant_array_figures(args.seconds):
            print(line)
        return 0

    probe = Plant()
    sol = probe.config.model.solver
    m = probe.mj_model
    print("SpiRob plant benchmark (hil.sim.plant)")
    print(
        f"  solver: integrator={sol.integrator} timestep={sol.timestep_s * 1e3:g} ms "
        f"({probe.substeps} step(s) per {probe.control_period_us} us control period), solver={sol.solver} "
        f"iterations={sol.iterations} ls_iterations={sol.ls_iterations} tolerance={sol.tolerance:g} "
        f"cone={sol.cone}"
    )
    print(f"  default model: {m.nbody} bodies, nq={m.nq}, nv={m.nv}, {m.ntendon} cables, {m.nu} motors")
    print()
    print(f"  {'scenario':<70} {'periods/s':>10} {'RTF wall':>9} {'RTF cpu':>8} {'rows':>6}")
    for name, design in (
        ("prototype", SpiralDesign.paper_prototype()),
        ("authors", SpiralDesign.authors_default()),
    ):
        for label, model in MODELS:
            for fig in scenarios(f"{name} {label}", design, args.seconds, model):
                print(
                    f"  {fig.label:<70} {fig.periods / fig.wall_s:>10.0f} {fig.rtf_wall:>8.1f}x "
                    f"{fig.rtf_cpu:>7.1f}x {fig.mean_constraints:>6.0f}"
                )
    print()
    for line in array_figures(args.seconds):
        print(line)
    for line in plant_array_figures(args.seconds):
        print(line)
    print()
    design = SpiralDesign.paper_prototype()
    for label, model in MODELS:
        print(
            f"  stability (prototype {label}): {stability(design, args.stability_seconds, args.seed, model)}"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
