"""The twin judged by grasps (``hil.identify.twin_grasp``, ``bench/twin_grasp.py``): the three plants of a
hidden-truth row, the agreement figures, and one real grasp on each plant."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from controller.param_file import apply_param_file
from hil.experiments.common import EXPERIMENT_STEP_S
from hil.identify.synthetic import draw_truth
from hil.identify.twin_grasp import (
    PLANTS,
    Verdict,
    agreement,
    nudged_truth,
    placements,
    rate_errors,
    twin_models,
)
from hil.sim.presets import PRESETS
from hil.sim.types import PhysicsExtremes
from hil.sim.uncertain import ID_PARAMS, nominal
from hil.trial.grasp import GraspOutcome, GraspSetup, grasp_firmware, grasp_trial

ROOT = Path(__file__).resolve().parents[3]


def _row(
    seed: int, values: dict[str, float], known: tuple[str, ...] = ("torque_scale",)
) -> dict[str, object]:
    """A hidden-truth row as bench/identify.py writes it, with ``values`` as the fitted ones."""
    params = [
        {"name": p.name, "value": values[p.name], "interval": [0.0, 1.0], "identifiable": True}
        for p in ID_PARAMS
        if p.name not in known
    ]
    return {"kind": "truth", "seed": seed, "known": {k: values[k] for k in known}, "params": params}


def test_a_twin_fitted_exactly_is_the_truth_and_an_unfitted_one_the_preset(tmp_path: Path) -> None:
    base = PRESETS["prototype"].model
    truth_values = draw_truth(np.random.default_rng(7), base)
    truth, twin, preset = twin_models(_row(7, truth_values), tmp_path)
    assert twin == truth  # through the model file and back, to the last digit
    assert preset == base.with_physics(EXPERIMENT_STEP_S)
    assert truth != preset
    assert truth.solver.timestep_s == EXPERIMENT_STEP_S
    assert (tmp_path / "twin-7.toml").is_file()  # the file --preset would read
    _, unfitted, _ = twin_models(_row(7, nominal(base)), tmp_path)
    assert unfitted == preset


def test_the_nudged_truth_moves_every_parameter_by_a_tenth_of_a_percent() -> None:
    base = PRESETS["prototype"].model
    row = _row(5, draw_truth(np.random.default_rng(5), base))
    truth = nominal(twin_models(row)[0])
    nudged = nominal(nudged_truth(row))
    ratios = [nudged[k] / truth[k] for k in truth if truth[k] != 0.0]
    assert len(ratios) == len(truth)
    assert all(abs(abs(r - 1.0) - 1e-3) < 1e-9 for r in ratios)
    assert {r > 1.0 for r in ratios} == {True, False}  # both signs
    assert nominal(nudged_truth(row)) == nudged  # seeded by the draw
    # A draw clipped to the model's bound is nudged inward, whatever its sign: every seed of 0-39 whose
    # stiffness exponent the draw clipped to 4 (the first of them failed the benchmark before).
    clipped = [
        s for s in range(40) if draw_truth(np.random.default_rng(s), base)["stiffness_exponent"] == 4.0
    ]
    assert clipped
    for s in clipped:
        p = nominal(nudged_truth(_row(s, draw_truth(np.random.default_rng(s), base))))["stiffness_exponent"]
        assert p == pytest.approx(4.0 * (1 - 1e-3))


def test_a_row_that_is_not_a_hidden_truth_is_refused() -> None:
    with pytest.raises(ValueError, match="not a hidden-truth row"):
        twin_models({"kind": "mismatch", "name": "capsules"})


def _outcome(success: bool, wrap_deg: float, state: str = "HOLD", pen_m: float = 1e-4) -> Verdict:
    ext = PhysicsExtremes(pen_m, 0.0, 0.0, 0.0)
    setup = GraspSetup(0.04, -0.12, 0.02)
    outcome = GraspOutcome(setup, state, 1.0, math.nan, 3, 3, wrap_deg, 0.0, 0.0, success, success, 0, ext)
    verdict = Verdict.of(outcome)
    assert Verdict.from_record(json.loads(json.dumps(outcome.as_dict(), default=str))) == verdict
    return verdict


def test_agreement_counts_the_pairs_where_one_plant_matches_the_truth() -> None:
    t, f = _outcome(True, 200.0), _outcome(False, 100.0)
    trials = [
        {"truth": t, "twin": t, "preset": f},  # only the twin agrees
        {"truth": t, "twin": t, "preset": f},
        {"truth": f, "twin": f, "preset": f},  # both agree
        {"truth": f, "twin": t, "preset": f},  # only the preset agrees
    ]
    s = agreement(trials)
    assert (s.n, s.twin_agrees, s.preset_agrees, s.only_twin, s.only_preset) == (4, 3, 2, 2, 1)
    assert s.success == {"truth": 2, "twin": 3, "preset": 0}
    assert s.p_value == pytest.approx(1.0)
    assert not s.goal_met  # 75 % < 90 %, and p = 1
    assert s.wrap_error_deg["twin"][0] == pytest.approx(25.0)  # |200-200|, 0, 0, |100-200| over 4
    assert s.wrap_error_deg["preset"][0] == pytest.approx(50.0)
    assert s.nudged_agrees is None  # no nudged grasps
    many = [{"truth": t, "twin": t, "preset": f}] * 10
    assert agreement(many).goal_met  # 10/10 and 10 only-twin: p = 0.002
    nudged = agreement([{**x, "nudged": f} for x in trials])
    assert nudged.nudged_agrees == 2  # the nudged truth failed: it agrees where the truth failed


def test_rate_errors_are_per_draw_success_rates_against_the_truth_s() -> None:
    t, f = _outcome(True, 200.0), _outcome(False, 100.0)
    draw_a = [{"truth": t, "twin": f, "preset": f}, {"truth": f, "twin": t, "preset": f}]  # rates equal
    draw_b = [{"truth": t, "twin": t, "preset": f}, {"truth": t, "twin": f, "preset": f}]  # twin 1/2 off
    errs = rate_errors([draw_a, draw_b])
    assert set(errs) == {"twin", "preset"}  # no nudged grasps
    assert errs["twin"][0] == pytest.approx(0.25) and errs["twin"][3] == 2
    assert errs["preset"][0] == pytest.approx(0.75)  # 1/2 off, then 2/2 off


def test_placements_are_seeded_and_in_the_prototype_s_reach() -> None:
    a, b = placements(6, 3), placements(6, 3)
    assert a == b and a != placements(6, 4)
    for p in a:
        assert 0.020 <= p.x_m <= 0.070 and -0.180 <= p.z_m <= -0.080 and 0.015 <= p.diameter_m <= 0.040


def test_the_benchmark_grasps_a_twin_fitted_exactly_like_its_truth(tmp_path: Path) -> None:
    """End to end on real MuJoCo: a row whose fitted values are its truth's gives the truth's verdicts on
    every placement (the twin and the truth are one plant); the preset's may differ."""
    fits = tmp_path / "fits.jsonl"
    row = _row(3, draw_truth(np.random.default_rng(3), PRESETS["prototype"].model))
    fits.write_text(json.dumps(row) + "\n", encoding="utf-8")
    out = tmp_path / "grasps.jsonl"
    cmd = [sys.executable, str(ROOT / "bench" / "twin_grasp.py"), "--fits", str(fits), "--placements", "1"]
    run = subprocess.run([*cmd, "--out", str(out)], capture_output=True, text=True, timeout=300, cwd=ROOT)
    assert run.returncode == 0, run.stderr
    assert "agrees with the truth: twin 1/1 = 100%" in run.stdout
    assert "the truth nudged by 0.1% agrees" in run.stdout
    again = subprocess.run(
        [*cmd, "--out", str(out), "--summary-only"], capture_output=True, text=True, timeout=60
    )
    assert again.returncode == 0, again.stderr
    assert again.stdout.strip() == run.stdout[run.stdout.index("pooled") :].strip()  # the stored figures
    recs = [json.loads(x) for x in out.read_text(encoding="utf-8").splitlines()]
    assert len(recs) == 1
    for r in recs:
        assert {*PLANTS, "nudged"} <= set(r)
        assert r["twin"]["success"] == r["truth"]["success"]
        assert r["twin"]["wrap_deg"] == r["truth"]["wrap_deg"]
    # The preset column is the preset's own grasp, with the shipped controller.
    spot = placements(1, 0)[0]
    fw = apply_param_file(ROOT / "examples" / "params_prototype_tuned.toml", grasp_firmware())
    setup = GraspSetup(
        spot.x_m, spot.z_m, spot.diameter_m, fw.grasp.strategy_on, firmware=fw, model=twin_models(row)[2]
    )
    direct = grasp_trial(setup)
    assert (recs[0]["preset"]["success"], recs[0]["preset"]["wrap_deg"]) == (direct.success, direct.wrap_deg)


def test_the_benchmark_resumes_without_running_a_whole_draw_again(tmp_path: Path) -> None:
    """--resume keeps the draws --out holds whole and drops a draw cut short (and a cut line): a stored
    record that it ran again would be replaced, so a sentinel in the kept draw's record proves it did not."""
    base = PRESETS["prototype"].model
    rows = [_row(s, draw_truth(np.random.default_rng(s), base)) for s in (3, 4)]
    fits = tmp_path / "fits.jsonl"
    fits.write_text("".join(json.dumps(r) + "\n" for r in rows), encoding="utf-8")
    out = tmp_path / "grasps.jsonl"
    kept: dict[str, object] = {"seed": 3, "placement": 0, "sentinel": True}
    for k in (*PLANTS, "nudged"):
        kept[k] = {"success": True, "state": "HOLD", "wrap_deg": 200.0, "extremes": {"penetration_m": 0.0}}
    cut = {**kept, "seed": 4}
    out.write_text(json.dumps(kept) + "\n" + json.dumps(cut)[:40], encoding="utf-8")
    cmd = [sys.executable, str(ROOT / "bench" / "twin_grasp.py"), "--fits", str(fits), "--placements", "1"]
    run = subprocess.run([*cmd, "--out", str(out), "--resume"], capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr
    assert "resumed: 1 draws already in" in run.stdout
    recs = [json.loads(x) for x in out.read_text(encoding="utf-8").splitlines()]
    assert [(r["seed"], r.get("sentinel", False)) for r in recs] == [(3, True), (4, False)]
    assert "draw  3" not in run.stdout and "draw  4" in run.stdout


def test_the_benchmark_says_what_is_wrong_with_its_input(tmp_path: Path) -> None:
    empty = tmp_path / "empty.jsonl"
    empty.write_text(json.dumps({"kind": "fit_time"}) + "\n", encoding="utf-8")
    cmd = [sys.executable, str(ROOT / "bench" / "twin_grasp.py"), "--fits"]
    for path, says in ((empty, "no hidden-truth rows"), (tmp_path / "missing.jsonl", "No such file")):
        run = subprocess.run([*cmd, str(path)], capture_output=True, text=True, timeout=60, cwd=ROOT)
        assert run.returncode == 2 and says in run.stderr and "Traceback" not in run.stderr
