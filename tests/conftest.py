"""Suite-wide fixtures and guards.

- A run in which no test passed fails (pytest itself only fails on "nothing collected").
- A test that leaves a thread or a child process running fails.
- Tests that need the machine to themselves are marked ``serial`` (``make test`` runs the others on two
  workers first, then these one at a time).
- Hypothesis has no deadline: tests never assert wall-clock times, and a loaded machine makes one example
  slow without making it wrong.
- Real-time tests (``@pytest.mark.realtime``) the machine starved are skipped as ``starved:``
  (``tests/support/realtime_guard.py``), and so are MAVProxy and browser tests (``mavproxy``,
  ``browser``) whose waits timed out on a starved machine. Starved means that others (processes outside
  this run's tree, stolen time) were busy meanwhile: ``tests/support/machine.py`` samples that from the
  start of the first such test. The end of the run counts the skips, warns about a file whose every
  such test was skipped, and with ``CI`` set fails the run for it: CI never passes on an all-skipped file.
"""

from __future__ import annotations

import multiprocessing
import os
import threading
from collections import defaultdict
from collections.abc import Iterator

import pytest
from hypothesis import settings

from tests.support import machine
from tests.support.realtime_guard import STARVED_PREFIX

settings.register_profile("spirob", deadline=None)
settings.load_profile("spirob")

_REALTIME: defaultdict[str, dict[str, int]] = defaultdict(lambda: {"passed": 0, "failed": 0, "starved": 0})
"""Per test file of this run: how many real-time tests passed, failed and were skipped as starved."""

_WALL_CLOCK_MARKS = frozenset({"realtime", "mavproxy", "browser"})
"""The tests that can be starved: they wait on wall-clock time, another process or a browser."""

_SERIAL_PATHS = (
    "tests/host/",
    "tests/test_docs.py",
    "tests/test_packaging.py",
    "tests/hil/test_board.py",
    "tests/hil/test_realtime.py",
    "tests/controller/test_clock.py",
    "tests/controller/test_firmware.py",
)
"""Files whose tests run real-time boards, link processes, browsers or CLIs in real time without a mark."""
_PARALLEL_HOST_FILES = (
    "tests/host/drone/test_component.py",
    "tests/host/drone/test_servo.py",
    "tests/host/panel/test_arbiter.py",
    "tests/host/panel/test_board_params.py",
    "tests/host/panel/test_board_state.py",
    "tests/host/panel/test_guard.py",
    "tests/host/panel/test_notices.py",
    "tests/host/panel/test_param_table.py",
    "tests/host/panel/test_plots.py",
    "tests/host/panel/test_record.py",
    "tests/host/panel/test_scene.py",
    "tests/host/panel/test_state_bar.py",
    "tests/host/test_gamepad.py",
    "tests/host/test_object_spec.py",
)
"""Host files of unit tests (fake clocks, lockstep boards, in-process servers on port 0): no real-time board,
link process, browser or CLI, so they run with the parallel phase (a wall-clock mark still makes a test
serial)."""


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Mark ``serial`` every test that must have the machine to itself: a wall-clock mark, a Ray cluster,
    or a file of :data:`_SERIAL_PATHS`. ``make test`` runs the rest on two workers first (pytest-xdist:
    simulations in lockstep, parsers, the firmware on a fake clock), then these one at a time."""
    root = config.rootpath
    for item in items:
        rel = item.path.relative_to(root).as_posix() if item.path.is_relative_to(root) else ""
        wall = not _WALL_CLOCK_MARKS.isdisjoint(item.keywords) or "ray" in item.keywords
        if wall or (rel.startswith(_SERIAL_PATHS) and rel not in _PARALLEL_HOST_FILES):
            item.add_marker(pytest.mark.serial)


def pytest_collection_finish(session: pytest.Session) -> None:
    """Start sampling the others' work before the first test that may be judged starved."""
    if any(not _WALL_CLOCK_MARKS.isdisjoint(item.keywords) for item in session.items):
        machine.monitor()


@pytest.fixture(autouse=True)
def _no_leaked_threads_or_processes() -> Iterator[None]:
    before = {t.ident for t in threading.enumerate()}
    yield
    # Give stopping threads a bounded moment to finish joining.
    leaked: list[threading.Thread] = []
    for t in threading.enumerate():
        if (
            t.ident in before
            or not t.is_alive()
            or isinstance(t, threading._DummyThread)
            or t.name == "machine-monitor"
        ):
            continue  # a dummy: a thread of a native library (foxglove-sdk's) that called into Python
        t.join(timeout=2.0)
        if t.is_alive():
            leaked.append(t)
    children = [p for p in multiprocessing.active_children() if p.is_alive()]
    for p in children:
        p.join(timeout=2.0)
    alive = [p for p in children if p.is_alive()]
    for p in alive:
        p.kill()
    assert not leaked, f"test left threads running: {[t.name for t in leaked]}"
    assert not alive, f"test left child processes running: {[p.name for p in alive]}"


def pytest_runtest_logreport(report: pytest.TestReport) -> None:
    if _WALL_CLOCK_MARKS.isdisjoint(report.keywords):
        return
    outcome: str | None = None
    if report.when == "call" and report.passed:
        outcome = "passed"
    elif report.failed:
        outcome = "failed"
    elif report.skipped and isinstance(report.longrepr, tuple) and STARVED_PREFIX in report.longrepr[2]:
        outcome = "starved"
    if outcome is not None:
        _REALTIME[report.nodeid.split("::")[0]][outcome] += 1


def _all_starved() -> list[str]:
    """The files whose every real-time test of this run was skipped as starved."""
    return sorted(f for f, n in _REALTIME.items() if n["starved"] and not n["passed"] and not n["failed"])


def pytest_terminal_summary(terminalreporter: pytest.TerminalReporter) -> None:
    files = _REALTIME
    starved = sum(n["starved"] for n in files.values())
    if not starved:
        return
    ran = sum(sum(n.values()) for n in files.values())
    terminalreporter.write_line(
        f"real-time, MAVProxy and browser tests: {starved} of {ran} skipped as starved by the machine "
        "(void runs, not results)",
        yellow=True,
    )
    for path in _all_starved():
        terminalreporter.write_line(
            f"warning: every wall-clock test of {path} was skipped as starved: it tested nothing"
            + ("; CI fails this run" if os.environ.get("CI") else ""),
            red=True,
        )


def pytest_sessionfinish(session: pytest.Session, exitstatus: int) -> None:
    reporter = session.config.pluginmanager.get_plugin("terminalreporter")
    if reporter is None or exitstatus != 0:
        return
    if not reporter.stats.get("passed"):
        session.exitstatus = 1
        reporter.write_line("error: no test passed; refusing an empty run", red=True)
    elif os.environ.get("CI") and _all_starved():
        session.exitstatus = 1  # CI runs alone: a file whose real-time tests all starved tested nothing
