"""A claim's map from a paired campaign: where one value of a two-valued axis beats the other.

A claim such as "the strategy grasps more than the plain ramp" is a comparison of two arms on the same
placements. A campaign that varies the arm (``controller.strategy_on``) beside the plant's uncertain
parameters (``design.*``) answers it per plant: every run is paired with the run that differs only in
the arm, and each *cell* (one value of every other design, controller and array axis) gets the exact
McNemar test of its discordant pairs. The claim **holds in a cell** when the arm it names (the larger
value of the axis: ``true`` for a switch) wins more discordant pairs with p < :data:`ALPHA`. The rule is
fixed here, before any campaign is run with it; :func:`verdict` says in one sentence where it holds, or
that it holds nowhere.

:func:`claim_map` draws the cells as panels of heat maps (the difference of the two arms' success rates,
each cell marked with both arms' successes of its pairs and p) when at most three of those axes besides
the arm vary.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Final

from hil.campaign.summary import CHOICE_PREFIXES
from hil.experiments.stats import mcnemar_exact
from hil.trial.scene import beyond_goal

__all__ = ["ALPHA", "PairedCell", "claim_map", "paired_cells", "verdict"]

ALPHA: Final = 0.05
"""A cell's claim holds at McNemar p below this (two-sided, exact), the named arm winning."""


@dataclass(frozen=True, slots=True)
class PairedCell:
    """One plant and controller, its pairs compared.

    Attributes:
        inputs: the cell's design choices (:data:`~hil.campaign.summary.CHOICE_PREFIXES`), the arm's axis
            left out.
        pairs: placements (and seeds) run with both arms, neither an error.
        a_successes: successes of the named arm (the axis's larger value).
        b_successes: successes of the other.
        only_a: pairs only the named arm won.
        only_b: pairs only the other won.
        p: exact McNemar p of the discordant pairs.
        penetration_m: the deepest penetration of the cell's runs (NaN if none says).
        placed_inside: the cell's paired runs whose object was put in place overlapping the arm beyond the
            penetration goal (:attr:`hil.trial.grasp.GraspOutcome.placed_inside`): not grasps, though
            counted as run.
    """

    inputs: dict[str, Any]
    pairs: int
    a_successes: int
    b_successes: int
    only_a: int
    only_b: int
    p: float
    penetration_m: float
    placed_inside: int = 0

    @property
    def holds(self) -> bool:
        """The named arm wins more discordant pairs, with p < :data:`ALPHA`."""
        return self.only_a > self.only_b and self.p < ALPHA

    @property
    def label(self) -> str:
        """The cell's inputs, ``name=value`` without their section."""
        return ", ".join(f"{k.partition('.')[2]}={_fmt(v)}" for k, v in sorted(self.inputs.items())) or "all"


def _fmt(v: Any) -> str:
    return f"{v:g}" if isinstance(v, float) else str(v).lower() if isinstance(v, bool) else str(v)


def arm_values(rows: Iterable[Mapping[str, Any]], arm_key: str) -> tuple[Any, Any]:
    """The axis's two values, the named arm's (the larger) first.

    Raises:
        ValueError: the rows do not give the axis exactly two values.
    """
    values = {r["inputs"].get(arm_key) for r in rows}
    if len(values) != 2 or None in values:
        shown = ", ".join(sorted(_fmt(v) for v in values)) or "none"
        raise ValueError(f"{arm_key} must take exactly two values to pair runs, got {shown}")
    low, high = sorted(values)
    return high, low


def paired_cells(rows: Sequence[Mapping[str, Any]], arm_key: str) -> list[PairedCell]:
    """Pair every run with the one that differs only in ``arm_key``; one :class:`PairedCell` per cell.

    Raises:
        ValueError: ``arm_key`` does not take exactly two values.
    """
    a, b = arm_values(rows, arm_key)
    cells: dict[
        tuple[tuple[str, str], ...], dict[tuple[tuple[str, str], ...], dict[Any, Mapping[str, Any]]]
    ] = {}
    for r in rows:
        inputs = r["inputs"]
        cell = tuple(
            sorted((k, repr(v)) for k, v in inputs.items() if k != arm_key and k.startswith(CHOICE_PREFIXES))
        )
        spot = tuple(
            sorted(
                (k, repr(v)) for k, v in inputs.items() if k != arm_key and not k.startswith(CHOICE_PREFIXES)
            )
        )
        cells.setdefault(cell, {}).setdefault(spot, {})[inputs[arm_key]] = r
    out = []
    for spots in cells.values():
        both = [(s[a], s[b]) for s in spots.values() if a in s and b in s]
        both = [(x, y) for x, y in both if x["outcome"] != "error" and y["outcome"] != "error"]
        if not both:
            continue
        wins_a = [x["outcome"] == "success" for x, _ in both]
        wins_b = [y["outcome"] == "success" for _, y in both]
        only_a = sum(p and not q for p, q in zip(wins_a, wins_b, strict=True))
        only_b = sum(q and not p for p, q in zip(wins_a, wins_b, strict=True))
        depths = [
            float(run["measured"]["extremes"]["penetration_m"])
            for pair in both
            for run in pair
            if isinstance(run.get("measured"), Mapping) and "extremes" in run["measured"]
        ]
        inside = sum(_placed_inside(run) for pair in both for run in pair)
        first = both[0][0]["inputs"]
        out.append(
            PairedCell(
                {k: v for k, v in first.items() if k != arm_key and k.startswith(CHOICE_PREFIXES)},
                len(both),
                sum(wins_a),
                sum(wins_b),
                only_a,
                only_b,
                mcnemar_exact(only_a, only_b),
                max(depths) if depths else math.nan,
                inside,
            )
        )
    return out


def _placed_inside(run: Mapping[str, Any]) -> bool:
    measured = run.get("measured")
    if not isinstance(measured, Mapping):
        return False
    depth = measured.get("placed_overlap_m")
    diameter = run["inputs"].get("object.diameter_m")
    if not isinstance(depth, int | float) or not isinstance(diameter, int | float):
        return False  # rows written before the field existed, or no object
    return beyond_goal(float(depth), float(diameter) / 2)


def verdict(cells: Sequence[PairedCell], arm_key: str, a: Any) -> str:
    """One sentence a reader can act on: where the claim holds, or that it holds nowhere here."""
    name = f"{arm_key.partition('.')[2]}={_fmt(a)}"
    holding = [c for c in cells if c.holds]
    wins_a = sum(c.only_a for c in cells)
    wins_b = sum(c.only_b for c in cells)
    pooled = f"pooled {wins_a} / {wins_b} discordant pairs, p = {mcnemar_exact(wins_a, wins_b):.2g}"
    if not holding:
        worse = sum(c.only_b > c.only_a and c.p < ALPHA for c in cells)
        said = (
            f"{name} wins in none of {len(cells)} cells ({pooled}; it loses significantly in {worse}): "
            "the claim holds nowhere in this range"
        )
    else:
        said = f"{name} wins in {len(holding)} of {len(cells)} cells ({pooled}): holds when " + "; or ".join(
            c.label for c in holding
        )
    inside = [c for c in cells if c.placed_inside]
    if inside:
        said += (
            f"; but {sum(c.placed_inside for c in inside)} runs in {len(inside)} cells put the object inside "
            "the arm (overlapping it beyond the penetration goal when placed), which is not a grasp: "
            + "; ".join(f"{c.label} ({c.placed_inside})" for c in inside)
        )
    return said


def claim_map(cells: Sequence[PairedCell], path: Path, title: str) -> Path | None:
    """Heat maps of the named arm's success rate minus the other's, one panel per value of a third varied
    axis; None (nothing drawn) when more than three axes vary or fewer than one does."""
    varied = sorted(
        k for k in {k for c in cells for k in c.inputs} if len({repr(c.inputs.get(k)) for c in cells}) > 1
    )
    if not 1 <= len(varied) <= 3:
        return None
    from hil.experiments.common import pyplot, save_figure  # matplotlib only for a report

    x_key = varied[-1]
    y_key = varied[-2] if len(varied) >= 2 else None
    panel_key = varied[0] if len(varied) == 3 else None
    panels = sorted({c.inputs.get(panel_key) for c in cells}, key=repr) if panel_key else [None]
    xs = sorted({c.inputs[x_key] for c in cells}, key=repr)
    ys = sorted({c.inputs[y_key] for c in cells}, key=repr) if y_key else [None]
    plt = pyplot()
    fig, axes = plt.subplots(1, len(panels), figsize=(1.6 + 1.5 * len(xs) * len(panels), 1.4 + 1.0 * len(ys)))
    axes = axes if len(panels) > 1 else [axes]
    for ax, pv in zip(axes, panels, strict=True):
        grid = [[math.nan] * len(xs) for _ in ys]
        for c in cells:
            if panel_key and c.inputs.get(panel_key) != pv:
                continue
            i = ys.index(c.inputs.get(y_key)) if y_key else 0
            j = xs.index(c.inputs[x_key])
            diff = (c.a_successes - c.b_successes) / c.pairs
            grid[i][j] = diff
            mark = "*" if c.holds else ""
            text = f"{c.a_successes} vs {c.b_successes} of {c.pairs}\np={c.p:.2g}{mark}"
            ink = "white" if abs(diff) > 0.5 else "black"
            ax.text(j, i, text, ha="center", va="center", fontsize=7, color=ink)
        ax.imshow(grid, cmap="RdBu", vmin=-1.0, vmax=1.0, origin="lower", aspect="auto")
        ax.set_xticks(range(len(xs)), [_fmt(v) for v in xs])
        ax.set_yticks(range(len(ys)), [_fmt(v) for v in ys] if y_key else [""])
        ax.set_xlabel(x_key.partition(".")[2])
        if y_key:
            ax.set_ylabel(y_key.partition(".")[2])
        ax.set_title(f"{panel_key.partition('.')[2]}={_fmt(pv)}" if panel_key else "", fontsize=9)
    fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    return save_figure(fig, path)
