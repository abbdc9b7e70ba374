"""hil.sim.uncertain: every identified parameter reads and writes its own field of the model."""

from __future__ import annotations

import math

import pytest

from hil.sim.config import ModelConfig
from hil.sim.uncertain import ID_PARAMS, apply, by_name, nominal


def test_every_row_names_a_field_and_apply_reads_back() -> None:
    model = ModelConfig()
    values = nominal(model)
    assert list(values) == [p.name for p in ID_PARAMS]
    changed = {name: (v * 1.1 if v else 1e-3) for name, v in values.items()}
    out = apply(model, changed)
    assert nominal(out) == pytest.approx(changed)
    assert nominal(model) == values  # frozen: the original is untouched


def test_bounds_hold_the_preset_and_relative_rows_scale_with_it() -> None:
    model = ModelConfig()
    for p in ID_PARAMS:
        v = p.read(model)
        lo, hi = p.bounds(v)
        assert lo <= v <= hi, p.name
        xlo, xhi = p.x_bounds(v)
        assert xlo <= p.to_x(v, v) <= xhi, p.name
        assert p.from_x(p.to_x(0.9 * hi, v), v) == pytest.approx(0.9 * hi), p.name
    k = by_name("base_stiffness")
    assert k.bounds(0.5) == pytest.approx((0.5 / 3, 1.5))


@pytest.mark.parametrize(
    ("values", "why"),
    [
        ({"stiffness": 1.0}, "unknown identified parameter"),
        ({"damping_ratio": math.nan}, "not a finite value"),
        ({"rotor_inertia": -1e-7}, "rotor_inertia_kg_m2"),
        ({"stiffness_exponent": 5.0}, "stiffness_exponent"),
    ],
)
def test_bad_values_are_refused(values: dict[str, float], why: str) -> None:
    with pytest.raises(ValueError, match=why):
        apply(ModelConfig(), values)


def test_a_value_a_rounding_error_past_its_bound_is_kept_at_the_bound() -> None:
    """A fit's step landed the delay at -7e-21 s; the model refuses that, so the value is kept at 0."""
    model = ModelConfig()
    values = nominal(model)
    for p in ID_PARAMS:
        v0 = values[p.name]
        lo, hi = p.bounds(v0)
        xlo, xhi = p.x_bounds(v0)
        below, above = p.value_at(xlo - 1e-12, v0), p.value_at(xhi + 1e-12, v0)
        assert below == lo and above == hi, p.name
        assert p.value_at(0.5 * (xlo + xhi), v0) == pytest.approx(p.from_x(0.5 * (xlo + xhi), v0))
        apply(model, {p.name: below})
    delay = by_name("delay")
    assert delay.value_at(-6.938893903907229e-21 / delay.scale, values["delay"]) == 0.0
