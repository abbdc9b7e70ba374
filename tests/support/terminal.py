"""Ctrl-C as a terminal sends it: SIGINT to the whole foreground process group."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def start_in_own_group(module: str, *args: str, merge_stderr: bool = False) -> subprocess.Popen[str]:
    """``python -m module args`` from the repository, in a process group of its own (a foreground job)."""
    return subprocess.Popen(
        [sys.executable, "-m", module, *args],
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT if merge_stderr else subprocess.PIPE,
        text=True,
        start_new_session=True,
        # A terminal's foreground job takes Ctrl-C; a shell's background job (a CI runner's, `cmd &`)
        # starts with SIGINT ignored, and a child would inherit that.
        preexec_fn=_default_sigint,
    )


def _default_sigint() -> None:
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def ctrl_c(proc: subprocess.Popen[str], timeout_s: float = 60.0) -> tuple[str, str]:
    """Press Ctrl-C: SIGINT to ``proc``'s group; its output once it ended (killed if it does not end)."""
    try:
        os.killpg(proc.pid, signal.SIGINT)
        out, err = proc.communicate(timeout=timeout_s)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait(timeout=10)
    return out or "", err or ""


def children(proc: subprocess.Popen[str]) -> list[int]:
    """The pids of ``proc``'s child processes (Linux's ``/proc/PID/task/PID/children``)."""
    try:
        text = Path(f"/proc/{proc.pid}/task/{proc.pid}/children").read_text()
    except OSError:
        return []
    return [int(p) for p in text.split()]
