"""How ``spirob-hil tune`` scores one set of firmware values: the grasp experiments' trial at every placement
of a set, counted by the experiments' success criterion, stopped early when it cannot beat the best.

Placements: per diameter and jitter seed, one jittered point per cell of a grid over a region beside the
arm, clear of the packed coil and the straight arm (the strategy experiment's
:func:`~hil.experiments.geometry.jittered_placements`). The training set and the held-out set are drawn
from independent random streams of the one seed, so the held-out placements are never seen by the search.

A grasp is one campaign run (:func:`hil.campaign.runner.run_one`: the same trial, physics and success as
``spirob-hil campaign``), so the rows are the campaign's and the local executor is the campaign's.
"""

from __future__ import annotations

import dataclasses
import json
import math
import threading
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from hil.campaign.runner import ResultsFile, execute_local
from hil.campaign.spec import Run, build_design, run_key
from hil.experiments.geometry import ArmFootprint, jittered_placements
from hil.experiments.stats import wilson_interval

__all__ = [
    "PRUNE_RULES",
    "Evaluation",
    "Placement",
    "TuneSpec",
    "evaluate",
    "hopeless",
    "placement_sets",
    "runs_for",
]

PRUNE_RULES = ("bound", "wilson", "none")
"""``bound``: stop a trial's placements once even all the remaining ones succeeding cannot beat the best
trial; ``wilson``: also once the Wilson 95 % upper bound of its rate so far (after at least
:data:`WILSON_MIN_N` placements) is below the best trial's rate; ``none``: every placement runs."""
WILSON_MIN_N = 4
"""The fewest placements the ``wilson`` rule judges a rate on."""

Placement = tuple[float, float, float]
"""``(x_m, z_m, diameter_m)`` of one object (the grasp trial's scene, ``hil.trial.scene``)."""


@dataclass(frozen=True)
class TuneSpec:
    """Everything that fixes a tuning's question (stored with the study: a resume must ask the same).

    Attributes:
        preset: the plant model's preset (``spirob-hil design --help``).
        diameters_m: object diameters.
        x_range_m: object centres' horizontal distance from the arm's axis, low and high.
        z_range_m: object centres' height relative to the base (negative = below), low and high.
        grid: cells along x and z; one jittered placement per cell, diameter and jitter seed.
        train_seeds: jitter seeds of the training set.
        test_seeds: jitter seeds of the held-out set.
        seed: seed of both sets' random streams (and of the search's sampler).
        clearance_m: smallest gap between a placed object and the packed or straight arm.
        mass_kg: object mass.
        prune: one of :data:`PRUNE_RULES`.
    """

    preset: str = "prototype"
    diameters_m: tuple[float, ...] = (0.016, 0.024, 0.036)
    x_range_m: tuple[float, float] = (0.02, 0.07)
    z_range_m: tuple[float, float] = (-0.18, -0.06)
    grid: tuple[int, int] = (3, 2)
    train_seeds: int = 1
    test_seeds: int = 1
    seed: int = 0
    clearance_m: float = 0.002
    mass_kg: float = 0.02
    prune: str = "bound"

    def __post_init__(self) -> None:
        if self.prune not in PRUNE_RULES:
            raise ValueError(f"prune must be one of {', '.join(PRUNE_RULES)}, got {self.prune!r}")
        if not self.diameters_m or any(not (d > 0 and math.isfinite(d)) for d in self.diameters_m):
            raise ValueError(f"diameters must be > 0, got {self.diameters_m}")
        for name, (lo, hi) in (("x range", self.x_range_m), ("z range", self.z_range_m)):
            if not (math.isfinite(lo) and math.isfinite(hi) and lo <= hi):
                raise ValueError(f"{name} wants LOW <= HIGH, got {lo}, {hi}")
        if min(self.grid) < 1 or max(self.grid) > 20:
            raise ValueError(f"grid cells must be 1..20 per axis, got {self.grid[0]}x{self.grid[1]}")
        if not (1 <= self.train_seeds <= 20 and 1 <= self.test_seeds <= 20):
            raise ValueError("train and test seeds must be 1..20")
        if not self.mass_kg > 0:
            raise ValueError(f"mass must be > 0, got {self.mass_kg}")

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready form (lists for tuples)."""
        out: dict[str, Any] = json.loads(json.dumps(dataclasses.asdict(self)))
        return out

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> TuneSpec:
        """Inverse of :meth:`as_dict`."""
        tuples = {"diameters_m", "x_range_m", "z_range_m", "grid"}
        fields: dict[str, Any] = {k: tuple(v) if k in tuples else v for k, v in d.items()}
        return cls(**fields)

    def describe(self) -> str:
        """The placement sets in words."""
        per = self.grid[0] * self.grid[1] * len(self.diameters_m)
        ds = "/".join(f"{d * 1000:g}" for d in self.diameters_m)
        return (
            f"{self.preset} plant, {ds} mm cylinders of {self.mass_kg * 1000:g} g, centres "
            f"{self.x_range_m[0] * 1000:g}-{self.x_range_m[1] * 1000:g} mm from the axis and "
            f"{-self.z_range_m[1] * 1000:g}-{-self.z_range_m[0] * 1000:g} mm below the base, "
            f"{self.grid[0]}x{self.grid[1]} jittered cells: {per * self.train_seeds} training and "
            f"{per * self.test_seeds} held-out placements (seed {self.seed})"
        )


def placement_sets(spec: TuneSpec) -> tuple[list[Placement], list[Placement]]:
    """The training and held-out placements of ``spec`` (each shuffled, so a pruned trial has seen every
    diameter and region).

    Raises:
        ValueError: the region is blocked by the arm for a diameter.
    """
    design, model = build_design({"design.preset": spec.preset}, physics="fine")
    foot = ArmFootprint.of(design, model)
    sets: list[list[Placement]] = []
    for role, seeds in ((0, spec.train_seeds), (1, spec.test_seeds)):
        out: list[Placement] = []
        for d in spec.diameters_m:
            for s in range(seeds):
                rng = np.random.default_rng([spec.seed, role, s, round(d * 1e6)])
                cells = jittered_placements(
                    foot, d, spec.x_range_m, spec.z_range_m, spec.grid, rng, spec.clearance_m
                )
                out.extend((round(x, 6), round(z, 6), d) for x, z in cells)
        order = np.random.default_rng([spec.seed, role, 99]).permutation(len(out))
        sets.append([out[i] for i in order])
    return sets[0], sets[1]


def runs_for(values: Mapping[str, Any], placements: Sequence[Placement], spec: TuneSpec) -> list[Run]:
    """One campaign grasp run per placement with the firmware ``values`` (flat keys) on top of the grasp
    experiments' firmware (``grasp_strategy_on`` becomes the trial's ``strategy_on``)."""
    out = []
    for x, z, d in placements:
        inputs: dict[str, Any] = {
            "kind": "grasp",
            "design.preset": spec.preset,
            "object.diameter_m": d,
            "object.x_m": x,
            "object.z_m": z,
            "object.mass_kg": spec.mass_kg,
        }
        for k, v in sorted(values.items()):
            inputs["controller.strategy_on" if k == "grasp_strategy_on" else f"controller.{k}"] = v
        inputs["seed"] = 0
        out.append(Run(run_key(inputs), inputs))
    return out


def hopeless(successes: int, done: int, n: int, best: int | None, rule: str) -> bool:
    """A trial with ``successes`` of ``done`` placements (of ``n``) cannot beat the best trial's ``best``
    successes (None: no finished trial yet), by ``rule`` (:data:`PRUNE_RULES`)."""
    if best is None or rule == "none":
        return False
    if successes + (n - done) <= best:
        return True
    if rule == "wilson" and done >= WILSON_MIN_N and done < n:
        return wilson_interval(successes, done)[1] < best / n
    return False


@dataclass
class Evaluation:
    """One set of values scored on a set of placements.

    Attributes:
        n: placements in the set.
        rows: the campaign rows that finished (by run key).
        pruned: stopped early: it could not beat the best.
        interrupted: stopped by Ctrl-C.
        wall_s: wall time.
        cached: the run keys taken from the cache (not grasped now).
    """

    n: int
    rows: dict[str, dict[str, Any]] = field(default_factory=dict)
    cached: set[str] = field(default_factory=set)
    pruned: bool = False
    interrupted: bool = False
    wall_s: float = 0.0

    @property
    def done(self) -> int:
        """Placements finished."""
        return len(self.rows)

    @property
    def successes(self) -> int:
        """Grasps that succeeded (the experiments' criterion); an ``error`` row is not a success."""
        return sum(r["outcome"] == "success" for r in self.rows.values())

    @property
    def errors(self) -> int:
        """Runs that raised."""
        return sum(r["outcome"] == "error" for r in self.rows.values())

    @property
    def complete(self) -> bool:
        """Every placement ran."""
        return self.done == self.n

    def outcomes(self, runs: Sequence[Run]) -> list[bool | None]:
        """Per run of ``runs``, success (None: not run)."""
        return [None if r.key not in self.rows else self.rows[r.key]["outcome"] == "success" for r in runs]


Executor = Callable[[Sequence[Run], int, threading.Event], Iterator[dict[str, Any]]]


def _local(runs: Sequence[Run], jobs: int, stop: threading.Event) -> Iterator[dict[str, Any]]:
    return execute_local(runs, jobs, stop)


def evaluate(
    runs: Sequence[Run],
    *,
    jobs: int,
    stop: threading.Event,
    best: int | None = None,
    rule: str = "bound",
    cache: ResultsFile | None = None,
    on_row: Callable[[Evaluation], None] | None = None,
    executor: Executor = _local,
) -> Evaluation:
    """Run ``runs`` (one placement each) until all finished, the trial is :func:`hopeless` against
    ``best`` successes, or ``stop`` is set.

    Rows already in ``cache`` are taken from it (the same inputs, the same run key); each new row is
    appended to it as it finishes, so an interruption keeps what finished.
    """
    ev = Evaluation(len(runs))
    t0 = time.perf_counter()
    todo = []
    for r in runs:
        if cache is not None and r.key in cache.done:
            ev.rows[r.key] = cache.done[r.key]
            ev.cached.add(r.key)
        else:
            todo.append(r)

    def judged() -> bool:
        ev.pruned = not ev.complete and hopeless(ev.successes, ev.done, ev.n, best, rule)
        return ev.pruned

    if todo and not judged():
        rows = executor(todo, jobs, stop)
        try:
            for row in rows:
                ev.rows[row["key"]] = row
                if cache is not None:
                    cache.append(row)
                if on_row is not None:
                    on_row(ev)
                if judged():
                    break
        finally:
            close = getattr(rows, "close", None)
            if close is not None:
                close()  # stops the workers of a pruned or interrupted trial
    ev.interrupted = stop.is_set() and not ev.complete and not ev.pruned
    ev.wall_s = time.perf_counter() - t0
    return ev
