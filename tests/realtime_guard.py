"""Real-time tests on a shared machine: a run the machine starved is retried, then skipped with the
measured reason; never reported as a product failure, never silently passed.

A real-time run knows when it is void: its own validity check (the largest unplanned gap between the RC
frames the board received, ``hil.scenarios.RC_GAP_CHECK``) or the host loop's own send gaps say the
machine, not the board, stalled. :func:`retry_void` runs such a run again (up to :data:`ATTEMPTS_N` times
in all) and, if every attempt was void, skips the test with the measured gap and the load average. The
skip reason starts with :data:`STARVED_PREFIX`; ``tests/conftest.py`` counts those skips per file, prints
them at the end and fails a CI run (``CI`` set) in which every real-time test of a file was skipped.

Tests that use this mark themselves ``@pytest.mark.realtime``.
"""

from __future__ import annotations

import itertools
import os
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, NoReturn, TypeVar

import pytest

if TYPE_CHECKING:  # tests/conftest.py imports this module: hil (and MuJoCo) only when a test needs it
    from hil.scenarios import ScenarioResult

__all__ = [
    "ATTEMPTS_N",
    "STARVED_PREFIX",
    "largest_gap_s",
    "load_text",
    "retry_void",
    "skip_starved",
    "void_reason",
]

ATTEMPTS_N = 3
"""Attempts of a void run in all (the first and two more); on a quiet machine the first one counts."""

STARVED_PREFIX = "starved:"
"""How every skip for a machine-starved run begins (``tests/conftest.py`` counts them by it)."""

T = TypeVar("T")


def load_text() -> str:
    """The load average as a person reads it, e.g. ``load average 6.1 / 4.0 / 3.2 on 2 cores``."""
    one, five, fifteen = os.getloadavg()
    return f"load average {one:.1f} / {five:.1f} / {fifteen:.1f} on {os.cpu_count() or 1} cores"


def skip_starved(reason: str) -> NoReturn:
    """Skip the running test as starved by the machine: ``starved: REASON; load average ...``."""
    pytest.skip(f"{STARVED_PREFIX} {reason}; {load_text()}")


def void_reason(result: ScenarioResult) -> str | None:
    """Why a port run of a scenario is void (its RC gap check failed), or None if it counts."""
    from hil.scenarios import RC_GAP_CHECK

    for check in result.checks:
        if check.name.startswith(RC_GAP_CHECK) and not check.passed:
            return (
                f"largest unplanned gap between the RC frames {check.value / 1000:.0f} ms > "
                f"{check.bound / 1000:.0f} ms in {result.name!r} (the run is void)"
            )
    return None


def retry_void(run: Callable[[], T], void: Callable[[T], str | None], attempts: int = ATTEMPTS_N) -> T:
    """Run ``run()`` until ``void(result)`` is None, at most ``attempts`` times in all.

    Returns:
        The first result that is not void; the test then judges it like any other.

    Raises:
        pytest.skip.Exception: every attempt was void (the last one's reason and the load average).
    """
    reason: str | None = None
    for _ in range(attempts):
        result = run()
        reason = void(result)
        if reason is None:
            return result
    skip_starved(f"{reason}, {attempts} attempts")


def largest_gap_s(times_s: Sequence[float]) -> float:
    """The largest interval between consecutive instants (0 for fewer than two)."""
    return max((b - a for a, b in itertools.pairwise(times_s)), default=0.0)
