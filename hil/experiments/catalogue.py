"""The catalogue: every experiment by its CLI name, with its sizes, its table rows and its figure."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from hil.experiments import (
    contact,
    convergence,
    dynamic,
    grasp_range,
    load,
    packing,
    sensitivity,
    strategy,
    workspace,
)
from hil.experiments.common import BOARD_MODEL, DEFAULT_MODEL, Progress, Row, sized
from hil.sim.config import ModelConfig
from hil.sim.spiral import SpiralDesign


@dataclass(frozen=True)
class Experiment:
    """One experiment of the catalogue.

    Attributes:
        name: the CLI word.
        summary: one line.
        run: ``run(design, size, seed, progress, jobs, model)`` -> result (``model``: the plant's model,
            a preset or a sensitivity variant).
        rows: the result's numbers next to the paper's.
        samples: the result's sample counts, in words.
        plot: writes the figure, returns its path.
        model: the plant model it runs on unless given one: the experiments' fine physics
            (:data:`~hil.experiments.common.DEFAULT_MODEL`), or the board's for ``convergence``, which
            varies the step under the board's constraint time constants.
    """

    name: str
    summary: str
    run: Callable[[SpiralDesign, str, int, Progress | None, int, ModelConfig], Any]
    rows: Callable[[Any], list[Row]]
    samples: Callable[[Any], str]
    plot: Callable[[Any, Path], Path]
    model: ModelConfig = DEFAULT_MODEL


EXPERIMENTS: dict[str, Experiment] = {
    e.name: e
    for e in (
        Experiment(
            "workspace",
            "random cable tensions on 2- and 3-cable arms of three tapers vs. the envelope ρw (Note S2)",
            workspace.run_at_size,
            workspace.table_rows,
            workspace.describe_samples,
            workspace.plot_figure,
        ),
        Experiment(
            "packing",
            "one cable's tension ramped until the arm packs: current, fitted b, curl order (Note S3)",
            packing.run_at_size,
            packing.table_rows,
            packing.describe_samples,
            packing.plot_figure,
        ),
        Experiment(
            "strategy",
            "paired grasps, strategy off / on / on with true contact: Wilson intervals, McNemar (Note S4)",
            strategy.run_at_size,
            strategy.table_rows,
            strategy.describe_samples,
            strategy.plot_figure,
        ),
        Experiment(
            "contact",
            "the firmware's contact detector, old and new, vs. the true contact: precision, recall, delay",
            contact.run_at_size,
            contact.table_rows,
            contact.describe_samples,
            contact.plot_figure,
        ),
        Experiment(
            "grasp-range",
            "pull-out force against diameter (bootstrap intervals) vs. d_min, d_max (eq. 14, 15)",
            grasp_range.run_at_size,
            grasp_range.table_rows,
            grasp_range.describe_samples,
            grasp_range.plot_figure,
        ),
        Experiment(
            "load",
            "held mass against wrap force 2.5-20 N at three frictions: slope and interval vs. eq. 16",
            load.run_at_size,
            load.table_rows,
            load.describe_samples,
            load.plot_figure,
        ),
        Experiment(
            "dynamic",
            "45 cm arm: a current step grasps a pen; throws, one cable held at length or tension (Fig. S11)",
            dynamic.run_at_size,
            dynamic.table_rows,
            dynamic.describe_samples,
            dynamic.plot_figure,
        ),
        Experiment(
            "sensitivity",
            "±50 % on stiffness, damping, spool inertia, drive and contact friction: what survives",
            sensitivity.run_at_size,
            sensitivity.table_rows,
            sensitivity.describe_samples,
            sensitivity.plot_figure,
        ),
        Experiment(
            "convergence",
            "packing tension, a pen's half wrap, penetration and tension extremes at 1, 0.5, 0.25 ms steps",
            convergence.run_at_size,
            convergence.table_rows,
            convergence.describe_samples,
            convergence.plot_figure,
            BOARD_MODEL,
        ),
    )
}
"""Every experiment, by CLI name."""


def run_experiment(
    name: str,
    *,
    design: SpiralDesign | None = None,
    size: str = "default",
    seed: int = 0,
    progress: Progress | None = None,
    jobs: int = 1,
    model: ModelConfig | None = None,
) -> Any:
    """Run the experiment ``name`` at ``size`` on the plant ``model`` (default: the experiment's own,
    :attr:`Experiment.model`; pure; the result is frozen and picklable).

    Raises:
        KeyError: unknown experiment.
        ValueError: unknown size.
    """
    exp = EXPERIMENTS[name]
    sized(size, 0, 0, 0)
    return exp.run(
        design or SpiralDesign.paper_prototype(), size, seed, progress, max(1, jobs), model or exp.model
    )
