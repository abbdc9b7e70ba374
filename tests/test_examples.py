"""The numbered examples are the tutorial: each one runs to completion on a fresh machine."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

from tests.support.realtime_guard import retry_void

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = sorted((ROOT / "examples").glob("[0-9][0-9]_*.py"))


def test_examples_exist() -> None:
    assert len(EXAMPLES) >= 4


WALL_CLOCK = frozenset({"03_host_panel.py", "04_drone_link.py", "06_scripted_grasp.py"})
"""The examples that run a real-time board, a link process or a host: marked ``realtime`` (they need the
machine to themselves); the others are lockstep simulations and computations."""


def _starved(proc: subprocess.CompletedProcess[str]) -> str | None:
    """A failed run whose host summary shows the link's RC frames more than 30 ms apart was starved by the
    machine (the board rightly latched RC_LOST): void, not a result."""
    m = re.search(r"RC gaps over 30 ms: [1-9]\d*.*", proc.stdout)
    return None if proc.returncode == 0 or m is None else f"the link's RC frames were late: {m.group(0)}"


@pytest.mark.parametrize(
    "example",
    [pytest.param(p, marks=pytest.mark.realtime) if p.name in WALL_CLOCK else p for p in EXAMPLES],
    ids=[p.name for p in EXAMPLES],
)
def test_example_runs(example: Path, tmp_path: Path) -> None:
    def run() -> subprocess.CompletedProcess[str]:
        return subprocess.run(
            [sys.executable, str(example)], cwd=tmp_path, capture_output=True, text=True, timeout=180
        )

    proc = retry_void(run, _starved) if example.name in WALL_CLOCK else run()
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    assert proc.stdout.strip()


@pytest.mark.realtime
def test_the_host_example_fails_with_one_line_and_exit_1() -> None:
    """A demo that cannot run says why in one line and exits 1 (never a traceback, never exit 0)."""
    import socket

    with socket.socket() as s:  # a port nobody listens on: take one, then free it
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    example = ROOT / "examples" / "03_host_panel.py"
    proc = subprocess.run(
        [sys.executable, str(example), "--port", f"socket://127.0.0.1:{port}"],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode == 1, proc.stdout + proc.stderr
    lines = [line for line in proc.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("03_host_panel: cannot start: board link:"), lines
