"""The plant's value types and vector checks (hil.sim.types), importable without MuJoCo."""

from __future__ import annotations

import math

import numpy as np
import pytest

from hil.sim.types import PlantConfig, finite_vector, unit_quat


def test_plant_config_validates() -> None:
    PlantConfig().validate()
    for bad in (
        PlantConfig(control_period_us=0),
        PlantConfig(control_period_us=True),
        PlantConfig(max_joint_speed_rad_s=math.nan),
        PlantConfig(max_spool_speed_m_s=-1.0),
    ):
        with pytest.raises(ValueError):
            bad.validate()


def test_vectors_and_quaternions_are_checked() -> None:
    assert finite_vector("p", (1, 2, 3), 3).tolist() == [1.0, 2.0, 3.0]
    with pytest.raises(ValueError, match="p must be 3 finite numbers"):
        finite_vector("p", (1.0, math.inf, 0.0), 3)
    with pytest.raises(ValueError):
        finite_vector("p", (1.0, 2.0), 3)
    assert np.allclose(unit_quat((2.0, 0.0, 0.0, 0.0)), (1.0, 0.0, 0.0, 0.0))
    with pytest.raises(ValueError, match="non-zero"):
        unit_quat((0.0, 0.0, 0.0, 0.0))
