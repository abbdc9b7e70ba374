"""Experiments that reproduce the paper's simulation results with the plant and the firmware (issue 8).

Each experiment is one module with one shape (:mod:`hil.experiments.base`): its parameters per size, its
run, a pure function of ``(params, conditions)`` (the conditions: the design, the plant's
:class:`~hil.sim.config.ModelConfig` (a preset or a variant), the seed, the workers, a
``progress(done, total)`` callback) that runs the virtual board in lockstep (firmware + plant,
:class:`hil.board.VirtualBoard`), and its result: frozen, picklable, with ``as_dict()``, the worst physics of
its trials, its table rows and its figure. :mod:`hil.experiments.catalogue` lists them. The geometry, the
statistics, the parallel map and the grasp experiments' outcomes they share have modules of their own, and
the trial code they share with campaigns (the rig, the grasp trial, the 45 cm arm) is :mod:`hil.trial`.
``spirob-hil experiment NAME`` (:mod:`hil.cli.experiment`) prints each number next to the paper's
prediction and, with ``--report DIR``, writes a PNG.

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
convergence    (not in the paper: is the step fine?)       the bare plant, no firmware: packing tension,
                                                           a pen's half wrap, penetrations and tension
                                                           extremes at 1, 0.5 and 0.25 ms physics steps
=============  ==========================================  =============================================

Geometry: :mod:`hil.trial.scene` (the arm hangs along −z under the drone, cable 0 on its +x side; object
positions are relative to the arm's base, in the x-z plane).
"""
