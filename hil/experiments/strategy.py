"""strategy (Note S4, Fig. S6, Fig. 3C): paired grasps at the same placements with the strategy off, on
with the firmware's contact detector, and on with the simulator's true contact (an oracle).

Placements: per diameter and per seed, one jittered point in each cell of a grid beside the arm, kept
only if the object clears the packed coil and the straight arm (:class:`~.geometry.ArmFootprint`).
Success, fixed before any run: HOLD reached, the support removed, and ``hold_s`` later the object still
touches at least 2 units, has dropped less than 60 mm, moves slower than 5 cm/s (``held``) and the
contacts span at least 180° around it (:data:`~.common.SUCCESS_WRAP_DEG`).
Statistics: Wilson 95 % interval per arm, McNemar's exact test of each strategy-on arm against off.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from hil.experiments.base import Conditions, Experiment, Sizes
from hil.experiments.common import DEFAULT_MODEL, Row, extremes_rows, pct, pyplot, save_figure
from hil.experiments.geometry import ArmFootprint, jittered_placements
from hil.experiments.outcomes import GraspOutcomes, grasp_trials
from hil.experiments.stats import mcnemar_exact, wilson_interval
from hil.sim.config import ModelConfig
from hil.sim.spiral import SpiralDesign
from hil.trial.grasp import GraspOutcome, GraspSetup
from hil.trial.scene import SUCCESS_WRAP_DEG

ARMS = ("off", "on", "oracle")
"""The three arms: strategy off; on with the firmware's contact detector; on with the true contact."""


@dataclass(frozen=True)
class StrategyParams:
    """Attributes:
    diameters_m: the object diameters.
    x_range_m: object centres' horizontal distance from the arm's axis (target side, +x), low and high.
    z_range_m: object centres' height relative to the base (negative = below), low and high.
    grid: cells along x and z; one jittered placement per cell and seed.
    seeds: jitter seeds (each gives ``grid[0] * grid[1]`` placements per diameter).
    clearance_m: smallest gap kept between a placed object and the packed or straight arm.
    mass_kg: object mass.
    hold_s: how long a released object must stay to count.
    oracle: also run the strategy with the true-contact oracle.
    """

    diameters_m: tuple[float, ...] = (0.016, 0.024, 0.036)
    x_range_m: tuple[float, float] = (0.02, 0.10)
    z_range_m: tuple[float, float] = (-0.18, -0.06)
    grid: tuple[int, int] = (4, 4)
    seeds: int = 3
    clearance_m: float = 0.002
    mass_kg: float = 0.02
    hold_s: float = 0.6
    oracle: bool = True


TINY = StrategyParams(
    diameters_m=(0.02,), x_range_m=(0.04, 0.04), z_range_m=(-0.11, -0.11), grid=(1, 1), seeds=1
)
"""The smoke-test size: the one reference placement (a 20 mm object 40 mm out, 110 mm below the base)."""


def arm_of(o: GraspOutcome) -> str:
    """Which of :data:`ARMS` a trial belongs to."""
    if not o.setup.strategy_on:
        return "off"
    return "oracle" if o.setup.contact_oracle else "on"


def placements(
    design: SpiralDesign, p: StrategyParams, seed: int, model: ModelConfig = DEFAULT_MODEL
) -> list[tuple[float, float, float]]:
    """``(x, z, diameter)`` of every placement: per diameter and jitter seed,
    :func:`~.geometry.jittered_placements` over the grid, clear of the packed coil and the straight arm.

    Raises:
        ValueError: the whole region is blocked for a diameter.
    """
    foot = ArmFootprint.of(design, model)
    out = []
    for d in p.diameters_m:
        for s in range(p.seeds):
            rng = np.random.default_rng([seed, s, round(d * 1e6)])
            for x, z in jittered_placements(foot, d, p.x_range_m, p.z_range_m, p.grid, rng, p.clearance_m):
                out.append((x, z, d))
    return out


@dataclass(frozen=True)
class StrategyResult(GraspOutcomes):
    """Every placement grasped by each arm (:data:`ARMS`; a :class:`~hil.experiments.base.Result`)."""

    params: StrategyParams
    seed: int
    outcomes: tuple[GraspOutcome, ...]

    def arms(self) -> tuple[str, ...]:
        """The arms that ran."""
        return tuple(a for a in ARMS if any(arm_of(o) == a for o in self.outcomes))

    def _select(self, arm: str, d: float | None = None) -> list[GraspOutcome]:
        return [o for o in self.outcomes if arm_of(o) == arm and (d is None or o.setup.diameter_m == d)]

    def rate(self, arm: str, d: float | None = None) -> dict[str, Any]:
        """Successes, trials, rate and Wilson 95 % interval of ``arm`` (one diameter or all)."""
        sel = self._select(arm, d)
        k = sum(o.success for o in sel)
        lo, hi = wilson_interval(k, len(sel))
        return {
            "successes": k,
            "n": len(sel),
            "rate": k / len(sel) if sel else math.nan,
            "ci95": [lo, hi],
            "held": sum(o.held for o in sel),
        }

    @property
    def success_on(self) -> float:
        """Success rate with the strategy on and the firmware's detector."""
        return float(self.rate("on")["rate"])

    @property
    def success_off(self) -> float:
        """Success rate with the strategy off."""
        return float(self.rate("off")["rate"])

    def paired(self, arm: str, other: str = "off") -> dict[str, Any]:
        """Discordant pairs of ``arm`` vs ``other`` at the same placements, and McNemar's exact p-value."""
        theirs = {_key(o): o.success for o in self._select(other)}
        pairs = [(o.success, theirs[_key(o)]) for o in self._select(arm) if _key(o) in theirs]
        only_arm = sum(1 for a, b in pairs if a and not b)
        only_other = sum(1 for a, b in pairs if b and not a)
        return {
            "arm": arm,
            "vs": other,
            "pairs": len(pairs),
            f"only_{arm}": only_arm,
            f"only_{other}": only_other,
            "p_value": mcnemar_exact(only_arm, only_other),
        }

    def paired_all(self) -> list[dict[str, Any]]:
        """:meth:`paired` of every strategy-on arm against off."""
        return [self.paired(a) for a in self.arms() if a != "off"]

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        arms = self.arms()
        e = self.extremes
        return {
            "experiment": "strategy",
            "seed": self.seed,
            "criterion": f"held {self.params.hold_s:g} s after release and wrap >= {SUCCESS_WRAP_DEG:g} deg",
            "success_on": self.success_on,
            "success_off": self.success_off,
            "success_oracle": float(self.rate("oracle")["rate"]) if "oracle" in arms else math.nan,
            "arms": {a: self.rate(a) for a in arms},
            "mcnemar": self.paired_all(),
            "per_diameter": [
                {"diameter_m": d, **{a: self.rate(a, d) for a in arms}} for d in self.params.diameters_m
            ],
            "penetration_m": e.penetration_m,
            "penetration_ratio": e.penetration_ratio,
            **self.outcomes_dict(),
            "params": dataclasses.asdict(self.params),
        }

    def table_rows(self) -> list[Row]:
        """The result's numbers next to the paper's, one row each."""
        arms = self.arms()
        label = {
            "off": ("strategy off (plain ramp)", "only objects near the tip (Fig. S6A)"),
            "on": ("strategy on, firmware's contact detector", "wider range than off (Fig. S6B, 3C)"),
            "oracle": ("strategy on, true contact (oracle)", "wider range than off"),
        }
        rows: list[Row] = [(f"success: {label[a][0]}", _rate_text(self.rate(a)), label[a][1]) for a in arms]
        for c in self.paired_all():
            rows.append(
                (
                    f"  {c['arm']} vs off: only {c['arm']} / only off; McNemar p",
                    f"{c['only_' + c['arm']]} / {c['only_off']}; p = {c['p_value']:.3g}",
                    "on > off",
                )
            )
        for d in self.params.diameters_m:
            rows.append(
                (
                    f"  diameter {d * 1000:g} mm: " + " / ".join(arms),
                    " / ".join(pct(self.rate(a, d)["rate"]) for a in arms),
                    "",
                )
            )
        rows.extend(extremes_rows(self.extremes))
        rows.extend(self.placement_rows())
        return rows

    def describe_samples(self) -> str:
        """Diameters, placements, arms and grasps, in words."""
        p = self.params
        per_d = p.grid[0] * p.grid[1] * p.seeds
        return (
            f"{len(p.diameters_m)} diameters x {per_d} placements ({p.grid[0]} x {p.grid[1]} cells x "
            f"{p.seeds} seeds) x {len(self.arms())} arms = {len(self.outcomes)} grasps "
            f"({1000 * p.mass_kg:g} g objects; success "
            f"= held {p.hold_s:g} s after release and wrapped >= {SUCCESS_WRAP_DEG:g}°)"
        )

    def figure(self, out: Path) -> Path:
        """Write the figure into the directory ``out``; returns its path (``strategy.png``): per diameter,
        each placement's outcome with the strategy on (firmware detector) against off."""
        plt = pyplot()
        ds = self.params.diameters_m
        fig, axes = plt.subplots(1, len(ds), figsize=(3.8 * len(ds), 4.6), squeeze=False)
        off = {_key(o): o.success for o in self.outcomes if arm_of(o) == "off"}
        style = {
            (True, True): ("o", "tab:green"),
            (True, False): ("^", "tab:blue"),
            (False, True): ("v", "tab:orange"),
            (False, False): ("x", "0.6"),
        }
        for ax, d in zip(axes[0], ds, strict=True):
            for o in self.outcomes:
                s = o.setup
                if s.diameter_m != d or arm_of(o) != "on":
                    continue
                marker, colour = style[(o.success, off.get(_key(o), False))]
                ax.plot(s.x_m * 1000, s.z_m * 1000, marker=marker, color=colour, ms=7, ls="")
                ax.add_patch(
                    plt.Circle((s.x_m * 1000, s.z_m * 1000), d * 500, fill=False, color=colour, lw=0.5)
                )
            ax.plot([0, 0], [0, -223], "k-", lw=3, alpha=0.3)
            rates = ", ".join(f"{a} {pct(self.rate(a, d)['rate'])}" for a in self.arms())
            ax.set_title(f"d = {d * 1000:g} mm: {rates}", fontsize=8)
            ax.set_aspect("equal")
            ax.set_xlim(-15, 125)
            ax.set_ylim(-235, 10)
            ax.grid(alpha=0.3)
            ax.set_xlabel("object centre from the arm's axis [mm]", fontsize=8)
            ax.set_ylabel("object centre below the base [mm]", fontsize=8)
        handles = [
            plt.Line2D([], [], marker=m, color=c, ls="", label=lab)
            for (m, c), lab in zip(
                style.values(), ("both", "strategy on only", "strategy off only", "neither"), strict=True
            )
        ]
        axes[0][0].legend(handles=handles, fontsize=7, loc="lower left")
        fig.suptitle(
            "strategy on (firmware detector) vs off: held, wrapped >= 180° (arm in grey)", fontsize=10
        )
        return save_figure(fig, out / "strategy.png")


def _key(o: GraspOutcome) -> tuple[float, float, float]:
    return (o.setup.x_m, o.setup.z_m, o.setup.diameter_m)


def strategy(p: StrategyParams, on: Conditions) -> StrategyResult:
    """Every placement (:func:`placements`) grasped through the firmware's GRASP mode by each arm
    (strategy off, on, on with the contact oracle), on the plant ``on.model`` (Note S4, Fig. S6, Fig. 3C)."""
    arms = [(False, False), (True, False)] + ([(True, True)] if p.oracle else [])
    setups = [
        GraspSetup(
            x,
            z,
            d,
            strategy_on=strategy_on,
            contact_oracle=oracle,
            mass_kg=p.mass_kg,
            hold_s=p.hold_s,
            model=on.model,
            seed=on.seed,
        )
        for x, z, d in placements(on.design, p, on.seed, on.model)
        for strategy_on, oracle in arms
    ]
    return StrategyResult(p, on.seed, grasp_trials(setups, on))


def _rate_text(r: dict[str, Any]) -> str:
    lo, hi = r["ci95"]
    return f"{pct(r['rate'])} ({r['successes']}/{r['n']}; 95 % CI {pct(lo)}-{pct(hi)})"


EXPERIMENT = Experiment(
    "strategy",
    "paired grasps, strategy off / on / on with true contact: Wilson intervals, McNemar (Note S4)",
    # tiny: the one reference placement, three arms; default: 3 diameters x 48 placements (4 x 4 cells x 3
    # seeds) x 3 arms; large: 6 x 6 cells
    Sizes(TINY, StrategyParams(), StrategyParams(grid=(6, 6))),
    strategy,
)
"""The strategy experiment (:mod:`hil.experiments.catalogue`)."""
