"""``--object`` specs: parsing, formatting, placement in the plant, and the default demo's object."""

from __future__ import annotations

import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from host.object_spec import (
    AXES,
    DEFAULT_OBJECT,
    MAX_DIAMETER_M,
    MAX_DISTANCE_M,
    SHAPES,
    ObjectSpec,
    format_object,
    parse_object,
    plant_objects,
)


def test_the_issue_example_parses_with_units() -> None:
    spec = parse_object("cylinder:d=20mm,x=40mm,z=-110mm")
    assert spec == ObjectSpec("cylinder", 0.020, 0.060, 0.040, 0.0, -0.110, "y")
    other = parse_object("Capsule: d=2cm, len=0.1m, y=-1.5cm, z=-0.12m, axis=X")
    assert other.shape == "capsule" and other.axis == "x"
    assert math.isclose(other.diameter_m, 0.02) and math.isclose(other.length_m, 0.1)
    assert math.isclose(other.y_m, -0.015) and math.isclose(other.z_m, -0.12)


@pytest.mark.parametrize(
    ("text", "needle"),
    [
        ("cylinder", "expected SHAPE:KEY=VALUE"),
        ("sphere:d=20mm,z=-10mm", "unknown shape 'sphere'"),
        ("cylinder:d=20,z=-110mm", "d=20: give a unit"),
        ("cylinder:d=20in,z=-110mm", "not a length"),
        ("cylinder:d=20mm", "z= is required"),
        ("cylinder:z=-20mm", "d= is required"),
        ("cylinder:d=20mm,z=-1mm,q=3mm", "unknown key 'q'"),
        ("cylinder:d=20mm,z=-1mm,x", "expected KEY=VALUE"),
        ("cylinder:d=20mm,d=30mm,z=-1mm", "d given twice"),
        ("cylinder:d=0mm,z=-1mm", "d must be more than 0"),
        ("cylinder:d=-5mm,z=-1mm", "d must be more than 0"),
        ("cylinder:d=20mm,len=1m,z=-1mm", "len must be more than 0 and at most 500mm"),
        ("cylinder:d=20mm,z=-3m", "z must be within ±2m"),
        ("cylinder:d=nanmm,z=-1mm", "not a length"),
        ("cylinder:d=20mm,z=-1mm,axis=w", "axis must be one of x, y, z"),
    ],
)
def test_bad_specs_say_what_is_wrong_in_one_line(text: str, needle: str) -> None:
    with pytest.raises(ValueError, match=None) as info:
        parse_object(text)
    message = str(info.value)
    assert needle in message and "\n" not in message


_lengths = st.floats(min_value=1e-6, max_value=MAX_DIAMETER_M, allow_nan=False)
_coords = st.floats(min_value=-MAX_DISTANCE_M, max_value=MAX_DISTANCE_M, allow_nan=False)


@given(
    st.builds(
        ObjectSpec,
        st.sampled_from(SHAPES),
        _lengths,
        _lengths,
        _coords,
        _coords,
        _coords,
        st.sampled_from(sorted(AXES)),
    )
)
def test_format_then_parse_is_the_identity(spec: ObjectSpec) -> None:
    assert parse_object(format_object(spec)) == spec


def test_objects_are_placed_from_the_arms_base_and_fixed() -> None:
    from hil.sim.config import DroneConfig, ModelConfig, ObjectConfig

    model = ModelConfig(drone=DroneConfig(pos_m=(0.5, -0.2, 1.0), mount_offset_m=0.02)).with_objects(
        ObjectConfig("object1", 0.01, 0.05, (0.0, 0.0, 0.3))
    )
    a, b = plant_objects([DEFAULT_OBJECT, parse_object("capsule:d=10mm,y=5mm,z=-50mm,axis=z")], model)
    assert a.name == "object2" and b.name == "object3"  # object1 is the model's own
    assert a.pos_m == pytest.approx((0.5 + 0.070, -0.2, 0.98 - 0.140))
    assert a.radius_m == pytest.approx(0.010) and a.mass_kg is None  # fixed: a pole to grasp
    assert b.shape == "capsule" and b.axis == (0.0, 0.0, 1.0)
    assert b.pos_m == pytest.approx((0.5, -0.195, 0.93))


def test_the_default_object_is_grasped_from_the_default_start() -> None:
    """The default demo, in lockstep: the arm hangs straight, the right lever goes UP (GRASP mode: the
    arm packs), the grasp is asked for 3 s later; the strategy reaches HOLD wrapped around the pole."""
    from controller.config import FirmwareConfig
    from hil.sim.config import ModelConfig
    from hil.sim.objects import contact_units, contact_wrap_deg
    from hil.sim.spiral import SpiralDesign
    from hil.trial.rig import Rig, rc_frame
    from hil.trial.scene import MS, S
    from protocol.dbus import Lever
    from protocol.messages import GraspState

    (obj,) = plant_objects([DEFAULT_OBJECT], ModelConfig())
    rig = Rig(
        SpiralDesign.paper_prototype(),
        FirmwareConfig(),
        [(0, rc_frame()), (20 * MS, rc_frame(Lever.UP)), (3 * S, rc_frame(Lever.UP, Lever.UP))],
        objects=(obj,),
    )
    try:
        hold_us = None
        while rig.now_us < 12 * S and (hold_us is None or rig.now_us < hold_us + 1500 * MS):
            rig.step()
            state = rig.firmware.grasp_state
            assert state != GraspState.FAILED
            if hold_us is None and state == GraspState.HOLD:
                hold_us = rig.now_us
        assert hold_us is not None, "HOLD never reached"
        # Measured 1.5 s into HOLD: 5 units and 179.5° around the pole on one machine; on another (an AMD
        # EPYC, the same code and packages) 5 units and 170° at 1.2 s, then a unit slid off: 4 units, 143°.
        # The wrap of this one grasp moves with the machine's rounding; the units holding it do not.
        assert len(contact_units(rig.plant, obj.name)) >= 4
        assert contact_wrap_deg(rig.plant, obj.name) > 90.0  # around the pole, not resting against it
    finally:
        rig.close()
