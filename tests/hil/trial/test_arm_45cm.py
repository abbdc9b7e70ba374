"""The 45 cm arm of Fig. S11 and the model scaled to it (hil.trial.arm_45cm)."""

from __future__ import annotations

import math

import pytest

from hil.sim.config import ModelConfig
from hil.sim.spiral import SpiralDesign
from hil.trial.arm_45cm import paper_arm_45cm, scaled_model, with_contact_timeconst, with_timestep


def test_the_45cm_arm_is_the_papers_two_cable_arm() -> None:
    d = paper_arm_45cm()
    assert d.cables == 2
    assert d.units == 24
    assert abs(d.length_m - 0.45) < 0.02  # 0.45 m rounded to whole 30° units
    assert d.tip_width_m == pytest.approx(0.010)
    assert math.degrees(d.taper_rad) == pytest.approx(10.0)


def test_scaling_to_the_prototype_itself_changes_nothing_and_grows_with_size() -> None:
    proto = SpiralDesign.paper_prototype()
    m = ModelConfig()
    assert scaled_model(m, proto, proto) == m
    big = scaled_model(m, paper_arm_45cm(), proto)
    # base joint about 2.8 times as wide: stiffness x its cube; mass x the volume ratio (> 10)
    assert big.arm.base_stiffness_nm_per_rad / m.arm.base_stiffness_nm_per_rad == pytest.approx(
        (paper_arm_45cm().unit_widths_m()[0][1] / proto.unit_widths_m()[0][1]) ** 3
    )
    assert big.arm.total_mass_kg > 10 * m.arm.total_mass_kg
    assert big.arm.damping_ratio == m.arm.damping_ratio and big.motor == m.motor
    assert with_timestep(m, 0.00025).solver.timestep_s == 0.00025
    assert with_contact_timeconst(m, 0.0005).contact.timeconst_s == 0.0005
