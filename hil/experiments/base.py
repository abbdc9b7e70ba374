"""The shape every experiment shares: its parameters per size, its run, and its result.

An experiment is one module that declares

- its parameters, a frozen dataclass (``PackingParams``), with one set per size (:class:`Sizes`);
- its run, ``run(params, conditions) -> result``: a pure function of its parameters and the
  :class:`Conditions` (the arm, the plant model, the seed, the worker processes);
- its result, a frozen, picklable dataclass that is a :class:`Result`: JSON-ready, the worst physics of
  its trials, its table rows next to the paper's, its sample counts in words and its figure;

and ends with its :class:`Experiment`, which :mod:`hil.experiments.catalogue` lists.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Generic, Protocol, TypeVar

from hil.experiments.common import DEFAULT_MODEL, Progress, Row, sized
from hil.sim.config import ModelConfig
from hil.sim.spiral import SpiralDesign
from hil.sim.types import PhysicsExtremes

__all__ = ["Conditions", "Experiment", "Result", "Sizes"]


class Result(Protocol):
    """What an experiment returns (a frozen dataclass: picklable, so campaigns can fan out)."""

    @property
    def seed(self) -> int:
        """The seed it ran with."""

    @property
    def extremes(self) -> PhysicsExtremes:
        """The worst physics over its trials (:meth:`hil.sim.plant.Plant.extremes`): is it trustworthy?"""

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready form (NaN allowed: the command line writes it as null)."""

    def table_rows(self) -> list[Row]:
        """Its numbers next to the paper's, one row each."""

    def describe_samples(self) -> str:
        """Its sample counts, in words."""

    def figure(self, out: Path) -> Path:
        """Write its figure, a PNG, into the directory ``out``; returns the file's path."""


P = TypeVar("P")
R = TypeVar("R", bound=Result)


@dataclass(frozen=True)
class Conditions:
    """What an experiment runs under besides its own parameters.

    Attributes:
        design: the arm (``workspace``'s tapers, ``dynamic``'s 45 cm arm and ``convergence``, which
            measures the plant, use arms of their own).
        model: the plant's model (a preset or a sensitivity variant); objects are appended to it.
        seed: seed of every random choice.
        jobs: worker processes for independent trials.
        progress: ``progress(done, total)`` in work units (trials or simulated milliseconds).
    """

    design: SpiralDesign = field(default_factory=SpiralDesign.paper_prototype)
    model: ModelConfig = DEFAULT_MODEL
    seed: int = 0
    jobs: int = 1
    progress: Progress | None = None


@dataclass(frozen=True)
class Sizes(Generic[P]):
    """An experiment's parameters at each size: ``tiny`` (a smoke test of seconds), ``default`` (the
    documented run) and ``large``."""

    tiny: P
    default: P
    large: P

    def pick(self, size: str) -> P:
        """The parameters of ``size``.

        Raises:
            ValueError: ``size`` is not one of :data:`~hil.experiments.common.SIZES`.
        """
        return sized(size, self.tiny, self.default, self.large)


@dataclass(frozen=True)
class Experiment(Generic[P, R]):
    """One experiment of the catalogue.

    Attributes:
        name: the command-line word.
        summary: one line.
        sizes: its parameters at each size.
        run: ``run(params, conditions) -> result``, pure.
        model: the plant model it runs on unless given one: the experiments' fine physics
            (:data:`~hil.experiments.common.DEFAULT_MODEL`), or the board's for ``convergence``, which
            varies the step under the board's constraint time constants.
        own_arm: the arms it drives whatever :attr:`Conditions.design` is, in words (empty: it runs on the
            design it is given); the command line refuses design options for such an experiment rather
            than print figures of other arms.
    """

    name: str
    summary: str
    sizes: Sizes[P]
    run: Callable[[P, Conditions], R]
    model: ModelConfig = DEFAULT_MODEL
    own_arm: str = ""

    def run_at_size(self, size: str, conditions: Conditions) -> R:
        """Run at ``size`` (see :class:`Sizes`).

        Raises:
            ValueError: an unknown size.
        """
        return self.run(self.sizes.pick(size), conditions)
