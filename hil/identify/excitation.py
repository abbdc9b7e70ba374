"""Excitation profiles: the per-cable tension motion a lab records to identify its arm.

A profile is a pure function of time (seconds since it started) to three cable tensions [N], sent to the
board in DIRECT mode (``SET_TENSIONS``) by whoever plays it: ``spirob-host --excite`` against a real board,
the ``excitation`` scenario against the virtual board. The board stays in charge of safety: it clamps every
tension to ``[pretension_n, tension_max_n]``, slews it, runs the pay-in governor and the current limit, and
the pilot's right lever is the enable (DOWN = SAFE = zero current at once; the player then stops).

Every profile is a chain of segments, each starting from rest at the pretension so that a fit can simulate
any segment on its own from the hanging, straight arm (:mod:`hil.identify.motor_data`):

- ``ramp``: one cable slowly up to the peak and back (quasi-static: the tension-length curve, whose knees
  are the joints closing one by one, gives the stiffness profile and gravity's share; the gap between the
  way up and the way down is friction);
- ``steps``: tension steps on one or two cables, held long enough to settle (the rings and their decay:
  damping, the spool's reflected inertia, the delay);
- ``multisine``: a sum of sines on all cables at once, log-spaced 0.2-5 Hz with Schroeder phases for a low
  crest factor (the frequency response in one go, with the cables' couplings);
- ``rest``: the pretension on every cable (the arm hangs back to straight; the next segment starts here).

The figures (peak tension, durations, band) are chosen for the 3-cable prototype on the M2006 (a tension of
10 N is about 0.56 A, a fifth of the 3 A limit) and can be scaled with ``peak_n``. Where the arm gives way
at once (a joint snapping shut on the prototype's ``quick`` ramp), a cable can reel in faster than the
firmware's 0.1 m/s pay-in governor allows, and the board cuts that cable's tension back for a moment: the
fit reads the currents the board sent, so the data stay true; the governor is the board's to apply.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Final

__all__ = ["OPENING_S", "PROFILES", "SEGMENT_KINDS", "Profile", "Segment", "profile"]

SEGMENT_KINDS: Final = ("rest", "ramp", "steps", "multisine")
CABLES: Final = 3


@dataclass(frozen=True, slots=True)
class Segment:
    """One piece of a profile.

    Attributes:
        kind: one of :data:`SEGMENT_KINDS`.
        start_s: start, seconds since the profile began.
        end_s: end (exclusive).
        cables: the cables it moves (none for ``rest``).
    """

    kind: str
    start_s: float
    end_s: float
    cables: tuple[int, ...] = ()

    @property
    def duration_s(self) -> float:
        """Its length in seconds."""
        return self.end_s - self.start_s


@dataclass(frozen=True, slots=True)
class Profile:
    """A named excitation: its segments and the tension levels they move between.

    Attributes:
        name: the profile's name (``PROFILES``).
        segments: in time order, back to back, starting at 0.
        rest_n: tension on every cable at rest. Above the drive's friction at the cable (about 1 N on the
            M2006, up to 2 N with a stiff gearbox): a cable the arm paid out while it bent is reeled back
            in, so every segment starts from the same state, the arm hanging straight on taut cables. (At
            the firmware's 0.5 N pretension a slack cable stays slack: the spool cannot overcome its own
            friction.)
        peak_n: the largest tension asked for.
        multisine_band_hz: lowest and highest frequency of the multisine.
    """

    name: str
    segments: tuple[Segment, ...]
    rest_n: float = 2.0
    peak_n: float = 10.0
    multisine_band_hz: tuple[float, float] = (0.2, 5.0)

    def __post_init__(self) -> None:
        if not self.segments or self.segments[0].start_s != 0.0:
            raise ValueError("a profile starts with a segment at 0 s")
        for a, b in zip(self.segments, self.segments[1:], strict=False):
            if not math.isclose(a.end_s, b.start_s):
                raise ValueError(f"segments must be back to back: {a} then {b}")
        for s in self.segments:
            if s.kind not in SEGMENT_KINDS or s.end_s <= s.start_s:
                raise ValueError(f"bad segment {s}")
            if any(not 0 <= c < CABLES for c in s.cables):
                raise ValueError(f"segment {s} names a cable outside 0..{CABLES - 1}")
        if not 0.0 <= self.rest_n < self.peak_n:
            raise ValueError(f"need 0 <= rest_n < peak_n, got {self.rest_n} and {self.peak_n}")
        lo, hi = self.multisine_band_hz
        if not 0.0 < lo < hi:
            raise ValueError(f"bad multisine band {self.multisine_band_hz}")

    @property
    def duration_s(self) -> float:
        """The whole profile, seconds."""
        return self.segments[-1].end_s

    def segment_at(self, t_s: float) -> Segment | None:
        """The segment playing at ``t_s`` (None before 0 or after the end)."""
        for s in self.segments:
            if s.start_s <= t_s < s.end_s:
                return s
        return None

    def tensions_n(self, t_s: float) -> tuple[float, float, float]:
        """The three cable tensions asked for at ``t_s`` seconds into the profile (rest outside it)."""
        out = [self.rest_n] * CABLES
        seg = self.segment_at(t_s)
        if seg is None or seg.kind == "rest":
            return (out[0], out[1], out[2])
        u = (t_s - seg.start_s) / seg.duration_s  # 0..1 through the segment
        span = self.peak_n - self.rest_n
        if seg.kind == "ramp":
            level = self.rest_n + span * (1.0 - abs(2.0 * u - 1.0))
            for c in seg.cables:
                out[c] = level
        elif seg.kind == "steps":
            # Five levels held a fifth of the segment each: up, higher, down, up again, back to rest.
            fractions = (0.4, 0.8, 0.25, 0.6, 0.0)
            level = self.rest_n + span * fractions[min(int(u * len(fractions)), len(fractions) - 1)]
            for c in seg.cables:
                out[c] = level
        else:  # multisine
            t = t_s - seg.start_s
            for c in seg.cables:
                out[c] = self.rest_n + span * (0.35 + 0.3 * _multisine(t, c, self.multisine_band_hz))
        return (out[0], out[1], out[2])

    def moving_segments(self) -> tuple[Segment, ...]:
        """The segments that move a cable (what a fit simulates), in time order."""
        return tuple(s for s in self.segments if s.kind != "rest")

    def describe(self) -> dict[str, Any]:
        """A JSON-ready description (recorded beside the data, so a fit can find the segments)."""
        return {
            "name": self.name,
            "duration_s": self.duration_s,
            "rest_n": self.rest_n,
            "peak_n": self.peak_n,
            "multisine_band_hz": list(self.multisine_band_hz),
            "segments": [[s.kind, s.start_s, s.end_s, list(s.cables)] for s in self.segments],
        }

    @classmethod
    def from_description(cls, d: Mapping[str, Any]) -> Profile:
        """The inverse of :meth:`describe`.

        Raises:
            ValueError: a malformed description.
        """
        try:
            segs = tuple(
                Segment(str(k), float(a), float(b), tuple(int(c) for c in cs))
                for k, a, b, cs in d["segments"]
            )
            band = d.get("multisine_band_hz", (0.2, 5.0))
            return cls(
                str(d["name"]), segs, float(d["rest_n"]), float(d["peak_n"]), (float(band[0]), float(band[1]))
            )
        except (KeyError, TypeError, ValueError) as exc:
            raise ValueError(f"not an excitation profile description: {exc}") from exc


_SINES: Final = 12


def _multisine(t_s: float, cable: int, band_hz: tuple[float, float]) -> float:
    """A unit-amplitude (|x| <= 1) multisine; each cable gets its own interleaved frequencies.

    Frequencies are log-spaced over the band and dealt to the cables in turn, so no two cables share a line
    (their responses can be told apart); Schroeder phases keep the crest factor low.
    """
    lo, hi = band_hz
    lines = [lo * (hi / lo) ** (k / (CABLES * _SINES - 1)) for k in range(CABLES * _SINES)]
    mine = lines[cable::CABLES]
    total = 0.0
    for k, f in enumerate(mine):
        phase = -math.pi * k * (k + 1) / len(mine)
        total += math.sin(2.0 * math.pi * f * t_s + phase)
    # Schroeder phases keep the peak near sqrt(2 * n); scale so the sum stays within [-1, 1].
    return max(-1.0, min(1.0, total / math.sqrt(2.0 * len(mine)) / 1.6))


def _chain(pieces: Sequence[tuple[str, float, tuple[int, ...]]]) -> tuple[Segment, ...]:
    out: list[Segment] = []
    t = 0.0
    for kind, duration, cables in pieces:
        out.append(Segment(kind, round(t, 6), round(t + duration, 6), cables))
        t += duration
    return tuple(out)


_OPENING: Final[tuple[tuple[str, float, tuple[int, ...]], ...]] = (
    ("rest", 1.0, ()),
    ("ramp", 4.0, (0,)),
    ("rest", 1.0, ()),
    ("steps", 2.5, (1,)),
    ("rest", 1.0, ()),
    ("multisine", 4.0, (0, 1, 2)),
    ("rest", 1.0, ()),
)
"""One segment of each kind (14.5 s): the ``quick`` profile, and the opening of ``standard``. A fit's
rollout starts at a recording's first sample, so what it can afford to simulate of each recording is its
start: the opening puts every kind of motion there (``hil.identify.fit.FitOptions.min_span_s``)."""

OPENING_S: Final = sum(d for _, d, _ in _OPENING)
"""How long the opening of ``standard`` and ``quick`` lasts [s]."""


def _standard() -> Profile:
    rest = 1.5
    pieces: list[tuple[str, float, tuple[int, ...]]] = list(_OPENING)
    for c in (1, 2, 0):
        pieces += [("ramp", 8.0, (c,)), ("rest", rest, ())]
    pieces += [("steps", 5.0, (0, 2)), ("rest", rest, ())]
    pieces += [("multisine", 9.0, (0, 1, 2)), ("rest", 1.5, ())]
    return Profile("standard", _chain(pieces))


def _quick() -> Profile:
    return Profile("quick", _chain(_OPENING))


def _tiny() -> Profile:
    pieces: list[tuple[str, float, tuple[int, ...]]] = [
        ("rest", 0.8, ()),
        ("ramp", 2.0, (0,)),
        ("rest", 0.5, ()),
        ("steps", 1.5, (1,)),
        ("rest", 0.5, ()),
    ]
    return Profile("tiny", _chain(pieces))


PROFILES: Final[dict[str, Profile]] = {p.name: p for p in (_standard(), _quick(), _tiny())}
"""The named profiles: ``standard`` (60 s, every segment kind on every cable, opening with one of each
kind; what a lab records, five times with the arm re-hung in between if it can), ``quick`` (14.5 s, one of
each kind: the opening alone) and ``tiny`` (5.3 s,
a ramp and steps: the test suite's)."""


def profile(name: str, *, peak_n: float | None = None, rest_n: float | None = None) -> Profile:
    """A named profile, optionally with another peak or rest tension.

    Raises:
        ValueError: an unknown name, or levels a profile cannot take.
    """
    try:
        p = PROFILES[name]
    except KeyError:
        raise ValueError(f"unknown excitation profile {name!r} (known: {', '.join(PROFILES)})") from None
    return Profile(
        p.name,
        p.segments,
        p.rest_n if rest_n is None else rest_n,
        p.peak_n if peak_n is None else peak_n,
        p.multisine_band_hz,
    )
