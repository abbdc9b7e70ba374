"""The shared Plots folder: uPlot charts of tensions, currents and cable lengths, with their controls.

Controls (shared by every tab: the charts are one set): pause, the window length, which charts and
which cables are shown. Each chart's y range is computed here, never left to uPlot's auto-scaling:
an empty chart shows its physical range (0..tension ceiling, ±1 A, 0..10 mm), and a flat trace gets a
minimum span around its value instead of an arbitrary 0..100.

The x axis is pinned too, to ``[-window, 0]`` (``auto: false``), never left to uPlot. Why (viser 1.1.1's
``UplotComponent.tsx``): any change of a chart's ``scales`` makes uplot-react destroy and rebuild the
chart, and for an *auto* x scale viser keeps the user's zoom as bounds relative to the data, read back
from the chart in an effect clean-up. Read from a chart just rebuilt, whose scales uPlot has not yet
committed (min and max still null), they default to 0 and 1: the relative bounds become 1.0..1.1 of the
data's span, i.e. x = 0..1 s, one dot at t = 0, and every later update keeps that window until the page
is reloaded. A fixed x range skips that code (viser returns early for a non-auto x scale) and is pinned
again by the init hook of every rebuilt chart.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt
import viser

__all__ = ["CABLE_CHOICES", "PlotHandles", "build_plot_panel", "fixed_scales", "plot_frame", "y_range"]

_ORDER_PLOTS = 100.0  # folder order in the panel: Control (0), Plots (100), Health (200)
_CABLE_STROKES = ("#dc3c3c", "#3caa3c", "#e6a01e")
CABLE_CHOICES = ("all cables", "cable 1", "cable 2", "cable 3")
"""The cable selector's options."""
_MIN_SPAN = {"tensions": 1.0, "currents": 0.2, "lengths": 2.0}
"""Smallest y span per chart (N, A, mm): a flat trace is drawn in a readable range, not 0..100."""
_EMPTY_RANGE = {"tensions": (0.0, 20.0), "currents": (-1.0, 1.0), "lengths": (-5.0, 5.0)}
"""y range per chart before any sample."""
CHART_COLUMNS = {"tensions": (0, 6), "currents": (6, 12), "lengths": (12, 15)}
"""Chart -> its slice of the history's value columns (``host.panel.history.PLOT_COLUMNS``)."""


@dataclass
class PlotHandles:
    """The shared uPlot charts and their controls."""

    tensions: Any
    currents: Any
    lengths: Any
    pause: Any
    window: Any
    cables: Any
    show: dict[str, Any]

    def chart(self, name: str) -> Any:
        """The uPlot handle of chart ``name`` (``tensions``, ``currents``, ``lengths``)."""
        return {"tensions": self.tensions, "currents": self.currents, "lengths": self.lengths}[name]


def _series(label: str, stroke: str, dash: bool = False) -> dict[str, Any]:
    s: dict[str, Any] = {"label": label, "stroke": stroke, "width": 1.5}
    if dash:
        s["dash"] = [5, 4]
    return s


def fixed_scales(lo: float, hi: float, window_s: float) -> dict[str, Any]:
    """A chart's ``scales``: x fixed to the last ``window_s`` seconds (relative time, 0 = newest), y fixed
    to ``lo..hi`` (see the module's docstring for why neither is left to uPlot)."""
    return {
        "x": {"time": False, "auto": False, "range": [-float(window_s), 0.0]},
        "y": {"auto": False, "range": [lo, hi]},
    }


def _add_plot(
    server: viser.ViserServer,
    title: str,
    series: tuple[dict[str, Any], ...],
    empty: tuple[float, float],
    window_s: float,
) -> Any:
    """One uPlot with an empty sample per series, a relative-time x axis and a fixed y range."""
    return server.gui.add_uplot(
        data=tuple(np.zeros(1) for _ in series),
        series=series,  # type: ignore[arg-type]
        title=title,
        scales=fixed_scales(*empty, window_s),
        aspect=1.6,
    )


def y_range(
    values: npt.NDArray[np.float64], chart: str, empty: tuple[float, float] | None = None
) -> tuple[float, float]:
    """The y range of ``chart`` for ``values`` (NaN = hidden): padded, at least the chart's minimum span.

    Args:
        values: every plotted value of the chart.
        chart: ``tensions``, ``currents`` or ``lengths``.
        empty: the range with no value (default: the chart's physical range).
    """
    finite = values[np.isfinite(values)]
    if finite.size == 0:
        return empty or _EMPTY_RANGE[chart]
    lo, hi = float(finite.min()), float(finite.max())
    span = max(hi - lo, _MIN_SPAN[chart])
    mid = 0.5 * (lo + hi)
    lo, hi = mid - 0.55 * span, mid + 0.55 * span
    if chart == "tensions" and float(finite.min()) >= 0.0:
        lo = max(lo, 0.0)  # tensions are never negative: keep 0 as the floor
    step = _MIN_SPAN[chart] / 4  # round outwards: the range changes (and is sent) less often
    return float(np.floor(lo / step) * step), float(np.ceil(hi / step) * step)


def plot_frame(
    data: npt.NDArray[np.float64], window_s: float, cable: str, max_points: int
) -> tuple[npt.NDArray[np.float64], dict[str, list[npt.NDArray[np.float64]]]]:
    """The x axis (s relative to the newest row) and each chart's series for the chosen window and cable.

    Args:
        data: history rows, time first (``host.panel.history.RingBuffer.snapshot``), oldest first.
        window_s: seconds shown.
        cable: one of :data:`CABLE_CHOICES`; other cables' series are NaN (uPlot draws nothing).
        max_points: most rows kept (decimated evenly, the newest kept).
    """
    if len(data) == 0:
        return np.zeros(1), {c: [np.full(1, np.nan)] * (b - a) for c, (a, b) in CHART_COLUMNS.items()}
    t_end = data[-1, 0]
    data = data[data[:, 0] >= t_end - window_s]
    if len(data) > max_points:
        step = int(np.ceil(len(data) / max_points))
        data = data[::-1][::step][::-1]
    x = data[:, 0] - t_end
    keep = None if cable not in CABLE_CHOICES[1:] else CABLE_CHOICES.index(cable) - 1
    out: dict[str, list[npt.NDArray[np.float64]]] = {}
    for chart, (a, b) in CHART_COLUMNS.items():
        cols = []
        for k in range(b - a):
            col = data[:, 1 + a + k]
            cables = 3 if b - a == 6 else b - a  # 6 columns = target/est (or cmd/meas) of 3 cables
            if keep is not None and k % cables != keep:
                col = np.full(len(col), np.nan)
            cols.append(col)
        out[chart] = cols
    return x, out


def build_plot_panel(
    server: viser.ViserServer, *, window_s: float = 10.0, history_s: float = 20.0
) -> PlotHandles:
    """Build the shared Plots folder (x axis: seconds relative to the newest sample).

    Args:
        server: the viser server.
        window_s: the initial window length.
        history_s: the longest window (the model's history).
    """
    gui = server.gui
    window_s = min(window_s, history_s)
    x: dict[str, Any] = {"label": "t [s]"}
    cables = tuple(enumerate(_CABLE_STROKES))
    with gui.add_folder("Plots", order=_ORDER_PLOTS):
        pause = gui.add_checkbox(
            "Pause", initial_value=False, hint="Freeze the charts (the board keeps running)"
        )
        window = gui.add_slider("Window [s]", min=1.0, max=history_s, step=1.0, initial_value=window_s)
        cable = gui.add_dropdown("Cables", CABLE_CHOICES, initial_value=CABLE_CHOICES[0])
        show = {
            "tensions": gui.add_checkbox("Show tensions", initial_value=True),
            "currents": gui.add_checkbox("Show currents", initial_value=True),
            "lengths": gui.add_checkbox("Show cable lengths", initial_value=True),
        }
        tensions = _add_plot(
            server,
            "Cable tension [N]",
            (
                x,
                *(_series(f"T{i + 1} target", c, dash=True) for i, c in cables),
                *(_series(f"T{i + 1} est", c) for i, c in cables),
            ),
            _EMPTY_RANGE["tensions"],
            window_s,
        )
        currents = _add_plot(
            server,
            "Motor current [A]",
            (
                x,
                *(_series(f"I{i + 1} cmd", c, dash=True) for i, c in cables),
                *(_series(f"I{i + 1} meas", c) for i, c in cables),
            ),
            _EMPTY_RANGE["currents"],
            window_s,
        )
        lengths = _add_plot(
            server,
            "Cable paid in [mm]",
            (x, *(_series(f"L{i + 1}", c) for i, c in cables)),
            _EMPTY_RANGE["lengths"],
            window_s,
        )
    h = PlotHandles(tensions, currents, lengths, pause, window, cable, show)
    for name, box in show.items():

        def _toggle(_event: Any, name: str = name) -> None:
            handle: Any = h.chart(name)
            handle.visible = bool(h.show[name].value)

        box.on_update(_toggle)
    return h
