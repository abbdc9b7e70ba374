"""``bench/hold.py`` end to end on the real plant (one placement at the board's 1 ms step), and its refusals
of bad input."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[3]
BENCH = [sys.executable, str(ROOT / "bench" / "hold.py")]


def test_the_rule_only_refuses_holds_and_every_grasp_is_written(tmp_path: Path) -> None:
    out = tmp_path / "hold.jsonl"
    args = ["--placements", "2", "--jobs", "1", "--strategy", "off", "--step-ms", "1", "--out", str(out)]
    run = subprocess.run([*BENCH, *args], capture_output=True, text=True, timeout=300, check=False)
    assert run.returncode == 0, run.stderr
    assert (
        "grasp in the air (ramp):" in run.stdout and "HOLDs only with the rule: 0 (must be 0)" in run.stdout
    )
    rows = [json.loads(line) for line in out.read_text(encoding="utf-8").splitlines()]
    assert len(rows) == 4 and all(not r["on"] for r in rows)
    off = [r for r in rows if not r["rules"]]
    on = [r for r in rows if r["rules"]]
    for a, b in zip(off, on, strict=True):
        assert (a["x"], a["z"], a["d"]) == (b["x"], b["z"], b["d"])
        assert a["payin_m"] == b["payin_m"]  # the same physics up to the verdict
        assert b["hold"] <= a["hold"]


def test_bad_input_is_one_line_and_exit_2(tmp_path: Path) -> None:
    for bad in (["--step-ms", "0.3"], ["--params", str(tmp_path / "none.toml")], ["--preset", "nope"]):
        run = subprocess.run([*BENCH, *bad], capture_output=True, text=True, timeout=60, check=False)
        assert run.returncode == 2 and "Traceback" not in run.stderr, bad
        assert run.stderr.strip().splitlines()[-1].startswith("hold.py: error:"), run.stderr
