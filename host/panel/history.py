"""The telemetry history behind the panel's plots: a fixed-size ring of rows (time first)."""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

__all__ = ["PLOT_COLUMNS", "RingBuffer"]

PLOT_COLUMNS = (
    "tension_target_1",
    "tension_target_2",
    "tension_target_3",
    "tension_est_1",
    "tension_est_2",
    "tension_est_3",
    "commanded_a_1",
    "commanded_a_2",
    "commanded_a_3",
    "measured_a_1",
    "measured_a_2",
    "measured_a_3",
    "cable_mm_1",
    "cable_mm_2",
    "cable_mm_3",
)
"""Columns of the telemetry history (after the time column)."""


class RingBuffer:
    """Fixed-capacity rows of floats (time first); the newest ``capacity`` rows are kept."""

    def __init__(self, capacity: int, columns: int) -> None:
        """Create an empty buffer.

        Args:
            capacity: rows kept.
            columns: values per row, not counting the time column.

        Raises:
            ValueError: a size is not positive.
        """
        if capacity <= 0 or columns <= 0:
            raise ValueError("capacity and columns must be > 0")
        self._data = np.zeros((capacity, columns + 1), dtype=np.float64)
        self._n = 0
        self._i = 0

    def __len__(self) -> int:
        return self._n

    def append(self, t: float, values: tuple[float, ...] | list[float]) -> None:
        """Add one row."""
        row = self._data[self._i]
        row[0] = t
        row[1:] = values
        self._i = (self._i + 1) % len(self._data)
        self._n = min(self._n + 1, len(self._data))

    def clear(self) -> None:
        """Drop every row."""
        self._n = 0
        self._i = 0

    def snapshot(self, max_points: int | None = None) -> npt.NDArray[np.float64]:
        """Rows oldest first (a copy), decimated to at most ``max_points`` rows."""
        cap = len(self._data)
        if self._n < cap:
            out = self._data[: self._n].copy()
        else:
            out = np.concatenate((self._data[self._i :], self._data[: self._i]))
        if max_points is not None and len(out) > max_points > 0:
            step = math.ceil(len(out) / max_points)
            out = out[::-1][::step][::-1].copy()
        return out
