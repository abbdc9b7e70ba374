"""A campaign's summary: success rate per design with its Wilson interval (best first) and, for grasp
campaigns, a success map over the object's placement per design (PNG heat maps).

A *design* here is everything a lab chooses (the run's ``design.*`` and ``controller.*`` inputs); the
rate of a design is over everything else the campaign varied (objects, placements, faults, seeds).
"""

from __future__ import annotations

import json
import math
import shutil
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from hil.experiments.common import pyplot, save_figure
from hil.experiments.stats import wilson_interval

if TYPE_CHECKING:
    from hil.render import Pictures

__all__ = ["CHOICE_PREFIXES", "DesignRate", "campaign_pictures", "design_rates", "success_maps"]

CHOICE_PREFIXES = ("design.", "controller.", "array.")
"""Inputs that choose a design (the arm, the plant, the firmware, an array's layout); the rest (the object,
its placement, the seed, faults) are what a design is judged over."""
_MAP_BINS_N = 8
"""The most cells along a placement axis of a map."""


@dataclass(frozen=True)
class DesignRate:
    """How often one design succeeded.

    Attributes:
        choice: the design's ``design.*`` and ``controller.*`` inputs.
        successes: runs that succeeded.
        n: runs that finished (errors excluded).
        errors: runs that raised.
        ci95: Wilson 95 % interval of ``successes / n``.
    """

    choice: Mapping[str, Any]
    successes: int
    n: int
    errors: int
    ci95: tuple[float, float]

    @property
    def rate(self) -> float:
        """``successes / n`` (NaN with no run)."""
        return self.successes / self.n if self.n else math.nan

    @property
    def label(self) -> str:
        """The design as ``name=value`` pairs (``default`` if the campaign varied none)."""
        return " ".join(f"{k.partition('.')[2]}={_fmt(v)}" for k, v in self.choice.items()) or "default"

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready form (NaN as null)."""
        lo, hi = self.ci95
        return {
            "design": dict(self.choice),
            "label": self.label,
            "successes": self.successes,
            "n": self.n,
            "errors": self.errors,
            "rate": None if math.isnan(self.rate) else self.rate,
            "ci95": [None if math.isnan(lo) else lo, None if math.isnan(hi) else hi],
        }


def _fmt(v: Any) -> str:
    return f"{v:g}" if isinstance(v, float) else str(v)


def _choice(row: Mapping[str, Any]) -> dict[str, Any]:
    return {k: v for k, v in row["inputs"].items() if k.startswith(CHOICE_PREFIXES)}


def _group(rows: Iterable[Mapping[str, Any]]) -> dict[str, list[Mapping[str, Any]]]:
    groups: dict[str, list[Mapping[str, Any]]] = {}
    for row in rows:
        groups.setdefault(json.dumps(_choice(row), sort_keys=True), []).append(row)
    return groups


def design_rates(rows: Iterable[Mapping[str, Any]]) -> list[DesignRate]:
    """Success rate of every design in ``rows``, best first: by the Wilson interval's lower end (a rate
    measured on few runs ranks below the same rate on many), then the rate, then the run count."""
    out = []
    for members in _group(rows).values():
        finished = [r for r in members if r["outcome"] != "error"]
        k = sum(r["outcome"] == "success" for r in finished)
        lo, hi = wilson_interval(k, len(finished))
        out.append(DesignRate(_choice(members[0]), k, len(finished), len(members) - len(finished), (lo, hi)))

    def rank(d: DesignRate) -> tuple[float, float, int]:
        lo = d.ci95[0]
        return (-1.0 if math.isnan(lo) else lo, -1.0 if math.isnan(d.rate) else d.rate, d.n)

    return sorted(out, key=rank, reverse=True)


def _edges(values: Sequence[float]) -> np.ndarray:
    """Cell edges of one placement axis: one cell per value of an evenly spaced axis (a grid's) of at
    most :data:`_MAP_BINS_N` values, else that many even bins (a random sample's)."""
    distinct = np.asarray(sorted(set(values)), dtype=np.float64)
    if len(distinct) == 1:
        return np.asarray([distinct[0] - 0.005, distinct[0] + 0.005])
    steps = np.diff(distinct)
    if len(distinct) <= _MAP_BINS_N and np.ptp(steps) <= 0.01 * steps.mean():
        half = steps[0] / 2
        return np.append(distinct - half, distinct[-1] + half)
    return np.linspace(distinct[0], distinct[-1], min(_MAP_BINS_N, len(distinct)) + 1)


def success_maps(rows: Sequence[Mapping[str, Any]], out_dir: Path) -> list[Path]:
    """Write one PNG heat map per design of a grasp campaign: the success rate in each cell of the
    object's placement (``object.x_m`` across, ``object.z_m`` up, millimetres), each cell marked with its
    ``successes/runs``. Files ``map_01.png`` ... in the order of :func:`design_rates`.

    Returns:
        The files written (none for a scenario campaign, or no finished run).
    """
    placed = [r for r in rows if r["outcome"] != "error" and "object.x_m" in r["inputs"]]
    if not placed:
        return []
    x_edges = _edges([r["inputs"]["object.x_m"] for r in placed])
    z_edges = _edges([r["inputs"]["object.z_m"] for r in placed])
    groups = _group(placed)
    plt = pyplot()
    paths = []
    for i, design in enumerate(design_rates(placed), start=1):
        members = groups[json.dumps(dict(design.choice), sort_keys=True)]
        x = np.asarray([r["inputs"]["object.x_m"] for r in members])
        z = np.asarray([r["inputs"]["object.z_m"] for r in members])
        ok = np.asarray([r["outcome"] == "success" for r in members], dtype=np.float64)
        runs_n, _, _ = np.histogram2d(x, z, bins=(x_edges, z_edges))
        wins_n, _, _ = np.histogram2d(x, z, bins=(x_edges, z_edges), weights=ok)
        with np.errstate(invalid="ignore", divide="ignore"):
            rate = np.where(runs_n > 0, wins_n / runs_n, np.nan)
        fig, ax = plt.subplots(figsize=(5.5, 4.5))
        mesh = ax.pcolormesh(x_edges * 1e3, z_edges * 1e3, rate.T, cmap="RdYlGn", vmin=0.0, vmax=1.0)
        fig.colorbar(mesh, ax=ax, label="success rate")
        for xi in range(len(x_edges) - 1):
            for zi in range(len(z_edges) - 1):
                if runs_n[xi, zi] > 0:
                    cx = (x_edges[xi] + x_edges[xi + 1]) / 2 * 1e3
                    cz = (z_edges[zi] + z_edges[zi + 1]) / 2 * 1e3
                    text = f"{wins_n[xi, zi]:.0f}/{runs_n[xi, zi]:.0f}"
                    ax.text(cx, cz, text, ha="center", va="center", fontsize=8)
        ax.set_xlabel("object x from the base [mm]")
        ax.set_ylabel("object z from the base [mm]")
        lo, hi = design.ci95
        ax.set_title(
            f"{design.label}\n{design.successes}/{design.n} succeeded (95 % CI {lo:.2f}-{hi:.2f})",
            fontsize=9,
        )
        paths.append(save_figure(fig, out_dir / f"map_{i:02d}.png"))
    return paths


def campaign_pictures(
    rows: Sequence[Mapping[str, Any]], out_dir: Path
) -> tuple[list[tuple[str, Any]], list[str]]:
    """Pictures of a campaign's representative runs: the best design's first success and the campaign's
    first failure, each run again and shown only if it measures exactly what its row recorded (a grasp
    filmed by :func:`hil.render.film_grasp_trial`; a scenario with its own report in ``run-success/`` or
    ``run-failure/``, linked from the notes).

    Returns:
        ``([(heading, Pictures), ...], notes)`` for :func:`hil.report.write_index`.
    """
    from hil.render import NO_GL, Pictures, gl_backends

    finished = [r for r in rows if r["outcome"] != "error"]
    if not finished:
        return [], ["no run finished: no pictures"]
    best = design_rates(finished)[0]
    picks = [
        (
            "success",
            next(
                (r for r in finished if r["outcome"] == "success" and _choice(r) == dict(best.choice)), None
            ),
        ),
        ("failure", next((r for r in finished if r["outcome"] == "failure"), None)),
    ]
    out: list[tuple[str, Pictures]] = []
    notes: list[str] = []
    for label, row in picks:
        if row is None:
            continue
        i = row["inputs"]
        if i["kind"] == "array":
            notes.append(
                f"a {label}: {_label(row)}, seed {i['seed']} (run {row['key']}); array runs are not filmed"
            )
            continue
        if i["kind"] != "grasp":
            notes += _scenario_pictures(label, row, out_dir / f"run-{label}")
            continue
        if not gl_backends():  # MUJOCO_GL=disable: no trial is run again for nothing
            out.append(("", Pictures(note=NO_GL)))
            break
        heading = (
            f"a {label}: {_label(row)}; object {1000 * i['object.diameter_m']:.0f} mm at "
            f"x = {1000 * i['object.x_m']:.0f} mm, z = {1000 * i['object.z_m']:.0f} mm, seed {i['seed']} "
            f"(run {row['key']})"
        )
        out.append((heading, grasp_row_pictures(row, out_dir, f"run-{label}")))
    return out, notes


def grasp_row_pictures(row: Mapping[str, Any], out_dir: Path, name: str) -> Pictures:
    """A grasp campaign row run again, filmed (its design and firmware values from its inputs), and
    rendered as ``out_dir/NAME-*`` only if it measures exactly what the row recorded
    (:func:`hil.render.film_grasp_trial`); otherwise the one line saying what differed."""
    from hil.campaign.runner import grasp_setup
    from hil.render import RERUN, Pictures, film_grasp_trial, render_film

    setup, design = grasp_setup(row["inputs"])
    film, note = film_grasp_trial(setup, design, row["measured"])
    return Pictures(note=note) if film is None else render_film(film, out_dir, name, source=RERUN)


def _scenario_pictures(label: str, row: Mapping[str, Any], out_dir: Path) -> list[str]:
    """A scenario run again with its report into ``out_dir``, kept only if it measures what its row
    recorded; the index's lines about it."""
    from hil.campaign.runner import scenario_measured
    from hil.render import same_measurements

    i = row["inputs"]
    name = i["scenario.name"]
    lines = [f"### a {label}: scenario {name}, {_label(row)}, seed {i['seed']} (run {row['key']})", ""]
    measured, report = scenario_measured(i, report_dir=out_dir)
    differ = same_measurements(row["measured"], measured)
    if differ:
        shutil.rmtree(out_dir, ignore_errors=True)
        return [
            *lines,
            f"re-run differs from the recorded run ({', '.join(differ[:3])}): pictures skipped",
            "",
        ]
    link = f"{out_dir.name}/{name}.md"
    return [*lines, f"its report: [{link}]({link})", "", *report, ""]


def _label(row: Mapping[str, Any]) -> str:
    return " ".join(f"{k.partition('.')[2]}={_fmt(v)}" for k, v in _choice(row).items()) or "default design"
