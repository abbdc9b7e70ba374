"""FirmwareConfig: defaults, validation with messages, from_dict, runtime parameters by wire name."""

from __future__ import annotations

import dataclasses

import pytest

from controller.config import (
    FailsafeConfig,
    FirmwareConfig,
    GraspConfig,
    HoldConfig,
    MappingConfig,
    MotorDriveConfig,
)
from controller.errors import ConfigError


def test_defaults_are_the_documented_facts() -> None:
    c = FirmwareConfig()
    assert (
        c.motor.spool_radius_m,
        c.motor.torque_constant_nm_per_a,
        c.motor.gear_ratio,
        c.motor.current_limit_a,
    ) == (
        0.010,
        0.18,
        36.0,
        3.0,
    )
    assert (c.failsafe.rc_timeout_us, c.failsafe.motor_timeout_us, c.failsafe.host_timeout_us) == (
        30_000,
        10_000,
        500_000,
    )
    assert c.motor.current_limit_raw == 3000


@pytest.mark.parametrize(
    ("field", "value", "match"),
    [
        ("current_limit_a", 11.0, "current_limit_a"),
        ("spool_radius_m", 0.0, "spool_radius_m"),
        ("pretension_n", 30.0, "pretension_n"),
        ("detect_period_us", 1500, "whole number"),
        ("motor_signs", (1, 0, 1), "motor_signs"),
        ("grasp_reach_n", 9.0, "grasp_reach_n"),
        ("control_period_us", 1.5, "expected int"),
        ("host_required", 1, "expected bool"),
    ],
)
def test_invalid_values_raise_config_error_naming_the_field(field: str, value: object, match: str) -> None:
    with pytest.raises(ConfigError, match=match):
        FirmwareConfig().replaced(**{field: value})  # type: ignore[arg-type]
    assert issubclass(ConfigError, ValueError)


def test_from_dict_coerces_and_rejects_unknown_keys() -> None:
    c = FirmwareConfig.from_dict(
        {"cable_angles_deg": [0, 120, 240], "rc_timeout_us": 30000.0, "pretension_n": 1}
    )
    assert (
        c.mapping.cable_angles_deg == (0.0, 120.0, 240.0)
        and c.failsafe.rc_timeout_us == 30000
        and c.mapping.pretension_n == 1.0
    )
    with pytest.raises(ConfigError, match="unknown"):
        FirmwareConfig.from_dict({"spool_radius": 0.01})
    assert FirmwareConfig.from_dict(FirmwareConfig().to_dict()) == FirmwareConfig()


def test_with_param_validates_and_converts() -> None:
    c = FirmwareConfig()
    assert c.with_param("PRETENSION_N", 1.5).mapping.pretension_n == 1.5
    assert c.with_param("HOST_REQUIRED", 1.0).failsafe.host_required is True
    assert c.with_param("HOST_TIMEOUT_US", 250000.0).failsafe.host_timeout_us == 250000
    assert c.get_param("GRASP_STRATEGY") == 1.0
    for name, value in [
        ("PRETENSION_N", -1.0),
        ("HOST_REQUIRED", 0.5),
        ("HOST_TIMEOUT_US", 1.5),
        ("CURRENT_LIMIT_A", float("nan")),
        ("NOPE", 1.0),
    ]:
        with pytest.raises(ConfigError):
            c.with_param(name, value)


def test_sections_group_the_fields_and_the_flat_form_names_every_one() -> None:
    c = FirmwareConfig(
        failsafe=FailsafeConfig(host_required=True), grasp=GraspConfig(pack_n=16.0), mapping=MappingConfig()
    )
    flat = c.to_dict()
    assert flat["host_required"] is True and flat["grasp_pack_n"] == 16.0
    leaves = sum(
        len(dataclasses.fields(section))
        for section in (MotorDriveConfig, MappingConfig, FailsafeConfig, GraspConfig, HoldConfig)
    ) + sum(1 for f in dataclasses.fields(FirmwareConfig) if not dataclasses.is_dataclass(getattr(c, f.name)))
    assert len(flat) == leaves  # every leaf once (sections are not leaves)
    assert list(flat)[:3] == ["control_period_us", "link_period_us", "detect_period_us"]
    assert c.replaced(pretension_n=1.0).mapping.pretension_n == 1.0
    with pytest.raises(ConfigError, match="unknown"):
        c.replaced(pack_n=1.0)  # a grasp field's flat name is grasp_pack_n
    with pytest.raises(ConfigError, match="grasp_pack_n"):
        FirmwareConfig(grasp=GraspConfig(pack_n=30.0))  # sections are validated inside the whole
