"""Experiments that reproduce the paper's simulation results with the plant and the firmware (issue 8).

Each experiment is a pure function of ``(design, params, seed, model)`` (``model``: the plant's
:class:`~hil.sim.config.ModelConfig`, a preset or a variant) that runs the virtual board in
lockstep (firmware + plant, :class:`hil.board.VirtualBoard`) and returns a frozen, picklable result with
``as_dict()``; a ``progress(done, total)`` callback reports how far it is. Each experiment is one module
(its parameters, its run, its table rows and its figure); the geometry, the statistics and the parallel
map they share have their own, and the trial code they share with campaigns (the rig, the grasp trial, the
45 cm arm) is :mod:`hil.trial`. ``spirob-hil experiment NAME`` (:mod:`hil.cli.experiment`)
prints each number next to the paper's prediction and, with ``--report DIR``, writes a PNG.

=============  ==========================================  =============================================
name           paper                                       what runs through the firmware
=============  ==========================================  =============================================
workspace      Note S2, Fig. 2E / S4: envelope ρw          random per-cable tensions (DIRECT mode, host
                                                           commands over the board link), 2 and 3 cables,
                                                           three taper angles
packing        Note S3, Fig. S5C: packed spiral = design b one cable's tension ramped (DIRECT) until every
                                                           joint sits at its limit
strategy       Note S4, Fig. S6, Fig. 3C                   the GRASP state machine (left lever): strategy
                                                           off, on, on with the true-contact oracle, at
                                                           the same jittered placements; Wilson, McNemar
contact        (issue 13: the detector, not in the paper)  the strategy's reach at its placements, old
                                                           and new contact detector against the true
                                                           contact: precision, recall (Wilson), delay
                                                           (bootstrap)
grasp-range    eq. (14), (15): d_min, d_max                a strategy-on grasp, then a growing pull along
                                                           +x: pull-out force vs. diameter, bootstrap CI
load           eq. (16), Fig. 2F: M(φ, d, F_max)           grasps at 2.5-20 N and friction 0-0.8, then a
                                                           growing downward load: slope of held mass vs. F
dynamic        Fig. S11: 0.06 s grasp, 120 ms capture      45 cm arm: a current step on one cable
                                                           (DIRECT); thrown objects with cable 0 held at
                                                           length (HOLD_LENGTHS) or at a tension; Wilson
sensitivity    which conclusions survive ±50 % on the      packing, dynamic and strategy re-run per
               model's uncertain parameters                variant of the model; holds / fails table
=============  ==========================================  =============================================

Geometry: :mod:`hil.trial.scene` (the arm hangs along −z under the drone, cable 0 on its +x side; object
positions are relative to the arm's base, in the x-z plane).
"""

from __future__ import annotations

from hil.experiments.catalogue import EXPERIMENTS, Experiment, run_experiment
from hil.experiments.common import SIZES, Progress
from hil.experiments.dynamic import DynamicParams, DynamicResult
from hil.experiments.geometry import Envelope, base_first_tip_curve, fit_log_spiral
from hil.experiments.grasp_range import GraspRangeParams, GraspRangeResult
from hil.experiments.load import LoadParams, LoadResult
from hil.experiments.packing import PackingParams, PackingResult
from hil.experiments.strategy import StrategyParams, StrategyResult
from hil.experiments.workspace import WorkspaceParams, WorkspaceResult

__all__ = [
    "EXPERIMENTS",
    "SIZES",
    "DynamicParams",
    "DynamicResult",
    "Envelope",
    "Experiment",
    "GraspRangeParams",
    "GraspRangeResult",
    "LoadParams",
    "LoadResult",
    "PackingParams",
    "PackingResult",
    "Progress",
    "StrategyParams",
    "StrategyResult",
    "WorkspaceParams",
    "WorkspaceResult",
    "base_first_tip_curve",
    "fit_log_spiral",
    "run_experiment",
]
