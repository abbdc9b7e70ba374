"""What the grasp experiments (strategy, grasp-range, load) share: their grasps run over the workers, and
results made of grasp outcomes."""

from __future__ import annotations

from hil.experiments.base import Conditions
from hil.experiments.parallel import parallel_map
from hil.trial.grasp import GraspOutcome, GraspSetup, grasp_trial_job


def grasp_trials(setups: list[GraspSetup], on: Conditions) -> tuple[GraspOutcome, ...]:
    """:func:`~hil.trial.grasp.grasp_trial` of every setup on ``on.design``, over ``on.jobs`` workers."""
    return tuple(parallel_map(grasp_trial_job, [(s, on.design) for s in setups], on.jobs, on.progress))
