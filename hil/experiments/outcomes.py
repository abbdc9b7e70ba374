"""What the grasp experiments (strategy, grasp-range, load) share: their grasps run over the workers, and
the part of their results that is the grasp outcomes."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from hil.experiments.base import Conditions
from hil.experiments.common import Row, worst_extremes
from hil.experiments.parallel import parallel_map
from hil.sim.types import PhysicsExtremes
from hil.trial.grasp import GraspOutcome, GraspSetup, grasp_trial_job


def grasp_trials(setups: list[GraspSetup], on: Conditions) -> tuple[GraspOutcome, ...]:
    """:func:`~hil.trial.grasp.grasp_trial` of every setup on ``on.design``, over ``on.jobs`` workers."""
    return tuple(parallel_map(grasp_trial_job, [(s, on.design) for s in setups], on.jobs, on.progress))


def placement_row(outcomes: Sequence[GraspOutcome | None]) -> Row:
    """How many of the grasps (None: a grasp left out) put their object inside the arm when placed
    (:attr:`GraspOutcome.placed_inside`), as a table row."""
    inside = sum(o.placed_inside for o in outcomes if o is not None)
    return (
        "objects put inside the arm when placed (not grasps)",
        f"{inside} of {len(outcomes)}",
        "goal 0 (overlap beyond the penetration goal on the tick after placing)",
    )


class GraspOutcomes:
    """The part of a result that is its grasp outcomes (a base of the results' dataclasses)."""

    outcomes: tuple[GraspOutcome, ...]
    """Every grasp, in the order its setup was made."""

    @property
    def extremes(self) -> PhysicsExtremes:
        """The worst physics over every grasp."""
        return worst_extremes(o.extremes for o in self.outcomes)

    @property
    def placed_inside_n(self) -> int:
        """Grasps whose object was put in place inside the arm (:attr:`GraspOutcome.placed_inside`): not
        grasps, so a figure that counts them says so."""
        return sum(o.placed_inside for o in self.outcomes)

    def placement_rows(self) -> list[Row]:
        """The table row that says how many objects were put inside the arm when placed."""
        return [placement_row(self.outcomes)]

    def outcomes_dict(self) -> dict[str, Any]:
        """The grasps, JSON-ready: the worst physics, how many, and each outcome (the tail of ``as_dict``)."""
        return {
            "extremes": self.extremes.as_dict(),
            "trials": len(self.outcomes),
            "placed_inside": self.placed_inside_n,
            "outcomes": [o.as_dict() for o in self.outcomes],
        }
