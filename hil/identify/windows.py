"""A recording made ready to simulate: its commands on the 1 ms control grid, and the samples it is judged on.

The fit (:mod:`hil.identify.fit`) simulates each recording from its first sample with the commanded currents
the board sent, one per control period, and compares the motors' view (cable length from the first sample,
cable speed, and the tracked tip when recorded) at the judged samples. :func:`length_rms_m` does the same
for one model and one recording, with no fit: what a given model predicts (a benchmark's reference, such
as the truth's own values in a model that cannot represent the truth exactly). :class:`Trace` is a
recording's measured cable lengths against a fitted and the preset model's, as the report draws them.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Final

import numpy as np
from numpy.typing import NDArray

from hil.identify.motor_data import MotorData
from hil.identify.rollout import RolloutJob, simulate
from hil.sim.config import ModelConfig
from hil.sim.spiral import SpiralDesign

__all__ = [
    "CH",
    "LEN",
    "TEN",
    "TIP",
    "VEL",
    "Trace",
    "Window",
    "at_samples",
    "length_rms_m",
    "prepare_window",
    "rms_of_traces",
]

FloatArray = NDArray[np.float64]

TEN, LEN, VEL, TIP = slice(0, 3), slice(3, 6), slice(6, 9), slice(9, 12)
"""Columns of a rollout and of the measured samples: tensions, lengths, speeds, tip."""
CH: Final = 12
"""Columns per sample."""


@dataclass(frozen=True)
class Window:
    """A recording ready to simulate from its start up to ``end``: its 1 ms input, and the measured samples
    it is judged on."""

    recording: MotorData
    end: int
    """One past the last sample simulated."""
    currents_a: FloatArray
    """(n, 3): the command in force during each control period from the first sample."""
    t0_s: float
    """MotorData time of the first control period (its first sample)."""
    sample_rows: NDArray[np.int64]
    """For each judged sample, the rollout row that ends at its time."""
    sample_t_s: FloatArray
    measured: FloatArray
    """(m, 12): the sensors' columns: length from the first sample, speed, tip (NaN where not measured)."""
    stale: NDArray[np.bool_]
    """(m, 3): a motor's judged sample that the board read a period late (:attr:`MotorData.stale`): it is
    compared with the rollout a period earlier."""

    @property
    def seconds(self) -> float:
        return len(self.currents_a) * 1e-3


def prepare_window(rec: MotorData, end: int, period_s: float) -> Window:
    """``rec`` up to sample ``end`` on the 1 ms grid, judged every ``period_s`` from the excitation."""
    t = rec.t_s
    t0 = float(t[0])
    n = max(2, round((float(t[end - 1]) - t0) / 1e-3))
    grid = t0 + np.arange(n) * 1e-3
    if rec.source == "can":
        # One sample per control period: the command in force from each sample to the next. A tick may
        # start late (a real-time loop's jitter, a fraction of the period), and its stamp with it: the
        # period a sample belongs to is its time rounded to the period. Floored, a late tick's command
        # would act a period late in the rollout, and the fit would shorten the delay to make up for it.
        tick = np.rint((t - t0) / 1e-3).astype(np.int64)
        idx = np.clip(np.searchsorted(tick, np.arange(n), side="right") - 1, 0, len(t) - 1)
        currents = rec.current_cmd_a[idx]
    else:
        currents = np.stack([np.interp(grid, t, rec.current_cmd_a[:, k]) for k in range(3)], axis=1)
    # Judged samples: from the excitation's start to the end, decimated to the residual period.
    step = max(1, round(period_s / max(rec.period_s, 1e-6)))
    idx_s = np.arange(rec.first_judged(), end, step)
    t_s = t[idx_s]
    rows = np.rint((t_s - t0) / 1e-3).astype(np.int64) - 1
    keep = (rows >= 0) & (rows < n)
    idx_s, t_s, rows = idx_s[keep], t_s[keep], rows[keep]
    meas = np.full((len(idx_s), CH), np.nan)
    meas[:, LEN] = rec.length_m[idx_s] - rec.length_m[0]
    meas[:, VEL] = rec.speed_m_s[idx_s]
    # The frames right after a late one may be late too without showing it (each repeats its
    # predecessor's measurement, not its content; runs of three happen at 5 % a frame): a motor's sample
    # within three frames after one seen late is not judged.
    after_late = np.zeros_like(rec.stale)
    for lag in (1, 2, 3):
        after_late[lag:] |= rec.stale[:-lag]
    doubt = after_late[idx_s]
    meas[:, LEN][doubt] = np.nan
    meas[:, VEL][doubt] = np.nan
    if rec.tip_m is not None:
        meas[:, TIP] = rec.tip_m[idx_s]
    return Window(rec, end, currents, t0, rows, t_s, meas, rec.stale[idx_s] & (rows >= 1)[:, None])


def at_samples(w: Window, out: FloatArray) -> FloatArray:
    """A rollout's rows as the board measured them at the judged samples: a late frame holds the motor's
    state a period before its sample's time."""
    sim = out[w.sample_rows].copy()
    if w.stale.any():
        earlier = out[w.sample_rows - 1]
        for cols in (LEN, VEL):
            sim[:, cols] = np.where(w.stale, earlier[:, cols], sim[:, cols])
    return sim


def length_rms_m(rec: MotorData, model: ModelConfig, design: SpiralDesign, period_s: float = 0.01) -> float:
    """RMS error of ``model``'s cable lengths against ``rec``'s, simulated whole from its first sample with
    its commands, judged every ``period_s`` from the excitation's start (the fit's held-out figure)."""
    w = prepare_window(rec, len(rec.t_s), period_s)
    sim = at_samples(w, simulate(RolloutJob(design, model, w.currents_a)))
    err = sim[:, LEN] - w.measured[:, LEN]
    return float(np.sqrt(np.nanmean(err**2))) if err.size else math.nan


@dataclass(frozen=True, slots=True)
class Trace:
    """Measured against simulated for one recording, simulated whole from its start (the report draws it).

    Attributes:
        recording: the recording's name.
        t_s: judged sample times (the recording's clock).
        held_out: per sample, the fit never saw it.
        measured_m: (m, 3) cable lengths from the first sample.
        fitted_m: the fitted model's.
        nominal_m: the preset's.
    """

    recording: str
    t_s: FloatArray
    held_out: NDArray[np.bool_]
    measured_m: FloatArray
    fitted_m: FloatArray
    nominal_m: FloatArray

    def rms_m(self, held_out: bool, which: str = "fitted") -> float:
        """RMS length error of the fitted (or ``nominal``) model over the fitted (or held-out) samples."""
        sim = self.fitted_m if which == "fitted" else self.nominal_m
        sel = self.held_out == held_out
        if not sel.any():
            return math.nan
        return float(np.sqrt(np.nanmean((sim[sel] - self.measured_m[sel]) ** 2)))


def rms_of_traces(traces: Sequence[Trace], held_out: bool, which: str) -> float:
    """RMS length error over the fitted (or held-out) samples of every trace, of the fitted or ``nominal``
    model."""
    errs = [
        ((t.fitted_m if which == "fitted" else t.nominal_m) - t.measured_m)[t.held_out == held_out]
        for t in traces
    ]
    flat = np.concatenate([e.ravel() for e in errs]) if errs else np.empty(0)
    return float(np.sqrt(np.nanmean(flat**2))) if flat.size else math.nan
