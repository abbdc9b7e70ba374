"""hil.identify.scale_tie: the force scale as a coordinate of its own is a change of coordinates only (the
same points, the same Jacobian), and it lets the solver walk the scale where the parameters' own coordinates
stop."""

from __future__ import annotations

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from hil.identify.scale_tie import ScaleTie

NAMES = ["base_stiffness", "damping_ratio", "rotor_inertia", "drive_friction", "torque_scale", "delay"]


def test_without_the_torque_constant_or_its_partners_the_coordinates_are_the_parameters() -> None:
    for names in (["base_stiffness", "rotor_inertia", "delay"], ["torque_scale", "delay", "cable_mu"]):
        tie = ScaleTie(names)
        assert not tie.active and np.array_equal(tie.m, np.eye(len(names)))


def test_the_scale_is_one_coordinate_and_the_partners_their_ratios_to_it() -> None:
    tie = ScaleTie(NAMES)
    assert tie.active
    x = np.array([0.2, -0.1, 0.25, 0.15, 0.2, 0.3])  # stiffness, inertia and friction ride the scale
    z = tie.to_z(x)
    assert z[4] == 0.2 and np.allclose(z[[0, 2, 3]], [0.0, 0.05, -0.05]) and np.allclose(z[[1, 5]], x[[1, 5]])
    # Moving the scale alone moves every partner with it: all forces times one factor.
    dz = np.zeros(6)
    dz[4] = 0.1
    assert np.allclose(tie.to_x(z + dz) - x, [0.1, 0.0, 0.1, 0.1, 0.1, 0.0])


@given(st.lists(st.floats(-1.0, 1.0), min_size=6, max_size=6))
def test_the_change_is_exact_both_ways_and_the_jacobian_follows(values: list[float]) -> None:
    tie = ScaleTie(NAMES)
    x = np.array(values)
    assert np.allclose(tie.to_x(tie.to_z(x)), x, atol=1e-12)
    # r(x) linear: J_x recovered from J_z = J_x M.
    rng = np.random.default_rng(len(values))
    jac_x = rng.normal(size=(9, 6))
    assert np.allclose(tie.jacobian_x(jac_x @ tie.m), jac_x)


def test_the_solver_s_box_holds_the_parameters_box() -> None:
    tie = ScaleTie(NAMES)
    lo, hi = -np.ones(6) * 1.1, np.ones(6) * 1.1
    z_lo, z_hi = tie.z_bounds(lo, hi)
    rng = np.random.default_rng(3)
    for x in rng.uniform(lo, hi, size=(200, 6)):
        z = tie.to_z(x)
        assert np.all(z >= z_lo - 1e-12) and np.all(z <= z_hi + 1e-12)
