"""workspace (Note S2, Fig. 2E / S4): random per-cable tensions against the envelope ρw."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from controller.config import FirmwareConfig, MappingConfig, MotorDriveConfig
from hil.experiments.base import Conditions, Experiment, Sizes
from hil.experiments.common import Row, extremes_rows, pct, pyplot, save_figure, worst_extremes
from hil.experiments.geometry import Envelope
from hil.experiments.parallel import parallel_map
from hil.sim.config import ActuatorConfig, ModelConfig
from hil.sim.spiral import SpiralDesign
from hil.sim.types import PhysicsExtremes
from hil.trial.rig import direct_rig
from hil.trial.scene import BASE_Z_M


@dataclass(frozen=True)
class WorkspaceParams:
    """Attributes:
    tapers_deg: taper angles of the three designs (length, tip width and Δθ of the prototype).
    cables: cable counts to run for each taper.
    duration_s: random drive per design (one tip sample every ``sample_ms``).
    sample_ms: tip sample period.
    hold_ms: each random tension set is held for a time drawn from this range.
    tension_max_n: largest random tension (the firmware's per-cable ceiling).
    cell_m: raster cell of the coverage measure.
    drive: how a random tension set is drawn (see :func:`_random_tensions`).
    variants: plant variants run for every design (:data:`VARIANTS`): ``as-given`` is the model the
        experiment was given; Fig. 2E's setup is ``gravity-off`` (the authors' simulation had no gravity)
        and ``gravity-off-light`` (also a light ideal tension source instead of the M2006 and spool).
    saturate_window_s: coverage has saturated when it grew less than ``saturate_gain`` (a share of the
        exact area) over the last ``saturate_window_s``; the drive then stops, at the latest after
        ``duration_s``.
    saturate_gain: see ``saturate_window_s``; 0 = never stop early.
    """

    tapers_deg: tuple[float, ...] = (5.0, 6.5, 9.0)
    cables: tuple[int, ...] = (2,)
    duration_s: float = 240.0
    sample_ms: int = 5
    hold_ms: tuple[int, int] = (50, 300)
    tension_max_n: float = 20.0
    cell_m: float = 0.004
    drive: str = "mixed"
    variants: tuple[str, ...] = ("as-given", "gravity-off", "gravity-off-light")
    saturate_window_s: float = 30.0
    saturate_gain: float = 0.01


GOVERNOR_OFF_M_S = 10.0
"""The governor's largest setting, far above the M2006's no-load cable speed (0.52 m/s): never acts."""

VARIANTS = ("as-given", "gravity-off", "gravity-off-light")
"""The plant variants :func:`variant_model` knows."""


def variant_model(model: ModelConfig, variant: str) -> ModelConfig:
    """``model`` as it is, with gravity off, or with gravity off and a light ideal tension source.

    Raises:
        ValueError: an unknown variant.
    """
    if variant == "as-given":
        return model
    if variant == "gravity-off":
        return dataclasses.replace(model, mounting="gravity-off")
    if variant == "gravity-off-light":
        return dataclasses.replace(model, mounting="gravity-off", actuator=ActuatorConfig(kind="tension"))
    raise ValueError(f"unknown workspace variant {variant!r}; choose from {', '.join(VARIANTS)}")


@dataclass(frozen=True)
class WorkspaceRun:
    """One design's random drive.

    ``inside_share`` / ``coverage`` / ``envelope_area_m2`` refer to Table S1's ρw (the involute unwound from
    the virtual tip), ``*_exact`` to the real tip's base-first curve (:func:`base_first_tip_curve`);
    ``inside_share_eta`` allows ρw the discretisation tolerance 1/η. Areas: the half plane on the curl
    side (u >= 0), rastered in ``cell_m`` cells; ``covered_area_m2``: the cells the tip visited.
    ``coverage_trace``: ``coverage_exact`` after each simulated second; ``saturated``: the drive stopped
    because coverage stopped growing (see :class:`WorkspaceParams`), after ``duration_s``.
    """

    taper_deg: float
    cables: int
    variant: str
    b: float
    units: int
    samples: int
    inside_share: float
    inside_share_eta: float
    inside_share_exact: float
    coverage: float
    coverage_exact: float
    envelope_area_m2: float
    exact_area_m2: float
    covered_area_m2: float
    duration_s: float
    saturated: bool
    coverage_trace: tuple[float, ...]
    extremes: PhysicsExtremes
    u_m: tuple[float, ...] = field(repr=False)
    z_m: tuple[float, ...] = field(repr=False)
    boundary: tuple[tuple[float, float], ...] = field(repr=False)
    exact_boundary: tuple[tuple[float, float], ...] = field(repr=False)


@dataclass(frozen=True)
class WorkspaceResult:
    """All designs: the share of tip samples inside ρw, and the covered share of its area (a
    :class:`~hil.experiments.base.Result`)."""

    params: WorkspaceParams
    seed: int
    runs: tuple[WorkspaceRun, ...]

    @property
    def inside_share(self) -> float:
        """Share of all tip samples (every design) inside the envelope."""
        n = sum(r.samples for r in self.runs)
        return sum(r.inside_share * r.samples for r in self.runs) / n if n else math.nan

    @property
    def extremes(self) -> PhysicsExtremes:
        """The worst physics over every run."""
        return worst_extremes(r.extremes for r in self.runs)

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready form (without the raw samples)."""
        return {
            "experiment": "workspace",
            "seed": self.seed,
            "inside_share": self.inside_share,
            "samples": sum(r.samples for r in self.runs),
            "extremes": self.extremes.as_dict(),
            "runs": [
                {
                    k: v
                    for k, v in dataclasses.asdict(r).items()
                    if k not in ("u_m", "z_m", "boundary", "exact_boundary")
                }
                for r in self.runs
            ],
            "params": dataclasses.asdict(self.params),
        }

    def table_rows(self) -> list[Row]:
        """The result's numbers next to the paper's, one row each."""
        n = sum(x.samples for x in self.runs)
        exact = sum(x.inside_share_exact * x.samples for x in self.runs) / n if n else math.nan
        rows: list[Row] = [
            ("tip samples inside ρw (all designs)", pct(self.inside_share), "reachable points lie inside ρw"),
            ("  inside the real tip's base-first curve", pct(exact), "(ρw is for the virtual tip)"),
        ]
        for run in self.runs:
            rows.append(
                (
                    f"taper {run.taper_deg:g}° (b = {run.b:.3f}), {run.cables} cables, {run.variant}: "
                    "area inside ρw / exact",
                    f"{run.envelope_area_m2 * 1e4:.0f} / {run.exact_area_m2 * 1e4:.0f} cm²",
                    "shrinks as b grows",
                )
            )
            rows.append(
                (
                    "  share of that area the tip reached (ρw / exact)",
                    f"{pct(run.coverage)} / {pct(run.coverage_exact)} ({run.covered_area_m2 * 1e4:.0f} cm²)",
                    "every point inside is reachable",
                )
            )
            rows.append(
                (
                    "  drive time; coverage saturated",
                    f"{run.duration_s:.0f} s; {'yes' if run.saturated else 'no (time limit)'}",
                    "-",
                )
            )
        rows.extend(extremes_rows(self.extremes))
        return rows

    def describe_samples(self) -> str:
        """Designs, plant variants, drive time and tip samples, in words."""
        return (
            f"{len(self.runs)} design/plant variants x up to {self.params.duration_s:g} s of random tensions "
            f"(until coverage saturates), "
            f"{sum(x.samples for x in self.runs)} tip samples (every {self.params.sample_ms} ms)"
        )

    def figure(self, out: Path) -> Path:
        """Write the figure into the directory ``out``; returns its path (``workspace.png``)."""
        plt = pyplot()
        rows_of = sorted({(x.cables, x.variant) for x in self.runs})
        tapers = sorted({x.taper_deg for x in self.runs})
        # One row of tip clouds per (cables, variant), one column per taper; the last row: coverage against
        # time.
        fig = plt.figure(figsize=(3.6 * len(tapers), 4.2 * len(rows_of) + 3.0))
        grid = fig.add_gridspec(len(rows_of) + 1, len(tapers), height_ratios=[4.2] * len(rows_of) + [3.0])
        axes = [[fig.add_subplot(grid[i, j]) for j in range(len(tapers))] for i in range(len(rows_of))]
        cov = fig.add_subplot(grid[len(rows_of), :])
        for run in self.runs:
            cov.plot(
                np.arange(1, len(run.coverage_trace) + 1),
                100 * np.array(run.coverage_trace),
                lw=1.0,
                label=f"{run.cables} cables, {run.variant}, taper {run.taper_deg:g}°",
            )
        cov.set_xlabel("drive time [s]", fontsize=7)
        cov.set_ylabel("share of the exact envelope reached [%]", fontsize=7)
        cov.grid(alpha=0.3)
        cov.legend(fontsize=6, ncol=3)
        cov.tick_params(labelsize=7)
        for run in self.runs:
            ax = axes[rows_of.index((run.cables, run.variant))][tapers.index(run.taper_deg)]
            b = np.array(run.boundary)
            ax.plot(np.array(run.u_m) * 1000, (np.array(run.z_m) - BASE_Z_M) * 1000, ".", ms=1.2, alpha=0.5)
            ax.plot(b[:, 0] * 1000, (b[:, 1] - BASE_Z_M) * 1000, "r-", lw=1.2, label="ρw (Table S1)")
            e = np.array(run.exact_boundary)
            ax.plot(e[:, 0] * 1000, (e[:, 1] - BASE_Z_M) * 1000, "g-", lw=1.0, label="real tip, base first")
            ax.plot([0], [0], "k^", ms=6, label="base")
            ax.set_title(
                f"taper {run.taper_deg:g}°, b={run.b:.3f}, {run.cables} cables, {run.variant}\n"
                f"inside ρw {pct(run.inside_share)}, exact {pct(run.inside_share_exact)}; "
                f"reached {pct(run.coverage_exact)} of the exact area",
                fontsize=8,
            )
            ax.set_aspect("equal")
            ax.set_xlim(-20, 280)
            ax.grid(alpha=0.3)
            ax.set_xlabel("distance from the arm's axis [mm]", fontsize=7)
            ax.set_ylabel("height above the base [mm]", fontsize=7)
            ax.tick_params(labelsize=7)
        axes[0][0].legend(fontsize=7, loc="lower right")
        fig.suptitle("workspace: tip samples under random cable tensions vs. the envelope ρw", fontsize=10)
        return save_figure(fig, out / "workspace.png")


def _random_tensions(rng: np.random.Generator, p: WorkspaceParams) -> npt.NDArray[np.float64]:
    """One random tension set: ``uniform`` per cable, or ``single``: one cable anywhere in the range and
    the others low (one cable at a time is what bends the arm furthest), or ``mixed`` (either, 50/50)."""
    hi = p.tension_max_n
    single = p.drive == "single" or (p.drive == "mixed" and rng.random() < 0.5)
    if not single:
        return rng.uniform(0.5, hi, 3)
    out = rng.uniform(0.5, 2.0, 3)
    out[int(rng.integers(0, 3))] = rng.uniform(0.5, hi)
    return out


def _workspace_run(args: tuple[float, int, str, WorkspaceParams, int, ModelConfig]) -> WorkspaceRun:
    taper_deg, cables, variant, p, seed, model = args
    base = SpiralDesign.paper_prototype()
    design = SpiralDesign.from_physical(
        length_m=0.23,
        tip_width_m=base.tip_width_m,
        taper_rad=math.radians(taper_deg),
        dtheta_rad=base.dtheta_rad,
        cables=cables,
    )
    # The firmware's reel-in governor (a safety limit for the cable, 0.1 m/s) is off: Fig. 2E asks what the
    # arm's body can reach, as the paper's simulation does without a drive. With it on, 30 s of this drive
    # covered 17-19 % of the exact area instead of 21-24 % (docs/experiments.md).
    fw = FirmwareConfig(
        motor=MotorDriveConfig(payin_limit_m_per_s=GOVERNOR_OFF_M_S),
        mapping=MappingConfig(tension_max_n=p.tension_max_n),
    )
    rig = direct_rig(design, fw, seed=seed, model=variant_model(model, variant))
    env = Envelope.of(rig.plant)
    # The raster, fixed before the drive so coverage can be followed while it runs: cells whose centre is
    # inside each envelope (a sample outside the grid counts in its edge cell, outside both envelopes).
    bnd = env.boundary()
    margin = 0.02
    lo_u, hi_u = 0.0, float(bnd[:, 0].max()) + margin
    lo_z, hi_z = float(bnd[:, 1].min()) - margin, float(bnd[:, 1].max()) + margin
    nu = int((hi_u - lo_u) / p.cell_m) + 1
    nz = int((hi_z - lo_z) / p.cell_m) + 1
    in_w = np.zeros((nu, nz), bool)
    in_exact = np.zeros((nu, nz), bool)
    for a in range(nu):
        for b in range(nz):
            cu, cz = lo_u + (a + 0.5) * p.cell_m, lo_z + (b + 0.5) * p.cell_m
            in_w[a, b] = env.ratio(cu, cz) <= 1.0
            in_exact[a, b] = env.exact_ratio(cu, cz) <= 1.0
    hit = np.zeros((nu, nz), bool)
    exact_cells = int(in_exact.sum())
    rng = np.random.default_rng([seed, cables, round(taper_deg * 100), VARIANTS.index(variant)])
    limit_ms = int(p.duration_s * 1000)
    window = max(1, round(p.saturate_window_s))
    u: list[float] = []
    z: list[float] = []
    trace: list[float] = []
    next_change = 0
    warm = 300  # ms before the first sample
    t = 0
    saturated = False
    while t < limit_ms + warm and not saturated:
        if t >= next_change:
            tensions = _random_tensions(rng, p)
            rig.set_tensions(tensions[:cables].tolist() + [0.0] * (3 - cables))
            next_change = t + int(rng.integers(p.hold_ms[0], p.hold_ms[1] + 1))
        rig.step()
        t += 1
        if t > warm and t % p.sample_ms == 0:
            tip = rig.plant.tip_pose().pos_m
            uu = abs(tip[0]) if cables < 3 else math.hypot(tip[0], tip[1])
            u.append(uu)
            z.append(float(tip[2]))
            ia = min(max(int((uu - lo_u) / p.cell_m), 0), nu - 1)
            ib = min(max(int((tip[2] - lo_z) / p.cell_m), 0), nz - 1)
            hit[ia, ib] = True
        if t > warm and (t - warm) % 1000 == 0:
            trace.append(float((hit & in_exact).sum() / exact_cells) if exact_cells else math.nan)
            grown = trace[-1] - trace[-1 - window] if len(trace) > window else math.inf
            saturated = p.saturate_gain > 0 and grown < p.saturate_gain
    extremes = rig.plant.extremes()
    rig.close()
    ua, za = np.array(u), np.array(z)
    ratios = np.array([env.ratio(float(a), float(b)) for a, b in zip(ua, za, strict=True)])
    exact = np.array([env.exact_ratio(float(a), float(b)) for a, b in zip(ua, za, strict=True)])
    cell_area = p.cell_m**2

    def share(mask: npt.NDArray[np.bool_]) -> float:
        cells = int(mask.sum())
        return float((hit & mask).sum() / cells) if cells else math.nan

    return WorkspaceRun(
        taper_deg,
        cables,
        variant,
        design.b,
        design.units,
        len(u),
        float(np.mean(ratios <= 1.0)) if len(u) else math.nan,
        float(np.mean(ratios <= 1.0 / design.eta)) if len(u) else math.nan,
        float(np.mean(exact <= 1.0 + 1e-9)) if len(u) else math.nan,
        share(in_w),
        share(in_exact),
        float(in_w.sum()) * cell_area,
        float(in_exact.sum()) * cell_area,
        float(hit.sum()) * cell_area,
        (t - warm) / 1000.0,
        saturated,
        tuple(trace),
        extremes,
        tuple(u),
        tuple(z),
        tuple((float(a), float(b)) for a, b in bnd),
        tuple((float(a), float(b)) for a, b in env.exact_boundary()),
    )


def workspace(p: WorkspaceParams, on: Conditions) -> WorkspaceResult:
    """Random per-cable tensions through the firmware (DIRECT mode) on arms of three taper angles (not
    ``on.design``), on the plant ``on.model`` and its variants (Fig. 2E: a 2-cable arm with gravity off), each
    until its coverage of the exact envelope saturates; tip samples against the involute envelope ρw
    (Note S2, Fig. 2E / S4).

    Raises:
        ValueError: an unknown variant.
    """
    seed, model = on.seed, on.model
    for v in p.variants:
        variant_model(model, v)
    items = [(taper, c, v, p, seed, model) for taper in p.tapers_deg for c in p.cables for v in p.variants]
    runs = parallel_map(_workspace_run, items, on.jobs, on.progress)
    return WorkspaceResult(p, seed, tuple(runs))


EXPERIMENT = Experiment(
    "workspace",
    "random cable tensions on 2- and 3-cable arms of three tapers vs. the envelope ρw (Note S2)",
    Sizes(
        WorkspaceParams(tapers_deg=(6.5,), duration_s=2.0, variants=("gravity-off",), saturate_window_s=1.0),
        WorkspaceParams(),
        WorkspaceParams(cables=(2, 3), duration_s=600.0, saturate_gain=0.005),
    ),
    workspace,
    own_arm="2- and 3-cable arms of three tapers (Note S2)",
)
"""The workspace experiment (:mod:`hil.experiments.catalogue`)."""
