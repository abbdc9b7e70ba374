"""Trial code that experiments and campaigns share: the rig a trial runs in, the scene it is set in, the grasp
trial, and the paper's 45 cm arm.

- :mod:`hil.trial.scene`: units of board time, where the drone, the arm's base and a waiting object are,
  and what counts as held;
- :mod:`hil.trial.rig`: :class:`~hil.trial.rig.Rig`, the one lockstep loop built from what a trial varies
  (design, firmware, radio script, objects, plant model), and :func:`~hil.trial.rig.direct_rig`;
- :mod:`hil.trial.grasp`: one grasp through the firmware's GRASP mode, measured
  (:func:`~hil.trial.grasp.grasp_trial` of a :class:`~hil.trial.grasp.GraspSetup`);
- :mod:`hil.trial.arm_45cm`: the 2-cable 45 cm arm of Fig. S11 and the prototype's model scaled to it.

Experiments (:mod:`hil.experiments`) and campaigns (:mod:`hil.campaign`) import these; nothing here knows
either of them.
"""
