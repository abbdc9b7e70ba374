"""Real-time tests on a shared machine: a run the machine starved is retried, then skipped with the
measured reason; never reported as a product failure, never silently passed, and never the other way round.

Who starved whom is judged from the machine, never from the board's own intake: a board that stalls
itself looks, from its RC receive times, exactly like a starved machine. ``tests.support.machine``
measures the CPU the machine spent on work that is not this test run's (other processes, kernel
workers, stolen time: the whole machine's busy time minus this process tree's). A run whose own validity
check failed (the largest unplanned gap between the RC frames the board received,
``hil.scenarios.RC_GAP_CHECK``) is void only if those others were busy during it
(:data:`tests.support.machine.BUSY_OTHERS_CORES`); :func:`retry_void` then runs it again (up to
:data:`ATTEMPTS_N` times in all) and, if every attempt was void, skips the test with the measured gap,
the host sender's own largest gap and the others' load. On an idle machine the run counts, and a board
that stalled fails its test. The skip reason starts with :data:`STARVED_PREFIX`; ``tests/conftest.py``
counts those skips per file, prints them at the end and fails a CI run (``CI`` set) in which every
real-time test of a file was skipped.

Tests that use this mark themselves ``@pytest.mark.realtime``.

The MAVProxy and Chromium tests (``mavproxy``, ``browser``) wait on another program instead: their waits
grow with the load per core (:func:`scaled_s`, at most :data:`LOAD_SCALE_MAX` times), and a wait that
still times out skips the test as ``starved:`` only if others were busy during the wait
(:func:`timed_out`, :func:`starved_timeouts`); otherwise it fails.
"""

from __future__ import annotations

import contextlib
import itertools
import os
import time
from collections.abc import Callable, Iterator, Sequence
from typing import TYPE_CHECKING, NoReturn, TypeVar

import pytest

from tests.support import machine
from tests.support.machine import OthersLoad

if TYPE_CHECKING:  # tests/conftest.py imports this module: hil (and MuJoCo) only when a test needs it
    from hil.run_record import ScenarioResult

__all__ = [
    "ATTEMPTS_N",
    "LOAD_SCALE_MAX",
    "STARVED_PREFIX",
    "TIMEOUT_WINDOW_S",
    "largest_gap_s",
    "load_per_core",
    "load_text",
    "others_during",
    "retry_void",
    "scaled_s",
    "skip_if_others_were_busy",
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

TIMEOUT_WINDOW_S = 60.0
"""How far back a timed-out wait looks for others' work when its caller does not say when it began."""

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
    """``timeout_s`` (a quiet machine's wait) times the load per core, within 1..:data:`LOAD_SCALE_MAX`.

    A wait may grow with any load, this run's own included: only the verdict on a time-out is judged from
    the others' work."""
    return timeout_s * min(LOAD_SCALE_MAX, max(1.0, load_per_core()))


def others_during(since: float, until: float | None = None) -> OthersLoad:
    """Others' work between two monotonic instants (no samples: nothing may be called starved)."""
    mon = machine.monitor()
    return mon.others(since, until) if mon is not None else OthersLoad(0.0, 0.0, 0.0, 0)


def timed_out(what: str, detail: str = "", since: float | None = None) -> NoReturn:
    """A wait for ``what`` timed out: skipped as starved if others were busy meanwhile, a failure otherwise.

    Args:
        what: what the test waited for (one line: it ends up in the skip reason).
        detail: appended to the failure only (e.g. the program's last output lines).
        since: when the wait began (monotonic); default the last :data:`TIMEOUT_WINDOW_S`.

    Raises:
        pytest.skip.Exception: others took at least half a core during the wait.
        AssertionError: they did not (the program under test did not answer).
    """
    others = others_during(time.monotonic() - TIMEOUT_WINDOW_S if since is None else since)
    if others.busy:
        skip_starved(f"timed out waiting for {what} ({others.text()})")
    raise AssertionError(f"timed out waiting for {what} ({others.text()}){detail}")


@contextlib.contextmanager
def starved_timeouts(*timeouts: type[Exception], what: str) -> Iterator[None]:
    """Inside: a ``timeouts`` exception (e.g. Playwright's) skips the test as starved if others were busy
    while it waited; otherwise the exception propagates and the test fails as it would without this."""
    since = time.monotonic()
    try:
        yield
    except timeouts as exc:
        others = others_during(since)
        if others.busy:
            first = str(exc).strip().splitlines()[:1]
            skip_starved(
                f"timed out waiting for {what} ({first[0] if first else type(exc).__name__}; {others.text()})"
            )
        raise


def skip_if_others_were_busy(since: float, reason: str) -> None:
    """Skip the test as starved with ``reason`` if others were busy since ``since`` (monotonic); return
    otherwise, and the test goes on to judge what it got (an idle machine's stall is the product's)."""
    others = others_during(since)
    if others.busy:
        skip_starved(f"{reason} ({others.text()})")


def void_reason(result: ScenarioResult) -> str | None:
    """Why a port run of a scenario may be void (its RC gap check failed), or None if it counts whatever
    the machine did. Whether it *is* void, :func:`retry_void` decides from the others' work."""
    from hil.scenarios import RC_GAP_CHECK

    for check in result.checks:
        if check.name.startswith(RC_GAP_CHECK) and not check.passed:
            sender = result.counters.get("host_rc_send_gap_max_us")
            host = "" if sender is None else f", the host's own sender {sender / 1000:.0f} ms"
            return (
                f"largest unplanned gap between the RC frames {check.value / 1000:.0f} ms > "
                f"{check.bound / 1000:.0f} ms in {result.name!r}{host}"
            )
    return None


def retry_void(run: Callable[[], T], void: Callable[[T], str | None], attempts: int = ATTEMPTS_N) -> T:
    """Run ``run()`` until it counts, at most ``attempts`` times in all.

    A result counts if ``void(result)`` is None, or if it is not but others were not busy while it ran
    (then the board, the link or the harness stalled on an idle machine: the test judges the result and
    fails on it).

    Returns:
        The first result that counts.

    Raises:
        pytest.skip.Exception: every attempt was void while others were busy (the last one's reason and
            the others' load).
    """
    reason: str | None = None
    for _ in range(attempts):
        since = time.monotonic()
        result = run()
        reason = void(result)
        if reason is None:
            return result
        others = others_during(since)
        if not others.busy:
            return result  # an idle machine: the stall is the product's, and the test says so
        reason = f"{reason}; {others.text()}"
    skip_starved(f"{reason}, {attempts} attempts (the run is void)")


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
