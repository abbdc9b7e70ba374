"""Spiral design math (hil.sim.spiral): every closed form of Table S1 / Note S2 against numerics or
geometry."""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hil.sim.spiral import (
    AUTHORS_DEFAULT,
    G_M_S2,
    PAPER_PROTOTYPE,
    SpiralDesign,
    b_from_taper,
    taper_from_b,
)

EXACT = 1e-9  # relative tolerance for closed forms checked against converged quadrature

_NODES, _WEIGHTS = np.polynomial.legendre.leggauss(80)


def quad(f: Callable[[np.ndarray], np.ndarray], a: float, b: float, pieces: int = 8) -> float:
    """Composite Gauss-Legendre quadrature (converged to ~1e-15 for these smooth exponentials)."""
    edges = np.linspace(a, b, pieces + 1)
    total = 0.0
    for lo, hi in itertools.pairwise(edges):
        x = 0.5 * (hi - lo) * _NODES + 0.5 * (hi + lo)
        total += 0.5 * (hi - lo) * float(np.sum(_WEIGHTS * f(x)))
    return total


def rho_c(d: SpiralDesign, theta: np.ndarray) -> np.ndarray:
    """The central spiral, re-derived here as the midpoint of the contours one turn apart."""
    return 0.5 * (d.a_m * np.exp(d.b * theta) + d.a_m * np.exp(d.b * (theta + 2 * math.pi)))


def speed(d: SpiralDesign, theta: np.ndarray) -> np.ndarray:
    """|dC/dθ| of the central spiral in polar form: sqrt(ρc² + ρc'²) with ρc' by central difference."""
    h = 1e-6
    r = rho_c(d, theta)
    dr = (rho_c(d, theta + h) - rho_c(d, theta - h)) / (2 * h)
    return np.asarray(np.sqrt(r * r + dr * dr))


def arc_from_virtual_tip(d: SpiralDesign, theta: float) -> float:
    """s(θ) = L(−∞, θ) by quadrature, the lower end far enough that ρc is below 1e-30 m."""
    lower = theta - 80.0 / d.b
    return quad(lambda x: np.sqrt(1 + d.b**2) * rho_c(d, x), lower, theta, pieces=40)


DESIGNS = [PAPER_PROTOTYPE, AUTHORS_DEFAULT, SpiralDesign.from_params(0.002, 0.35, 2 * math.pi, math.pi / 8)]


@pytest.mark.parametrize("d", DESIGNS, ids=["prototype", "authors", "steep"])
class TestClosedForms:
    def test_length_between_matches_integral_of_speed(self, d: SpiralDesign) -> None:
        for t1, t2 in [(0.0, d.theta0_rad), (1.0, 2.5), (-3.0, 0.5)]:
            numeric = quad(lambda x: speed(d, x), t1, t2)
            assert d.length_between_m(t1, t2) == pytest.approx(numeric, rel=1e-8)  # finite difference ~1e-10

    def test_robot_length_is_l_zero_theta0(self, d: SpiralDesign) -> None:
        exact = quad(lambda x: np.sqrt(1 + d.b**2) * rho_c(d, x), 0.0, d.theta0_rad)
        assert d.length_m == pytest.approx(exact, rel=EXACT)
        assert d.length_m == pytest.approx(d.length_between_m(0.0, d.theta0_rad), rel=1e-12)

    def test_central_spiral_is_midpoint_of_contours(self, d: SpiralDesign) -> None:
        for theta in (0.0, 1.3, d.theta0_rad):
            assert d.rho_c_m(theta) == pytest.approx(
                0.5 * (d.rho_m(theta) + d.rho_m(theta + 2 * math.pi)), rel=1e-14
            )

    def test_curvature_matches_polar_curvature_formula(self, d: SpiralDesign) -> None:
        # κ = (r² + 2r'² − r r'') / (r² + r'²)^{3/2} with r = ρc, r' = bρc, r'' = b²ρc.
        for theta in (0.0, 2.0, d.theta0_rad):
            r = d.rho_c_m(theta)
            r1, r2 = d.b * r, d.b * d.b * r
            kappa = (r * r + 2 * r1 * r1 - r * r2) / (r * r + r1 * r1) ** 1.5
            assert d.curvature_packed_per_m(theta) == pytest.approx(kappa, rel=1e-12)

    def test_radius_of_curvature_is_b_times_arc_length(self, d: SpiralDesign) -> None:
        for theta in (0.0, 3.0, d.theta0_rad):
            s = arc_from_virtual_tip(d, theta)
            assert s == pytest.approx(d.arc_from_virtual_tip_m(theta), rel=EXACT)
            assert d.radius_of_curvature_m(s) == pytest.approx(
                1.0 / d.curvature_packed_per_m(theta), rel=EXACT
            )

    def test_taper_is_the_cone_angle_of_the_straightened_robot(self, d: SpiralDesign) -> None:
        # Straightened, width grows linearly with arc length from the virtual tip: tan(φ/2) = (δ/2)/s.
        for theta in (0.0, d.theta0_rad):
            s = arc_from_virtual_tip(d, theta)
            assert math.tan(d.taper_rad / 2) == pytest.approx(0.5 * d.width_m(theta) / s, rel=EXACT)

    def test_width_is_gap_between_contours_on_a_ray(self, d: SpiralDesign) -> None:
        for theta in (0.0, 1.0, d.theta0_rad):
            outer = d.a_m * math.exp(d.b * (theta + 2 * math.pi))
            inner = d.a_m * math.exp(d.b * theta)
            assert d.width_m(theta) == pytest.approx(outer - inner, rel=1e-14)
        assert d.tip_width_m == d.width_m(0.0)
        assert d.base_width_m == pytest.approx(d.tip_width_m * math.exp(d.b * d.theta0_rad), rel=1e-12)

    def test_beta_is_the_ratio_of_adjacent_units(self, d: SpiralDesign) -> None:
        chords, arcs, widths = d.unit_chords_m(), d.unit_arc_lengths_m(), d.unit_widths_m()
        for i in range(d.units - 1):
            assert chords[i] / chords[i + 1] == pytest.approx(d.beta, rel=1e-12)
            assert arcs[i] / arcs[i + 1] == pytest.approx(d.beta, rel=1e-12)
            assert widths[i][0] / widths[i + 1][0] == pytest.approx(d.beta, rel=1e-12)
        assert sum(arcs) == pytest.approx(d.length_m, rel=1e-12)
        fractions = d.unit_mass_fractions()
        assert sum(fractions) == pytest.approx(1.0, rel=1e-12)
        assert fractions[0] / fractions[1] == pytest.approx(d.beta**3, rel=1e-12)

    def test_chords_join_points_of_the_central_spiral(self, d: SpiralDesign) -> None:
        chords = d.unit_chords_m()
        for i, chord in enumerate(chords):
            lo, hi = d.unit_theta_range_rad(i)
            p = d.rho_c_m(lo) * np.exp(1j * lo)
            q = d.rho_c_m(hi) * np.exp(1j * hi)
            assert chord == pytest.approx(abs(q - p), rel=1e-12)
            assert chord < d.unit_arc_lengths_m()[i]

    def test_workspace_envelope_is_the_involute_of_the_central_spiral(self, d: SpiralDesign) -> None:
        # Unwind a string from the central spiral (from the virtual tip): P = C − s·T. Its distance from the
        # pole is ρw evaluated a quarter turn on (Table S1's angle is measured from the opposite ray).
        for theta in (0.5, 2.0, d.theta0_rad):
            c = d.rho_c_m(theta) * np.exp(1j * theta)
            tangent = (d.b + 1j) * np.exp(1j * theta) / math.sqrt(1 + d.b**2)
            p = c - arc_from_virtual_tip(d, theta) * tangent
            assert abs(p) == pytest.approx(d.rho_w_m(theta + math.pi / 2), rel=EXACT)
            assert abs(p) == pytest.approx(d.rho_c_m(theta) / d.b, rel=EXACT)

    def test_d_min_is_the_inscribed_circle_of_the_packed_spiral(self, d: SpiralDesign) -> None:
        # The inner contour crosses the horizontal axis at ρ(0) (θ = 0) and ρ(π) on the other side.
        contour = [d.rho_m(t) * np.exp(1j * t) for t in (0.0, math.pi)]
        assert d.d_min_m == pytest.approx(abs(contour[0] - contour[1]), rel=1e-12)
        e = math.exp(math.pi * d.b)
        assert d.d_min_m == pytest.approx(d.tip_width_m * (e + 1) / (e * e - 1), rel=1e-12)  # eq. (14)

    def test_d_max_solves_eq_15_numerically(self, d: SpiralDesign) -> None:
        k = d.grasp_rate
        assert k == pytest.approx(1.0 / math.tan((math.pi - d.taper_rad) / 2), rel=1e-12)

        def wrap_length(diameter: float) -> float:
            def integrand(x: np.ndarray) -> np.ndarray:
                r = 0.5 * (diameter + d.tip_width_m) * np.exp(k * x)
                return np.sqrt(r * r + (k * r) ** 2)

            return quad(integrand, 0.0, math.pi)

        lo, hi = 0.0, 10.0
        for _ in range(200):
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if wrap_length(mid) < d.length_m else (lo, mid)
        assert d.d_max_m == pytest.approx(0.5 * (lo + hi), rel=EXACT)
        assert wrap_length(d.d_max_m) == pytest.approx(d.length_m, rel=EXACT)

    def test_grasp_length_matches_eq_13(self, d: SpiralDesign) -> None:
        k = d.grasp_rate
        for diameter, n in ((d.d_min_m, 0.5), (0.05, 0.75), (0.0, 1.0)):

            def integrand(x: np.ndarray, dd: float = diameter) -> np.ndarray:
                return np.asarray(np.sqrt(1 + k * k) * 0.5 * (dd + d.tip_width_m) * np.exp(k * x))

            numeric = quad(integrand, 0.0, 2 * math.pi * n)
            assert d.grasp_length_m(diameter, n) == pytest.approx(numeric, rel=EXACT)
            assert d.rho_c_grasp_m(1.0, diameter) == pytest.approx(
                0.5 * (diameter + d.tip_width_m) * math.exp(k)
            )

    def test_load_bound_is_the_torque_balance_of_eq_16(self, d: SpiralDesign) -> None:
        for diameter in (d.d_min_m, 0.04, 0.1):
            r = d.rho_c_grasp_m(math.pi, diameter)
            mass = d.max_load_kg(diameter, 54.0)
            assert mass * G_M_S2 * r == pytest.approx(54.0 * (r - diameter / 2), rel=1e-12)
        assert d.max_load_kg(0.0, 10.0) == pytest.approx(10.0 / G_M_S2)

    def test_eta_is_swept_area_ratio_of_eq_10(self, d: SpiralDesign) -> None:
        # S1 = L(θ)·Δθ, S2 = ∫_{θ−Δθ}^{θ} L(θ') dθ', L from the virtual tip; η does not depend on θ.
        for theta in (1.0, d.theta0_rad):
            s1 = d.arc_from_virtual_tip_m(theta) * d.dtheta_rad
            s2 = quad(lambda x: math.sqrt(1 + d.b**2) / d.b * rho_c(d, x), theta - d.dtheta_rad, theta)
            assert d.eta == pytest.approx(s2 / s1, rel=EXACT)
        assert 0 < d.eta < 1


class TestTaper:
    @settings(max_examples=200, deadline=None)
    @given(st.floats(min_value=1e-4, max_value=20.0))
    def test_bisection_inverts_the_taper_formula(self, b: float) -> None:
        assert b_from_taper(taper_from_b(b)) == pytest.approx(b, rel=1e-9)

    def test_taper_is_monotone_in_b(self) -> None:
        bs = np.geomspace(1e-4, 50, 400)
        tapers = [taper_from_b(float(b)) for b in bs]
        assert all(t2 > t1 for t1, t2 in itertools.pairwise(tapers))
        assert tapers[0] > 0 and tapers[-1] < math.pi / 2

    @pytest.mark.parametrize("bad", [0.0, -0.1, math.pi / 2, 2.0, float("nan"), float("inf")])
    def test_bad_taper_is_refused(self, bad: float) -> None:
        with pytest.raises(ValueError, match="taper"):
            b_from_taper(bad)


class TestConstructors:
    def test_from_physical_keeps_tip_and_taper_and_rounds_length_to_units(self) -> None:
        d = SpiralDesign.from_physical(
            length_m=0.3, tip_width_m=0.01, taper_rad=math.radians(8), dtheta_rad=math.radians(20), cables=2
        )
        assert d.tip_width_m == pytest.approx(0.01, rel=1e-12)
        assert d.taper_rad == pytest.approx(math.radians(8), rel=1e-12)
        assert d.cables == 2
        unit = d.unit_arc_lengths_m()[0]  # the largest unit bounds the rounding error
        assert abs(d.length_m - 0.3) <= unit / 2 + 1e-12
        assert dict(d.inputs)["length_m"] == 0.3

    def test_base_width_and_taper_forms_agree(self) -> None:
        by_taper = SpiralDesign.from_physical(
            length_m=0.25, tip_width_m=0.008, taper_rad=math.radians(7), dtheta_rad=math.radians(30)
        )
        base = by_taper.base_width_m
        by_base = SpiralDesign.from_physical(
            length_m=by_taper.length_m, tip_width_m=0.008, base_width_m=base, dtheta_rad=math.radians(30)
        )
        assert by_base.units == by_taper.units
        assert by_base.b == pytest.approx(by_taper.b, rel=1e-9)
        assert by_base.a_m == pytest.approx(by_taper.a_m, rel=1e-9)

    def test_paper_prototype(self) -> None:
        d = SpiralDesign.paper_prototype()
        assert d == PAPER_PROTOTYPE
        assert d.cables == 3
        assert d.tip_width_m == pytest.approx(0.007)
        assert math.degrees(d.taper_rad) == pytest.approx(6.5)
        assert math.degrees(d.dtheta_rad) == pytest.approx(30.0)
        assert 20 <= d.units <= 21
        assert 0.20 <= d.length_m <= 0.235
        assert 0.028 <= d.base_width_m <= 0.033
        assert d.beta == pytest.approx(1.076, abs=0.002)

    def test_authors_default(self) -> None:
        d = SpiralDesign.authors_default()
        assert (d.a_m, d.b, d.units) == (0.00495, 0.1764, 24)
        assert d.tip_width_m == pytest.approx(0.010, abs=1e-4)
        assert d.length_m == pytest.approx(0.46, abs=0.015)
        assert math.degrees(d.taper_rad) == pytest.approx(10.0, abs=0.01)

    def test_presets_by_name(self) -> None:
        assert SpiralDesign.preset("prototype") == PAPER_PROTOTYPE
        assert SpiralDesign.preset("authors") == AUTHORS_DEFAULT
        with pytest.raises(ValueError, match="unknown design preset"):
            SpiralDesign.preset("nope")

    def test_with_cables(self) -> None:
        d = PAPER_PROTOTYPE.with_cables(1)
        assert d.cables == 1 and d.b == PAPER_PROTOTYPE.b

    def test_summary_has_the_documented_keys(self) -> None:
        s = PAPER_PROTOTYPE.summary()
        for key in (
            "a_m",
            "b",
            "dtheta_rad",
            "theta0_rad",
            "units",
            "beta",
            "taper_rad",
            "tip_width_m",
            "base_width_m",
            "length_m",
            "d_min_m",
            "d_max_m",
            "eta",
            "inputs",
        ):
            assert key in s
        assert len(s["unit_chords_m"]) == s["units"]


class TestValidation:
    @pytest.mark.parametrize(
        ("kwargs", "match"),
        [
            ({"length_m": -0.2}, "length"),
            ({"length_m": 0.0}, "length"),
            ({"tip_width_m": 0.0}, "tip width"),
            ({"taper_rad": 0.0}, "taper"),
            ({"taper_rad": math.pi / 2}, "taper"),
            ({"taper_rad": math.radians(95)}, "taper"),
            ({"dtheta_rad": 0.0}, "dtheta"),
            ({"dtheta_rad": -0.1}, "dtheta"),
            ({"cables": 4}, "cables"),
            ({"length_m": float("nan")}, "length"),
        ],
    )
    def test_bad_physical_inputs(self, kwargs: dict[str, float], match: str) -> None:
        args: dict[str, float] = {
            "length_m": 0.2,
            "tip_width_m": 0.007,
            "taper_rad": math.radians(6),
            "dtheta_rad": math.radians(30),
        }
        args.update(kwargs)
        with pytest.raises(ValueError, match=match):
            SpiralDesign.from_physical(**args)  # type: ignore[arg-type]

    def test_taper_xor_base_width(self) -> None:
        with pytest.raises(ValueError, match="exactly one"):
            SpiralDesign.from_physical(length_m=0.2, tip_width_m=0.007, dtheta_rad=0.5)
        with pytest.raises(ValueError, match="exactly one"):
            SpiralDesign.from_physical(
                length_m=0.2, tip_width_m=0.007, dtheta_rad=0.5, taper_rad=0.1, base_width_m=0.03
            )
        with pytest.raises(ValueError, match="larger than the tip"):
            SpiralDesign.from_physical(length_m=0.2, tip_width_m=0.007, dtheta_rad=0.5, base_width_m=0.005)

    def test_dtheta_that_leaves_no_unit(self) -> None:
        with pytest.raises(ValueError, match="leaves no unit"):
            SpiralDesign.from_params(0.005, 0.15, math.radians(20), math.radians(30))
        with pytest.raises(ValueError, match="leaves no unit"):
            SpiralDesign.from_physical(
                length_m=0.001, tip_width_m=0.007, taper_rad=math.radians(6), dtheta_rad=math.radians(170)
            )

    def test_theta0_must_be_whole_units(self) -> None:
        with pytest.raises(ValueError, match="whole number"):
            SpiralDesign.from_params(0.005, 0.15, math.radians(100), math.radians(30))

    def test_grasp_arguments(self) -> None:
        with pytest.raises(ValueError):
            PAPER_PROTOTYPE.grasp_length_m(-0.01)
        with pytest.raises(ValueError):
            PAPER_PROTOTYPE.grasp_length_m(0.02, 0.0)
        with pytest.raises(ValueError):
            PAPER_PROTOTYPE.max_load_kg(0.02, 0.0)
        with pytest.raises(IndexError):
            PAPER_PROTOTYPE.unit_theta_range_rad(PAPER_PROTOTYPE.units)

    def test_frozen(self) -> None:
        with pytest.raises(AttributeError):
            PAPER_PROTOTYPE.b = 0.2  # type: ignore[misc]
