"""Variants of a plant model (hil.sim.variants): one uncertain parameter scaled, named by a label."""

from __future__ import annotations

import pytest

from hil.sim.config import ModelConfig
from hil.sim.variants import BASELINE, PARAMETERS, Variant


def test_a_variant_scales_only_its_parameter() -> None:
    base = ModelConfig()
    assert Variant(BASELINE, 1.0).apply(base) == base
    half = Variant("damping ratio", 0.5).apply(base)
    assert half.arm.damping_ratio == 0.5 * base.arm.damping_ratio
    assert half.motor == base.motor
    assert half.arm.base_stiffness_nm_per_rad == base.arm.base_stiffness_nm_per_rad


@pytest.mark.parametrize("parameter", list(PARAMETERS))
def test_a_label_parses_back_to_its_variant(parameter: str) -> None:
    for v in (Variant(parameter, 0.5), Variant(parameter, 1.5), Variant(BASELINE, 1.0)):
        assert Variant.parse(v.label) == v


@pytest.mark.parametrize(
    "bad", ["", "stiffness x0.5", "spool inertia x0", "spool inertia x-2", "spool inertia"]
)
def test_a_bad_label_says_what_a_label_is(bad: str) -> None:
    with pytest.raises(ValueError, match="is not 'baseline' or 'PARAMETER xFACTOR'"):
        Variant.parse(bad)
