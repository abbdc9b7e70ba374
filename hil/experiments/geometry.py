"""Geometry of the arm's curl: the log-spiral fit and the workspace envelope ρw."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from hil.sim.config import ModelConfig
from hil.sim.plant import Plant
from hil.sim.spiral import SpiralDesign
from hil.sim.types import PlantConfig
from hil.trial.scene import BASE_Z_M


def fit_log_spiral(points: npt.NDArray[np.complex128]) -> tuple[float, complex, float]:
    """Fit a discrete logarithmic spiral to planar points (complex numbers), base first.

    Consecutive points of a log spiral are related by one similarity ``z' = s·z + t`` whose fixed point is
    the pole; log ρ is then regressed on the unwrapped polar angle. Returns ``(b, pole, turn per point)``.
    """
    a = np.stack([points[:-1], np.ones(len(points) - 1)], axis=1)
    s, t = np.linalg.lstsq(a, points[1:], rcond=None)[0]
    pole = t / (1 - s)
    w = points - pole
    angle = np.unwrap(np.angle(w))
    slope = np.polyfit(angle, np.log(np.abs(w)), 1)[0]
    return abs(float(slope)), complex(pole), float(np.angle(s))


def joint_points_xz(plant: Plant) -> npt.NDArray[np.complex128]:
    """Joint positions and the tip in the x-z plane (x + i·z), base first."""
    pos, _ = plant.unit_poses()
    pts = np.vstack([pos, plant.tip_pose().pos_m])
    return np.asarray(pts[:, 0] + 1j * pts[:, 2], dtype=np.complex128)


def base_first_tip_curve(
    design: SpiralDesign, base_z_m: float = BASE_Z_M, steps: int = 12
) -> npt.NDArray[np.float64]:
    """The real tip's path when the joints close one at a time from the base (Fig. S4A), from the straight
    arm to the packed one: rows ``(u, z)``, u toward the curl side from the arm's axis, z the world height
    of a point on an arm whose base (mount) is at ``base_z_m``. Exact for the discretised arm; Table S1's
    ρw is the smooth involute of the same spiral unwound from the *virtual* tip (θ → −∞), so it lies
    further out by about the virtual part of the arm, s(0) = δ(0) / (2 tan(φ/2))."""
    chords = design.unit_chords_m()
    n = len(chords)
    dtheta = design.dtheta_rad
    out = []
    for k in range(1, n):
        for a in np.linspace(0.0, dtheta, steps, endpoint=k == n - 1):
            # joints 1..k-1 closed, joint k at a, the distal ones straight; heading from -z toward +u
            heading = 0.0
            u, z = 0.0, base_z_m - chords[0]
            for j in range(1, n):
                if j < k:
                    heading += dtheta
                elif j == k:
                    heading += float(a)
                u += chords[j] * math.sin(heading)
                z -= chords[j] * math.cos(heading)
            out.append((u, z))
    return np.array(out)


@dataclass(frozen=True)
class Envelope:
    """The workspace envelope ρw of one bending side, in the bending plane (u = horizontal distance from
    the arm's axis toward the packed side, z = height), as the involute of the packed central spiral
    about its pole (Table S1; the same construction as ``tests/test_plant.py``)."""

    design: SpiralDesign
    pole: complex
    base_angle: float
    sense: float
    exact_angle: tuple[float, ...] = field(default=(), repr=False)
    exact_radius: tuple[float, ...] = field(default=(), repr=False)

    @classmethod
    def of(cls, plant: Plant) -> Envelope:
        """Measure the packed spiral's pole on ``plant`` (which is left straight and at rest)."""
        plant.set_packed(0)
        pts = joint_points_xz(plant)
        base_z = float(plant.unit_poses()[0][0][2])
        _, pole, _ = fit_log_spiral(pts)
        w = pts - pole
        base_angle = float(np.angle(w[0]))
        sense = 1.0 if np.angle(w[1] / w[0]) < 0 else -1.0
        plant.set_straight()
        curve = base_first_tip_curve(plant.design, base_z)
        wc = curve[:, 0] + 1j * curve[:, 1] - pole
        ang = np.unwrap(np.angle(wc))
        order = np.argsort(ang)
        return cls(
            plant.design,
            pole,
            base_angle,
            sense,
            tuple(float(v) for v in ang[order]),
            tuple(float(v) for v in np.abs(wc)[order]),
        )

    def exact_ratio(self, u: float, z: float) -> float:
        """Like :meth:`ratio`, against the real tip's base-first curve (:func:`base_first_tip_curve`)."""
        w = complex(u, z) - self.pole
        phi = float(np.angle(w))
        ang = self.exact_angle
        best = 0.0
        for k in range(-4, 5):
            a = phi + 2 * math.pi * k
            if ang[0] <= a <= ang[-1]:
                best = max(best, float(np.interp(a, ang, self.exact_radius)))
        return abs(w) / best if best > 0 else math.inf

    def exact_boundary(self) -> npt.NDArray[np.float64]:
        """Points ``(u, z)`` of the real tip's base-first curve."""
        a = np.array(self.exact_angle)
        z = self.pole + np.array(self.exact_radius) * np.exp(1j * a)
        return np.stack([z.real, z.imag], axis=1)

    def radius(self, phi: float) -> float:
        """Envelope radius about the pole at polar angle ``phi`` (0 where the envelope has no point)."""
        d = self.design
        best = 0.0
        for k in range(-4, 5):
            theta = d.theta0_rad + self.sense * (phi - self.base_angle) + 2 * math.pi * k + math.pi / 2
            if 0.0 <= theta <= d.theta0_rad:
                best = max(best, d.rho_w_m(theta + math.pi / 2))
        return best

    def ratio(self, u: float, z: float) -> float:
        """Distance from the pole over the envelope radius in that direction (<= 1: inside)."""
        w = complex(u, z) - self.pole
        r = self.radius(float(np.angle(w)))
        return abs(w) / r if r > 0 else math.inf

    def boundary(self, n: int = 200) -> npt.NDArray[np.float64]:
        """Points ``(u, z)`` of the envelope curve (θ from the tip to the base)."""
        d = self.design
        out = []
        for theta in np.linspace(0.0, d.theta0_rad, n):
            phi = self.base_angle + self.sense * (theta - math.pi / 2 - d.theta0_rad)
            p = self.pole + d.rho_w_m(theta + math.pi / 2) * complex(math.cos(phi), math.sin(phi))
            out.append((p.real, p.imag))
        return np.array(out)


@dataclass(frozen=True)
class ArmFootprint:
    """The space the arm takes in the x-z plane when packed (the strategy's start) and when straight (the
    plain ramp's start): one capsule per unit, positions relative to the arm's base.

    Attributes:
        packed: per unit ``(x0, z0, x1, z1, half_width)`` with the arm packed toward cable 0 (+x).
        straight: the same with the arm hanging straight.
    """

    packed: tuple[tuple[float, float, float, float, float], ...]
    straight: tuple[tuple[float, float, float, float, float], ...]

    @classmethod
    def of(cls, design: SpiralDesign, model: ModelConfig) -> ArmFootprint:
        """Pose a plant of ``design`` and ``model`` packed and straight (kinematically) and read its units."""
        plant = Plant(design, PlantConfig(model=model))
        widths = [max(w0, w1) / 2 for _, w0, w1 in plant.unit_dimensions_m()]

        def capsules() -> tuple[tuple[float, float, float, float, float], ...]:
            pts = joint_points_xz(plant)
            rel = pts - pts[0]  # unit_00's origin is the mount
            return tuple(
                (float(a.real), float(a.imag), float(b.real), float(b.imag), w)
                for a, b, w in zip(rel[:-1], rel[1:], widths, strict=True)
            )

        plant.set_packed(0)
        packed = capsules()
        plant.set_straight()
        return cls(packed, capsules())

    def clearance_m(self, x_m: float, z_m: float, radius_m: float) -> float:
        """Smallest gap between a cylinder (axis y, centre ``(x, z)`` from the base) and any unit, packed or
        straight (negative: they overlap)."""
        gap = math.inf
        for x0, z0, x1, z1, half in (*self.packed, *self.straight):
            dx, dz = x1 - x0, z1 - z0
            t = ((x_m - x0) * dx + (z_m - z0) * dz) / (dx * dx + dz * dz)
            t = min(1.0, max(0.0, t))
            dist = math.hypot(x_m - (x0 + t * dx), z_m - (z0 + t * dz))
            gap = min(gap, dist - half - radius_m)
        return gap


def design_scale(design: SpiralDesign) -> float:
    """The design's length over the prototype's (exactly 1 for the prototype and for a model file of it).

    The grasp experiments chose their gaps, depths and diameters on the 22 cm prototype; on another arm
    they scale them by this factor (a geometrically similar experiment), else a 47 cm arm, 92 mm wide at
    its base, covers every placement 5-45 mm from its axis.
    """
    s = design.length_m / SpiralDesign.paper_prototype().length_m
    return 1.0 if abs(s - 1.0) < 1e-6 else s


def gap_depth_placements(
    foot: ArmFootprint,
    diameter_m: float,
    gap_range_m: tuple[float, float],
    depth_range_m: tuple[float, float],
    grid: tuple[int, int],
    clearance_m: float,
    seed: int,
) -> list[tuple[float, float]]:
    """:func:`jittered_placements` of an object given by the gap between the arm's axis and its near
    surface (``gap_range_m``) and the depth of its top below the base (``depth_range_m``), low and high;
    the jitter seeded by ``seed`` and the diameter."""
    d = diameter_m
    rng = np.random.default_rng([seed, round(d * 1e6)])
    xs = (gap_range_m[0] + d / 2, gap_range_m[1] + d / 2)
    zs = (-(depth_range_m[1] + d / 2), -(depth_range_m[0] + d / 2))
    return jittered_placements(foot, d, xs, zs, grid, rng, clearance_m)


def jittered_placements(
    foot: ArmFootprint,
    diameter_m: float,
    x_range_m: tuple[float, float],
    z_range_m: tuple[float, float],
    grid: tuple[int, int],
    rng: np.random.Generator,
    clearance_m: float,
) -> list[tuple[float, float]]:
    """One uniformly jittered object centre ``(x, z)`` per cell of a ``grid`` over the region, each
    clearing the packed and the straight arm by ``clearance_m``; a cell wholly blocked takes a point from
    anywhere in the region instead, so there are always ``grid[0] · grid[1]`` placements.

    Raises:
        ValueError: no point of the region clears the arm.
    """
    (x_lo, x_hi), (z_lo, z_hi) = x_range_m, z_range_m
    nx, nz = grid

    def draw(xs: tuple[float, float], zs: tuple[float, float], tries: int) -> tuple[float, float] | None:
        for _ in range(tries):
            x, z = float(rng.uniform(*xs)), float(rng.uniform(*zs))
            if foot.clearance_m(x, z, diameter_m / 2) >= clearance_m:
                return (x, z)
        return None

    out = []
    for i in range(nx):
        for j in range(nz):
            cx = (x_lo + (x_hi - x_lo) * i / nx, x_lo + (x_hi - x_lo) * (i + 1) / nx)
            cz = (z_lo + (z_hi - z_lo) * j / nz, z_lo + (z_hi - z_lo) * (j + 1) / nz)
            point = draw(cx, cz, 50) or draw(x_range_m, z_range_m, 2000)
            if point is None:
                raise ValueError(f"no placement of a {diameter_m * 1000:g} mm object clears the arm")
            out.append(point)
    return out
