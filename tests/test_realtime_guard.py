"""The starved-machine guard's waits: scaled with the load, skipped only on a starved machine."""

from __future__ import annotations

import os

import pytest

from tests.support import realtime_guard as guard


def _load(monkeypatch: pytest.MonkeyPatch, per_core: float) -> None:
    cores = os.cpu_count() or 1
    monkeypatch.setattr(os, "getloadavg", lambda: (per_core * cores, 0.0, 0.0))


@pytest.mark.parametrize(
    ("per_core", "scale"), [(0.1, 1.0), (1.0, 1.0), (2.5, 2.5), (40.0, guard.LOAD_SCALE_MAX)]
)
def test_waits_scale_with_the_load_per_core_within_bounds(
    monkeypatch: pytest.MonkeyPatch, per_core: float, scale: float
) -> None:
    _load(monkeypatch, per_core)
    assert guard.load_per_core() == pytest.approx(per_core)
    assert guard.scaled_s(10.0) == pytest.approx(10.0 * scale)


def test_a_timeout_fails_on_a_quiet_machine(monkeypatch: pytest.MonkeyPatch) -> None:
    _load(monkeypatch, guard.STARVED_LOAD_PER_CORE)  # at the threshold: not starved
    with pytest.raises(AssertionError, match="timed out waiting for the answer; last lines"):
        guard.timed_out("the answer", "; last lines")
    with pytest.raises(TimeoutError), guard.starved_timeouts(TimeoutError, what="the page"):
        raise TimeoutError("Timeout 30000ms exceeded.")


def test_a_timeout_on_a_starved_machine_is_skipped_as_starved(monkeypatch: pytest.MonkeyPatch) -> None:
    _load(monkeypatch, guard.STARVED_LOAD_PER_CORE + 0.5)
    with pytest.raises(pytest.skip.Exception, match=r"^starved: timed out waiting for the answer; load"):
        guard.timed_out("the answer", "; not in the skip reason")
    with (
        pytest.raises(pytest.skip.Exception, match=r"^starved: .*the page \(Timeout 30000ms exceeded\.\)"),
        guard.starved_timeouts(TimeoutError, what="the page"),
    ):
        raise TimeoutError("Timeout 30000ms exceeded.\nCall log: ...")
    with pytest.raises(ValueError), guard.starved_timeouts(TimeoutError, what="the page"):
        raise ValueError("not a time-out: always a failure")
