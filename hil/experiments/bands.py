"""bands (issue 24, item 1): the strategy claim tested where it lives.

The paper says the strategy grasps objects "at a larger but still reachable range" that a direct curl
misses (Note S4, Fig. S6). The strategy experiment's placements did not test that: most lay where neither
arm succeeds or where the ramp's hook catches. Here the placements are drawn per band, computed per design
before any grasp:

- **catch**: the object overlaps what the plain ramp sweeps. The sweep is measured, not assumed: the
  firmware's GRASP mode with the strategy off, no object in reach, from the straight arm to HOLD, every
  unit's segment every 5 ms (:func:`ramp_sweep`);
- **between**: the ramp never touches it, but its centre is inside the arm's reach, the exact workspace
  envelope of the design (:class:`~hil.experiments.geometry.Envelope`: the tip's path as the joints close
  from the base, Fig. S4A). This is the band the claim is about;
- **beyond**: the ramp never touches it and its centre is outside the reach, by at most
  ``beyond_ratio`` of the envelope's radius.

Every placement clears the packed and the straight arm (both starts) by ``clearance_m``. In two set-ups:
the 3-cable prototype hanging under gravity (the project's), and the paper's: the 2-cable 45 cm arm
bending in a plane on the authors' model, gravity off (:func:`setup_arm`).

Each placement is grasped with the strategy off (the ramp) and on (the firmware's detector), paired. A
grasp whose physics diverges is run again at half the step (:func:`band_grasp`); if it diverges again its
pair is left out of the rates and counted (``diverged``).
Success is the grasp experiments' criterion, fixed before any of them ran (held ``hold_s`` after release,
wrapped at least 180°, :data:`~hil.trial.scene.SUCCESS_WRAP_DEG`). Per set-up and band: Wilson 95 %
intervals and McNemar's exact test. The verdict rule, fixed before the run: the claim holds in a set-up
if, in its between band, the strategy succeeds more often than the ramp with McNemar p < 0.05.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from controller.config import FirmwareConfig
from hil.errors import PlantDivergedError
from hil.experiments.base import Conditions, Experiment, Sizes
from hil.experiments.common import Row, extremes_rows, pct, pyplot, save_figure, worst_extremes
from hil.experiments.geometry import ArmFootprint, Envelope, joint_points_xz
from hil.experiments.outcomes import placement_row
from hil.experiments.parallel import parallel_map
from hil.experiments.stats import mcnemar_exact, wilson_interval
from hil.sim.config import ModelConfig
from hil.sim.plant import Plant
from hil.sim.presets import PRESETS
from hil.sim.spiral import SpiralDesign
from hil.sim.types import PhysicsExtremes, PlantConfig
from hil.trial.arm_45cm import paper_arm_45cm, with_timestep
from hil.trial.grasp import GraspOutcome, GraspSetup, grasp_firmware, grasp_rig, grasp_trial
from hil.trial.scene import BASE_Z_M, MS, SUCCESS_WRAP_DEG, S
from protocol.messages import GraspState

BANDS = ("catch", "between", "beyond")
SETUPS = ("prototype", "paper")
"""``prototype``: the 3-cable 23 cm arm hanging under gravity, on the given model; ``paper``: the 2-cable
45 cm arm in a plane on the authors' model, gravity off (:func:`setup_arm`)."""


@dataclass(frozen=True)
class BandsParams:
    """Attributes:
    setups: which of :data:`SETUPS`.
    bands: which of :data:`BANDS`.
    per_band: placements per set-up and band.
    diameter_m: per set-up, the object's diameter (the paper's arm is twice the prototype's length).
    beyond_ratio: the beyond band's outer edge, in envelope radii.
    clearance_m: the smallest gap between a placement and the packed or straight arm.
    mass_kg: the object's mass.
    hold_s: how long a released object must stay.
    """

    setups: tuple[str, ...] = SETUPS
    bands: tuple[str, ...] = BANDS
    per_band: int = 16
    diameter_m: tuple[tuple[str, float], ...] = (("prototype", 0.024), ("paper", 0.048))
    beyond_ratio: float = 1.3
    clearance_m: float = 0.002
    mass_kg: float = 0.02
    hold_s: float = 0.6

    def diameter(self, setup: str) -> float:
        """The object's diameter in ``setup``."""
        return dict(self.diameter_m)[setup]


TINY = BandsParams(setups=("prototype",), bands=("catch", "between"), per_band=1)
"""The smoke-test size: one placement in the prototype's catch and between bands."""


def _is_force(key: str) -> bool:
    """A firmware key in newtons (a tension, a tension rate, a force gain or limit)."""
    return key.endswith("_n") or "_n_per_" in key


def setup_arm(setup: str, model: ModelConfig) -> tuple[SpiralDesign, ModelConfig, FirmwareConfig]:
    """The arm, plant model and firmware of a set-up (see :data:`SETUPS`).

    ``prototype``: the prototype on ``model`` with the grasp experiments' firmware. ``paper``: the 45 cm
    2-cable arm on the authors' model (``--preset authors``: muscles of 5 N, 0.04 N·m/rad, stiffness ∝
    size², gravity off) at ``model``'s physics step, and the same firmware with every tension and
    tension rate scaled by the muscle's force over the firmware's tension ceiling (5 N / 20 N): the
    grasp's tension schedule keeps its shape within what the authors' actuator can pull (every key in
    newtons: tensions, tension rates, the length hold's force gain and limit).

    Raises:
        ValueError: an unknown set-up.
    """
    firmware = grasp_firmware()
    if setup == "prototype":
        return SpiralDesign.paper_prototype(), model, firmware
    if setup == "paper":
        authors = PRESETS["authors"].model.with_physics(model.solver.timestep_s)
        scale = authors.muscle_force_n / firmware.mapping.tension_max_n
        values = firmware.to_dict()
        firmware = firmware.replaced(**{k: v * scale for k, v in values.items() if _is_force(k)})
        return paper_arm_45cm(), authors, firmware
    raise ValueError(f"unknown set-up {setup!r} (known: {', '.join(SETUPS)})")


@dataclass(frozen=True)
class Sweep:
    """What the plain ramp sweeps: every unit's segment (x-z, from the base) at every 5 ms snapshot.

    Attributes:
        a: segment starts, shape (snapshots, units), complex ``x + i z``.
        b: segment ends, the same shape.
        half_width_m: each unit's half width, shape (units,).
    """

    a: npt.NDArray[np.complex128]
    b: npt.NDArray[np.complex128]
    half_width_m: npt.NDArray[np.float64]

    def clearance_m(self, x_m: float, z_m: float, radius_m: float) -> float:
        """The smallest gap between an object of ``radius_m`` at ``(x, z)`` and the swept arm (< 0: the
        ramp touches it)."""
        p = complex(x_m, z_m)
        d = self.b - self.a
        t = np.clip(((p - self.a) * d.conjugate()).real / np.maximum(np.abs(d) ** 2, 1e-18), 0.0, 1.0)
        dist = np.abs(p - (self.a + t * d)) - self.half_width_m[None, :]
        return float(dist.min()) - radius_m


def ramp_sweep(
    design: SpiralDesign, model: ModelConfig, firmware: FirmwareConfig | None = None, timeout_s: float = 8.0
) -> Sweep:
    """Run the plain ramp (GRASP mode, strategy off) with no object in reach, from the straight arm to
    HOLD (and 0.3 s more) or FAILED, and keep every unit's segment every 5 ms.

    Raises:
        RuntimeError: the ramp never started.
    """
    return _sweep(design, model, firmware, False, timeout_s)


def reach_sweep(
    design: SpiralDesign, model: ModelConfig, firmware: FirmwareConfig | None = None, timeout_s: float = 12.0
) -> Sweep:
    """Run the strategy's reach (GRASP mode, strategy on) with no object in reach: from the packed arm, the
    pack and then the unroll until the reach times out (FAILED), every unit's segment every 5 ms of REACH.
    What it sweeps is where the strategy can meet an object (the test of the bands' cause).

    Raises:
        RuntimeError: the reach never started.
    """
    return _sweep(design, model, firmware, True, timeout_s)


def _sweep(
    design: SpiralDesign,
    model: ModelConfig,
    firmware: FirmwareConfig | None,
    strategy_on: bool,
    timeout_s: float,
) -> Sweep:
    setup = GraspSetup(1.0, 0.0, 0.02, strategy_on=strategy_on, model=model, firmware=firmware)  # object far
    rig = grasp_rig(setup, design)
    kept = (GraspState.REACH,) if strategy_on else (GraspState.WRAP, GraspState.HOLD)
    snaps: list[npt.NDArray[np.complex128]] = []
    end_us = int(timeout_s * S)
    base = complex(joint_points_xz(rig.plant)[0]) if strategy_on else None  # the packed start moves no base
    while rig.now_us < end_us:
        rig.step()
        state = rig.firmware.grasp_state
        if state in kept and rig.now_us % (5 * MS) == 0:
            pts = joint_points_xz(rig.plant)
            base = pts[0] if base is None else base
            snaps.append(pts - base)
        if state == GraspState.HOLD and end_us > rig.now_us + 300 * MS:
            end_us = rig.now_us + 300 * MS
        if state == GraspState.FAILED:
            break
    widths = np.array([max(w0, w1) / 2 for _, w0, w1 in rig.plant.unit_dimensions_m()])
    rig.close()
    if not snaps:
        raise RuntimeError(f"the {'reach' if strategy_on else 'ramp'} never started")
    pts = np.array(snaps)
    return Sweep(pts[:, :-1], pts[:, 1:], widths)


@dataclass(frozen=True)
class BandMap:
    """Where each band lies for one set-up: the sweep, the reach and the arm's two starts."""

    sweep: Sweep
    envelope: Envelope
    foot: ArmFootprint
    length_m: float

    def band(self, x_m: float, z_m: float, radius_m: float, p: BandsParams) -> str | None:
        """The band of an object at ``(x, z)`` (from the base), or None (in neither band, or not clear of
        the arm's starts)."""
        if self.foot.clearance_m(x_m, z_m, radius_m) < p.clearance_m:
            return None
        if self.sweep.clearance_m(x_m, z_m, radius_m) < 0.0:
            return "catch"
        ratio = self.envelope.exact_ratio(x_m, BASE_Z_M + z_m)
        if ratio <= 1.0:
            return "between"
        return "beyond" if ratio <= p.beyond_ratio else None


def band_map(design: SpiralDesign, model: ModelConfig, firmware: FirmwareConfig | None = None) -> BandMap:
    """Measure a set-up's bands (the ramp's sweep under ``firmware``, the envelope, the footprint)."""
    plant = Plant(design, PlantConfig(model=model))
    envelope = Envelope.of(plant)
    sweep = ramp_sweep(design, model, firmware)
    return BandMap(sweep, envelope, ArmFootprint.of(design, model), design.length_m)


def draw_placements(
    bands: BandMap, p: BandsParams, radius_m: float, rng: np.random.Generator
) -> dict[str, list[tuple[float, float]]]:
    """``per_band`` placements per band, uniform over the region beside the arm (x from 0 to 0.8 of its
    length toward cable 0, z from its length below the base to the base) by rejection.

    Raises:
        ValueError: a band too small to draw from.
    """
    out: dict[str, list[tuple[float, float]]] = {b: [] for b in p.bands}
    length = bands.length_m
    for _ in range(400_000):
        if all(len(v) >= p.per_band for v in out.values()):
            return out
        x, z = float(rng.uniform(0.0, 0.8 * length)), float(rng.uniform(-length, 0.0))
        band = bands.band(x, z, radius_m, p)
        if band in out and len(out[band]) < p.per_band:
            out[band].append((x, z))
    short = [b for b, v in out.items() if len(v) < p.per_band]
    raise ValueError(f"band(s) {', '.join(short)} too small: fewer than {p.per_band} placements found")


def band_grasp(job: tuple[GraspSetup, SpiralDesign]) -> GraspOutcome | None:
    """One grasp; diverged physics once more at half the step; None if that diverges too."""
    setup, design = job
    for attempt in range(2):
        try:
            return grasp_trial(setup, design)
        except PlantDivergedError:
            if attempt == 0:
                step = setup.model.solver.timestep_s / 2
                setup = dataclasses.replace(setup, model=with_timestep(setup.model, step))
    return None


@dataclass(frozen=True)
class BandsResult:
    """Every band's paired grasps (a :class:`~hil.experiments.base.Result`)."""

    params: BandsParams
    seed: int
    placements: tuple[tuple[str, str, float, float], ...]
    """``(set-up, band, x, z)`` of each placement, in the order of the outcomes' pairs."""
    outcomes: tuple[GraspOutcome | None, ...]
    """Per placement, the ramp's grasp then the strategy's (None: its physics diverged twice)."""
    reach_touches: tuple[bool, ...] = ()
    """Per placement, whether the strategy's reach with no object (:func:`reach_sweep`) passes through it:
    where the strategy can meet an object at all."""

    def reached(self, setup: str, band: str) -> tuple[int, int]:
        """Placements of one set-up and band the reach's sweep passes through, of all."""
        sel = [
            t
            for (s, b, _, _), t in zip(self.placements, self.reach_touches, strict=False)
            if (s, b) == (setup, band)
        ]
        return sum(sel), len(sel)

    @property
    def extremes(self) -> PhysicsExtremes:
        """The worst physics over every grasp."""
        return worst_extremes(o.extremes for o in self.outcomes if o is not None)

    def diverged(self, setup: str | None = None) -> int:
        """Pairs left out because a grasp diverged at both steps (of one set-up, or all)."""
        return sum(
            1
            for i, (s, _, _, _) in enumerate(self.placements)
            if (setup is None or s == setup)
            and (self.outcomes[2 * i] is None or self.outcomes[2 * i + 1] is None)
        )

    def finer_step(self) -> int:
        """Grasps that diverged once and were run at half the step."""
        steps = [o.setup.model.solver.timestep_s for o in self.outcomes if o is not None]
        return sum(1 for t in steps if t < max(steps)) if steps else 0

    def pairs(self, setup: str, band: str) -> list[tuple[GraspOutcome, GraspOutcome]]:
        """The (ramp, strategy) grasps of one set-up and band (pairs with a diverged grasp left out)."""
        out = []
        for i, (s, b, _, _) in enumerate(self.placements):
            off, on = self.outcomes[2 * i], self.outcomes[2 * i + 1]
            if s == setup and b == band and off is not None and on is not None:
                out.append((off, on))
        return out

    def cell(self, setup: str, band: str) -> dict[str, Any]:
        """Rates with Wilson intervals of both arms, discordant pairs and McNemar's p."""
        pairs = self.pairs(setup, band)
        out: dict[str, Any] = {"n": len(pairs)}
        for name, k in (("off", sum(a.success for a, _ in pairs)), ("on", sum(b.success for _, b in pairs))):
            lo, hi = wilson_interval(k, len(pairs))
            out[name] = {"successes": k, "rate": k / len(pairs) if pairs else math.nan, "ci95": [lo, hi]}
        only_on = sum(1 for a, b in pairs if b.success and not a.success)
        only_off = sum(1 for a, b in pairs if a.success and not b.success)
        out.update(only_on=only_on, only_off=only_off, p_value=mcnemar_exact(only_on, only_off))
        return out

    def verdict(self, setup: str) -> str:
        """The fixed rule on the between band: ``holds`` or ``not reproduced`` (or ``not tested``)."""
        if "between" not in self.params.bands:
            return "not tested"
        c = self.cell(setup, "between")
        return "holds" if c["only_on"] > c["only_off"] and c["p_value"] < 0.05 else "not reproduced"

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        p = self.params
        return {
            "experiment": "bands",
            "seed": self.seed,
            "criterion": f"held {p.hold_s:g} s after release and wrap >= {SUCCESS_WRAP_DEG:g} deg",
            "cells": {s: {b: self.cell(s, b) for b in p.bands} for s in p.setups},
            "verdicts": {s: self.verdict(s) for s in p.setups},
            "placements": [list(x) for x in self.placements],
            "reach_touches": {s: {b: list(self.reached(s, b)) for b in p.bands} for s in p.setups},
            "diverged_pairs": self.diverged(),
            "finer_step_grasps": self.finer_step(),
            "extremes": self.extremes.as_dict(),
            "trials": len(self.outcomes),
            "outcomes": [None if o is None else o.as_dict() for o in self.outcomes],
            "params": dataclasses.asdict(p),
        }

    def table_rows(self) -> list[Row]:
        """Per set-up and band: ramp and strategy with intervals, McNemar; the verdicts; the physics."""
        rows: list[Row] = []
        for s in self.params.setups:
            for b in self.params.bands:
                c = self.cell(s, b)
                text = " / ".join(
                    f"{pct(c[a]['rate'])} [{pct(c[a]['ci95'][0])}, {pct(c[a]['ci95'][1])}]"
                    for a in ("off", "on")
                )
                rows.append(
                    (
                        f"{s}, {b} band (n = {c['n']}): ramp / strategy",
                        f"{text}; only on {c['only_on']}, only off {c['only_off']}, p = {c['p_value']:.3g}",
                        "strategy > ramp" if b == "between" else "",
                    )
                )
            reached = ", ".join(f"{b} {k}/{n}" for b in self.params.bands for k, n in [self.reached(s, b)])
            rows.append((f"{s}: placements the strategy's reach passes through (no object)", reached, ""))
            rows.append((f"{s}: the claim in its between band", self.verdict(s), "holds (Note S4)"))
        rows.append(
            (
                "grasps run again at half the step / pairs left out (diverged twice)",
                f"{self.finer_step()} / {self.diverged()}",
                "",
            )
        )
        rows.append(placement_row(self.outcomes))
        rows.extend(extremes_rows(self.extremes))
        return rows

    def describe_samples(self) -> str:
        """Set-ups, bands, placements and grasps, in words."""
        p = self.params
        return (
            f"{len(p.setups)} set-up(s) x {len(p.bands)} bands x {p.per_band} placements x 2 (ramp, "
            f"strategy) = {len(self.outcomes)} grasps (success = held {p.hold_s:g} s after release and "
            f"wrapped >= {SUCCESS_WRAP_DEG:g}°)"
        )

    def figure(self, out: Path) -> Path:
        """Write ``bands.png``: per set-up, each placement coloured by its band, marked by who grasped it."""
        plt = pyplot()
        setups = self.params.setups
        fig, axes = plt.subplots(1, len(setups), figsize=(5.0 * len(setups), 5.4), squeeze=False)
        colour = {"catch": "tab:blue", "between": "tab:green", "beyond": "tab:red"}
        marker = {(True, True): "o", (True, False): "^", (False, True): "v", (False, False): "x"}
        for ax, s in zip(axes[0], setups, strict=True):
            for i, (setup, band, x, z) in enumerate(self.placements):
                if setup != s:
                    continue
                a, b = self.outcomes[2 * i], self.outcomes[2 * i + 1]
                if a is None or b is None:
                    continue
                off, on = a.success, b.success
                ax.plot(x * 1000, z * 1000, marker=marker[(on, off)], color=colour[band], ls="", ms=7)
            verdict = self.verdict(s)
            ax.set_title(f"{s}: claim {verdict}", fontsize=9)
            ax.set_aspect("equal")
            ax.grid(alpha=0.3)
            ax.set_xlabel("object centre from the arm's axis [mm]", fontsize=8)
            ax.set_ylabel("object centre from the base [mm]", fontsize=8)
        handles = [
            plt.Line2D([], [], marker="s", color=c, ls="", label=f"{b} band") for b, c in colour.items()
        ]
        handles += [
            plt.Line2D([], [], marker=m, color="0.3", ls="", label=lab)
            for m, lab in zip(marker.values(), ("both", "strategy only", "ramp only", "neither"), strict=True)
        ]
        axes[0][0].legend(handles=handles, fontsize=7, loc="lower left")
        fig.suptitle("the strategy claim per band (placements drawn per band before any grasp)", fontsize=10)
        return save_figure(fig, out / "bands.png")


def bands(p: BandsParams, on: Conditions) -> BandsResult:
    """Measure each set-up's bands, draw the placements, grasp each with the ramp and the strategy (Note
    S4). The arms are the set-ups' own, not ``on.design``."""
    placements: list[tuple[str, str, float, float]] = []
    touches: list[bool] = []
    jobs: list[tuple[GraspSetup, SpiralDesign]] = []
    for s in p.setups:
        design, model, firmware = setup_arm(s, on.model)
        d = p.diameter(s)
        rng = np.random.default_rng([on.seed, SETUPS.index(s)])
        drawn = draw_placements(band_map(design, model, firmware), p, d / 2, rng)
        reach = reach_sweep(design, model, firmware)
        for band in p.bands:
            for x, z in drawn[band]:
                placements.append((s, band, x, z))
                touches.append(reach.clearance_m(x, z, d / 2) < 0.0)
                for strategy_on in (False, True):
                    setup = GraspSetup(
                        x,
                        z,
                        d,
                        strategy_on=strategy_on,
                        mass_kg=p.mass_kg,
                        hold_s=p.hold_s,
                        model=model,
                        seed=on.seed,
                    )
                    jobs.append((setup, design))
    outcomes = parallel_map(band_grasp, jobs, on.jobs, on.progress)
    return BandsResult(p, on.seed, tuple(placements), tuple(outcomes), tuple(touches))


EXPERIMENT = Experiment(
    "bands",
    "the strategy against the ramp per band (ramp's catch, between it and the reach, beyond), two set-ups",
    # tiny: one placement in the prototype's catch and between bands; default: 16 per band and set-up
    Sizes(TINY, BandsParams(), BandsParams(per_band=40)),
    bands,
    own_arm="its set-ups' arms (the prototype; the 45 cm 2-cable arm)",
)
"""The bands experiment (:mod:`hil.experiments.catalogue`)."""
