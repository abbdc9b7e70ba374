"""hil.identify.excitation: profiles are back-to-back segments within their tension levels, and round-trip."""

from __future__ import annotations

import pytest

from hil.identify.excitation import OPENING_S, PROFILES, SEGMENT_KINDS, Profile, Segment, profile
from hil.identify.fit import FitOptions


@pytest.mark.parametrize("name", sorted(PROFILES))
def test_profiles_stay_between_rest_and_peak_and_start_and_end_at_rest(name: str) -> None:
    p = PROFILES[name]
    samples = [p.tensions_n(k * 0.005) for k in range(int(p.duration_s / 0.005) + 1)]
    flat = [t for row in samples for t in row]
    assert min(flat) >= p.rest_n - 1e-12
    assert max(flat) <= p.peak_n + 1e-12
    assert max(flat) > 0.9 * p.peak_n  # the ramps reach the peak
    assert p.segments[0].kind == "rest" and p.segments[-1].kind == "rest"
    assert {"rest", "ramp", "steps"} <= {s.kind for s in p.segments}
    assert p.tensions_n(-1.0) == (p.rest_n,) * 3 and p.tensions_n(p.duration_s + 1.0) == (p.rest_n,) * 3


def test_standard_profile_lasts_a_minute_and_moves_every_cable() -> None:
    p = PROFILES["standard"]
    assert p.duration_s == pytest.approx(60.0)
    moved = {c for s in p.moving_segments() for c in s.cables}
    assert moved == {0, 1, 2}


def test_standard_opens_with_one_segment_of_each_kind_which_the_fit_spends_its_budget_on() -> None:
    """A fit simulates each recording from its start, as far as its budget allows: the opening it sees
    holds every kind of motion (the quick profile), and the default budget is two such openings."""
    standard, quick = PROFILES["standard"], PROFILES["quick"]
    opening = [s for s in standard.segments if s.end_s <= OPENING_S + 1e-9]
    assert opening == list(quick.segments) and quick.duration_s == OPENING_S
    assert {s.kind for s in opening} == set(SEGMENT_KINDS)
    assert FitOptions().min_span_s == OPENING_S and FitOptions().budget_s == 2 * OPENING_S


def test_multisine_cables_are_not_copies_of_each_other() -> None:
    p = PROFILES["quick"]
    seg = next(s for s in p.segments if s.kind == "multisine")
    rows = [p.tensions_n(seg.start_s + k * 0.01) for k in range(int(seg.duration_s / 0.01))]
    a = [r[0] for r in rows]
    b = [r[1] for r in rows]
    assert max(abs(x - y) for x, y in zip(a, b, strict=True)) > 1.0


def test_description_round_trips() -> None:
    p = profile("quick", peak_n=8.0)
    assert Profile.from_description(p.describe()) == p


@pytest.mark.parametrize(
    ("make", "why"),
    [
        (lambda: profile("nope"), "unknown excitation profile"),
        (lambda: Profile("x", (Segment("rest", 1.0, 2.0),)), "starts with a segment at 0"),
        (lambda: Profile("x", (Segment("rest", 0.0, 1.0), Segment("ramp", 2.0, 3.0, (0,)))), "back to back"),
        (lambda: Profile("x", (Segment("twirl", 0.0, 1.0),)), "bad segment"),
        (lambda: Profile("x", (Segment("ramp", 0.0, 1.0, (3,)),)), "outside 0..2"),
        (lambda: profile("quick", peak_n=0.1), "rest_n < peak_n"),
        (lambda: Profile.from_description({"name": "x"}), "not an excitation profile"),
    ],
)
def test_bad_profiles_are_refused(make: object, why: str) -> None:
    with pytest.raises(ValueError, match=why):
        make()  # type: ignore[operator]
