"""The plant model's configs (hil.model_config): validated alone, shared with the firmware."""

from __future__ import annotations

import math

import pytest

from controller.config import MotorDriveConfig
from hil.model_config import ArmConfig, DroneConfig, ModelConfig, MotorConfig, ObjectConfig, SolverConfig


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
        (ObjectConfig("pole", 0.01, 0.1, (0, 0, 1), shape="box"), "shape"),
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
