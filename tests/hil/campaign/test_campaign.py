"""Campaigns (hil.campaign.spec, hil.campaign.runner, hil.campaign.summary, ``spirob-hil campaign``):
expansion,
one-line errors, the streamed results file, resume after Ctrl-C, a worker that dies, the summary, and
(marked ``ray``) the same rows on a Ray cluster the test starts on 127.0.0.1 as on local processes."""

from __future__ import annotations

import functools
import json
import os
import secrets
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from hil.campaign import runner
from hil.campaign.provenance import UNKNOWN, code_id, row_stamp, source_digest
from hil.campaign.runner import ResultsFile, execute_local, grasp_setup, run_one, stable_row
from hil.campaign.spec import Campaign, CampaignError, Run, build_design, load_campaign, parse_campaign
from hil.campaign.summary import design_rates, success_maps
from hil.cli.main import main
from hil.render import NO_GL
from hil.sim.config import ModelConfig
from hil.sim.spiral import SpiralDesign

ROOT = Path(__file__).resolve().parents[3]
PYTHON = sys.executable

SCENARIO_CAMPAIGN = """
kind = "scenario"
seeds = 3
[scenario]
name = ["startup-gate", "overcurrent"]
"""
"""Six runs of 1.5 simulated seconds each."""
SCENARIO_ARGS = ["campaign", "--set", "kind=scenario", "--set", "scenario.name=rc-loss", "-o", "x.jsonl"]


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def rows_of(path: Path) -> list[dict[str, Any]]:
    return [json.loads(line) for line in path.read_text().splitlines()]


def write(tmp_path: Path, name: str, text: str) -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


# ---------------------------------------------------------------------- expansion


def test_a_grid_runs_every_combination_once_with_stable_keys() -> None:
    raw = {
        "kind": "grasp",
        "seeds": [4, 7],
        "design": {"cable_mu": [0.2, 0.4], "arm_friction": {"min": 0.5, "max": 0.9, "n": 3}},
        "object": {"diameter_m": 0.02, "x_m": [0.03, 0.05], "z_m": -0.11},
        "controller": {"strategy_on": True, "grasp_wrap_n": [10.0, 14.0]},
    }
    runs = parse_campaign(raw).runs()
    assert len(runs) == 2 * 3 * 2 * 2 * 2
    assert len({r.key for r in runs}) == len(runs)
    assert {r.inputs["design.arm_friction"] for r in runs} == {0.5, 0.7, 0.9}
    assert {r.inputs["seed"] for r in runs} == {4, 7}
    assert [r.key for r in parse_campaign(raw).runs()] == [r.key for r in runs]

    def key(mu: float) -> Campaign:
        return parse_campaign(
            {"kind": "scenario", "scenario": {"name": "rc-loss"}, "design": {"cable_mu": mu}}
        )

    assert key(1).runs()[0].key == key(1.0).runs()[0].key  # 1 and 1.0 are one run


def test_a_random_sample_is_drawn_from_its_seed_within_its_ranges() -> None:
    raw = {
        "kind": "grasp",
        "sampling": "random",
        "samples": 20,
        "seed": 3,
        "object": {"diameter_m": [0.016, 0.024], "x_m": {"min": 0.02, "max": 0.08}, "z_m": -0.1},
        "design": {"cables": {"min": 2, "max": 3}},
    }
    runs = parse_campaign(raw).runs()
    assert len(runs) == 20
    assert all(0.02 <= r.inputs["object.x_m"] <= 0.08 for r in runs)
    assert {r.inputs["object.diameter_m"] for r in runs} == {0.016, 0.024}
    assert {r.inputs["design.cables"] for r in runs} == {2, 3}
    assert [r.key for r in parse_campaign(raw).runs()] == [r.key for r in runs]
    other = parse_campaign({**raw, "seed": 4}).runs()
    assert [r.key for r in other] != [r.key for r in runs]


def test_overrides_change_the_file(tmp_path: Path) -> None:
    path = write(tmp_path, "c.toml", SCENARIO_CAMPAIGN)
    c = load_campaign(
        path, ["seeds=[5]", "scenario.name=rc-loss", "scenario.faults=[[], ['motor-silence@1']]"]
    )
    assert [(r.inputs["scenario.name"], r.inputs["seed"]) for r in c.runs()] == [("rc-loss", 5)] * 2
    assert [r.inputs["scenario.faults"] for r in c.runs()] == [[], ["motor-silence@1"]]


_DEEP = "nested deeper than 16 levels"


def _nested(n: int) -> str:
    return "[" * n + "]" * n


MALFORMED = [
    ("bad.toml", 'kind = "scenario"\n[scenario\nname = "x"\n', "not valid TOML"),
    ("bad.json", '{"kind": "scenario",', "not valid JSON"),
    ("list.json", "[1, 2]", "a campaign is a table"),
    ("c.toml", 'kind = "scenario"\ncolour = 1\n[scenario]\nname = "rc-loss"\n', "unknown key 'colour'"),
    ("c.toml", "[scenario]\nname = 'rc-loss'\n", "kind must be one of"),
    ("c.toml", 'kind = "scenario"\n[scenario]\nname = "warp-drive"\n', "unknown scenario 'warp-drive'"),
    ("c.toml", 'kind = "scenario"\nseeds = -1\n[scenario]\nname = "rc-loss"\n', "seeds"),
    (
        "c.toml",
        'kind = "scenario"\n[scenario]\nname = "rc-loss"\nfaults = [["rc-loss@x"]]\n',
        "scenario.faults",
    ),
    (
        "c.toml",
        'kind = "grasp"\n[object]\ndiameter_m = 0.02\nx_m = {min = 0.02, max = 0.08}\nz_m = -0.1\n',
        "object.x_m: a range in a grid needs n",
    ),
    (
        "c.toml",
        'kind = "grasp"\n[object]\ndiameter_m = "big"\nx_m = 0.04\nz_m = -0.1\n',
        "object.diameter_m: want a finite number",
    ),
    (
        "c.toml",
        'kind = "grasp"\n[design]\nlength_m = 0.2\ntip_width_m = 0.008\ntaper_deg = 95\n'
        "[object]\ndiameter_m = 0.02\nx_m = 0.04\nz_m = -0.1\n",
        "taper angle must be in (0, 90) degrees",
    ),
    ("c.toml", 'kind = "grasp"\n[object]\nx_m = 0.04\nz_m = -0.1\n', "needs object.diameter_m"),
    (
        "c.toml",
        'kind = "grasp"\n[controller]\ngrasp_warp = 1\n[object]\ndiameter_m = 0.02\nx_m = 0.04\nz_m = -0.1\n',
        "controller.grasp_warp: not a scalar firmware configuration key",
    ),
    (
        "c.toml",
        'kind = "scenario"\n[object]\ndiameter_m = 0.02\n[scenario]\nname = "rc-loss"\n',
        "object.diameter_m: not a key of a scenario campaign",
    ),
    # limits: deep nesting used to end in a RecursionError traceback (exit 1)
    ("deep.json", '{"kind": "scenario", "seeds": ' + _nested(100_000) + "}", _DEEP),
    ("deep.toml", 'kind = "scenario"\nseeds = ' + _nested(100_000) + "\n", _DEEP),
    ("deep17.json", '{"kind": "scenario", "seeds": ' + _nested(16) + "}", _DEEP),
    (
        "big.toml",
        'kind = "scenario"\n' + "# padding\n" * 110_000,
        "larger than the 1 MiB a campaign file may",
    ),
]


@pytest.mark.parametrize(("name", "text", "message"), MALFORMED)
def test_a_malformed_campaign_is_one_clear_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], name: str, text: str, message: str
) -> None:
    path = write(tmp_path, name, text)
    out = tmp_path / "out.jsonl"
    status = main(["campaign", str(path), "-o", str(out)])
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert status == 2
    assert len(lines) == 1, captured.err
    assert lines[0].startswith("spirob-hil") and "error:" in lines[0] and message in lines[0], lines[0]
    assert not out.exists() or out.stat().st_size == 0  # no run started


def test_nesting_within_the_limit_reaches_the_checks(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """15 levels under the file's table: parsed, then refused by the campaign's own checks (not its depth)."""
    path = write(tmp_path, "c.json", '{"kind": "scenario", "seeds": ' + "[" * 15 + "]" * 15 + "}")
    assert main(["campaign", str(path), "-o", str(tmp_path / "o.jsonl")]) == 2
    line = capsys.readouterr().err.strip()
    assert "seeds" in line and "nested deeper" not in line, line


def test_an_unwritable_output_fails_before_the_first_run(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """``-o /dev/full`` opens fine and fails on its first write, which came after the first trial."""
    import hil.cli.campaign as campaign_cli

    def no_runs(*_args: object, **_kwargs: object) -> Iterator[dict[str, Any]]:
        raise AssertionError("a run started before the output was checked")

    monkeypatch.setattr(campaign_cli, "execute_local", no_runs)
    path = write(tmp_path, "c.toml", SCENARIO_CAMPAIGN)
    assert main(["campaign", str(path), "-o", "/dev/full"]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and "cannot write /dev/full: No space left on device" in lines[0], lines


def test_the_write_probe_leaves_the_results_file_as_it_was(tmp_path: Path) -> None:
    path = tmp_path / "r.jsonl"
    row = {"key": "a", "inputs": {}, "made_by": row_stamp({})}
    with ResultsFile(path, resume=False) as f:
        f.append(row)
    with ResultsFile(path, resume=True) as f:
        assert list(f.done) == ["a"] and f.unreadable_n == 0
    assert json.loads(path.read_text()) == row and path.read_text().count("\n") == 1


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["campaign"], "give a campaign FILE"),
        (["campaign", "missing.toml"], "no such campaign file"),
        (["campaign", "--set", "kind=scenario"], "name the results file with --out"),
        (["campaign", "--set", "kind", "-o", "x.jsonl"], "--set wants KEY=VALUE"),
        (["campaign", "--set", "kind=scenario", "-o", "x.jsonl", "--jobs", "0"], "--jobs must be"),
        (
            [*SCENARIO_ARGS, "--ray-address", "127.0.0.1"],
            "--ray-address wants HOST:PORT",
        ),
        (
            [*SCENARIO_ARGS, "--ray-address", f"127.0.0.1:{_free_port()}"],
            "cannot reach Ray at 127.0.0.1:",
        ),
    ],
)
def test_bad_command_lines_are_one_line(
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
    argv: list[str],
    message: str,
) -> None:
    monkeypatch.chdir(tmp_path)
    assert main(argv) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and message in lines[0], lines


def test_without_ray_a_ray_campaign_is_one_line_and_a_local_one_never_imports_it(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setitem(sys.modules, "ray", None)  # as if not installed
    path = write(tmp_path, "c.toml", SCENARIO_CAMPAIGN)
    for flags in (["--ray"], ["--ray-address", "127.0.0.1:1"]):
        assert main(["campaign", str(path), "-o", str(tmp_path / "o.jsonl"), *flags]) == 2
        lines = capsys.readouterr().err.strip().splitlines()
        assert len(lines) == 1 and "need Ray: pip install 'spirob-teleop[ray]'" in lines[0], lines
    code = (
        "import sys; from hil.cli.main import main; "
        f"s = main(['campaign', {str(path)!r}, '-o', {str(tmp_path / 'l.jsonl')!r}, '--set', "
        "'seeds=1', '--set', 'scenario.name=startup-gate', '--jobs', '1', '--json']); "
        "assert 'ray' not in sys.modules, 'ray imported'; sys.exit(s)"
    )
    done = subprocess.run([PYTHON, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert json.loads(done.stdout)["designs"][0]["successes"] == 1


# ---------------------------------------------------------------------- the results file and resume


def test_a_torn_last_line_is_cut_and_bad_lines_are_counted(tmp_path: Path) -> None:
    path = tmp_path / "r.jsonl"
    good = {"key": "a" * 16, "inputs": {}, "outcome": "success", "measured": {}, "run_time_s": 1.0}
    good["made_by"] = row_stamp({})
    path.write_bytes(json.dumps(good).encode() + b"\n\x00garbage\n" + b'{"key": "bbbb", "inp')
    with pytest.raises(CampaignError, match="--resume"):
        ResultsFile(path, resume=False)
    with ResultsFile(path, resume=True) as f:
        assert list(f.done) == ["a" * 16]
        assert f.unreadable_n == 2
        f.append({**good, "key": "c" * 16})
    keys = [json.loads(line)["key"] for line in path.read_bytes().splitlines() if line.startswith(b"{")]
    assert keys == ["a" * 16, "c" * 16]


def test_a_rows_stamp_ignores_comments_docstrings_and_layout_but_not_code() -> None:
    base = source_digest('"""Module."""\n\ndef f(x):\n    """Doc."""\n    return x + 1\n')
    assert source_digest("# a comment\ndef f( x ):\n    return x+1  # more\n") == base
    assert source_digest("def f(x):\n    return x + 2\n") != base
    assert len(code_id()) == 16 and code_id() == code_id()
    assert row_stamp({}, code="a") != row_stamp({}, code="b")
    assert row_stamp({}, code=UNKNOWN) == UNKNOWN  # code it cannot read stamps rows no resume takes


def test_rows_made_by_other_code_or_another_model_file_are_stale(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    model = tmp_path / "arm.toml"
    model.write_text("one")
    inputs = {"design.preset": str(model), "seed": 0}
    row = {"key": "k" * 16, "inputs": inputs, "outcome": "success", "made_by": row_stamp(inputs)}
    old = {**row, "key": "o" * 16, "made_by": row_stamp(inputs, code="0" * 16)}
    unstamped = {k: v for k, v in row.items() if k != "made_by"} | {"key": "u" * 16}
    path = tmp_path / "r.jsonl"
    path.write_text("".join(json.dumps(r) + "\n" for r in (row, old, unstamped)))
    with ResultsFile(path, resume=True) as f:
        assert list(f.done) == ["k" * 16] and sorted(f.stale) == ["o" * 16, "u" * 16]
        f.append({**old, "made_by": row_stamp(inputs)})  # run again: its last row counts
        assert sorted(f.done) == ["k" * 16, "o" * 16] and list(f.stale) == ["u" * 16]
    with ResultsFile(path, resume=True) as f:
        assert sorted(f.done) == ["k" * 16, "o" * 16] and list(f.stale) == ["u" * 16]
    model.write_text("two")  # the same name, another fitted model
    with ResultsFile(path, resume=True) as f:
        assert not f.done and len(f.stale) == 3
    monkeypatch.setattr(runner, "row_stamp", lambda _inputs: UNKNOWN)
    (tmp_path / "r2.jsonl").write_text(json.dumps({**row, "made_by": UNKNOWN}) + "\n")
    with ResultsFile(tmp_path / "r2.jsonl", resume=True) as f:
        assert not f.done and len(f.stale) == 1


def test_resume_refuses_rows_of_other_code_until_told_to_run_them_again(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.chdir(tmp_path)
    argv = ["campaign", "--set", "kind=scenario", "--set", "scenario.name=startup-gate", "--set", "seeds=2"]
    argv += ["-o", "s.jsonl", "--jobs", "1", "--json"]
    assert main(argv) == 0
    first = rows_of(tmp_path / "s.jsonl")
    assert len(first) == 2 and all(r["made_by"] == row_stamp(r["inputs"]) for r in first)
    first[1]["made_by"] = "0" * 16  # as if made before the plant changed
    (tmp_path / "s.jsonl").write_text("".join(json.dumps(r) + "\n" for r in first))
    capsys.readouterr()
    assert main([*argv, "--resume"]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and "1 of this campaign's rows were made by other code" in lines[0], lines
    assert "--rerun-stale" in lines[0]
    assert main([*argv, "--resume", "--rerun-stale"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["skipped_n"] == 1 and summary["ran_n"] == 1
    rows = rows_of(tmp_path / "s.jsonl")
    assert len(rows) == 3 and rows[2]["key"] == first[1]["key"]
    assert stable_row(rows[2]) | {"made_by": ""} == stable_row(first[1]) | {"made_by": ""}
    assert main([*argv, "--rerun-stale"]) == 2
    assert "--rerun-stale goes with --resume" in capsys.readouterr().err


def _wait_for_rows(path: Path, n: int, proc: subprocess.Popen[str], timeout_s: float) -> None:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline and proc.poll() is None:
        if path.exists() and path.read_bytes().count(b"\n") >= n:
            return
        time.sleep(0.05)
    raise AssertionError(f"{path} did not reach {n} rows (exit {proc.poll()})")


def test_ctrl_c_keeps_the_file_and_resume_runs_only_what_is_missing(tmp_path: Path) -> None:
    path = write(tmp_path, "c.toml", SCENARIO_CAMPAIGN)
    out = tmp_path / "c.jsonl"
    argv = [PYTHON, "-m", "hil.cli.main", "campaign", str(path), "-o", str(out), "--jobs", "1"]
    proc = subprocess.Popen(argv, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        _wait_for_rows(out, 2, proc, timeout_s=90)
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert proc.returncode == 130, err
    assert "interrupted" in err and "--resume" in err
    first = rows_of(out)
    assert 2 <= len(first) < 6
    with out.open("ab") as f:  # as if killed in the middle of a row
        f.write(b'{"key": "0123456789abcdef", "inputs": {"ki')
    again = subprocess.run(
        [*argv, "--resume", "--json"], cwd=ROOT, capture_output=True, text=True, timeout=120
    )
    assert again.returncode == 0, again.stderr
    summary = json.loads(again.stdout)
    assert summary["skipped_n"] == len(first) and summary["ran_n"] == 6 - len(first)
    rows = rows_of(out)
    assert rows[: len(first)] == first  # the finished runs are kept, not repeated
    assert len({r["key"] for r in rows}) == len(rows) == 6
    assert summary["designs"][0]["n"] == 6


def _dying_run(marker_dir: Path, always: bool, run: Run) -> dict[str, Any]:
    """A run whose worker dies (the first time, or always) for seed 1; a row for the others, which take
    long enough to be in flight when the pool breaks."""
    marker = marker_dir / run.key
    if run.inputs["seed"] == 1 and (always or not marker.exists()):
        marker.touch()
        os._exit(1)
    time.sleep(0.3)
    return {"key": run.key, "inputs": dict(run.inputs), "outcome": "success", "measured": {}, "run_time_s": 0}


def test_a_worker_that_dies_costs_that_run_only(tmp_path: Path) -> None:
    runs = parse_campaign({"kind": "scenario", "seeds": 4, "scenario": {"name": "rc-loss"}}).runs()
    once = functools.partial(_dying_run, tmp_path, False)
    rows = list(execute_local(runs, 2, threading.Event(), fn=once, max_retries=2))
    assert sorted(r["key"] for r in rows) == sorted(r.key for r in runs)
    assert all(r["outcome"] == "success" for r in rows)
    always = functools.partial(_dying_run, tmp_path, True)
    rows = list(execute_local(runs, 2, threading.Event(), fn=always, max_retries=1))
    assert sorted(r["key"] for r in rows) == sorted(r.key for r in runs)
    lost = [r for r in rows if r["outcome"] == "error"]
    assert [r["inputs"]["seed"] for r in lost] == [1] and lost[0]["error"] == "worker lost 2 times"


# ---------------------------------------------------------------------- the summary


def _row(choice: dict[str, Any], x: float, ok: bool) -> dict[str, Any]:
    inputs = {"kind": "grasp", **choice, "object.x_m": x, "object.z_m": -0.1, "seed": 0}
    return {
        "key": str(hash((str(choice), x, ok))),
        "inputs": inputs,
        "outcome": "success" if ok else "failure",
    }


def test_designs_rank_by_their_interval_and_each_gets_a_map(tmp_path: Path) -> None:
    few = [_row({"design.cable_mu": 0.2}, 0.03, True)]  # 1/1: a rate of 1, on one run
    many = [_row({"design.cable_mu": 0.4}, x, x < 0.07) for x in (0.03, 0.04, 0.05, 0.06, 0.07)] * 4
    bad = [_row({"design.cable_mu": 0.6}, 0.03, False)] * 3
    ranked = design_rates(few + many + bad)
    assert [d.label for d in ranked] == ["cable_mu=0.4", "cable_mu=0.2", "cable_mu=0.6"]
    assert (ranked[0].successes, ranked[0].n) == (16, 20)
    lo, hi = ranked[0].ci95
    assert 0.58 < lo < 0.8 < hi < 0.93
    maps = success_maps(few + many + bad, tmp_path)
    assert [p.name for p in maps] == ["map_01.png", "map_02.png", "map_03.png"]
    assert all(p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" for p in maps)


def test_a_grasp_campaign_end_to_end(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = write(
        tmp_path,
        "g.json",
        # the machinery end to end, on the board's physics, where the grasp scenario's placement succeeds
        # (at the fine physics the firmware's grasp of it holds but wraps it less than half way)
        json.dumps(
            {
                "kind": "grasp",
                "design": {"physics": "board"},
                "object": {"diameter_m": 0.02, "x_m": [0.04, 0.3], "z_m": -0.11},
            }
        ),
    )
    out = tmp_path / "g.jsonl"
    status = main(["campaign", str(path), "-o", str(out), "--report", str(tmp_path / "maps"), "--json"])
    summary = json.loads(capsys.readouterr().out)
    assert status == 0
    rows = {r["inputs"]["object.x_m"]: r for r in rows_of(out)}
    assert rows[0.04]["outcome"] == "success" and rows[0.04]["measured"]["state"] == "HOLD"
    assert rows[0.3]["outcome"] == "failure"  # 30 cm out: beyond the arm's reach
    assert (summary["designs"][0]["successes"], summary["designs"][0]["n"]) == (1, 2)
    assert summary["maps"] == [str(tmp_path / "maps" / "map_01.png")]
    # the report pictures the success and the failure, each re-run filmed and matching its row
    index = (tmp_path / "maps" / "campaign.md").read_text()
    assert summary["report"] == str(tmp_path / "maps" / "campaign.md") and "](map_01.png)" in index
    assert "### a success: " in index and "### a failure: " in index and "re-run differs" not in index
    if NO_GL not in index:
        names = [Path(p).name for p in summary["pictures"]]
        assert "run-success.gif" in names and "run-failure-01-start.png" in names
        assert any("grasp-hold" in n and n.startswith("run-success") for n in names)
        assert all(f"]({n})" in index for n in names)


# ---------------------------------------------------------------------- Ray


@pytest.fixture
def ray_head(tmp_path: Path) -> Iterator[tuple[str, dict[str, str]]]:
    """A one-CPU Ray head on 127.0.0.1 started by the test (its own token, no dashboard, no usage
    stats) and stopped by it: its process group, by id, so no other Ray on the machine is touched."""
    ray = shutil.which("ray", path=str(Path(PYTHON).parent))
    assert ray is not None, "the ray command is missing: install the test extra (pip install -e '.[test]')"
    port = _free_port()
    temp_dir = tempfile.mkdtemp(prefix="ray", dir="/tmp")  # Ray's socket paths must stay under 108 bytes
    env = dict(
        os.environ,
        RAY_USAGE_STATS_ENABLED="0",
        RAY_AUTH_MODE="token",
        RAY_AUTH_TOKEN=secrets.token_hex(16),
    )
    argv = [
        ray, "start", "--head", "--block", "--node-ip-address", "127.0.0.1", "--port", str(port),
        "--num-cpus", "1", "--include-dashboard", "false", "--disable-usage-stats",
        "--ray-client-server-port", str(_free_port()), "--dashboard-agent-listen-port", str(_free_port()),
        "--temp-dir", temp_dir,
    ]  # fmt: skip
    log = (tmp_path / "head.log").open("w")
    head = subprocess.Popen(
        argv, cwd=ROOT, env=env, stdout=log, stderr=subprocess.STDOUT, start_new_session=True
    )  # its workers import this checkout's code, as the campaign's driver does
    try:
        deadline = time.monotonic() + 90
        while "Ray runtime started" not in (tmp_path / "head.log").read_text():
            assert head.poll() is None, (tmp_path / "head.log").read_text()
            assert time.monotonic() < deadline, "the Ray head did not start in 90 s"
            time.sleep(0.2)
        yield f"127.0.0.1:{port}", env
    finally:
        for sig, wait_s in ((signal.SIGTERM, 3.0), (signal.SIGKILL, 10.0)):
            try:
                os.killpg(head.pid, sig)
            except ProcessLookupError:
                break
            try:
                head.wait(wait_s)
            except subprocess.TimeoutExpired:
                continue
        log.close()
        shutil.rmtree(temp_dir, ignore_errors=True)


@pytest.mark.ray
def test_a_ray_cluster_gives_the_rows_of_local_processes(
    tmp_path: Path, ray_head: tuple[str, dict[str, str]]
) -> None:
    address, env = ray_head
    path = write(tmp_path, "c.toml", SCENARIO_CAMPAIGN.replace("seeds = 3", "seeds = 1"))
    on_ray = tmp_path / "ray.jsonl"
    base = [PYTHON, "-m", "hil.cli.main", "campaign", str(path), "--json"]
    done = subprocess.run(
        [*base, "-o", str(on_ray), "--ray-address", address], cwd=ROOT, env=env, capture_output=True,
        text=True, timeout=180,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert json.loads(done.stdout)["ran_n"] == 2
    runs = load_campaign(path, []).runs()
    local = {r["key"]: stable_row(r) for r in execute_local(runs, 2, threading.Event())}
    assert sorted(local) == sorted(r.key for r in runs)
    assert {r["key"]: stable_row(r) for r in rows_of(on_ray)} == local


@pytest.mark.ray
def test_ray_starts_a_local_node_and_stops_it(tmp_path: Path) -> None:
    temp_dir = tempfile.mkdtemp(prefix="ray", dir="/tmp")  # Ray's socket paths must stay under 108 bytes
    env = dict(
        os.environ,
        RAY_USAGE_STATS_ENABLED="0",
        RAY_AUTH_MODE="token",
        RAY_AUTH_TOKEN=secrets.token_hex(16),
        RAY_TMPDIR=temp_dir,  # its session files, apart from any other Ray on the machine
    )
    out = tmp_path / "ray.jsonl"
    argv = [*SCENARIO_ARGS[:-1], str(out), "--set", "scenario.name=startup-gate", "--ray", "--jobs", "1"]
    try:
        done = subprocess.run(
            [PYTHON, "-m", "hil.cli.main", *argv, "--json"], cwd=ROOT, env=env, capture_output=True,
            text=True, timeout=180,
        )  # fmt: skip
        assert done.returncode == 0, done.stderr
        assert "on a local Ray of 1 CPUs" in done.stderr
        assert json.loads(done.stdout)["ran_n"] == 1
        (row,) = rows_of(out)
        (run,) = parse_campaign({"kind": "scenario", "scenario": {"name": "startup-gate"}}).runs()
        assert stable_row(row) == stable_row(run_one(run))
        raylets = subprocess.run(["pgrep", "-f", temp_dir], capture_output=True, text=True).stdout.split()
        assert raylets == [], "the local Ray node outlived its campaign"
    finally:
        shutil.rmtree(temp_dir, ignore_errors=True)


def test_physics_defaults_fine_for_grasps_board_for_scenarios_and_is_checked() -> None:
    _, fine = build_design({"design.preset": "prototype"}, physics="fine")
    assert (fine.solver.timestep_s, fine.contact.timeconst_s, fine.arm.limit_timeconst_s) == (
        0.25e-3,
        0.5e-3,
        0.5e-3,
    )
    _, board = build_design({"design.physics": "board"}, physics="fine")  # the campaign's key wins
    assert (board.solver.timestep_s, board.contact.timeconst_s) == (1e-3, 2e-3)
    with pytest.raises(CampaignError, match=r"design.physics: unknown 'nope'"):
        build_design({"design.physics": "nope"})


def test_a_sensitivity_variant_scales_its_parameter_and_a_bad_one_is_one_line() -> None:
    _, base = build_design({}, physics="fine")
    _, half = build_design({"design.variant": "spool inertia x0.5"}, physics="fine")
    assert half.motor.rotor_inertia_kg_m2 == pytest.approx(0.5 * base.motor.rotor_inertia_kg_m2)
    assert build_design({"design.variant": "baseline"}, physics="fine")[1] == base
    for bad in ("nope", "spool inertia x0", "spool inertia xhalf"):
        with pytest.raises(
            CampaignError, match=r"design\.variant: .* is not 'baseline' or 'PARAMETER xFACTOR'"
        ):
            build_design({"design.variant": bad})


def test_the_size_law_is_an_axis_and_out_of_its_range_is_one_line() -> None:
    _, base = build_design({}, physics="fine")
    _, p2 = build_design({"design.stiffness_exponent": 2.0, "design.base_stiffness_nm_per_rad": 0.25})
    assert (p2.arm.stiffness_exponent, p2.arm.base_stiffness_nm_per_rad) == (2.0, 0.25)
    assert base.arm.stiffness_exponent == 3
    with pytest.raises(CampaignError, match=r"design stiffness_exponent=5.0: .*stiffness_exponent"):
        build_design({"design.stiffness_exponent": 5.0})


def test_scale_model_scales_the_preset_to_the_run_s_arm_in_the_same_material() -> None:
    long_arm = {"design.length_m": 0.45, "design.tip_width_m": 0.010, "design.taper_deg": 10.0}
    design, as_given = build_design({**long_arm, "design.base_stiffness_nm_per_rad": 0.125})
    _, scaled = build_design(
        {**long_arm, "design.base_stiffness_nm_per_rad": 0.125, "design.scale_model": True}
    )
    assert (as_given.arm.total_mass_kg, as_given.arm.base_stiffness_nm_per_rad) == (
        ModelConfig().arm.total_mass_kg,
        0.125,
    )
    prototype = SpiralDesign.paper_prototype()
    width = design.unit_widths_m()[0][1] / prototype.unit_widths_m()[0][1]
    assert scaled.arm.base_stiffness_nm_per_rad == pytest.approx(0.125 * width**3)
    assert scaled.arm.total_mass_kg > 10 * as_given.arm.total_mass_kg  # 2.1x longer: the volume's cube
    assert scaled.solver == as_given.solver  # the physics is the run's
    # On the preset's own arm the scale is one.
    _, same = build_design({"design.scale_model": True})
    assert same == build_design({})[1]
    with pytest.raises(CampaignError, match="scale_model"):
        parse_campaign(
            {
                "kind": "grasp",
                "design": {"scale_model": "yes"},
                "object": {"diameter_m": 0.02, "x_m": 0.04, "z_m": -0.1},
            }
        )


def test_the_claims_strategy_long_example_expands_to_its_stated_runs() -> None:
    path = Path(__file__).resolve().parents[3] / "examples" / "campaign_claims_strategy_long.toml"
    runs = load_campaign(path, []).runs()
    assert len(runs) == 192  # 2 materials x 2 stiffnesses x 2 cable counts x 12 placements x 2 arms
    for r in runs[:: len(runs) // 8]:
        design, _ = build_design(r.inputs, physics="fine")
        assert design.units == 24 and design.cables == r.inputs["design.cables"]


def test_the_free_object_example_lets_its_objects_go_at_the_first_touch() -> None:
    path = Path(__file__).resolve().parents[3] / "examples" / "campaign_free_object.toml"
    runs = load_campaign(path, []).runs()
    assert len(runs) == 96  # 24 placements x 2 reach rates x 2 arms
    setups = [grasp_setup(r.inputs)[0] for r in runs]
    assert all(s.release_at_touch for s in setups)
    assert {s.firmware.grasp.reach_rate_n_per_s for s in setups if s.firmware is not None} == {10.0, 2.5}
    assert not grasp_setup({**runs[0].inputs, "object.release_at_touch": False})[0].release_at_touch


def test_the_claims_strategy_example_expands_to_its_stated_runs() -> None:
    path = Path(__file__).resolve().parents[3] / "examples" / "campaign_claims_strategy.toml"
    runs = load_campaign(path, []).runs()
    assert len(runs) == 384  # 2 mountings x 4 stiffnesses x 2 size laws x 12 placements x 2 arms
    for r in runs[:: len(runs) // 8]:
        build_design(r.inputs, physics="fine")  # every plant builds


def test_the_claims_strategy_axes_example_expands_to_its_stated_runs() -> None:
    path = Path(__file__).resolve().parents[3] / "examples" / "campaign_claims_strategy_axes.toml"
    runs = load_campaign(path, []).runs()
    assert len(runs) == 192  # 2 actuators x 2 cable counts x 2 stiffnesses x 12 placements x 2 arms
    kinds = set()
    for r in runs[:: len(runs) // 8]:
        design, model = build_design(r.inputs, physics="fine")  # every plant builds
        assert design.cables == r.inputs["design.cables"]
        kinds.add(model.actuator.kind)
    assert kinds == {"motor", "tension"}


def test_the_sensitivity_strategy_example_expands_to_its_stated_runs() -> None:
    path = Path(__file__).resolve().parents[3] / "examples" / "campaign_sensitivity_strategy.toml"
    runs = load_campaign(path, []).runs()
    assert len(runs) == 528  # 11 models x 2 arms x 12 placements x 2 seeds, as its comment says
    for run in runs[:: len(runs) // 11]:
        build_design(run.inputs, physics="fine")  # every variant builds
