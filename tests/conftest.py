"""Suite-wide fixtures and guards.

- A run in which no test passed fails (pytest itself only fails on "nothing collected").
- A test that leaves a thread or a child process running fails.
"""

from __future__ import annotations

import multiprocessing
import threading
from collections.abc import Iterator

import pytest


@pytest.fixture(autouse=True)
def _no_leaked_threads_or_processes() -> Iterator[None]:
    before = {t.ident for t in threading.enumerate()}
    yield
    # Give stopping threads a bounded moment to finish joining.
    leaked: list[threading.Thread] = []
    for t in threading.enumerate():
        if t.ident in before or not t.is_alive():
            continue
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


def pytest_sessionfinish(session: pytest.Session, exitstatus: int) -> None:
    reporter = session.config.pluginmanager.get_plugin("terminalreporter")
    if reporter is None or exitstatus != 0:
        return
    if not reporter.stats.get("passed"):
        session.exitstatus = 1
        reporter.write_line("error: no test passed; refusing an empty run", red=True)
