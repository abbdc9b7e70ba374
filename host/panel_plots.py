"""The shared Plots folder: uPlot charts of tensions, currents and cable lengths."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import viser

__all__ = ["PlotHandles", "build_plot_panel"]

_ORDER_PLOTS = 100.0  # folder order in the panel: Control (0), Plots (100), Health (200)
_CABLE_STROKES = ("#dc3c3c", "#3caa3c", "#e6a01e")


@dataclass
class PlotHandles:
    """The shared uPlot charts."""

    tensions: Any
    currents: Any
    lengths: Any


def _series(label: str, stroke: str, dash: bool = False) -> dict[str, Any]:
    s: dict[str, Any] = {"label": label, "stroke": stroke, "width": 1.5}
    if dash:
        s["dash"] = [5, 4]
    return s


def _add_plot(server: viser.ViserServer, title: str, series: tuple[dict[str, Any], ...]) -> Any:
    """One uPlot with an empty sample per series and an auto-scaled relative-time x axis."""
    return server.gui.add_uplot(
        data=tuple(np.zeros(1) for _ in series),
        series=series,  # type: ignore[arg-type]
        title=title,
        scales={"x": {"time": False, "auto": True}, "y": {"auto": True}},
        aspect=1.6,
    )


def build_plot_panel(server: viser.ViserServer) -> PlotHandles:
    """Build the shared Plots folder (x axis: seconds relative to the newest sample)."""
    x: dict[str, Any] = {"label": "t [s]"}
    cables = tuple(enumerate(_CABLE_STROKES))
    with server.gui.add_folder("Plots", order=_ORDER_PLOTS):
        tensions = _add_plot(
            server,
            "Cable tension [N]",
            (
                x,
                *(_series(f"T{i + 1} target", c, dash=True) for i, c in cables),
                *(_series(f"T{i + 1} est", c) for i, c in cables),
            ),
        )
        currents = _add_plot(
            server,
            "Motor current [A]",
            (
                x,
                *(_series(f"I{i + 1} cmd", c, dash=True) for i, c in cables),
                *(_series(f"I{i + 1} meas", c) for i, c in cables),
            ),
        )
        lengths = _add_plot(server, "Cable paid in [mm]", (x, *(_series(f"L{i + 1}", c) for i, c in cables)))
    return PlotHandles(tensions, currents, lengths)
