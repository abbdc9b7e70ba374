"""The dynamic (Fig. S11) and sensitivity experiments at their tiny size, and their building blocks."""

from __future__ import annotations

import json
import math
import pickle

import pytest

from controller.config import FirmwareConfig
from hil.experiments.base import Conditions
from hil.experiments.common import BOARD_MODEL, DEFAULT_MODEL
from hil.experiments.dynamic import (
    TINY,
    DynamicParams,
    DynamicResult,
    _clear_start_offset_m,
    _clearance_m,
    dynamic,
)
from hil.experiments.sensitivity import MEASURES, SensitivityResult, packing_measure, sensitivity, variants
from hil.sim.config import ModelConfig, ObjectConfig
from hil.sim.spiral import SpiralDesign
from hil.sim.variants import PARAMETERS, Variant
from hil.trial.arm_45cm import (
    paper_arm_45cm,
    scaled_model,
)
from hil.trial.rig import direct_rig
from hil.trial.scene import FAR_M, MS, OBJ, world_m


def test_contacts_are_twice_the_first_step_and_the_same_at_every_step() -> None:
    # only the physics step changes between the convergence columns
    assert DynamicParams().contact_s == pytest.approx(0.0005)
    assert DynamicParams(timesteps_s=(0.001,)).contact_s == pytest.approx(0.002)
    assert DynamicParams(contact_timeconst_s=0.001).contact_s == 0.001


def test_a_throw_starts_clear_of_the_hook() -> None:
    # The hook curled toward +x reaches past the lower aims: started 60 mm out from unit 11 the object
    # would sit inside the tip units (the 12.6 mm, 72°, 510 N run); the start moves out until it is clear.
    design = paper_arm_45cm()
    model = scaled_model(DEFAULT_MODEL, design, SpiralDesign.paper_prototype())
    p = DynamicParams()
    obj = ObjectConfig(OBJ, radius_m=0.01, length_m=0.06, pos_m=FAR_M, mass_kg=0.01)
    rig = direct_rig(design, FirmwareConfig(), objects=(obj,), model=model)
    plant = rig.plant
    plant.hold_object(OBJ)
    rig.set_tensions([p.hold_tension_n, 0.5, 0.5])
    rig.run(p.settle_ms * MS)
    unit = plant.unit_poses()[0][11]
    aim = (float(unit[0]), float(unit[2] - world_m(0.0, 0.0)[2]))
    offset = _clear_start_offset_m(plant, aim, p)
    assert offset > p.throw_offset_m
    assert _clearance_m(plant, p) >= p.throw_clearance_m
    rig.close()


@pytest.fixture(scope="module")
def tiny_dynamic() -> DynamicResult:
    return dynamic(TINY, Conditions(seed=1))


def test_dynamic_tiny_reports_every_trial_and_the_convergence(tiny_dynamic: DynamicResult) -> None:
    r = pickle.loads(pickle.dumps(tiny_dynamic))
    d = r.as_dict()
    json.dumps(d)
    assert d["arm"]["units"] == 24
    # one pen step and one throw per hold (length, tension) per physics step, the headline at each step
    assert [c["timestep_s"] for c in d["convergence"]] == list(TINY.timesteps_s)
    assert len(r.runs) == 3 * len(TINY.timesteps_s)
    assert set(d["capture"]) == {"length", "tension"}
    for run in d["runs"]:
        for key in ("penetration_m", "penetration_ratio", "tension_n", "limit_overshoot_rad"):
            assert run[key] >= 0.0
    for hold in ("length", "tension"):
        k, n, (lo, hi) = r.capture(hold)
        assert n == 1 and 0.0 <= lo <= k / n <= hi <= 1.0
    # the step on cable 0 reaches the pen (it stands beside the arm, 12 cm up from the tip)
    pen = r.at(TINY.timesteps_s[0], "pen")[0]
    assert not math.isnan(pen.first_contact_ms)
    assert pen.extremes.tension_n > 10.0
    # with 0.5 ms contacts every trial stays within the goal (< 10 % of the object's radius)
    # and no joint passes its limit by more than a few degrees (the 72° run started inside the hook)
    for run in r.runs:
        assert run.extremes.penetration_ratio < 0.1
        assert math.degrees(run.extremes.limit_overshoot_rad) < 5.0


def test_sensitivity_variants_change_one_parameter_each() -> None:
    base = ModelConfig()
    vs = variants()
    assert vs[0].label == "baseline" and vs[0].apply(base) == base
    assert len(vs) == 1 + 2 * len(PARAMETERS)
    assert len(variants("tiny")) == 3
    half = Variant("contact friction", 0.5).apply(base)
    assert half.arm.geom_friction == pytest.approx(0.5 * base.arm.geom_friction)
    assert half.motor == base.motor
    inertia = Variant("spool inertia", 1.5).apply(base)
    assert inertia.motor.rotor_inertia_kg_m2 == pytest.approx(1.5 * base.motor.rotor_inertia_kg_m2)
    assert inertia.arm == base.arm


def test_packing_measure_runs_on_the_given_model() -> None:
    proto = SpiralDesign.paper_prototype()
    soft = packing_measure("tiny", Conditions(proto, Variant("base stiffness", 0.5).apply(ModelConfig())))
    stiff = packing_measure("tiny", Conditions(proto, Variant("base stiffness", 1.5).apply(ModelConfig())))
    # the base joint sets the packing tension: a stiffer base needs more
    assert soft["pack_tension_n"] < stiff["pack_tension_n"]


def test_sensitivity_tiny_table_and_json() -> None:
    # The table's and the JSON's shape, not the physics: the board's 1 ms step keeps it quick.
    r = sensitivity("tiny", Conditions(model=BOARD_MODEL))
    r = pickle.loads(pickle.dumps(r))
    assert isinstance(r, SensitivityResult)
    d = r.as_dict()
    json.dumps(d)
    names = [c.name for _, conclusions in MEASURES.values() for c in conclusions]
    assert list(d["conclusions"]) == names
    # tiny: the baseline and the first parameter at x0.5 and x1.5
    assert list(d["variants"]) == ["baseline", "base stiffness x0.5", "base stiffness x1.5"]
    for cells in d["conclusions"].values():
        assert list(cells) == [v.label for v in variants("tiny")]
    strategy = d["measured"]["strategy"]["baseline"]
    assert strategy["n"] == 1 and {"off", "on", "oracle"} <= set(strategy)
    assert "packing: curls from the tip (rank correlation < -0.8)" in d["survive_all"]
