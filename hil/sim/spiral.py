"""Logarithmic-spiral design math of a SpiRob (the paper's Table S1, Note S2, Note S3).

The robot's two outer contours are the logarithmic spiral ``ρ(θ) = a·e^{bθ}`` one turn apart; its central
axis is the *central spiral* ``ρc(θ) = a/2·(e^{2πb} + 1)·e^{bθ}``. The robot occupies ``θ ∈ [0, θ0]`` with
**θ = 0 at the tip** and θ0 at the base, and is discretised into ``units = θ0 / Δθ`` units, each
``β = e^{bΔθ}`` times larger than its tip-side neighbour.

Two constructors build a :class:`SpiralDesign`:

- :meth:`SpiralDesign.from_params` from the spiral's own parameters (a, b, θ0, Δθ);
- :meth:`SpiralDesign.from_physical` from what users know: length, tip width, taper angle *or* base width,
  Δθ and the cable count. The taper angle φ(b) of Table S1 is monotone in b, so b is found by bisection.

Every closed form below is checked in ``tests/test_spiral.py`` against numerical integration or geometry.
Units are SI throughout (metres, radians, kilograms, newtons).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

__all__ = [
    "AUTHORS_DEFAULT",
    "G_M_S2",
    "PAPER_PROTOTYPE",
    "SpiralDesign",
    "b_from_taper",
    "taper_from_b",
]

G_M_S2 = 9.80665
"""Standard gravity, used by the load bound of eq. (16)."""

_TWO_PI = 2.0 * math.pi
# Bisection on b stops at this relative bracket width (well below float64 resolution of φ).
_B_REL_TOL = 1e-15
_B_MAX_ITER = 400
# θ0 / Δθ closer than this to a whole number counts as whole (4π / (π/6) is 24.000000000000004).
_UNITS_ABS_TOL = 1e-6


def taper_from_b(b: float) -> float:
    """Taper angle φ of the straightened robot for spiral parameter ``b`` (Table S1).

    ``φ = 2·atan( b·(e^{2πb} − 1) / (√(b²+1)·(e^{2πb} + 1)) )``; monotone increasing from 0 (b → 0) to
    π/2 (b → ∞). Written with ``tanh(πb) = (e^{2πb} − 1)/(e^{2πb} + 1)`` so it never overflows.

    Raises:
        ValueError: ``b`` is not a finite positive number.
    """
    _check_positive("b", b)
    return 2.0 * math.atan(b * math.tanh(math.pi * b) / math.sqrt(b * b + 1.0))


def b_from_taper(taper_rad: float) -> float:
    """Invert :func:`taper_from_b` by bisection (φ(b) is strictly increasing).

    Args:
        taper_rad: full taper angle φ of the straightened robot, in (0, π/2) rad.

    Returns:
        The spiral parameter ``b`` with ``taper_from_b(b) == taper_rad`` to float64 precision.

    Raises:
        ValueError: ``taper_rad`` is not in the open interval (0, π/2).
    """
    if not (math.isfinite(taper_rad) and 0.0 < taper_rad < math.pi / 2.0):
        raise ValueError(f"taper angle must be in (0, 90) degrees, got {math.degrees(taper_rad):g} degrees")
    lo, hi = 0.0, 1.0
    while taper_from_b(hi) < taper_rad:
        lo, hi = hi, 2.0 * hi
        if hi > 1e300:  # φ → π/2 only as b → ∞; a taper this close to 90° is numerically 90°
            raise ValueError(f"taper angle {math.degrees(taper_rad):.15g} degrees is too close to 90")
    for _ in range(_B_MAX_ITER):
        mid = 0.5 * (lo + hi)
        if mid <= lo or mid >= hi:
            break
        if taper_from_b(mid) < taper_rad:
            lo = mid
        else:
            hi = mid
        if hi - lo <= _B_REL_TOL * hi:
            break
    return 0.5 * (lo + hi)


def _check_positive(name: str, value: float) -> None:
    if not (isinstance(value, int | float) and math.isfinite(value) and value > 0.0):
        raise ValueError(f"{name} must be a finite number > 0, got {value!r}")


def _check_dtheta(dtheta_rad: float) -> None:
    if not (isinstance(dtheta_rad, int | float) and math.isfinite(dtheta_rad) and 0 < dtheta_rad < math.pi):
        raise ValueError(f"dtheta must be in (0, 180) degrees, got {dtheta_rad!r} rad")


def _check_cables(cables: int) -> None:
    if isinstance(cables, bool) or cables not in (1, 2, 3):
        raise ValueError(f"cables must be 1, 2 or 3, got {cables!r}")


@dataclass(frozen=True)
class SpiralDesign:
    """A discretised logarithmic-spiral arm. Build it with :meth:`from_params` or :meth:`from_physical`.

    Attributes:
        a_m: scaling factor ``a`` of ``ρ(θ) = a·e^{bθ}`` [m].
        b: growth rate ``b`` of the spiral [1/rad].
        theta0_rad: spiral angle of the base, ``θ0 = units·Δθ`` (θ = 0 is the tip) [rad].
        dtheta_rad: discretisation step Δθ: the angle each unit spans, and each joint's limit [rad].
        cables: number of cables, 1, 2 or 3 (hinges for 1-2, ball joints for 3).
        inputs: the physical inputs the design was built from, as ``(name, value)`` pairs (informative;
            excluded from equality).
    """

    a_m: float
    b: float
    theta0_rad: float
    dtheta_rad: float
    cables: int = 3
    inputs: tuple[tuple[str, float], ...] = field(default=(), compare=False)

    def __post_init__(self) -> None:
        _check_positive("a", self.a_m)
        _check_positive("b", self.b)
        _check_positive("theta0", self.theta0_rad)
        _check_dtheta(self.dtheta_rad)
        _check_cables(self.cables)
        ratio = self.theta0_rad / self.dtheta_rad
        n = round(ratio)
        if ratio < 1.0 - _UNITS_ABS_TOL:
            raise ValueError(
                f"dtheta = {math.degrees(self.dtheta_rad):g} degrees leaves no unit in "
                f"theta0 = {math.degrees(self.theta0_rad):g} degrees"
            )
        if abs(ratio - n) > _UNITS_ABS_TOL:
            raise ValueError(
                f"theta0 / dtheta = {ratio:.6g} is not a whole number of units; "
                f"use theta0 = {math.floor(ratio)} or {math.ceil(ratio)} x dtheta"
            )

    # ------------------------------------------------------------------ constructors

    @classmethod
    def from_params(
        cls, a_m: float, b: float, theta0_rad: float, dtheta_rad: float, cables: int = 3
    ) -> SpiralDesign:
        """Build from the spiral's own parameters (Table S1).

        Args:
            a_m: scaling factor ``a`` [m].
            b: growth rate ``b`` [1/rad].
            theta0_rad: spiral angle of the base; must be a whole number of ``dtheta_rad``.
            dtheta_rad: discretisation step Δθ, in (0, π).
            cables: 1, 2 or 3.

        Raises:
            ValueError: a value is not positive and finite, Δθ is out of range or leaves no unit, θ0 is
                not a whole number of units, or the cable count is not 1-3.
        """
        inputs = (("a_m", a_m), ("b", b), ("theta0_rad", theta0_rad), ("dtheta_rad", dtheta_rad))
        return cls(a_m, b, theta0_rad, dtheta_rad, cables, inputs=inputs)

    @classmethod
    def from_physical(
        cls,
        *,
        length_m: float,
        tip_width_m: float,
        dtheta_rad: float,
        taper_rad: float | None = None,
        base_width_m: float | None = None,
        cables: int = 3,
    ) -> SpiralDesign:
        """Build from the physical quantities a designer knows.

        Give the taper angle *or* the base width. The tip width fixes ``a`` for a given ``b``
        (``a = δ(0)/(e^{2πb} − 1)``, eq. 14); the length then fixes θ0, which is rounded to the nearest
        whole number of units (at least one), so the realised length and base width can differ slightly
        from the request (the request is kept in :attr:`inputs`).

        Args:
            length_m: length of the straightened robot along its central axis [m].
            tip_width_m: width of the tip, δ(0) [m].
            dtheta_rad: discretisation step Δθ, in (0, π).
            taper_rad: full taper angle φ of the straightened robot, in (0, π/2).
            base_width_m: width at the base, δ(θ0) [m]; must exceed the tip width.
            cables: 1, 2 or 3.

        Raises:
            ValueError: a value is out of range, both or neither of taper and base width are given, or
                the design would have no unit.
        """
        _check_positive("length", length_m)
        _check_positive("tip width", tip_width_m)
        _check_dtheta(dtheta_rad)
        _check_cables(cables)
        if (taper_rad is None) == (base_width_m is None):
            raise ValueError("give exactly one of the taper angle and the base width")
        inputs: list[tuple[str, float]] = [
            ("length_m", length_m),
            ("tip_width_m", tip_width_m),
            ("dtheta_rad", dtheta_rad),
        ]
        if base_width_m is not None:
            _check_positive("base width", base_width_m)
            if base_width_m <= tip_width_m:
                raise ValueError(
                    f"base width ({base_width_m:g} m) must be larger than the tip width ({tip_width_m:g} m)"
                )
            # The straightened robot is a cone: tan(φ/2) = (δ(θ0) − δ(0)) / (2 L).
            taper = 2.0 * math.atan((base_width_m - tip_width_m) / (2.0 * length_m))
            inputs.append(("base_width_m", base_width_m))
        else:
            assert taper_rad is not None  # narrowed by the check above
            taper = taper_rad
            inputs.append(("taper_rad", taper_rad))
        b = b_from_taper(taper)
        a = tip_width_m / math.expm1(_TWO_PI * b)
        # Arc length from the virtual tip (θ → −∞) to the tip: s(0) = δ(0) / (2 tan(φ/2)).
        s0 = tip_width_m / (2.0 * math.tan(taper / 2.0))
        theta0_exact = math.log1p(length_m / s0) / b
        units = round(theta0_exact / dtheta_rad)
        if units < 1:
            raise ValueError(
                f"dtheta = {math.degrees(dtheta_rad):g} degrees leaves no unit in a {length_m:g} m arm "
                f"(it spans only {math.degrees(theta0_exact):.3g} degrees of spiral)"
            )
        return cls(a, b, units * dtheta_rad, dtheta_rad, cables, inputs=tuple(inputs))

    @classmethod
    def paper_prototype(cls) -> SpiralDesign:
        """The paper's drone-mounted 3-cable prototype (reconstructed in docs/plant.md).

        Built from length 0.23 m, tip width 7 mm, taper 6.5° and Δθ = 30°: 21 units, β ≈ 1.075, base
        width ≈ 32 mm, realised central-axis length ≈ 0.22 m. The published reconstructions (226-231 mm,
        20-21 units, β ≈ 1.076, base 28-32 mm) are not exactly mutually consistent for a spiral;
        this keeps tip, taper and Δθ exact and rounds the length to whole units.
        """
        return cls.from_physical(
            length_m=0.23,
            tip_width_m=0.007,
            taper_rad=math.radians(6.5),
            dtheta_rad=math.radians(30.0),
            cables=3,
        )

    @classmethod
    def authors_default(cls, cables: int = 3) -> SpiralDesign:
        """The authors' design-tool default: a = 4.95 mm, b = 0.1764, Δθ = 30°, θ0 = 4π (24 units)."""
        return cls.from_params(0.00495, 0.1764, 4.0 * math.pi, math.radians(30.0), cables)

    @classmethod
    def preset(cls, name: str) -> SpiralDesign:
        """A named design: ``"prototype"`` (the paper's prototype) or ``"authors"`` (the authors' default).

        Raises:
            ValueError: unknown name.
        """
        if name == "prototype":
            return cls.paper_prototype()
        if name == "authors":
            return cls.authors_default()
        raise ValueError(f"unknown design preset {name!r}; choose from {', '.join(PRESETS)}")

    def with_cables(self, cables: int) -> SpiralDesign:
        """The same spiral with another cable count."""
        return SpiralDesign(self.a_m, self.b, self.theta0_rad, self.dtheta_rad, cables, self.inputs)

    # ------------------------------------------------------------------ Table S1

    @property
    def _e2pib(self) -> float:
        return math.exp(_TWO_PI * self.b)

    @property
    def units(self) -> int:
        """Number of units, θ0 / Δθ."""
        return round(self.theta0_rad / self.dtheta_rad)

    @property
    def joints(self) -> int:
        """Number of joints between units (the base unit is fixed to the mount): ``units − 1``."""
        return self.units - 1

    @property
    def beta(self) -> float:
        """Ratio between adjacent units, ``β = e^{bΔθ}`` (each unit is β times its tip-side neighbour)."""
        return math.exp(self.b * self.dtheta_rad)

    def rho_m(self, theta_rad: float) -> float:
        """The logarithmic spiral ``ρ(θ) = a·e^{bθ}`` [m]."""
        return self.a_m * math.exp(self.b * theta_rad)

    def rho_c_m(self, theta_rad: float) -> float:
        """The central spiral ``ρc(θ) = a/2·(e^{2πb} + 1)·e^{bθ}`` [m] (the robot's packed axis)."""
        return 0.5 * self.a_m * (self._e2pib + 1.0) * math.exp(self.b * theta_rad)

    def length_between_m(self, theta1_rad: float, theta2_rad: float) -> float:
        """Arc length of the central spiral from θ1 to θ2, ``√(b²+1)/b·(ρc(θ2) − ρc(θ1))`` [m]."""
        return (
            math.sqrt(self.b * self.b + 1.0) / self.b * (self.rho_c_m(theta2_rad) - self.rho_c_m(theta1_rad))
        )

    @property
    def length_m(self) -> float:
        """Length of the robot, ``L(0, θ0) = a√(b²+1)/(2b)·(e^{2πb} + 1)·(e^{bθ0} − 1)`` [m]."""
        b = self.b
        return (
            self.a_m
            * math.sqrt(b * b + 1.0)
            / (2.0 * b)
            * (self._e2pib + 1.0)
            * math.expm1(b * self.theta0_rad)
        )

    def arc_from_virtual_tip_m(self, theta_rad: float) -> float:
        """``s(θ) = L(−∞, θ) = √(b²+1)/b·ρc(θ)``: arc length from the virtual tip (θ → −∞) [m]."""
        return math.sqrt(self.b * self.b + 1.0) / self.b * self.rho_c_m(theta_rad)

    def curvature_packed_per_m(self, theta_rad: float) -> float:
        """Curvature of the central axis when packed into the spiral, ``κ(θ) = 1/(ρc·√(b²+1))`` [1/m]."""
        return 1.0 / (self.rho_c_m(theta_rad) * math.sqrt(self.b * self.b + 1.0))

    def radius_of_curvature_m(self, s_m: float) -> float:
        """Radius of curvature at arc length ``s`` from the virtual tip, ``r(s) = b·s`` [m]."""
        return self.b * s_m

    @property
    def taper_rad(self) -> float:
        """Full taper angle φ of the straightened robot (Table S1) [rad]."""
        return taper_from_b(self.b)

    def width_m(self, theta_rad: float) -> float:
        """Width of the robot at θ, ``δ(θ) = a·e^{b(θ+2π)} − a·e^{bθ}`` [m]."""
        return self.a_m * math.exp(self.b * theta_rad) * math.expm1(_TWO_PI * self.b)

    @property
    def tip_width_m(self) -> float:
        """Width at the tip, δ(0) [m]."""
        return self.width_m(0.0)

    @property
    def base_width_m(self) -> float:
        """Width at the base, δ(θ0) [m]."""
        return self.width_m(self.theta0_rad)

    def rho_w_m(self, theta_rad: float) -> float:
        """Workspace envelope, the involute of the central spiral:
        ``ρw = a/(2b)·(e^{2πb} + 1)·e^{b(θ − π/2)}`` [m]."""
        return (
            self.a_m / (2.0 * self.b) * (self._e2pib + 1.0) * math.exp(self.b * (theta_rad - math.pi / 2.0))
        )

    @property
    def d_min_m(self) -> float:
        """Smallest graspable diameter, ``d_min = ρ(0) + ρ(π) = a(1 + e^{bπ})`` (eq. 14) [m]."""
        return self.a_m * (1.0 + math.exp(math.pi * self.b))

    @property
    def grasp_rate(self) -> float:
        """Growth rate ``k = cot((π − φ)/2) = tan(φ/2)`` of the grasping spiral ρ'c of eq. (12)."""
        return math.tan(self.taper_rad / 2.0)

    def rho_c_grasp_m(self, theta_rad: float, d_m: float) -> float:
        """Central axis of the part wrapped around a disc of diameter d, eq. (12):
        ``ρ'c(θ, d) = (d + δ(0))/2·e^{cot((π−φ)/2)·θ}`` [m]."""
        return 0.5 * (d_m + self.tip_width_m) * math.exp(self.grasp_rate * theta_rad)

    def grasp_length_m(self, d_m: float, wrap_fraction: float = 0.5) -> float:
        """Length used to wrap a fraction ``n`` of a disc of diameter d, eq. (13) in closed form [m].

        ``L_grasp = ∫_0^{2πn} √(ρ'c² + ρ'c'²) dθ = (d + δ(0))/2·√(1+k²)/k·(e^{2πnk} − 1)``.

        Raises:
            ValueError: ``d_m`` is negative or the fraction is not in (0, 1].
        """
        if not (math.isfinite(d_m) and d_m >= 0.0):
            raise ValueError(f"object diameter must be >= 0, got {d_m!r}")
        if not (math.isfinite(wrap_fraction) and 0.0 < wrap_fraction <= 1.0):
            raise ValueError(f"wrap fraction must be in (0, 1], got {wrap_fraction!r}")
        k = self.grasp_rate
        return (
            0.5
            * (d_m + self.tip_width_m)
            * math.sqrt(1.0 + k * k)
            / k
            * math.expm1(_TWO_PI * wrap_fraction * k)
        )

    @property
    def d_max_m(self) -> float:
        """Largest graspable diameter, from eq. (15): the whole length wraps half the circumference [m].

        Eq. (15) ``L = ∫_0^π √(ρ'c² + ρ'c'²) dθ`` is linear in ``d + δ(0)``, so the root is found exactly:
        ``d_max = 2 L k / (√(1+k²)(e^{πk} − 1)) − δ(0)`` (checked against quadrature + bisection in the
        tests). Zero if even the tip cannot wrap half a disc of zero diameter.
        """
        k = self.grasp_rate
        half_sum = self.length_m * k / (math.sqrt(1.0 + k * k) * math.expm1(math.pi * k))
        return max(0.0, 2.0 * half_sum - self.tip_width_m)

    def max_load_kg(self, d_m: float, f_max_n: float, g_m_s2: float = G_M_S2) -> float:
        """Load bound ``M(φ, d, F_max) = F_max/g·(1 − d/((d + δ(0))·e^{cot((π−φ)/2)·π}))`` (eq. 16) [kg].

        A theoretical upper bound: it ignores the elastic layer, cable friction and unit deformation.

        Raises:
            ValueError: negative diameter or non-positive force or gravity.
        """
        if not (math.isfinite(d_m) and d_m >= 0.0):
            raise ValueError(f"object diameter must be >= 0, got {d_m!r}")
        _check_positive("F_max", f_max_n)
        _check_positive("g", g_m_s2)
        return (
            f_max_n / g_m_s2 * (1.0 - d_m / ((d_m + self.tip_width_m) * math.exp(self.grasp_rate * math.pi)))
        )

    @property
    def eta(self) -> float:
        """Discretisation efficiency ``η = S2/S1 = (1 − e^{−bΔθ})/(bΔθ)`` (eq. 11), in (0, 1]."""
        x = self.b * self.dtheta_rad
        return -math.expm1(-x) / x

    # ------------------------------------------------------------------ units (index 0 = base, like unit_00)

    def unit_theta_range_rad(self, index: int) -> tuple[float, float]:
        """Spiral angles ``(θ_tip_side, θ_base_side)`` spanned by unit ``index`` (0 = base unit).

        Raises:
            IndexError: no such unit.
        """
        n = self.units
        if not 0 <= index < n:
            raise IndexError(f"unit index {index} outside 0..{n - 1}")
        j = n - 1 - index  # index counted from the tip
        return j * self.dtheta_rad, (j + 1) * self.dtheta_rad

    def unit_arc_lengths_m(self) -> tuple[float, ...]:
        """Central-spiral arc length of each unit, base first: ``L(jΔθ, (j+1)Δθ)`` [m]."""
        return tuple(self.length_between_m(*self.unit_theta_range_rad(i)) for i in range(self.units))

    def unit_chords_m(self) -> tuple[float, ...]:
        """Joint-to-joint distance of each unit, base first [m].

        The joints sit on the central spiral at θ = jΔθ, so a unit is the chord
        ``ρc(jΔθ)·|β·e^{iΔθ} − 1|``. With every joint at its limit Δθ the joints then lie exactly on ρc:
        the packed pose of Note S3 / Fig. S5. Each chord is a factor ``|βe^{iΔθ} − 1|/(√(b²+1)(β−1)/b)``
        (0.996 for the prototype) shorter than the arc it replaces.
        """
        factor = abs(self.beta * complex(math.cos(self.dtheta_rad), math.sin(self.dtheta_rad)) - 1.0)
        return tuple(self.rho_c_m(self.unit_theta_range_rad(i)[0]) * factor for i in range(self.units))

    def unit_widths_m(self) -> tuple[tuple[float, float], ...]:
        """``(base-side width, tip-side width)`` of each unit, base first [m]."""
        out = []
        for i in range(self.units):
            lo, hi = self.unit_theta_range_rad(i)
            out.append((self.width_m(hi), self.width_m(lo)))
        return tuple(out)

    def unit_scales(self) -> tuple[float, ...]:
        """Linear size of each unit relative to the base unit, base first: ``β^{−index}``."""
        return tuple(self.beta ** (-i) for i in range(self.units))

    def unit_mass_fractions(self) -> tuple[float, ...]:
        """Share of the total mass in each unit at uniform density (mass ∝ size³), base first."""
        w = [s**3 for s in self.unit_scales()]
        total = sum(w)
        return tuple(x / total for x in w)

    # ------------------------------------------------------------------ reporting

    def summary(self) -> dict[str, Any]:
        """Every design quantity as a JSON-ready dict (SI units; the keys carry the units)."""
        return {
            "a_m": self.a_m,
            "b": self.b,
            "dtheta_rad": self.dtheta_rad,
            "theta0_rad": self.theta0_rad,
            "cables": self.cables,
            "units": self.units,
            "joints": self.joints,
            "beta": self.beta,
            "taper_rad": self.taper_rad,
            "tip_width_m": self.tip_width_m,
            "base_width_m": self.base_width_m,
            "length_m": self.length_m,
            "rho_c_tip_m": self.rho_c_m(0.0),
            "rho_c_base_m": self.rho_c_m(self.theta0_rad),
            "curvature_packed_tip_per_m": self.curvature_packed_per_m(0.0),
            "curvature_packed_base_per_m": self.curvature_packed_per_m(self.theta0_rad),
            "rho_w_base_m": self.rho_w_m(self.theta0_rad),
            "d_min_m": self.d_min_m,
            "d_max_m": self.d_max_m,
            "eta": self.eta,
            "grasp_length_d_min_m": self.grasp_length_m(self.d_min_m),
            "unit_chords_m": list(self.unit_chords_m()),
            "unit_widths_m": [list(w) for w in self.unit_widths_m()],
            "inputs": dict(self.inputs),
        }


PRESETS: tuple[str, ...] = ("prototype", "authors")
"""Names accepted by :meth:`SpiralDesign.preset` and ``spirob-hil design --preset``."""

PAPER_PROTOTYPE = SpiralDesign.paper_prototype()
"""The default design: the paper's drone-mounted 3-cable prototype."""

AUTHORS_DEFAULT = SpiralDesign.authors_default()
"""The authors' 24-unit design-tool default."""
