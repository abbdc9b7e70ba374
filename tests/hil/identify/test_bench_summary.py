"""``bench/identify.py --summary-only`` judges stored rows by today's rules (no fit is run)."""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np

from hil.identify.synthetic import draw_truth
from hil.sim.config import ModelConfig
from hil.sim.uncertain import ID_PARAMS, nominal

ROOT = Path(__file__).resolve().parents[3]


def _row(seed: int, kept_rms_m: float, off: dict[str, float]) -> dict[str, Any]:
    """A hidden-truth row whose every parameter the fit called identified within a 3 % interval, with the
    values in ``off`` that far from their truth (a relative error)."""
    params = []
    for p in ID_PARAMS:
        if p.name == "torque_scale":
            continue
        truth = nominal(ModelConfig())[p.name] or 1e-3
        value = truth * (1.0 + off.get(p.name, 0.0))
        lo, hi = value * 0.97, value * 1.03
        params.append(
            {
                "name": p.name,
                "truth": truth,
                "value": value,
                "interval": [lo, hi],
                "naive_interval": [lo, hi],
                "identifiable": True,
                "why": "",
                "rel_error": abs(value - truth) / truth,
                "covered": lo <= truth <= hi,
                "naive_covered": lo <= truth <= hi,
            }
        )
    return {
        "kind": "truth",
        "seed": seed,
        "params": params,
        "starts": [[5.0, 10 * kept_rms_m], [1.0, kept_rms_m]],
        "fitted_rms_m": kept_rms_m,
        "held_out_rms_m": 2 * kept_rms_m,
        "held_out_rms_nominal_m": 7e-3,
        "second_recording_rms_m": 2 * kept_rms_m,
        "fit_wall_s": 100.0,
        "fit_s": 14.5,
    }


def test_a_stored_fit_that_did_not_settle_is_judged_to_identify_nothing(tmp_path: Path) -> None:
    """Two rows written by the earlier rule (a fit explained its data within 0.3 mm): one settled at the
    sensors' noise and right, one stopped at 2.1 um and called a damping 17 % off identified. Judged
    again, the second identifies nothing (its kept start, not its first, decides), the first everything
    although it stopped at its iteration cap, and the coverage is printed apart for fits that settled and
    fits that did not."""
    rows = tmp_path / "rows.jsonl"
    settled = _row(22, 0.06e-6, {})
    for x in settled["params"]:  # at its iteration cap: a fit that settled counts as converged
        x["identifiable"], x["why"] = False, "the fit had not converged after 25 iterations"
    stuck = _row(26, 2.1e-6, {"damping_ratio": 0.17})
    rows.write_text("".join(json.dumps(r) + "\n" for r in (settled, stuck)), encoding="utf-8")
    run = subprocess.run(
        [sys.executable, str(ROOT / "bench" / "identify.py"), "--summary-only", "--out", str(rows)],
        capture_output=True,
        text=True,
        timeout=120,
        cwd=ROOT,
    )
    assert run.returncode == 0, run.stderr
    out = run.stdout
    assert "draws whose every identifiable parameter is within 10 %: 2/2" in out, out
    assert "called nothing identified (met by refusing): seeds [26]" in out, out
    assert "delay                      1/2          1/1" in out, out
    assert "damping_ratio              1/2          1/1            1/2" in out, out
    assert "in the 1 draws whose fit settled (the sensors' noise: 0.62 um): 8/8 covered" in out, out
    assert "in the 1 draws whose fit did not settle (the sensors' noise: 0.62 um): 7/8 covered" in out, out
    assert "identified or not: [26]" in out, out


def _bench(*args: str) -> subprocess.CompletedProcess[str]:
    cmd = [sys.executable, str(ROOT / "bench" / "identify.py"), *args]
    return subprocess.run(cmd, capture_output=True, text=True, timeout=300, cwd=ROOT)


def test_the_line_from_a_fit_to_its_truth_ends_at_the_sensors_noise(tmp_path: Path) -> None:
    """``--line`` makes the draw's recording again and walks the fit's objective from a stored fit (here its
    truth with the damping 20 % high) to the truth: real MuJoCo, the fit's own residual. At the truth the
    objective is lowest and the cable lengths are left at the encoders' noise."""
    seed = 3
    truth = draw_truth(np.random.default_rng(seed))
    row = _row(seed, 1e-6, {})
    for x in row["params"]:
        x["truth"] = truth[x["name"]]
        x["value"] = truth[x["name"]] * (1.2 if x["name"] == "damping_ratio" else 1.0)
    row.update(known={"torque_scale": truth["torque_scale"]}, jacobian="auto", timing_noise=True, fit_s=4.0)
    rows = tmp_path / "rows.jsonl"
    rows.write_text(json.dumps(row) + "\n", encoding="utf-8")
    run = _bench("--line", "--out", str(rows), "--profile", "tiny", "--line-t", "0,1", "--jobs", "1")
    assert run.returncode == 0, run.stderr
    found = re.findall(r"t = (\S+): objective (\S+), cable lengths (\S+) um RMS", run.stdout)
    assert [t for t, _, _ in found] == ["0", "1"], run.stdout
    (_, at_fit, _), (_, at_truth, truth_um) = found
    assert float(at_truth) < 0.1 * float(at_fit), run.stdout
    assert float(truth_um) < 0.62, run.stdout
    # Only the damping moved, the others at the truth's: at t = 1 that is the truth again, to the digit.
    probe = _bench(
        "--line", "--out", str(rows), "--profile", "tiny", "--line-t", "1", "--jobs", "1",
        "--line-params", "damping_ratio", "--line-others", "truth",
    )  # fmt: skip
    assert probe.returncode == 0, probe.stderr
    assert f"t = 1: objective {at_truth}," in probe.stdout, probe.stdout
    assert "moving damping_ratio, the others at the truth's" in probe.stdout, probe.stdout
    bad = _bench("--line", "--out", str(rows), "--line-params", "no_such_param")
    assert bad.returncode == 2 and "no_such_param not fitted" in bad.stderr, bad.stderr


def test_a_negative_tracker_noise_is_one_line(tmp_path: Path) -> None:
    run = _bench("--tip-noise-mm", "-0.1", "--draws", "1", "--out", str(tmp_path / "rows.jsonl"))
    assert run.returncode == 2 and "--tip-noise-mm -0.1: a finite noise >= 0" in run.stderr, run.stderr
    assert "Traceback" not in run.stderr and not (tmp_path / "rows.jsonl").exists()
