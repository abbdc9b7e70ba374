"""The starved-machine guard: waits scaled with the load; a time-out or a void run skipped only when
others (not this run's processes) were busy meanwhile; the monitor that measures those others."""

from __future__ import annotations

import os
import subprocess
import sys
import time

import pytest

from tests.support import machine
from tests.support import realtime_guard as guard
from tests.support.machine import BUSY_OTHERS_CORES, MachineMonitor, OthersLoad

IDLE = OthersLoad(window_s=10.0, mean_cores=0.02, peak_cores=0.1, samples=40)
BUSY = OthersLoad(window_s=10.0, mean_cores=0.4, peak_cores=BUSY_OTHERS_CORES, samples=40)


def _load(monkeypatch: pytest.MonkeyPatch, per_core: float) -> None:
    cores = os.cpu_count() or 1
    monkeypatch.setattr(os, "getloadavg", lambda: (per_core * cores, 0.0, 0.0))


def _others(monkeypatch: pytest.MonkeyPatch, load: OthersLoad) -> None:
    monkeypatch.setattr(guard, "others_during", lambda since, until=None: load)


@pytest.mark.parametrize(
    ("per_core", "scale"), [(0.1, 1.0), (1.0, 1.0), (2.5, 2.5), (40.0, guard.LOAD_SCALE_MAX)]
)
def test_waits_scale_with_the_load_per_core_within_bounds(
    monkeypatch: pytest.MonkeyPatch, per_core: float, scale: float
) -> None:
    _load(monkeypatch, per_core)
    assert guard.load_per_core() == pytest.approx(per_core)
    assert guard.scaled_s(10.0) == pytest.approx(10.0 * scale)


def test_a_timeout_fails_when_others_were_idle_whatever_the_load(monkeypatch: pytest.MonkeyPatch) -> None:
    _load(monkeypatch, 40.0)  # this run's own work (a spinning board, a hung browser) raises the load
    _others(monkeypatch, IDLE)
    with pytest.raises(
        AssertionError, match=r"timed out waiting for the answer \(others' work .*\); last lines"
    ):
        guard.timed_out("the answer", "; last lines")
    with pytest.raises(TimeoutError), guard.starved_timeouts(TimeoutError, what="the page"):
        raise TimeoutError("Timeout 30000ms exceeded.")


def test_a_timeout_while_others_were_busy_is_skipped_as_starved(monkeypatch: pytest.MonkeyPatch) -> None:
    _others(monkeypatch, BUSY)
    with pytest.raises(pytest.skip.Exception, match=r"^starved: timed out waiting for the answer \(others'"):
        guard.timed_out("the answer", "; not in the skip reason")
    with (
        pytest.raises(
            pytest.skip.Exception, match=r"^starved: .*the page \(Timeout 30000ms exceeded\.; others'"
        ),
        guard.starved_timeouts(TimeoutError, what="the page"),
    ):
        raise TimeoutError("Timeout 30000ms exceeded.\nCall log: ...")
    with pytest.raises(ValueError), guard.starved_timeouts(TimeoutError, what="the page"):
        raise ValueError("not a time-out: always a failure")


def test_no_samples_is_no_evidence_of_starvation() -> None:
    assert not OthersLoad(0.0, 0.0, 0.0, 0).busy
    assert OthersLoad(0.0, 0.0, 0.0, 0).text() == "others' work not measured"
    assert BUSY.busy and not IDLE.busy


def test_a_void_run_on_an_idle_machine_counts_and_is_judged(monkeypatch: pytest.MonkeyPatch) -> None:
    """A board that stalled itself on an idle machine: its run is returned to the test (which fails it),
    at the first attempt, never retried into a skip."""
    _others(monkeypatch, IDLE)
    runs: list[int] = []

    def run() -> int:
        runs.append(1)
        return len(runs)

    assert guard.retry_void(run, lambda n: "largest unplanned RC gap 207 ms") == 1
    assert len(runs) == 1


def test_a_void_run_while_others_were_busy_is_retried_then_skipped(monkeypatch: pytest.MonkeyPatch) -> None:
    _others(monkeypatch, BUSY)
    runs: list[int] = []

    def run() -> int:
        runs.append(1)
        return len(runs)

    with pytest.raises(
        pytest.skip.Exception, match=r"^starved: largest unplanned RC gap 207 ms; others'.*3 attempts"
    ):
        guard.retry_void(run, lambda n: "largest unplanned RC gap 207 ms")
    assert len(runs) == guard.ATTEMPTS_N
    # A run that is not void counts at once, busy or not.
    assert guard.retry_void(lambda: 7, lambda n: None) == 7


@pytest.mark.skipif(not os.path.exists("/proc/stat"), reason="Linux /proc only")
def test_the_monitor_counts_work_outside_its_tree_as_others_and_its_own_as_not() -> None:
    """Watching a sleeping child's tree, a spinning child of this process is others' work; watching this
    process's tree, it is not. Judged against the CPU the spinner really got (the machine may be shared).
    The spin is a child process: a spinning thread here would hold the GIL the monitors sample with."""
    sleeper = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(30)"])
    spin = "import time\nt = time.monotonic()\nwhile time.monotonic() - t < 1.5: pass\ntime.sleep(30)"
    spinner = subprocess.Popen([sys.executable, "-c", spin])
    try:
        outside = MachineMonitor(root=sleeper.pid, sample_s=0.1).start()
        inside = MachineMonitor(root=os.getpid(), sample_s=0.1).start()
        t0, cpu0 = time.monotonic(), machine._tree_cpu_s(spinner.pid)
        time.sleep(2.0)  # the spin and the last samples
        spun_s = machine._tree_cpu_s(spinner.pid) - cpu0
        got_out = outside.others(t0)
        got_in = inside.others(t0)
        outside.stop()
        inside.stop()
    finally:
        for p in (sleeper, spinner):
            p.kill()
            p.wait()
    assert got_out.samples >= 5 and got_in.samples >= 5
    # Others' CPU seconds seen from outside include (nearly all of) our spin; from inside they exclude it.
    assert got_out.mean_cores * got_out.window_s >= 0.8 * spun_s - 0.05, (got_out, spun_s)
    assert (
        got_out.mean_cores * got_out.window_s - got_in.mean_cores * got_in.window_s >= 0.7 * spun_s - 0.1
    ), (
        got_out,
        got_in,
        spun_s,
    )


@pytest.mark.skipif(not os.path.exists("/proc/stat"), reason="Linux /proc only")
def test_the_tree_includes_children_and_their_cpu() -> None:
    child = subprocess.Popen(
        [
            sys.executable,
            "-c",
            "import time\nt=time.process_time()\nwhile time.process_time()-t<0.3: pass\ntime.sleep(30)",
        ]
    )
    try:
        before = machine._tree_cpu_s(os.getpid())
        deadline = time.monotonic() + 20.0
        while time.monotonic() < deadline and machine._tree_cpu_s(os.getpid()) - before < 0.25:
            time.sleep(0.05)
        assert machine._tree_cpu_s(os.getpid()) - before >= 0.25
    finally:
        child.kill()
        child.wait()
