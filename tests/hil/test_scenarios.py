"""Every scenario passes on the emulated firmware, its checks can fail, and runs are deterministic."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest

from controller.config import FirmwareConfig
from hil import scenarios
from hil.faults import Fault, FaultKind
from hil.scenarios import SCENARIOS, Check, run_scenario
from hil.scenarios.rc_loss import RcLoss


@pytest.mark.parametrize("name", sorted(SCENARIOS))
def test_scenario_passes(name: str) -> None:
    result = run_scenario(name, seed=1)
    failed = [c for c in result.checks if not c.passed]
    assert result.checks and not failed, failed
    assert result.as_dict()["passed"] is True
    # every lockstep run reports the plant's extremes beside its checks
    assert result.extremes is not None
    assert result.as_dict()["extremes"] == result.extremes.as_dict()


def test_a_slower_rc_timeout_fails_rc_loss(monkeypatch: pytest.MonkeyPatch) -> None:
    # The same scenario against a firmware that waits 60 ms before declaring RC lost must fail.
    class SlowRcLoss(RcLoss):
        def plan(self) -> scenarios.Plan:
            return dataclasses.replace(
                super().plan(), firmware=FirmwareConfig().replaced(rc_timeout_us=60_000)
            )

    monkeypatch.setitem(scenarios.SCENARIOS, "rc-loss", SlowRcLoss)
    result = run_scenario("rc-loss")
    assert not result.passed
    bad = {c.name for c in result.checks if not c.passed}
    assert "zero current after the last valid frame" in bad


def test_extra_faults_reach_the_run() -> None:
    # Killing the radio for good at 0.5 s: the arm never gets current after that.
    result = run_scenario("startup-gate", faults=[Fault(FaultKind.RC_SILENCE, 0)])
    assert not result.passed
    assert result.counters["injected_rc_silent_frames"] > 0


def test_check_operators() -> None:
    assert Check("a", 1, 1, "<=").passed and not Check("a", 2, 1, "<=").passed
    assert Check("a", 2, 1, ">=").passed and not Check("a", float("nan"), 1, ">=").passed
    assert Check("a", 0, 0, "==").passed


def test_unknown_scenario() -> None:
    with pytest.raises(KeyError):
        run_scenario("no-such-scenario")


def test_same_seed_gives_byte_identical_recordings(tmp_path: Path) -> None:
    a, b = tmp_path / "a.mcap", tmp_path / "b.mcap"
    run_scenario("link-noise", seed=7, record=a)
    run_scenario("link-noise", seed=7, record=b)
    assert a.read_bytes() == b.read_bytes()
    c = tmp_path / "c.mcap"
    run_scenario("link-noise", seed=8, record=c)
    assert c.read_bytes() != a.read_bytes()
