"""Model presets (hil.sim.presets) and the models they select: actuators, mountings, stiffness."""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest

from hil.scenarios import run_scenario
from hil.sim.config import ActuatorConfig, ModelConfig
from hil.sim.mjcf import build_mjcf, unit_geometry
from hil.sim.plant import Plant
from hil.sim.presets import PRESETS, preset, preset_names
from hil.sim.spiral import PAPER_PROTOTYPE, SpiralDesign
from hil.sim.types import PlantConfig

TWO_CABLES = PAPER_PROTOTYPE.with_cables(2)


def plant_with(model: ModelConfig, design: SpiralDesign = TWO_CABLES) -> Plant:
    return Plant(design, PlantConfig(model=model))


@pytest.mark.parametrize("name", preset_names())
def test_every_preset_builds_and_loads(name: str) -> None:
    chosen = PRESETS[name]
    design = SpiralDesign.preset(chosen.design_preset)
    if chosen.cables is not None:
        design = design.with_cables(chosen.cables)
    m = mujoco.MjModel.from_xml_string(build_mjcf(design, None, preset(name)))
    assert m.nu == design.cables
    assert chosen.source and chosen.summary


def test_prototype_is_the_default_and_authors_mirrors_the_generator() -> None:
    assert preset_names()[0] == "prototype"
    assert preset("prototype") == ModelConfig()
    authors = preset("authors")
    assert authors.actuator.kind == "muscle" and authors.muscle_force_n == 5.0
    assert authors.actuator.friction_n == 0.1
    assert authors.arm.stiffness_exponent == 2 and authors.arm.base_stiffness_nm_per_rad == 0.04
    assert authors.mounting == "gravity-off"
    assert PRESETS["authors"].design_preset == "authors"


def test_unknown_preset_is_a_clear_error() -> None:
    with pytest.raises(ValueError, match="unknown model preset 'nope'; choose from prototype, authors"):
        preset("nope")


@pytest.mark.parametrize("kind", ["motor", "tension", "muscle"])
def test_each_actuator_pulls_its_cable_and_reports_it_like_a_c610(kind: str) -> None:
    model = ModelConfig(actuator=ActuatorConfig(kind=kind))
    plant = plant_with(model)
    fpa = model.motor.force_per_amp_n
    plant.apply_currents([1000, 0])  # 1 A on cable 0: asks for 18 N
    plant.run(300_000)
    tension = plant.cable_tensions_n()
    assert tension[0] > 5.0 and tension[1] < 0.5  # cable 0 pulls, the other goes slack
    assert plant.spool_angles_rad()[0] > 0.0  # wound in: the rotor angle rises
    assert plant.joint_angles_rad()[-1] < -0.4  # the arm curls towards cable 0 (tip first)
    # The fed-back current is the delivered force over the firmware's force per amp; at rest that force
    # holds the cable within the actuator's friction.
    fed_back_a = plant.feedback()[0].current / 1000.0
    assert fed_back_a == pytest.approx(plant.applied_currents_a()[0], abs=1e-3)
    friction_n = model.motor.friction_force_n if kind == "motor" else model.actuator.friction_n
    assert fed_back_a * fpa == pytest.approx(tension[0], abs=friction_n + 0.5)
    if kind != "muscle":  # a muscle gives less than asked away from its optimal length
        assert fed_back_a == pytest.approx(1.0, abs=0.01)


@pytest.mark.parametrize("kind", ["tension", "muscle"])
def test_light_actuators_cannot_push(kind: str) -> None:
    plant = plant_with(ModelConfig(actuator=ActuatorConfig(kind=kind)))
    plant.apply_currents([-3000, -3000])
    plant.run(100_000)
    assert plant.applied_currents_a().tolist() == [0.0, 0.0]
    assert [fb.current for fb in plant.feedback()] == [0, 0]


def test_tension_lag_time_constant_is_measured_in_a_step_response() -> None:
    lag_s = 0.01
    plant = plant_with(ModelConfig(actuator=ActuatorConfig(kind="tension", lag_s=lag_s)))
    plant.apply_currents([1000, 1000])
    delivered = []
    for _ in range(30):
        plant.step()
        delivered.append(plant.applied_currents_a()[0])
    # Sample k is the force of step k + 1, which MuJoCo computes from the state after k steps.
    t_s = np.arange(1, 30) * 1e-3
    tau_s = -t_s / np.log1p(-np.array(delivered[1:]))
    assert tau_s == pytest.approx(lag_s, rel=1e-3)
    assert delivered[10] == pytest.approx(1.0 - math.exp(-1.0), abs=1e-3)  # 63 % after one τ


def test_gravity_off_really_removes_gravity() -> None:
    sideways = (math.cos(math.pi / 4), 0.0, math.sin(math.pi / 4), 0.0)  # the arm horizontal
    bent = {}
    for mounting in ("hanging", "gravity-off"):
        plant = plant_with(ModelConfig(mounting=mounting))
        plant.set_drone_pose((0.0, 0.0, 1.0), sideways, accel_m_s2=(0.0, 0.0, 5.0))
        plant.run(500_000)
        bent[mounting] = float(np.abs(plant.joint_angles_rad()).max())
        if mounting == "gravity-off":
            assert plant.mj_model.opt.gravity.tolist() == [0.0, 0.0, 0.0]  # no drone acceleration either
    assert bent["hanging"] > math.radians(1.0)  # its weight bends the horizontal arm
    assert bent["gravity-off"] < 1e-9


def test_table_keeps_the_arm_on_the_table() -> None:
    """A 3-cable arm (ball joints, free to droop) lies on the table and curls in the horizontal plane."""
    design = PAPER_PROTOTYPE
    plant = plant_with(ModelConfig(mounting="table"), design)
    geo = unit_geometry(design)
    table_z = 1.0 - 0.5 * geo.width_base_side_m[0]
    radii = np.array([geo.capsule_radius_m(i) for i in range(design.units)])

    def lowest_above_table_m() -> float:
        # Each capsule's lowest point: its axis' lowest end minus its radius.
        pos, _ = plant.unit_poses()
        ends = np.append(pos[1:, 2], plant.tip_pose().pos_m[2])
        return float((np.minimum(pos[:, 2], ends) - radii - table_z).min())

    plant.run(600_000)
    assert -1e-3 < lowest_above_table_m() < 1e-3  # resting on it, not sinking in
    assert any(c.other == "world" for c in plant.contacts())
    plant.apply_currents([1500, 0, 0])
    plant.run(1_000_000)
    assert np.degrees(plant.joint_angles_rad()).min() > 25.0  # curled
    assert lowest_above_table_m() > -1e-3
    assert abs(plant.tip_pose().pos_m[2] - 1.0) < 0.02  # the curl stays in the horizontal plane


def test_authors_preset_runs_the_virtual_board() -> None:
    chosen = PRESETS["authors"]
    result = run_scenario(
        "startup-gate", design=SpiralDesign.preset(chosen.design_preset), model=chosen.model
    )
    assert result.passed, [c for c in result.checks if not c.passed]
