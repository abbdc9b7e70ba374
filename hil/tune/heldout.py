"""The held-out comparison and the parameter file: the tuned controller, the firmware's defaults (strategy on)
and the plain ramp (strategy off) grasp the same held-out placements, which the search never saw; each rate
with its Wilson 95 % interval, the tuned controller against each of the others by McNemar's exact test on
the paired placements. The tuned values go into a firmware parameter file whose header says how they were
made and what they scored.
"""

from __future__ import annotations

import datetime
import importlib.metadata
import threading
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from controller.param_file import write_param_file
from hil.campaign.runner import ResultsFile
from hil.experiments.stats import mcnemar_exact, wilson_interval
from hil.tune.objective import Evaluation, Executor, Placement, TuneSpec, evaluate, runs_for

__all__ = ["SUCCESS_TEXT", "Rate", "compare_heldout", "file_header", "rate_text", "write_tuned"]

SUCCESS_TEXT = (
    "the grasp experiments' criterion: HOLD reached, support removed, 0.6 s later held (touching >= 2 "
    "units, < 60 mm below where let go, < 5 cm/s) and wrapped >= 180°"
)
"""The success criterion every count here uses (``hil.trial.grasp.GraspOutcome.success``)."""


@dataclass(frozen=True)
class Rate:
    """Successes of one controller on one placement set.

    Attributes:
        successes: grasps that succeeded.
        n: grasps run.
    """

    successes: int
    n: int

    @property
    def ci95(self) -> tuple[float, float]:
        """Wilson 95 % interval."""
        return wilson_interval(self.successes, self.n)

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        lo, hi = self.ci95
        return {
            "successes": self.successes,
            "n": self.n,
            "rate": self.successes / self.n if self.n else None,
            "ci95": [lo, hi] if self.n else None,
        }


def rate_text(r: Rate) -> str:
    """``9/24 = 38 % [21, 57 %]``."""
    if not r.n:
        return "0/0"
    lo, hi = r.ci95
    return f"{r.successes}/{r.n} = {r.successes / r.n:.0%} [{lo:.0%}, {hi:.0%}]".replace("%,", ",")


def compare_heldout(
    spec: TuneSpec,
    test: Sequence[Placement],
    controllers: Mapping[str, Mapping[str, Any]],
    *,
    jobs: int,
    stop: threading.Event,
    cache: ResultsFile | None = None,
    executor: Executor | None = None,
    on_row: Callable[[Evaluation], None] | None = None,
) -> tuple[dict[str, list[bool | None]], Evaluation]:
    """Every controller (label -> firmware values) at every held-out placement, in one batch.

    Returns:
        Per label, each placement's success (None: not run, after Ctrl-C), and the batch's evaluation.
    """
    per = {label: runs_for(values, test, spec) for label, values in controllers.items()}
    # A tuned controller equal to a baseline has the same runs (the same keys): grasped once.
    every = list({r.key: r for runs in per.values() for r in runs}.values())
    kw = {} if executor is None else {"executor": executor}
    ev = evaluate(every, jobs=jobs, stop=stop, rule="none", cache=cache, on_row=on_row, **kw)  # type: ignore[arg-type]
    return {label: ev.outcomes(runs) for label, runs in per.items()}, ev


def paired(a: Sequence[bool | None], b: Sequence[bool | None]) -> dict[str, Any]:
    """Discordant pairs of two controllers on the same placements and McNemar's exact p-value."""
    pairs = [(x, y) for x, y in zip(a, b, strict=True) if x is not None and y is not None]
    only_a = sum(1 for x, y in pairs if x and not y)
    only_b = sum(1 for x, y in pairs if y and not x)
    return {"pairs": len(pairs), "only_a": only_a, "only_b": only_b, "p_value": mcnemar_exact(only_a, only_b)}


def rate_of(outcomes: Sequence[bool | None]) -> Rate:
    """The rate of the placements that ran."""
    ran = [o for o in outcomes if o is not None]
    return Rate(sum(ran), len(ran))


def file_header(
    *,
    preset: str,
    made_by: str,
    spec: TuneSpec,
    trials_n: int,
    pruned_n: int,
    train: Rate,
    heldout: Mapping[str, Rate],
    mcnemar: Mapping[str, Mapping[str, Any]],
) -> list[str]:
    """The comment lines that say how a tuned parameter file was made and what it scored."""
    try:
        optuna_v = importlib.metadata.version("optuna")
    except importlib.metadata.PackageNotFoundError:  # pragma: no cover - optuna made the file
        optuna_v = "?"
    today = datetime.date.today().isoformat()
    lines = [
        f"Grasp controller tuned for the {preset} plant by spirob-hil tune ({today}, optuna {optuna_v} TPE,",
        f"seed {spec.seed}, pruning rule {spec.prune}): {trials_n} trials, {pruned_n} of them pruned.",
        f"Command: {made_by}",
        f"Placements: {spec.describe()}.",
        f"Success: {SUCCESS_TEXT}.",
        f"Training success of these values: {rate_text(train)} (Wilson 95 %).",
        "Held-out (never seen by the search), Wilson 95 %:",
    ]
    for label, r in heldout.items():
        lines.append(f"  {label}: {rate_text(r)}")
    for other, m in mcnemar.items():
        lines.append(
            f"  tuned vs {other} (McNemar, exact): {m['only_a']} only tuned / {m['only_b']} only {other}, "
            f"p = {m['p_value']:.3g}"
        )
    lines.append("Keys not in this file keep the firmware's defaults (docs/parameters.md, docs/tune.md).")
    return lines


def write_tuned(path: Path, values: Mapping[str, Any], header: Sequence[str]) -> Path:
    """Write the tuned values as a firmware parameter file (``controller.param_file``).

    Raises:
        ConfigError: a value the firmware refuses. OSError: the file cannot be written.
    """
    return write_param_file(path, values, header)
