"""The local search: an Optuna study (TPE) in a journal file under ``runs/``, one trial at a time, each trial
scored on the training placements by :func:`hil.tune.objective.evaluate` over local worker processes.

The study starts from the two controllers it is judged against (the firmware's defaults with the strategy
on and off: :func:`~hil.tune.space.baseline_points`), so its best is never below the better of them on the
training set. A trial that cannot beat the best is pruned (``TrialState.PRUNED``, its successes so far
reported as its value at the step of the placements it ran). The journal is appended as each trial ends:
Ctrl-C or a kill loses only the trial in flight (its finished grasps stay in the rows file), and
``--resume`` goes on with the same study.
"""

from __future__ import annotations

import json
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import optuna
from optuna.storages import JournalStorage
from optuna.storages.journal import JournalFileBackend
from optuna.trial import FrozenTrial, TrialState

from controller.errors import ConfigError
from hil.campaign.runner import ResultsFile
from hil.errors import HilError
from hil.tune.objective import Evaluation, Placement, TuneSpec, evaluate, runs_for
from hil.tune.space import baseline_points, firmware_values, suggest

__all__ = [
    "SPEC_ATTR",
    "TrialLine",
    "TuneError",
    "best_trial",
    "finished_trials",
    "open_study",
    "search_local",
]

SPEC_ATTR = "spirob_tune_spec"
"""The study's user attribute holding its :class:`TuneSpec` (JSON)."""


class TuneError(HilError, ValueError):
    """A tuning that cannot run as asked (reported as one line)."""


@dataclass(frozen=True)
class TrialLine:
    """What one finished trial says on the progress output.

    Attributes:
        number: the study's trial number.
        successes: training successes.
        done: placements run.
        n: training placements.
        state: ``complete``, ``pruned`` or ``failed``.
        best: the best trial's successes after it.
    """

    number: int
    successes: int
    done: int
    n: int
    state: str
    best: int | None

    def text(self) -> str:
        """``trial 4: 7/18 (pruned after 11), best 9/18``."""
        how = f" (pruned after {self.done})" if self.state == "pruned" else ""
        how = " (failed)" if self.state == "failed" else how
        best = "-" if self.best is None else f"{self.best}/{self.n}"
        return f"trial {self.number}: {self.successes}/{self.n}{how}, best {best}"


def _quiet_optuna() -> None:
    optuna.logging.set_verbosity(optuna.logging.WARNING)


def open_study(path: Path, name: str, spec: TuneSpec, *, resume: bool) -> optuna.Study:
    """The study ``name`` in the journal file ``path``: new (refused if the file has it and not
    ``resume``), or the one there (refused if it asked another question). On a resume, trials left
    running by a killed search are marked failed.

    Raises:
        TuneError: as above, or the file cannot be written.
    """
    _quiet_optuna()
    if resume and not path.is_file():
        raise TuneError(f"nothing to resume: no study file {path}")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        storage = JournalStorage(JournalFileBackend(str(path)))
    except OSError as exc:
        raise TuneError(f"cannot write {path}: {exc.strerror or exc}") from None
    names = {s.study_name for s in storage.get_all_studies()}
    if name in names and not resume:
        raise TuneError(f"{path} already has study {name!r}: --resume to go on with it, or another --study")
    if name not in names and resume:
        raise TuneError(f"nothing to resume: {path} has no study {name!r}")
    existing = len(storage.get_all_trials(storage.get_study_id_from_name(name))) if resume else 0
    sampler = optuna.samplers.TPESampler(seed=spec.seed + existing)
    if resume:
        study = optuna.load_study(study_name=name, storage=storage, sampler=sampler)
        stored = json.loads(study.user_attrs.get(SPEC_ATTR, "{}"))
        if stored != spec.as_dict():
            raise TuneError(
                f"study {name!r} was made with other placements or rules ({_diff(stored, spec.as_dict())}): "
                "give the same options, or another --study"
            )
        for t in study.get_trials(deepcopy=False, states=(TrialState.RUNNING,)):
            storage.set_trial_state_values(t._trial_id, TrialState.FAIL)
        return study
    study = optuna.create_study(study_name=name, storage=storage, sampler=sampler, direction="maximize")
    study.set_user_attr(SPEC_ATTR, json.dumps(spec.as_dict()))
    for point in baseline_points().values():
        study.enqueue_trial(point)
    return study


def _diff(stored: dict[str, Any], now: dict[str, Any]) -> str:
    keys = sorted(k for k in set(stored) | set(now) if stored.get(k) != now.get(k))
    return ", ".join(f"{k}: {stored.get(k)} then, {now.get(k)} now" for k in keys[:3])


def finished_trials(study: optuna.Study) -> list[FrozenTrial]:
    """Trials that ran to the end or were pruned."""
    return study.get_trials(deepcopy=False, states=(TrialState.COMPLETE, TrialState.PRUNED))


def best_trial(study: optuna.Study) -> FrozenTrial | None:
    """The complete trial with the most training successes (the earliest of equals), or None."""
    complete = study.get_trials(deepcopy=False, states=(TrialState.COMPLETE,))
    if not complete:
        return None
    return max(complete, key=lambda t: (t.user_attrs.get("successes", -1), -t.number))


def _best_successes(study: optuna.Study) -> int | None:
    t = best_trial(study)
    return None if t is None else int(t.user_attrs["successes"])


def search_local(
    study: optuna.Study,
    spec: TuneSpec,
    train: list[Placement],
    *,
    trials: int,
    budget_s: float | None,
    jobs: int,
    stop: threading.Event,
    cache: ResultsFile | None = None,
    on_row: Callable[[Evaluation], None] | None = None,
    on_trial: Callable[[TrialLine], None] | None = None,
) -> int:
    """Run trials until the study has ``trials`` finished (complete or pruned) ones, ``budget_s`` has
    passed (no trial starts after it), or ``stop`` is set. Returns the trials finished now."""
    n = len(train)
    t0 = time.monotonic()
    ran = 0
    while len(finished_trials(study)) < trials and not stop.is_set():
        if budget_s is not None and time.monotonic() - t0 >= budget_s:
            break
        trial = study.ask()
        try:
            values = firmware_values(suggest(trial))
        except ConfigError as exc:  # a point the firmware refuses: the space's fault, never silently kept
            trial.set_user_attr("error", str(exc))
            study.tell(trial, state=TrialState.FAIL)
            continue
        best = _best_successes(study)
        ev = evaluate(
            runs_for(values, train, spec),
            jobs=jobs,
            stop=stop,
            best=best,
            rule=spec.prune,
            cache=cache,
            on_row=on_row,
        )
        trial.set_user_attr("values", json.dumps(values))
        trial.set_user_attr("successes", ev.successes)
        trial.set_user_attr("done", ev.done)
        trial.set_user_attr("errors", ev.errors)
        if ev.interrupted:
            study.tell(trial, state=TrialState.FAIL)
            break
        if ev.pruned:
            trial.report(ev.successes / n, ev.done)
            study.tell(trial, state=TrialState.PRUNED)
            state = "pruned"
        else:
            study.tell(trial, ev.successes / n)
            state = "complete"
        ran += 1
        if on_trial is not None:
            on_trial(TrialLine(trial.number, ev.successes, ev.done, n, state, _best_successes(study)))
    return ran
