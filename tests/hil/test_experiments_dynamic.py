"""The dynamic (Fig. S11) and sensitivity experiments at their tiny size, and their building blocks."""

from __future__ import annotations

import json
import math
import pickle

import pytest

from hil.experiments.dynamic import TINY, DynamicResult, dynamic
from hil.experiments.dynamic_rig import paper_arm_45cm, scaled_model, with_timestep
from hil.experiments.sensitivity import (
    MEASURES,
    PARAMETERS,
    SensitivityResult,
    Variant,
    packing_measure,
    sensitivity,
    variants,
)
from hil.model_config import ModelConfig
from hil.spiral import SpiralDesign


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


@pytest.fixture(scope="module")
def tiny_dynamic() -> DynamicResult:
    return dynamic(TINY, seed=1)


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
    soft = packing_measure(proto, Variant("base stiffness", 0.5).apply(ModelConfig()), "tiny", 0, 1)
    stiff = packing_measure(proto, Variant("base stiffness", 1.5).apply(ModelConfig()), "tiny", 0, 1)
    # the base joint sets the packing tension: a stiffer base needs more
    assert soft["pack_tension_n"] < stiff["pack_tension_n"]


def test_sensitivity_tiny_table_and_json() -> None:
    r = sensitivity(size="tiny", seed=0, jobs=1)
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
