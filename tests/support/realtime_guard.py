"""Real-time tests on a shared machine: a run the machine starved is retried, then skipped with the
measured reason; never reported as a product failure, never silently passed.

A real-time run knows when it is void: its own validity check (the largest unplanned gap between the RC
frames the board received, ``hil.scenarios.RC_GAP_CHECK``) or the host loop's own send gaps say the
machine, not the board, stalled. :func:`retry_void` runs such a run again (up to :data:`ATTEMPTS_N` times
in all) and, if every attempt was void, skips the test with the measured gap and the load average. The
skip reason starts with :data:`STARVED_PREFIX`; ``tests/conftest.py`` counts those skips per file, prints
them at the end and fails a CI run (``CI`` set) in which every real-time test of a file was skipped.

Tests that use this mark themselves ``@pytest.mark.realtime``.

The MAVProxy and Chromium tests (``mavproxy``, ``browser``) wait on another program instead: their waits
grow with the load per core (:func:`scaled_s`, at most :data:`LOAD_SCALE_MAX` times), and a wait that
still times out while the machine is starved (load per core above :data:`STARVED_LOAD_PER_CORE`) skips
the test as ``starved:`` (:func:`timed_out`, :func:`starved_timeouts`); on a quieter machine it fails.
"""

from __future__ import annotations

import contextlib
import itertools
import os
import time
from collections.abc import Callable, Iterator, Sequence
from typing import TYPE_CHECKING, NoReturn, TypeVar

import pytest

if TYPE_CHECKING:  # tests/conftest.py imports this module: hil (and MuJoCo) only when a test needs it
    from hil.run_record import ScenarioResult

__all__ = [
    "ATTEMPTS_N",
    "LOAD_SCALE_MAX",
    "STARVED_LOAD_PER_CORE",
    "STARVED_PREFIX",
    "largest_gap_s",
    "load_per_core",
    "load_text",
    "retry_void",
    "scaled_s",
    "skip_starved",
    "starved_timeouts",
    "timed_out",
    "void_reason",
    "wait_for",
]

ATTEMPTS_N = 3
"""Attempts of a void run in all (the first and two more); on a quiet machine the first one counts."""

STARVED_PREFIX = "starved:"
"""How every skip for a machine-starved run begins (``tests/conftest.py`` counts them by it)."""

LOAD_SCALE_MAX = 3.0
"""The most a wait grows with the load (a hung program must still end within the suite's 300 s)."""

STARVED_LOAD_PER_CORE = 2.0
"""A wait that times out with more than this many runnable tasks per core (the 1-minute load average)
is the machine's fault: each task got at most half a core, on top of the already scaled wait."""

T = TypeVar("T")


def load_text() -> str:
    """The load average as a person reads it, e.g. ``load average 6.1 / 4.0 / 3.2 on 2 cores``."""
    one, five, fifteen = os.getloadavg()
    return f"load average {one:.1f} / {five:.1f} / {fifteen:.1f} on {os.cpu_count() or 1} cores"


def skip_starved(reason: str) -> NoReturn:
    """Skip the running test as starved by the machine: ``starved: REASON; load average ...``."""
    pytest.skip(f"{STARVED_PREFIX} {reason}; {load_text()}")


def load_per_core() -> float:
    """The 1-minute load average per CPU core (1.0: every core busy, nobody waiting)."""
    return os.getloadavg()[0] / (os.cpu_count() or 1)


def scaled_s(timeout_s: float) -> float:
    """``timeout_s`` (a quiet machine's wait) times the load per core, within 1..:data:`LOAD_SCALE_MAX`."""
    return timeout_s * min(LOAD_SCALE_MAX, max(1.0, load_per_core()))


def timed_out(what: str, detail: str = "") -> NoReturn:
    """A wait for ``what`` timed out: skipped as starved on a starved machine, a failure otherwise.

    Args:
        what: what the test waited for (one line: it ends up in the skip reason).
        detail: appended to the failure only (e.g. the program's last output lines).

    Raises:
        pytest.skip.Exception: the load per core is above :data:`STARVED_LOAD_PER_CORE`.
        AssertionError: it is not (the program under test did not answer).
    """
    if load_per_core() > STARVED_LOAD_PER_CORE:
        skip_starved(f"timed out waiting for {what}")
    raise AssertionError(f"timed out waiting for {what}{detail}")


@contextlib.contextmanager
def starved_timeouts(*timeouts: type[Exception], what: str) -> Iterator[None]:
    """Inside: a ``timeouts`` exception (e.g. Playwright's) skips the test as starved on a starved machine.

    On a quieter machine the exception propagates: the test fails as it would without this.
    """
    try:
        yield
    except timeouts as exc:
        if load_per_core() > STARVED_LOAD_PER_CORE:
            first = str(exc).strip().splitlines()[:1]
            skip_starved(f"timed out waiting for {what} ({first[0] if first else type(exc).__name__})")
        raise


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


def wait_for(cond: Callable[[], bool], timeout_s: float = 10.0, poll_s: float = 0.02) -> bool:
    """Poll ``cond`` until it holds or ``timeout_s`` (scaled with the load, :func:`scaled_s`) ran out; its
    last value. A wait, never a timing assertion: the caller asserts what it waited for."""
    deadline = time.monotonic() + scaled_s(timeout_s)
    while time.monotonic() < deadline:
        if cond():
            return True
        time.sleep(poll_s)
    return cond()
