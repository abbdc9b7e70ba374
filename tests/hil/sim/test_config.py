"""The plant model's configs (hil.sim.config): validated alone, shared with the firmware."""

from __future__ import annotations

import dataclasses
import math

import pytest

from controller.config import MotorDriveConfig
from hil.sim.config import (
    ArmConfig,
    ContactConfig,
    DroneConfig,
    ModelConfig,
    MotorConfig,
    ObjectConfig,
    SolverConfig,
)


def test_defaults_are_valid_and_the_motor_shares_the_firmware_drive_constants() -> None:
    ModelConfig().validate()
    drive, motor = MotorDriveConfig(), MotorConfig()
    assert motor.torque_constant_nm_per_a == drive.torque_constant_nm_per_a
    assert motor.gear_ratio == drive.gear_ratio
    assert motor.spool_radius_m == drive.spool_radius_m
    assert motor.force_per_amp_n == pytest.approx(drive.torque_constant_nm_per_a / drive.spool_radius_m)


@pytest.mark.parametrize(
    ("config", "match"),
    [
        (ArmConfig(damping_ratio=math.nan), "damping_ratio"),
        (MotorConfig(temperature_c=300), "temperature_c"),
        (DroneConfig(half_size_m=(0.1, 0.0, 0.1)), "half_size_m"),
        (SolverConfig(cone="round"), "cone"),
        (ObjectConfig("pole", 0.01, 0.1, (0, 0, 1), shape="torus"), "shape"),
        (
            ModelConfig(objects=(ObjectConfig("a", 0.01, 0.1, (0, 0, 0), mass_kg=0.1),)).with_objects(
                ObjectConfig("a_support", 0.01, 0.1, (0, 0, 1))
            ),
            "support",
        ),
    ],
)
def test_out_of_range_values_are_refused(
    config: ArmConfig | MotorConfig | DroneConfig | SolverConfig | ObjectConfig | ModelConfig, match: str
) -> None:
    with pytest.raises(ValueError, match=match):
        config.validate()


def test_with_objects_appends() -> None:
    pole = ObjectConfig("pole", 0.01, 0.3, (0.0, 0.0, 0.5))
    cup = ObjectConfig("cup", 0.03, 0.08, (0.1, 0.0, 0.5), mass_kg=0.05)
    config = ModelConfig().with_objects(pole).with_objects(cup)
    assert config.objects == (pole, cup)
    config.validate()


@pytest.mark.parametrize(
    ("config", "match"),
    [
        (ModelConfig(contact=ContactConfig(timeconst_s=0.0015)), "contact.timeconst_s = 1.5 ms"),
        (ModelConfig(arm=ArmConfig(limit_timeconst_s=0.001)), "arm.limit_timeconst_s"),
        (
            ModelConfig(contact=ContactConfig(timeconst_s=0.0008), solver=SolverConfig(timestep_s=0.0005)),
            "at least twice the physics step",
        ),
    ],
)
def test_a_time_constant_under_two_physics_steps_is_refused(config: ModelConfig, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        config.validate()


def test_a_short_time_constant_is_fine_with_a_short_step() -> None:
    ModelConfig(contact=ContactConfig(timeconst_s=0.0005), solver=SolverConfig(timestep_s=0.00025)).validate()


@pytest.mark.parametrize(
    ("contact", "match"),
    [
        (ContactConfig(timeconst_s=0.0), "timeconst_s"),
        (ContactConfig(damping_ratio=-1.0), "damping_ratio"),
        (ContactConfig(solimp=(0.99, 0.9, 0.001, 0.5, 2.0)), "dmin <= dmax"),
        (ContactConfig(solimp=(0.9, 0.95, 0.001, 0.5)), "5 finite numbers"),  # type: ignore[arg-type]
    ],
)
def test_contact_config_rejects_bad_values(contact: ContactConfig, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        contact.validate()


def test_the_cable_axial_stiffness_is_e_times_the_fibre_area() -> None:
    arm = ArmConfig()
    assert arm.cable_axial_stiffness_n == pytest.approx(109e9 * 0.5 * math.pi * 0.00025**2)
    with pytest.raises(ValueError, match="cable_fill_factor"):
        ArmConfig(cable_fill_factor=1.5).validate()


def test_with_physics_sets_the_step_and_the_stiffest_constraints_it_allows() -> None:
    fine = ModelConfig().with_physics(0.25e-3)
    fine.validate()
    assert fine.solver.timestep_s == 0.25e-3
    assert fine.contact.timeconst_s == fine.arm.limit_timeconst_s == 0.5e-3
    # nothing else changes
    assert (
        dataclasses.replace(
            fine, solver=ModelConfig().solver, contact=ModelConfig().contact, arm=ModelConfig().arm
        )
        == ModelConfig()
    )
    with pytest.raises(ValueError, match="at least twice the physics step"):
        dataclasses.replace(fine, solver=dataclasses.replace(fine.solver, timestep_s=1e-3)).validate()


def test_experiments_run_fine_physics_but_convergence_the_boards() -> None:
    from hil.experiments.catalogue import EXPERIMENTS
    from hil.experiments.common import BOARD_MODEL

    for name, exp in EXPERIMENTS.items():
        expected = BOARD_MODEL if name == "convergence" else BOARD_MODEL.with_physics(0.25e-3)
        assert exp.model == expected, name
