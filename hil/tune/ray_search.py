"""The search on Ray Tune (``spirob-hil tune --ray`` / ``--ray-address``): the same space, placements,
trial and pruning rule as the local search, with Ray Tune's Optuna search (TPE) and a scheduler that stops
a trial once it cannot beat the best. Ray is imported only here.

Each Ray trial takes one CPU and grasps its training placements one after another, reporting after each
(``score``: its successes over all the placements once it ran them all, and before that its successes
minus the set's size over the size, negative, so that a trial the scheduler stopped is told to the study
below every full one; ``successes``, ``done``). The Optuna study lives
in a journal file in the ``--storage`` directory (Ray Tune's own experiment directory beside it), so a
``--resume`` goes on with the same study; a trial that ran all its placements is one whose last
reported step is the set's size.
"""

from __future__ import annotations

import json
import os
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import optuna
import ray
from optuna.storages import JournalStorage
from optuna.storages.journal import JournalFileBackend
from optuna.trial import FrozenTrial, TrialState
from ray import tune
from ray.tune.schedulers import FIFOScheduler, TrialScheduler
from ray.tune.search.optuna import OptunaSearch

from hil.campaign.runner import init_ray, run_one
from hil.tune.objective import Placement, TuneSpec, hopeless, runs_for
from hil.tune.search import SPEC_ATTR, TuneError
from hil.tune.space import baseline_points, firmware_values, suggest

__all__ = ["load_study", "search_ray"]

JOURNAL = "study.journal"
"""The Optuna journal's name in the ``--storage`` directory."""


class _BoundScheduler(FIFOScheduler):  # type: ignore[misc]
    """FIFO, but a trial that cannot beat the best finished one (:func:`hopeless`) is stopped."""

    def __init__(self, n: int, rule: str, best: int | None) -> None:
        super().__init__()
        self.n = n
        self.rule = rule
        self.best = best

    def on_trial_result(self, tune_controller: Any, trial: Any, result: dict[str, Any]) -> str:
        done, k = int(result["done"]), int(result["successes"])
        if done >= self.n:
            self.best = k if self.best is None else max(self.best, k)
            return str(TrialScheduler.CONTINUE)
        if hopeless(k, done, self.n, self.best, self.rule):
            return str(TrialScheduler.STOP)
        return str(TrialScheduler.CONTINUE)


class _Journal(JournalStorage):  # type: ignore[misc]
    """Optuna's journal storage, picklable by its path (Ray Tune pickles the searcher with the tuner)."""

    def __init__(self, path: str) -> None:
        self.path = path
        super().__init__(JournalFileBackend(path))

    def __reduce__(self) -> tuple[Any, tuple[str]]:
        return (_Journal, (self.path,))


_STOPS: dict[int, threading.Event] = {}
"""The stop events of the searches in this process, by id (an event does not pickle; the tuner does)."""


class _Budget(tune.Stopper):  # type: ignore[misc]
    """Stops the whole search on Ctrl-C (``stop``) or once the budget has passed."""

    def __init__(self, stop: threading.Event, budget_s: float | None) -> None:
        _STOPS[id(stop)] = stop
        self.stop_id = id(stop)
        self.deadline = None if budget_s is None else time.monotonic() + budget_s

    @property
    def stop(self) -> threading.Event:
        return _STOPS.get(self.stop_id) or threading.Event()

    def __call__(self, trial_id: str, result: dict[str, Any]) -> bool:
        return False

    def stop_all(self) -> bool:
        return self.stop.is_set() or (self.deadline is not None and time.monotonic() >= self.deadline)


def _space(trial: Any) -> None:
    """Ray Tune's define-by-run space: the trial's parameters are the searched keys (module level: the
    searcher is pickled with plain ``pickle``)."""
    suggest(trial)


def load_study(storage: Path, name: str) -> optuna.Study | None:
    """The study ``name`` of a Ray search's ``--storage`` directory (None: there is none)."""
    path = storage / JOURNAL
    if not path.is_file():
        return None
    journal = _Journal(str(path))
    if name not in {s.study_name for s in journal.get_all_studies()}:
        return None
    return optuna.load_study(study_name=name, storage=journal)


def _full(t: FrozenTrial, n: int) -> bool:
    """The trial ran every placement (a trial the scheduler stopped ends on a negative score)."""
    return t.state == TrialState.COMPLETE and t.value is not None and t.value >= 0


def _trainable(spec: TuneSpec, train: list[Placement]) -> Callable[[dict[str, Any]], None]:
    n = len(train)

    def run(config: dict[str, Any]) -> None:
        runs = runs_for(firmware_values(config), train, spec)
        k = 0
        for i, r in enumerate(runs, start=1):
            k += run_one(r)["outcome"] == "success"
            # A stopped trial's last score is below every full one's: the study tells them apart by it.
            score = k / n if i == n else (k - n) / n
            tune.report({"score": score, "successes": k, "done": i})

    return run


def search_ray(
    spec: TuneSpec,
    train: list[Placement],
    *,
    name: str,
    storage: Path,
    resume: bool,
    trials: int,
    budget_s: float | None,
    jobs: int,
    address: str | None,
    stop: threading.Event,
    say: Callable[[str], None],
) -> tuple[dict[str, Any] | None, int, int, int]:
    """Search on Ray Tune until the study has ``trials`` trials, the budget passed or ``stop`` is set.

    Returns:
        The best full trial's firmware values (None if none), its successes, the study's trials, and how
        many of them stopped early.

    Raises:
        TuneError: the storage holds the study and not ``resume`` (or the reverse), another question,
            or Ray cannot be started or reached.
    """
    n = len(train)
    optuna.logging.set_verbosity(optuna.logging.WARNING)
    storage.mkdir(parents=True, exist_ok=True)
    journal = _Journal(str(storage / JOURNAL))
    names = {s.study_name for s in journal.get_all_studies()}
    if (name in names) != resume:
        raise TuneError(
            f"{storage} already has study {name!r}: --resume to go on with it"
            if name in names
            else f"nothing to resume: {storage} has no study {name!r}"
        )
    if resume:
        study = optuna.load_study(study_name=name, storage=journal)
        if json.loads(study.user_attrs.get(SPEC_ATTR, "{}")) != spec.as_dict():
            raise TuneError(f"study {name!r} was made with other placements or rules: give the same options")
        for t in study.get_trials(deepcopy=False, states=(TrialState.RUNNING,)):
            journal.set_trial_state_values(t._trial_id, TrialState.FAIL)
    else:
        study = optuna.create_study(study_name=name, storage=journal, direction="maximize")
        study.set_user_attr(SPEC_ATTR, json.dumps(spec.as_dict()))
    before = study.get_trials(deepcopy=False, states=(TrialState.COMPLETE, TrialState.PRUNED))
    best_before = max(
        (round(t.value * n) for t in before if _full(t, n) and t.value is not None), default=None
    )
    left = trials - len(before)
    if left > 0 and not stop.is_set():
        os.environ["TUNE_DISABLE_SIGINT_HANDLER"] = "1"  # Ctrl-C sets ``stop``; the Stopper ends the run
        why = init_ray(ray, address, jobs)
        if why is not None:
            raise TuneError(why)
        try:
            searcher = OptunaSearch(
                space=_space,
                metric="score",
                mode="max",
                points_to_evaluate=None if resume else list(baseline_points().values()),
                sampler=optuna.samplers.TPESampler(seed=spec.seed + len(before)),
                study_name=name,
                storage=journal,
            )
            tuner = tune.Tuner(
                tune.with_resources(_trainable(spec, train), {"cpu": 1}),
                tune_config=tune.TuneConfig(
                    search_alg=searcher,
                    scheduler=_BoundScheduler(n, spec.prune, best_before),
                    num_samples=left,
                    max_concurrent_trials=jobs,
                ),
                run_config=tune.RunConfig(
                    name="ray",
                    storage_path=str(storage.resolve()),
                    stop=_Budget(stop, budget_s),
                    verbose=0,
                ),
            )
            say(f"tune: {left} trial(s) on Ray Tune ({len(before)} already in {storage / JOURNAL})")
            tuner.fit()
        finally:
            ray.shutdown()
    study = optuna.load_study(study_name=name, storage=journal)
    done = study.get_trials(deepcopy=False, states=(TrialState.COMPLETE, TrialState.PRUNED))
    full = [t for t in done if _full(t, n) and t.value is not None]
    stopped = len(done) - len(full)
    if not full:
        return None, 0, len(done), stopped
    best = max(full, key=lambda t: (t.value, -t.number))
    return firmware_values(best.params), round((best.value or 0.0) * n), len(done), stopped
