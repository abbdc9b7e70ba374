"""host.panel.plots (window, cable choice, y ranges) and host.panel.health (checked numbers)."""

from __future__ import annotations

import numpy as np

from host.panel.board_state import BoardState
from host.panel.health import health_checks, health_html, health_text
from host.panel.history import PLOT_COLUMNS
from host.panel.plots import CABLE_CHOICES, plot_frame, y_range
from protocol.messages import ArmsTelemetry, Telemetry


def rows(n: int, dt_s: float = 0.01) -> np.ndarray:
    data = np.zeros((n, 1 + len(PLOT_COLUMNS)))
    data[:, 0] = np.arange(n) * dt_s
    data[:, 1:] = np.arange(len(PLOT_COLUMNS))[None, :] + 1.0
    return data


def test_window_cable_choice_and_decimation() -> None:
    x, series = plot_frame(rows(1000), 2.0, CABLE_CHOICES[0], 1000)
    assert x[-1] == 0.0 and x[0] >= -2.0 - 1e-9 and len(x) == 201
    assert [len(series[c]) for c in ("tensions", "currents", "lengths")] == [6, 6, 3]
    _, one = plot_frame(rows(1000), 2.0, "cable 2", 1000)
    # Cable 2 only: T2 target and T2 est drawn, the others NaN.
    drawn = [i for i, col in enumerate(one["tensions"]) if np.isfinite(col).all()]
    assert drawn == [1, 4]
    assert [i for i, col in enumerate(one["lengths"]) if np.isfinite(col).all()] == [1]
    x, _ = plot_frame(rows(1000), 20.0, CABLE_CHOICES[0], 100)
    assert len(x) <= 100 and x[-1] == 0.0
    x, empty = plot_frame(rows(0), 10.0, CABLE_CHOICES[0], 100)
    assert len(x) == 1 and all(np.isnan(c).all() for c in empty["tensions"])


def test_y_ranges_are_physical_when_empty_and_never_collapse() -> None:
    assert y_range(np.array([np.nan]), "tensions") == (0.0, 20.0)
    assert y_range(np.array([np.nan]), "tensions", (0.0, 12.0)) == (0.0, 12.0)
    assert y_range(np.array([]), "currents") == (-1.0, 1.0)
    lo, hi = y_range(np.full(50, 0.5), "tensions")  # a flat pretension: a readable band, not 0..100
    assert lo == 0.0 and 1.0 <= hi <= 2.0
    lo, hi = y_range(np.array([2.0, 9.0]), "tensions")
    assert lo <= 2.0 and hi >= 9.0 and hi - lo < 9.0
    lo, hi = y_range(np.array([-0.3, 0.4]), "currents")
    assert lo < -0.3 and hi > 0.4


def test_health_checks_grade_against_thresholds() -> None:
    m = BoardState()
    t = Telemetry(10_000_000, motors_online=0b011, control_exec_p99_us=950, control_lateness_p99_us=50)
    m.on_board_message(t)
    checks = {c.name: c for c in health_checks(m, malformed_n=3)}
    assert checks["Motors online"].level == "bad" and checks["Motors online"].value == "2/3"
    assert checks["Control exec p99"].level == "bad"
    assert checks["Control lateness p99"].level == "ok"
    assert (
        checks["Malformed panel messages"].level == "warn" and checks["Malformed panel messages"].value == "3"
    )
    page = health_html(list(checks.values()))
    assert page.count('data-level="bad"') == 2 and "ok &lt; 500 µs" in page


def test_scales_pin_both_axes() -> None:
    """Neither axis is left to uPlot: an auto x scale collapsed to 0..1 s in viser 1.1.1 whenever a new
    y range rebuilt the chart (host.panel.plots' docstring)."""
    from host.panel.plots import fixed_scales

    s = fixed_scales(-1.0, 2.5, 10.0)
    assert s["x"] == {"time": False, "auto": False, "range": [-10.0, 0.0]}
    assert s["y"] == {"auto": False, "range": [-1.0, 2.5]}


def test_health_says_the_board_is_an_array() -> None:
    m = BoardState()
    m.on_board_message(Telemetry(time_us=1, motors_online=0b1011_1111))
    summary, _, _ = health_text(m, "simulation", None)
    assert "array" not in summary and "M3 on" in summary and "M4" not in summary
    eight = (0,) * 8
    m.on_board_message(
        ArmsTelemetry(1, 4, 2, eight, eight, eight, eight, (0.0,) * 8, (0.0,) * 8, (0.0,) * 8, (False,) * 8)
    )
    summary, _, _ = health_text(m, "simulation", None)
    assert "the board is an array of 4 arms x 2 cable(s), 8 motors" in summary
    assert "M7 **OFF**" in summary and "M8 on" in summary
