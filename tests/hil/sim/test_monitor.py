"""The plant's physics extremes (hil.sim.monitor via Plant.extremes): penetration, tension, overshoot."""

from __future__ import annotations

import math

import pytest

from hil.sim.config import ModelConfig, ObjectConfig
from hil.sim.plant import Plant
from hil.sim.spiral import PAPER_PROTOTYPE
from hil.sim.types import PlantConfig

TWO_CABLE = PAPER_PROTOTYPE.with_cables(2)


def test_a_free_hanging_arm_has_no_penetration_and_no_overshoot() -> None:
    plant = Plant(TWO_CABLE)
    plant.run(100_000)
    ext = plant.extremes()
    assert ext.penetration_m == 0.0
    assert ext.penetration_ratio == 0.0
    assert ext.limit_overshoot_rad <= 0.0
    assert ext.tension_n == pytest.approx(float(plant.cable_tensions_n().max()), abs=0.5)


def test_penetration_is_the_depth_of_a_unit_inside_an_object() -> None:
    # A fixed rod of 10 mm radius whose axis lies 5 mm from the straight arm's axis, crossing it at a
    # unit: the unit's capsule overlaps it by about its own radius + 5 mm.
    plant = Plant(TWO_CABLE)
    pos, _ = plant.unit_poses()
    z = float(pos[3][2]) - 0.004
    rod = ObjectConfig("rod", radius_m=0.01, length_m=0.05, pos_m=(0.015, 0.0, z))
    plant.add_object(rod)
    plant.step()
    ext = plant.extremes()
    assert ext.penetration_m > 0.001
    assert ext.penetration_ratio == pytest.approx(ext.penetration_m / 0.01)
    plant.reset_extremes()
    assert plant.extremes().penetration_m == 0.0


def test_tension_and_overshoot_are_maxima_kept_until_reset() -> None:
    plant = Plant(TWO_CABLE)
    plant.apply_currents([3000, 0])
    plant.run(300_000)
    peak = plant.extremes()
    assert peak.tension_n > 10.0
    assert math.isfinite(peak.limit_overshoot_rad)
    plant.apply_currents([0, 0])
    plant.run(300_000)
    assert plant.extremes().tension_n == peak.tension_n  # a maximum, not the present value
    # Rebuilding the model for a new object keeps what was measured before it.
    plant.add_object(ObjectConfig("far", radius_m=0.01, length_m=0.05, pos_m=(1.0, 0.0, 0.0)))
    assert plant.extremes().tension_n == peak.tension_n
    plant.reset()
    assert plant.extremes().tension_n == 0.0


def test_a_plant_that_does_not_track_extremes_moves_the_same() -> None:
    """Identification's rollouts skip the monitor; the arm they simulate must be the same to the bit."""
    plants = [Plant(TWO_CABLE, PlantConfig(track_extremes=track)) for track in (True, False)]
    for p in plants:
        p.apply_currents([3000, 500])
        p.run(200_000)
    assert (plants[0].unit_poses()[0] == plants[1].unit_poses()[0]).all()
    assert plants[0].extremes().tension_n > 10.0
    assert plants[1].extremes().tension_n == 0.0  # not measured


def test_extremes_serialise_in_si_units() -> None:
    plant = Plant(TWO_CABLE, PlantConfig(model=ModelConfig()))
    plant.step()
    assert set(plant.extremes().as_dict()) == {
        "penetration_m",
        "penetration_ratio",
        "tension_n",
        "limit_overshoot_rad",
    }
