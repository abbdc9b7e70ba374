"""hil.identify.starts: the restarts' points lie in the half of the box around the first start, the same
for the same seed; the delay's other cells come first; the length error a fit may leave is the encoders'
quantization, derived, not picked."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from hil.identify.motor_data import load_motor_data
from hil.identify.starts import (
    SETTLED_FACTOR,
    cell_starts,
    default_horizons,
    parse_horizons,
    restart_points,
    restarts,
    settled_m,
)


@given(
    st.lists(st.tuples(st.floats(-5, 5), st.floats(0.01, 5), st.floats(0, 1)), min_size=1, max_size=9),
    st.integers(0, 9),
)
def test_restart_points_lie_in_the_half_box_around_the_start(
    rows: list[tuple[float, float, float]], n: int
) -> None:
    lower = np.array([a for a, _, _ in rows])
    upper = lower + np.array([w for _, w, _ in rows])
    x0 = lower + np.array([f for _, _, f in rows]) * (upper - lower)
    points = restart_points(x0, lower, upper, n, seed=1)
    assert len(points) == n
    for p in points:
        assert np.all(p >= x0 - 0.5 * (x0 - lower) - 1e-12) and np.all(p <= x0 + 0.5 * (upper - x0) + 1e-12)
    again = restart_points(x0, lower, upper, n, seed=1)
    assert all(np.array_equal(a, b) for a, b in zip(points, again, strict=True))


def test_restart_points_spread_over_each_parameter() -> None:
    points = np.array(restart_points(np.zeros(3), -np.ones(3), np.ones(3), 8, seed=0))
    assert points.shape == (8, 3)
    # A Sobol sequence of 8 puts one point in each eighth of every coordinate's range.
    for col in points.T:
        assert sorted(np.floor((col + 0.5) * 8).astype(int).tolist()) == list(range(8))


def test_restart_points_refuse_what_cannot_be_a_box() -> None:
    with pytest.raises(ValueError, match="outside"):
        restart_points(np.array([2.0]), np.array([0.0]), np.array([1.0]), 1)
    with pytest.raises(ValueError, match="same length"):
        restart_points(np.zeros(2), np.zeros(1), np.ones(1), 1)
    with pytest.raises(ValueError, match="n must be"):
        restart_points(np.zeros(1), -np.ones(1), np.ones(1), -1)
    assert restart_points(np.zeros(1), -np.ones(1), np.ones(1), 0) == []


def test_the_settled_error_is_the_encoders_quantization(preset_recording: Path) -> None:
    data = load_motor_data(preset_recording)
    quantum = 2 * math.pi / (8192 * 36) * 0.010  # one rotor count, through the P36 gear, on a 10 mm spool
    assert data.length_quantum_m == pytest.approx(quantum)
    assert settled_m([data]) == pytest.approx(quantum / math.sqrt(12) * SETTLED_FACTOR)
    # The recording's lengths are whole counts.
    counts = data.length_m / quantum
    assert np.allclose(counts, np.round(counts), atol=1e-6)
    assert math.isnan(settled_m([]))


def test_cell_starts_move_one_coordinate_to_each_cell_in_turn() -> None:
    x0 = np.array([0.1, 2.0, -0.3])
    starts = cell_starts(x0, 1, [0.5, 2.0, 3.5], 5)
    # The cell the first start is in is not started again; every other coordinate stays where it was.
    assert [s.tolist() for s in starts] == [[0.1, 0.5, -0.3], [0.1, 3.5, -0.3]]
    assert [s.tolist() for s in cell_starts(x0, 1, [0.5, 3.5], 1)] == [[0.1, 0.5, -0.3]]
    assert x0.tolist() == [0.1, 2.0, -0.3]  # the first start itself is left alone
    with pytest.raises(ValueError, match="outside"):
        cell_starts(x0, 3, [0.5], 1)
    with pytest.raises(ValueError, match="n must be"):
        cell_starts(x0, 0, [0.5], -1)


def test_restarts_take_the_cells_first_clipped_to_the_box_then_sobol() -> None:
    x0, lower, upper = np.array([0.0, 2.0]), np.array([-1.0, 0.0]), np.array([1.0, 10.0])
    points = restarts(x0, lower, upper, 4, (1, [0.5, 3.5]))
    assert len(points) == 4
    assert [p.tolist() for p in points[:2]] == [[0.0, 0.5], [0.0, 3.5]]
    assert all(
        np.array_equal(a, b) for a, b in zip(points[2:], restart_points(x0, lower, upper, 2), strict=True)
    )
    # A cell beyond the box starts on its bound; fewer restarts than cells take the first cells only.
    assert [p.tolist() for p in restarts(x0, lower, upper, 1, (1, [12.0, 3.5]))] == [[0.0, 10.0]]
    # No cells: the Sobol points alone.
    assert len(restarts(x0, lower, upper, 3)) == 3


def test_horizons_are_read_as_a_user_writes_them() -> None:
    assert parse_horizons("3,6,10") == (3.0, 6.0, 10.0)
    assert parse_horizons("none") == () == parse_horizons(" ")
    for bad, says in (("3,x", "seconds S,S"), ("0,6", "above 0"), ("nan", "above 0"), ("5000", "below 3600")):
        with pytest.raises(ValueError, match=says):
            parse_horizons(bad)


def test_continuation_is_the_default_only_where_the_torque_constant_is_given() -> None:
    """The twenty hidden-truth draws that showed continuation helps gave the torque constant; the timed fit
    that fitted it ended worse with it (docs/identify.md)."""
    assert default_horizons(["torque_scale"]) == (3.0, 6.0, 10.0)
    assert default_horizons(["delay", "torque_scale"]) == (3.0, 6.0, 10.0)
    assert default_horizons([]) == () == default_horizons(["delay"])
