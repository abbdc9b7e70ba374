"""packing (Note S3, Fig. S5C): one cable's tension ramped until the arm packs into the design spiral."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from controller.config import FirmwareConfig, MappingConfig
from hil.experiments.base import Conditions, Experiment, Sizes
from hil.experiments.common import Row, extremes_rows, pyplot, save_figure
from hil.experiments.geometry import fit_log_spiral, joint_points_xz
from hil.sim.types import PhysicsExtremes
from hil.trial.rig import direct_rig
from hil.trial.scene import BASE_Z_M


@dataclass(frozen=True)
class PackingParams:
    """Attributes:
    tension_end_n: the ramp of cable 0's tension ends here (54 N = 3 A, the firmware's current limit).
    ramp_s: ramp duration (slow: quasi-static).
    hold_s: the end tension is held this long before the spiral is fitted.
    limit_tol_deg: a joint counts as closed within this of its limit Δθ.
    command_ms: the host sends a new tension this often.
    """

    tension_end_n: float = 54.0
    ramp_s: float = 8.0
    hold_s: float = 0.5
    limit_tol_deg: float = 1.5
    command_ms: int = 10


@dataclass(frozen=True)
class PackingResult:
    """Ramp one cable until the arm packs: the tension and current it took, the fitted spiral, the order
    (a :class:`~hil.experiments.base.Result`)."""

    params: PackingParams
    seed: int
    b_design: float
    b_fit: float
    turn_design_deg: float
    turn_fit_deg: float
    joints: int
    packed: bool
    pack_tension_n: float
    pack_current_a: float
    close_order: tuple[int, ...]
    close_tension_n: tuple[float, ...]
    order_correlation: float
    extremes: PhysicsExtremes
    ramp_tension_n: tuple[float, ...] = field(repr=False)
    closed_count: tuple[int, ...] = field(repr=False)
    joint_points: tuple[tuple[float, float], ...] = field(repr=False)
    pole: tuple[float, float] = field(repr=False)

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        return {
            "experiment": "packing",
            "seed": self.seed,
            "b_design": self.b_design,
            "b_fit": self.b_fit,
            "b_error": self.b_fit / self.b_design - 1.0,
            "turn_design_deg": self.turn_design_deg,
            "turn_fit_deg": self.turn_fit_deg,
            "joints": self.joints,
            "packed": self.packed,
            "pack_tension_n": self.pack_tension_n,
            "pack_current_a": self.pack_current_a,
            "close_order": list(self.close_order),
            "close_tension_n": list(self.close_tension_n),
            "order_correlation": self.order_correlation,
            "extremes": self.extremes.as_dict(),
            "params": dataclasses.asdict(self.params),
        }

    def table_rows(self) -> list[Row]:
        """The result's numbers next to the paper's, one row each."""
        order = (
            "tip first"
            if self.order_correlation < -0.8
            else "base first"
            if self.order_correlation > 0.8
            else "mixed"
        )
        return [
            (
                "fitted spiral b of the packed joints",
                f"{self.b_fit:.4f} (design {self.b_design:.4f}, "
                f"{100 * (self.b_fit / self.b_design - 1):+.1f} %)",
                "packed = the design's log spiral (Fig. S5)",
            ),
            ("turn per joint when packed", f"{self.turn_fit_deg:.1f}°", f"Δθ = {self.turn_design_deg:g}°"),
            ("every joint at its limit", "yes" if self.packed else "no", "yes (tight packing)"),
            (
                "cable 0 tension / current that packed it",
                f"{self.pack_tension_n:.1f} N / {self.pack_current_a:.2f} A",
                "a minimum force exists (Fig. S3C; no value for this arm)",
            ),
            (
                "curl order (rank correlation joint index vs. closing tension)",
                f"{order} ({self.order_correlation:+.2f})",
                "curls from the tip (Fig. S5C, Note S4)",
            ),
            *extremes_rows(self.extremes),
        ]

    def describe_samples(self) -> str:
        """The ramp and the joints, in words."""
        return f"1 ramp of {self.params.ramp_s:g} s to {self.params.tension_end_n:g} N, {self.joints} joints"

    def figure(self, out: Path) -> Path:
        """Write the figure into the directory ``out``; returns its path (``packing.png``)."""
        plt = pyplot()
        fig, (a, b) = plt.subplots(1, 2, figsize=(10, 4.5))
        pts = np.array(self.joint_points)
        pole = complex(*self.pole)
        a.plot((pts[:, 0]) * 1000, (pts[:, 1] - BASE_Z_M) * 1000, "o-", ms=3, label="joints (packed)")
        w = pts[:, 0] + 1j * pts[:, 1] - pole
        ang = np.unwrap(np.angle(w))
        th = np.linspace(ang.min(), ang.max(), 300)
        r0 = abs(w[0])
        for bb, style, lab in ((self.b_design, "r--", "design b"), (self.b_fit, "g:", "fitted b")):
            rho = r0 * np.exp(bb * np.sign(ang[0] - ang[-1]) * (th - ang[0]))
            z = pole + rho * np.exp(1j * th)
            a.plot(z.real * 1000, (z.imag - BASE_Z_M) * 1000, style, lw=1, label=f"{lab} = {bb:.4f}")
        a.set_aspect("equal")
        a.grid(alpha=0.3)
        a.legend(fontsize=7)
        a.set_title("packed arm vs. the design spiral", fontsize=9)
        a.set_xlabel("x [mm]", fontsize=8)
        a.set_ylabel("z above the base [mm]", fontsize=8)
        b.plot(self.ramp_tension_n, self.closed_count, "-", lw=1.2)
        b.set_xlabel("cable 0 tension [N]", fontsize=8)
        b.set_ylabel("joints at their limit", fontsize=8)
        b2 = b.twinx()
        joints = np.arange(1, self.joints + 1)
        b2.plot(self.close_tension_n, joints, "r.", ms=5)
        b2.set_ylabel("joint (1 = base) by the tension that closed it", fontsize=8, color="r")
        b.set_title(
            f"packs at {self.pack_tension_n:.1f} N ({self.pack_current_a:.2f} A), curling from the tip",
            fontsize=9,
        )
        b.grid(alpha=0.3)
        return save_figure(fig, out / "packing.png")


def packing(p: PackingParams, on: Conditions) -> PackingResult:
    """Ramp cable 0's tension through the firmware (DIRECT) until every joint of ``on.design`` is at its
    limit Δθ; fit a logarithmic spiral to the joints; record in which order the joints closed (Note S3,
    Fig. S5C)."""
    design, seed, progress = on.design, on.seed, on.progress
    fw = FirmwareConfig(mapping=MappingConfig(tension_max_n=max(20.0, p.tension_end_n)))
    rig = direct_rig(design, fw, seed=seed, model=on.model)
    plant = rig.plant
    limit = design.dtheta_rad - math.radians(p.limit_tol_deg)
    n_joints = design.joints
    closed_at = np.full(n_joints, math.nan)
    ramp_ms = int(p.ramp_s * 1000)
    total = ramp_ms + int(p.hold_s * 1000)
    pretension = fw.mapping.pretension_n
    ramp_t: list[float] = []
    closed_n: list[int] = []
    pack_t = math.nan
    pack_i = math.nan
    for k in range(total):
        if k % p.command_ms == 0:
            t_cmd = pretension + (p.tension_end_n - pretension) * min(1.0, k / ramp_ms)
            rig.set_tensions([t_cmd, pretension, pretension])
        rig.step()
        # The cable's true tension at the spool, not the firmware's command: an actuator that cannot
        # deliver the command (the authors' 5 N muscles) must not be credited with it.
        tension = float(plant.cable_tensions_n()[0])
        angles = np.abs(plant.joint_angles_rad())
        now_closed = angles >= limit
        newly = now_closed & np.isnan(closed_at)
        closed_at[newly] = tension
        if k % 20 == 0:
            ramp_t.append(tension)
            closed_n.append(int(now_closed.sum()))
        if math.isnan(pack_t) and now_closed.all():
            pack_t = tension
            pack_i = abs(plant.commanded_currents_raw()[0]) / 1000.0
        if progress is not None and k % 100 == 0:
            progress(k, total)
    pts = joint_points_xz(plant)
    b_fit, pole, turn = fit_log_spiral(pts)
    extremes = plant.extremes()
    rig.close()
    order = tuple(
        int(j) + 1 for j in np.argsort(np.where(np.isnan(closed_at), np.inf, closed_at), kind="stable")
    )
    valid = ~np.isnan(closed_at)
    if valid.sum() >= 3:
        ranks_t = np.argsort(np.argsort(closed_at[valid]))
        ranks_j = np.argsort(np.argsort(np.arange(n_joints)[valid]))
        corr = float(np.corrcoef(ranks_j, ranks_t)[0, 1])
    else:
        corr = math.nan
    if progress is not None:
        progress(total, total)
    return PackingResult(
        p,
        seed,
        design.b,
        b_fit,
        math.degrees(design.dtheta_rad),
        abs(math.degrees(turn)),
        n_joints,
        bool(valid.all()),
        pack_t,
        pack_i,
        order,
        tuple(float(v) for v in closed_at),
        corr,
        extremes,
        tuple(ramp_t),
        tuple(closed_n),
        tuple((float(z.real), float(z.imag)) for z in pts),
        (pole.real, pole.imag),
    )


EXPERIMENT = Experiment(
    "packing",
    "one cable's tension ramped until the arm packs: current, fitted b, curl order (Note S3)",
    Sizes(PackingParams(ramp_s=1.5, hold_s=0.1), PackingParams(), PackingParams(ramp_s=16.0)),
    packing,
)
"""The packing experiment (:mod:`hil.experiments.catalogue`)."""
