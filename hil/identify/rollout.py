"""Rollouts of the plant for a fit: recorded currents in, the motors' view of the arm out.

A rollout is the project's own :class:`hil.sim.plant.Plant` (its drives in Python, capstan friction and
all), reset to the arm hanging straight at rest, driven with a window's recorded commanded currents one
control period at a time, and sampled every period: the wound cable and its speed at each spool (what the
motor encoders measure) and the tip's position in the drone's frame (what a tracker measures). Nothing of
the firmware runs: the currents are what the firmware sent, so the fit sees the plant alone.

Rollouts are independent, so :class:`RolloutPool` runs them in worker processes, one per core; a batch of
parameter vectors times windows (a finite-difference Jacobian is one batch) fans out in one call.
"""

from __future__ import annotations

import os
import signal
from collections.abc import Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from types import TracebackType

import numpy as np
from numpy.typing import NDArray

from hil.errors import PlantDivergedError
from hil.sim.config import ModelConfig
from hil.sim.plant import Plant
from hil.sim.spiral import SpiralDesign
from hil.sim.types import PlantConfig
from protocol.c610 import RAW_PER_AMP

__all__ = ["CHANNELS", "RolloutJob", "RolloutPool", "simulate"]

FloatArray = NDArray[np.float64]

CHANNELS = 12
"""Columns of a rollout: cable tension [N] x3, wound cable [m] x3, cable speed [m/s] x3, tip position in the
drone frame [m] x3 (the order of the identification model's sensors)."""


@dataclass(frozen=True)
class RolloutJob:
    """One simulation: a model, and the currents to drive it with.

    Attributes:
        design: the arm.
        model: the plant's model configuration (the candidate parameters applied).
        currents_a: (n, 3) commanded currents, one row per control period [A].
    """

    design: SpiralDesign
    model: ModelConfig
    currents_a: FloatArray


def simulate(job: RolloutJob) -> FloatArray:
    """Run one rollout; returns (n, :data:`CHANNELS`) samples, row k after the period driven by row k.

    A plant that diverges (a candidate far from the truth can) yields NaN from there on: the fit sees a
    huge residual, never an exception.
    """
    plant = Plant(job.design, PlantConfig(model=job.model, track_extremes=False))
    n = len(job.currents_a)
    out = np.full((n, CHANNELS), np.nan)
    raw = np.rint(np.asarray(job.currents_a, dtype=np.float64) * RAW_PER_AMP).astype(np.int64)
    r = plant.drives.spool_radius_m
    base = np.asarray(plant.drone_pose().pos_m, dtype=np.float64)
    apply = plant.apply_currents
    step = plant.step
    try:
        for k in range(n):
            row = raw[k]
            apply((int(row[0]), int(row[1]), int(row[2])))
            step()
            out[k, 0:3] = plant.cable_tensions_n()
            out[k, 3:6] = plant.spool_angles_rad() * r
            out[k, 6:9] = plant.spool_speeds_rad_s() * r
            out[k, 9:12] = plant.tip_pose().pos_m - base
    except PlantDivergedError:
        pass
    return out


def _init_worker() -> None:
    # Ctrl-C reaches the whole process group: the parent stops the pool in order.
    signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})


class RolloutPool:
    """Worker processes for rollouts (``jobs`` = 1 runs them in this process).

    A context manager; :meth:`close` is safe twice.
    """

    def __init__(self, jobs: int | None = None) -> None:
        self.jobs = max(1, jobs if jobs is not None else (os.cpu_count() or 1))
        self._pool: ProcessPoolExecutor | None = None
        self.rollouts = 0
        """Rollouts run so far."""
        self.simulated_s = 0.0
        """Control periods simulated so far, in seconds (1 ms each)."""

    def map(self, jobs: Sequence[RolloutJob]) -> list[FloatArray]:
        """Run every job; results in order."""
        self.rollouts += len(jobs)
        self.simulated_s += sum(len(j.currents_a) for j in jobs) * 1e-3
        if self.jobs == 1 or len(jobs) == 1:
            return [simulate(j) for j in jobs]
        if self._pool is None:
            self._pool = ProcessPoolExecutor(self.jobs, initializer=_init_worker)
        # Longest first: the pool's tail is then short.
        order = sorted(range(len(jobs)), key=lambda i: -len(jobs[i].currents_a))
        results = list(self._pool.map(simulate, [jobs[i] for i in order], chunksize=1))
        out: list[FloatArray] = [np.empty(0)] * len(jobs)
        for i, res in zip(order, results, strict=True):
            out[i] = res
        return out

    def close(self) -> None:
        """Stop the workers."""
        pool, self._pool = self._pool, None
        if pool is not None:
            pool.shutdown(wait=True, cancel_futures=True)

    def __enter__(self) -> RolloutPool:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()
