"""The catalogue: every experiment by its command-line name (each module's
:class:`~hil.experiments.base.Experiment`), and :func:`run_experiment`."""

from __future__ import annotations

from typing import Protocol

from hil.experiments import (
    array,
    bands,
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
from hil.experiments.base import Conditions, Result
from hil.experiments.common import Progress
from hil.sim.config import ModelConfig
from hil.sim.spiral import SpiralDesign

__all__ = ["EXPERIMENTS", "Entry", "run_experiment"]


class Entry(Protocol):
    """What the catalogue and the command line use of an :class:`~hil.experiments.base.Experiment`, whatever
    the type of its parameters."""

    @property
    def name(self) -> str:
        """The command-line word."""

    @property
    def summary(self) -> str:
        """One line."""

    @property
    def model(self) -> ModelConfig:
        """The plant model it runs on unless given one."""

    @property
    def own_arm(self) -> str:
        """The arms it drives whatever the design given, in words; empty when it runs on that design."""

    def run_at_size(self, size: str, conditions: Conditions) -> Result:
        """Run at ``size``."""


_ALL: tuple[Entry, ...] = (
    workspace.EXPERIMENT,
    packing.EXPERIMENT,
    strategy.EXPERIMENT,
    contact.EXPERIMENT,
    grasp_range.EXPERIMENT,
    load.EXPERIMENT,
    dynamic.EXPERIMENT,
    sensitivity.EXPERIMENT,
    convergence.EXPERIMENT,
    array.EXPERIMENT,
    bands.EXPERIMENT,
)

EXPERIMENTS: dict[str, Entry] = {e.name: e for e in _ALL}
"""Every experiment, by command-line name."""


def run_experiment(
    name: str,
    *,
    design: SpiralDesign | None = None,
    size: str = "default",
    seed: int = 0,
    progress: Progress | None = None,
    jobs: int = 1,
    model: ModelConfig | None = None,
) -> Result:
    """Run the experiment ``name`` at ``size`` on the plant ``model`` (default: the experiment's own,
    :attr:`Entry.model`; pure; the result is frozen and picklable).

    Raises:
        KeyError: unknown experiment.
        ValueError: unknown size.
    """
    exp = EXPERIMENTS[name]
    design = design or SpiralDesign.paper_prototype()
    on = Conditions(design, model or exp.model, seed, max(1, jobs), progress)
    return exp.run_at_size(size, on)
