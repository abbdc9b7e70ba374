"""sensitivity: which conclusions survive ±50 % on the model's uncertain parameters, one at a time.

The varied parameters (:data:`hil.sim.variants.PARAMETERS`) are the ones with no datasheet behind them:
the base joint's stiffness, the joints' damping ratio, the spool's (rotor) inertia, the drive's output
friction and the contact friction (arm and objects together: MuJoCo takes the larger of a pair's two
coefficients). Each variant re-runs every :data:`MEASURES` entry, a function ``(size, conditions) -> dict``,
and
each of a measure's :class:`Conclusion` s says whether it still holds, with its number and sample size.
The variants scale the model the experiment is given (the default model or a preset); a new measure is
one more entry of :data:`MEASURES`.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from hil.experiments.base import Conditions, Experiment, Sizes
from hil.experiments.common import Row, extremes_rows, pyplot, save_figure, sized, worst_extremes
from hil.experiments.dynamic import TINY, DynamicParams, dynamic
from hil.experiments.packing import EXPERIMENT as PACKING
from hil.experiments.parallel import parallel_map
from hil.experiments.strategy import TINY as STRATEGY_TINY
from hil.experiments.strategy import StrategyParams, strategy
from hil.sim.types import PhysicsExtremes
from hil.sim.variants import BASELINE, PARAMETERS, Variant

FACTORS = (0.5, 1.5)
"""Each parameter is multiplied by these (±50 %)."""


def variants(size: str = "default") -> tuple[Variant, ...]:
    """The baseline, then every parameter at every factor (``tiny``, a smoke test: the first parameter
    only, so that the strategy measure's grasps keep it to seconds)."""
    params = sized(size, tuple(PARAMETERS)[:1], tuple(PARAMETERS), tuple(PARAMETERS))
    return (Variant(BASELINE, 1.0), *(Variant(p, f) for p in params for f in FACTORS))


@dataclass(frozen=True)
class Conclusion:
    """A claim a measure's dict can confirm or refute.

    Attributes:
        name: the claim, in words.
        holds: whether the measure's dict confirms it.
        number: the number behind the verdict, for the table.
    """

    name: str
    holds: Callable[[dict[str, Any]], bool]
    number: Callable[[dict[str, Any]], str]


Measure = Callable[[str, Conditions], dict[str, Any]]
"""``measure(size, conditions) -> dict`` of JSON-ready numbers, with the worst physics of its trials as
``extremes`` (:meth:`~hil.sim.types.PhysicsExtremes.as_dict`)."""


def packing_measure(size: str, on: Conditions) -> dict[str, Any]:
    """The packing experiment (Note S3) on ``on.design`` at ``size``: curl order and packing tension."""
    r = PACKING.run_at_size(size, on)
    return {
        "order_correlation": r.order_correlation,
        "packed": r.packed,
        "pack_tension_n": r.pack_tension_n,
        "b_error": r.b_fit / r.b_design - 1.0,
        "extremes": r.extremes.as_dict(),
    }


def dynamic_measure(size: str, on: Conditions) -> dict[str, Any]:
    """Fig. S11 on the 45 cm arm (whatever ``on.design`` is), at the dynamic experiment's first step only
    (0.25 ms with 0.5 ms contacts: where its penetration meets the goal), throws with cable 0 held at length
    (the paper's setup)."""
    first = DynamicParams().timesteps_s[:1]
    params = sized(
        size,
        dataclasses.replace(TINY, timesteps_s=first, holds=("length",)),
        DynamicParams(throw_positions=3, timesteps_s=first, holds=("length",)),
        DynamicParams(timesteps_s=first, holds=("length",)),
    )
    r = dynamic(params, on)
    d = r.as_dict()
    return {
        "pen_half_wrap_ms": d["pen_half_wrap_ms"],
        "pen_carried": d["pen_carried"],
        "captured": d["capture"]["length"]["captured"],
        "throws": d["capture"]["length"]["throws"],
        "extremes": d["extremes"],
    }


def strategy_measure(size: str, on: Conditions) -> dict[str, Any]:
    """Paired grasps (strategy off / on / on with the true-contact oracle) at a few placements of one
    diameter: per arm, successes and trials (the strategy experiment's success criterion)."""
    params = sized(
        size,
        STRATEGY_TINY,
        StrategyParams(diameters_m=(0.024,), grid=(2, 2), seeds=1),
        StrategyParams(diameters_m=(0.024,), grid=(4, 4), seeds=1),
    )
    r = strategy(params, on)
    out: dict[str, Any] = {}
    for arm in ("off", "on", "oracle"):
        rate = r.rate(arm)
        out[arm] = rate["successes"]
        out["n"] = rate["n"]
    out["extremes"] = r.extremes.as_dict()
    return out


def _ms(x: float) -> str:
    return "never" if math.isnan(x) else f"{x:.0f} ms"


def _pair(a: str, b: str) -> Callable[[dict[str, Any]], str]:
    """The number of a strategy conclusion: both arms' successes out of the placements (the sample)."""
    return lambda d: f"{a} {d[a]}/{d['n']}, {b} {d[b]}/{d['n']}"


MEASURES: dict[str, tuple[Measure, tuple[Conclusion, ...]]] = {
    "packing": (
        packing_measure,
        (
            Conclusion(
                "packing: curls from the tip (rank correlation < -0.8)",
                lambda d: d["order_correlation"] < -0.8,
                lambda d: f"{d['order_correlation']:+.2f}",
            ),
            Conclusion(
                "packing: packs fully under the 3 A limit",
                lambda d: bool(d["packed"]),
                lambda d: "not packed" if math.isnan(d["pack_tension_n"]) else f"{d['pack_tension_n']:.1f} N",
            ),
        ),
    ),
    "dynamic": (
        dynamic_measure,
        (
            Conclusion(
                "dynamic: a current step wraps the pen half way",
                lambda d: not math.isnan(d["pen_half_wrap_ms"]),
                lambda d: _ms(d["pen_half_wrap_ms"]),
            ),
            Conclusion(
                "dynamic: the pen is carried toward the base",
                lambda d: bool(d["pen_carried"]),
                lambda d: "yes" if d["pen_carried"] else "no",
            ),
            Conclusion(
                "dynamic: most thrown objects are captured (cable 0 held at length)",
                lambda d: 2 * d["captured"] > d["throws"],
                lambda d: f"{d['captured']}/{d['throws']}",
            ),
        ),
    ),
    "strategy": (
        strategy_measure,
        (
            Conclusion(
                "strategy: on (firmware detector) succeeds at least as often as off",
                lambda d: d["on"] >= d["off"],
                _pair("on", "off"),
            ),
            Conclusion(
                "strategy: on with the true contact succeeds more often than with the firmware detector",
                lambda d: d["oracle"] > d["on"],
                _pair("oracle", "on"),
            ),
        ),
    ),
}
"""The measures: name -> (measure, its conclusions). The extension point for further measures."""


@dataclass(frozen=True)
class SensitivityResult:
    """Every measure on every variant, and each conclusion's verdict (a
    :class:`~hil.experiments.base.Result`).

    Attributes:
        size: the measures' size.
        seed: the seed of every run.
        variants: the variants' labels, baseline first.
        measured: ``measured[measure][variant]``: the measure's dict.
    """

    size: str
    seed: int
    variants: tuple[str, ...]
    measured: dict[str, dict[str, dict[str, Any]]]

    def verdicts(self) -> list[tuple[str, list[tuple[bool, str]]]]:
        """Per conclusion: ``(holds, number)`` per variant (in :attr:`variants` order)."""
        out = []
        for name, (_, conclusions) in MEASURES.items():
            if name not in self.measured:
                continue
            for c in conclusions:
                cells = [
                    (c.holds(self.measured[name][v]), c.number(self.measured[name][v])) for v in self.variants
                ]
                out.append((c.name, cells))
        return out

    @property
    def extremes(self) -> PhysicsExtremes:
        """The worst physics over every measure on every variant."""
        return worst_extremes(
            PhysicsExtremes(**d["extremes"])
            for per_variant in self.measured.values()
            for d in per_variant.values()
        )

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        return {
            "experiment": "sensitivity",
            "extremes": self.extremes.as_dict(),
            "seed": self.seed,
            "size": self.size,
            "variants": list(self.variants),
            "conclusions": {
                name: {v: {"holds": h, "number": n} for v, (h, n) in zip(self.variants, cells, strict=True)}
                for name, cells in self.verdicts()
            },
            "survive_all": [name for name, cells in self.verdicts() if all(h for h, _ in cells)],
            "measured": self.measured,
        }

    def table_rows(self) -> list[Row]:
        """Per conclusion, the baseline's verdict, then per parameter the verdicts at x0.5 / x1.5."""
        rows: list[Row] = []
        index = {v: i for i, v in enumerate(self.variants)}
        for name, cells in self.verdicts():
            survives = "survives every variant" if all(h for h, _ in cells) else "fails in some variant"
            rows.append((name, f"baseline: {_cell(cells[0])}", survives))
            for p in PARAMETERS:
                labels = [Variant(p, f).label for f in FACTORS]
                if not any(lab in index for lab in labels):
                    continue
                verdicts = " / ".join(_cell(cells[index[lab]]) for lab in labels if lab in index)
                rows.append((f"  {p} x{' / x'.join(f'{f:g}' for f in FACTORS)}", verdicts, ""))
        rows.extend(extremes_rows(self.extremes))
        return rows

    def describe_samples(self) -> str:
        """Models, measures and the strategy's placements, in words."""
        text = (
            f"{len(self.variants)} models (baseline, {(len(self.variants) - 1) // len(FACTORS)} parameters x "
            f"{len(FACTORS)}) x "
            f"{len(self.measured)} measures ({', '.join(self.measured)}) at size {self.size}"
        )
        strat = self.measured.get("strategy", {}).get(BASELINE)
        if strat is not None:
            text += f"; strategy: {strat['n']} placements x 3 arms per model"
        return text

    def figure(self, out: Path) -> Path:
        """Write the figure into the directory ``out``; returns its path (``sensitivity.png``)."""
        plt = pyplot()
        verdicts = self.verdicts()
        fig, ax = plt.subplots(figsize=(2 + 1.0 * len(self.variants), 1.5 + 0.5 * len(verdicts)))
        grid = [[1.0 if h else 0.0 for h, _ in cells] for _, cells in verdicts]
        ax.imshow(grid, cmap="RdYlGn", vmin=0.0, vmax=1.0, aspect="auto")
        for i, (_, cells) in enumerate(verdicts):
            for j, (_, number) in enumerate(cells):
                ax.text(j, i, number, ha="center", va="center", fontsize=7)
        ax.set_xticks(range(len(self.variants)), self.variants, rotation=40, ha="right", fontsize=7)
        ax.set_yticks(range(len(verdicts)), [name for name, _ in verdicts], fontsize=7)
        ax.set_title("which conclusions survive ±50 % (green: holds, red: fails)", fontsize=9)
        return save_figure(fig, out / "sensitivity.png")


def _run_one(item: tuple[str, Variant, str, Conditions]) -> dict[str, Any]:
    name, variant, size, on = item
    return MEASURES[name][0](size, dataclasses.replace(on, model=variant.apply(on.model)))


def sensitivity(size: str, on: Conditions) -> SensitivityResult:
    """Run every measure at ``size`` on the baseline ``on.model`` and on each ±50 % variant of it (the
    measures fan out over ``on.jobs``, each on one worker)."""
    vs = variants(size)
    alone = dataclasses.replace(on, jobs=1, progress=None)
    items = [(name, v, size, alone) for v in vs for name in MEASURES]
    out = parallel_map(_run_one, items, on.jobs, on.progress)
    measured: dict[str, dict[str, dict[str, Any]]] = {name: {} for name in MEASURES}
    for (name, v, *_), d in zip(items, out, strict=True):
        measured[name][v.label] = d
    return SensitivityResult(size, on.seed, tuple(v.label for v in vs), measured)


def _cell(cell: tuple[bool, str]) -> str:
    return f"{'holds' if cell[0] else 'FAILS'} ({cell[1]})"


EXPERIMENT = Experiment(
    "sensitivity",
    "±50 % on stiffness, damping, spool inertia, drive and contact friction: what survives",
    Sizes("tiny", "default", "large"),  # the measures' own size
    sensitivity,
)
"""The sensitivity experiment (:mod:`hil.experiments.catalogue`)."""
