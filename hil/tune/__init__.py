"""``spirob-hil tune``: a search of the grasp controller's firmware parameters for the highest grasp success
on a training set of placements, judged on held-out placements (``docs/tune.md``).

:mod:`hil.tune.space` is what is searched, :mod:`hil.tune.objective` the placements and how one set of
parameters is scored (grasp trials, pruned on a bound), :mod:`hil.tune.search` the local Optuna study,
:mod:`hil.tune.ray_search` the same on Ray Tune (imported only for ``--ray``), :mod:`hil.tune.heldout`
the held-out comparison and the parameter file it writes.
"""
