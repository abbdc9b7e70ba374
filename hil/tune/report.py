"""``spirob-hil tune --report DIR``: what a tuning run found, as a reader checks it.

- ``trials.png``: every finished trial's training success in the order it ran (pruned ones at what they
  had when stopped, marked), and the best so far;
- ``heldout.png``: the held-out success of the tuned controller, the firmware's defaults and the plain
  ramp, each with its Wilson 95 % interval;
- pictures of the tuned controller's first held-out grasp that succeeded and its first that did not, each
  run again with the tuned firmware values (they are part of the run's inputs) and shown only if the
  re-run measures exactly what the held-out grasp recorded (:func:`hil.campaign.summary.grasp_row_pictures`);
- ``tune.md``: the figures, the pictures, the held-out table with McNemar's test, and the parameter file.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from hil.experiments.common import pyplot, save_figure
from hil.tune.heldout import SUCCESS_TEXT, Rate, rate_text

if TYPE_CHECKING:
    from hil.render import Pictures

__all__ = ["TrialPoint", "trial_points", "write_tune_report"]


@dataclass(frozen=True)
class TrialPoint:
    """One finished trial as the progress figure draws it.

    Attributes:
        number: the trial's number in its study.
        successes: training grasps that succeeded.
        done: training grasps run (fewer than the set when pruned).
        pruned: stopped early (it could not beat the best).
    """

    number: int
    successes: int
    done: int
    pruned: bool


def trial_points(study: Any, n: int) -> list[TrialPoint]:
    """The finished (complete or pruned) trials of an Optuna ``study`` over ``n`` training placements.

    A local search stores each trial's successes and grasps run. A Ray Tune search stores its score as the
    trial's value: successes over the set for a trial that ran it all, successes minus the set's size
    over the size (negative) for one its scheduler stopped (``hil.tune.ray_search``).
    """
    from optuna.trial import TrialState

    out = []
    for t in study.get_trials(deepcopy=False, states=(TrialState.COMPLETE, TrialState.PRUNED)):
        if "successes" in t.user_attrs:
            k, done = int(t.user_attrs["successes"]), int(t.user_attrs.get("done", n))
            pruned = t.state == TrialState.PRUNED
        elif t.value is not None:
            pruned = t.value < 0
            k, done = round(t.value * n + (n if pruned else 0)), n
        else:
            continue
        out.append(TrialPoint(t.number, k, done, pruned))
    return sorted(out, key=lambda p: p.number)


def _trials_figure(points: Sequence[TrialPoint], n: int, out_dir: Path) -> Path:
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(6.4, 3.4))
    xs = [p.number for p in points]
    done = [p for p in points if not p.pruned]
    pruned = [p for p in points if p.pruned]
    ax.plot([p.number for p in done], [p.successes for p in done], "o", color="tab:blue", label="complete")
    if pruned:
        ax.plot(
            [p.number for p in pruned],
            [p.successes for p in pruned],
            "x",
            color="tab:gray",
            label="pruned (successes when stopped)",
        )
    best, line = -1, []
    for p in points:
        if not p.pruned:
            best = max(best, p.successes)
        line.append(best if best >= 0 else float("nan"))
    ax.step(xs, line, where="post", color="tab:orange", label="best complete so far")
    ax.set_xlabel("trial")
    from matplotlib.ticker import MaxNLocator

    ax.xaxis.set_major_locator(MaxNLocator(integer=True))
    ax.yaxis.set_major_locator(MaxNLocator(integer=True))
    ax.set_ylabel(f"training successes (of {n})")
    ax.set_ylim(-0.3, n + 0.3)
    ax.set_title(f"search: {len(points)} trials, {len(pruned)} pruned", fontsize=9)
    ax.legend(fontsize=7, loc="upper left")
    return save_figure(fig, out_dir / "trials.png")


def _heldout_figure(heldout: Mapping[str, Rate], out_dir: Path) -> Path:
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(5.0, 3.2))
    labels = list(heldout)
    rates = [r.successes / r.n if r.n else 0.0 for r in heldout.values()]
    lo = [rate - r.ci95[0] if r.n else 0.0 for rate, r in zip(rates, heldout.values(), strict=True)]
    hi = [r.ci95[1] - rate if r.n else 0.0 for rate, r in zip(rates, heldout.values(), strict=True)]
    colours = ["tab:green" if label == "tuned" else "tab:gray" for label in labels]
    ax.bar(labels, rates, color=colours, yerr=[lo, hi], capsize=6)
    for i, r in enumerate(heldout.values()):
        top = r.ci95[1] if r.n else 0.0
        ax.text(i + 0.08, top + 0.02, f"{r.successes}/{r.n}", ha="left", va="bottom", fontsize=8)
    ax.set_ylim(0, 1.1)
    ax.set_ylabel("held-out success (Wilson 95 %)")
    ax.set_title("held-out placements, never seen by the search", fontsize=9)
    return save_figure(fig, out_dir / "heldout.png")


def _pictures(tuned_rows: Sequence[Mapping[str, Any]], out_dir: Path) -> list[tuple[str, Pictures]]:
    from hil.campaign.summary import grasp_row_pictures
    from hil.render import NO_GL, Pictures, gl_backends

    finished = [r for r in tuned_rows if r["outcome"] != "error"]
    picks = [
        (label, slug, next((r for r in finished if (r["outcome"] == "success") == ok), None))
        for label, slug, ok in (("succeeded", "held", True), ("did not succeed", "failed", False))
    ]
    out: list[tuple[str, Pictures]] = []
    for label, slug, row in picks:
        if row is None:
            continue
        if not gl_backends():  # MUJOCO_GL=disable: no grasp is run again for nothing
            return [("", Pictures(note=NO_GL))]
        i = row["inputs"]
        heading = (
            f"the tuned controller, a held-out grasp that {label}: "
            f"{1000 * i['object.diameter_m']:.0f} mm object at x = {1000 * i['object.x_m']:.0f} mm, "
            f"z = {1000 * i['object.z_m']:.0f} mm (run {row['key']})"
        )
        out.append((heading, grasp_row_pictures(row, out_dir, f"tuned-{slug}")))
    return out


def write_tune_report(
    out_dir: Path,
    *,
    describe: str,
    points: Sequence[TrialPoint] | None,
    train_n: int,
    heldout: Mapping[str, Rate],
    mcnemar: Mapping[str, Mapping[str, Any]],
    tuned_rows: Sequence[Mapping[str, Any]],
    values: Mapping[str, Any],
    param_file: Path,
) -> Path:
    """Write the report into ``out_dir`` (figures, pictures, ``tune.md``); returns the index's path.

    Args:
        describe: the placement sets in words (``TuneSpec.describe``).
        points: the search's finished trials (None: not available, e.g. an interrupted Ray search).
        train_n: training placements.
        heldout: label -> held-out rate (``tuned``, ``default``, ``ramp``).
        mcnemar: other label -> McNemar's test of the tuned controller against it.
        tuned_rows: the campaign rows of the tuned controller's held-out grasps.
        values: the tuned firmware values.
        param_file: where they were written.
    """
    from hil.report import write_index

    out_dir.mkdir(parents=True, exist_ok=True)
    figures = [_heldout_figure(heldout, out_dir)]
    notes = ["## Held-out comparison", "", f"Placements: {describe}.", "", f"Success: {SUCCESS_TEXT}.", ""]
    notes += [
        "| controller | success (Wilson 95 %) | vs tuned: only tuned / only it, McNemar p |",
        "|---|---|---|",
    ]
    for label, r in heldout.items():
        m = mcnemar.get(label)
        vs = "" if m is None else f"{m['only_a']} / {m['only_b']}, p = {m['p_value']:.3g}"
        notes.append(f"| {label} | {rate_text(r)} | {vs} |")
    notes += ["", f"Parameter file: `{param_file}` ({len(values)} keys), as written:", "", "```toml"]
    notes += [*param_file.read_text(encoding="utf-8").splitlines(), "```", ""]
    if points:
        figures.insert(0, _trials_figure(points, train_n, out_dir))
    else:
        notes.append("The search's trials were not available: no progress figure.")
    pictures = _pictures(tuned_rows, out_dir)
    return write_index(out_dir, "tune", "Tuning run", figures, pictures, notes)
