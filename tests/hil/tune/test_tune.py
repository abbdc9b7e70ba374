"""``spirob-hil tune`` (hil.tune, hil.cli.tune): the space, the pruning bound, the placement sets, a search
that runs, resumes and keeps what finished after Ctrl-C, the parameter file it writes and its consumers
(spirob-hil board, campaigns; spirob-firmware and spirob-host have their own tests), one-line mistakes.

The searches grasp at the one reference placement (a 20 mm object 40 mm out, 110 mm below the base), the
same point in the training and the held-out set, so the held-out comparison reuses the training grasps
and a whole search costs two or three grasps.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import optuna
import pytest
from optuna.storages import JournalStorage
from optuna.storages.journal import JournalFileBackend
from optuna.trial import TrialState

from controller.config import FirmwareConfig
from controller.param_file import load_param_file, write_param_file
from hil.campaign.spec import load_campaign
from hil.cli.main import main
from hil.trial.grasp import grasp_firmware
from hil.tune.objective import TuneSpec, hopeless, placement_sets, runs_for
from hil.tune.space import DIMENSIONS, baseline_points, firmware_values, suggest

ROOT = Path(__file__).resolve().parents[3]
REF = ["--diameters-mm", "20", "--x-mm", "40,40", "--z-mm=-110,-110", "--grid", "1x1"]
"""The reference placement as the one training and held-out placement."""


def _journal_trials(path: Path, name: str = "t") -> list[optuna.trial.FrozenTrial]:
    storage = JournalStorage(JournalFileBackend(str(path)))
    return optuna.load_study(study_name=name, storage=storage).get_trials(deepcopy=False)


# ---------------------------------------------------------------------- pure parts


def test_every_point_of_the_space_is_a_valid_firmware() -> None:
    optuna.logging.set_verbosity(optuna.logging.WARNING)
    study = optuna.create_study(sampler=optuna.samplers.RandomSampler(seed=3), direction="maximize")
    seen_on = set()
    for _ in range(60):
        trial = study.ask()
        values = firmware_values(suggest(trial))
        seen_on.add(values["grasp_strategy_on"])
        fw = grasp_firmware(**values)  # raises on any invalid value
        assert fw.grasp.reach_timeout_us > fw.grasp.contact_grace_us
        strategy_keys = {d.name for d in DIMENSIONS if d.strategy_only}
        assert bool(strategy_keys & set(values)) == values["grasp_strategy_on"]
        study.tell(trial, 0.0)
    assert seen_on == {True, False}


def test_the_baselines_are_the_firmware_defaults_on_and_off() -> None:
    points = baseline_points()
    defaults = FirmwareConfig().to_dict()
    assert points["default"]["grasp_strategy_on"] is True and points["ramp"]["grasp_strategy_on"] is False
    for point in points.values():
        for name, value in point.items():
            if name != "grasp_strategy_on":
                assert value == defaults[name], name
    assert "grasp_pack_n" not in points["ramp"]


@pytest.mark.parametrize(
    ("k", "done", "n", "best", "rule", "out"),
    [
        (0, 0, 10, None, "bound", False),  # nothing to beat yet
        (2, 5, 10, 7, "bound", True),  # at most 2 + 5 = 7: a tie does not beat 7
        (2, 6, 10, 7, "bound", True),  # at most 6 of 10 < 7
        (9, 9, 10, 9, "bound", False),
        (0, 4, 20, 10, "bound", False),  # could still reach 16
        (0, 4, 20, 10, "wilson", True),  # Wilson upper of 0/4 = 49 % < 50 %
        (0, 3, 20, 10, "wilson", False),  # too few placements to judge a rate
        (0, 19, 20, 1, "none", False),
    ],
)
def test_hopeless(k: int, done: int, n: int, best: int | None, rule: str, out: bool) -> None:
    assert hopeless(k, done, n, best, rule) is out


def test_placement_sets_are_seeded_and_held_out_apart() -> None:
    spec = TuneSpec(diameters_m=(0.016, 0.024), grid=(2, 2), train_seeds=1, test_seeds=2, seed=5)
    train, test = placement_sets(spec)
    assert (len(train), len(test)) == (8, 16)
    assert not set(train) & set(test)
    assert placement_sets(spec) == (train, test)
    other = placement_sets(TuneSpec(diameters_m=(0.016, 0.024), grid=(2, 2), test_seeds=2, seed=6))
    assert other[0] != train
    for x, z, _ in train + test:
        assert 0.02 <= x <= 0.07 and -0.18 <= z <= -0.06
    runs = runs_for({"grasp_strategy_on": False, "grasp_wrap_n": 9.0}, train, spec)
    assert (
        runs[0].inputs["controller.strategy_on"] is False and runs[0].inputs["controller.grasp_wrap_n"] == 9.0
    )
    assert len({r.key for r in runs}) == len(runs)


# ---------------------------------------------------------------------- a search, resumed


@pytest.fixture(scope="module")
def searched(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[Path, Path, Path, dict[str, Any]]]:
    """Two trials (the two baselines) at the reference placement; the result as JSON."""
    d = tmp_path_factory.mktemp("tune")
    storage, out = d / "t.journal", d / "tuned.toml"
    argv = ["tune", *REF, "--study", "t", "--storage", str(storage), "-o", str(out), "--trials", "2"]
    old = Path.cwd()
    os.chdir(d)
    try:
        import contextlib
        import io

        buf = io.StringIO()
        with contextlib.redirect_stdout(buf):
            status = main([*argv, "--jobs", "1", "--json", "--report", str(d / "report")])
    finally:
        os.chdir(old)
    assert status == 0
    yield d, storage, out, json.loads(buf.getvalue())


def test_a_search_writes_a_file_of_its_best_trial(searched: tuple[Path, Path, Path, dict[str, Any]]) -> None:
    d, storage, out, result = searched
    trials = _journal_trials(storage)
    assert [t.state for t in trials] == [TrialState.COMPLETE] * 2
    rows = [json.loads(line) for line in (d / "t-rows.jsonl").read_text().splitlines() if line.strip()]
    assert len(rows) == 2  # one grasp per trial; the held-out comparison reused them (same placement)
    by_strategy = {r["inputs"]["controller.strategy_on"]: r["outcome"] == "success" for r in rows}
    best = max(trials, key=lambda t: (t.user_attrs["successes"], -t.number))
    assert result["values"] == json.loads(best.user_attrs["values"])
    assert load_param_file(out) == {k: v for k, v in result["values"].items()}
    assert result["heldout"]["default"]["successes"] == int(by_strategy[True])
    assert result["heldout"]["ramp"]["successes"] == int(by_strategy[False])
    assert result["train"]["successes"] == best.user_attrs["successes"]
    header = out.read_text().split("\n\n")[0]
    assert "Held-out (never seen by the search)" in header and "McNemar" in header
    assert "Wilson" in header and "2 trials" in header


def test_the_report_shows_the_search_the_heldout_comparison_and_the_tuned_grasp(
    searched: tuple[Path, Path, Path, dict[str, Any]],
) -> None:
    """``--report``: the progress and held-out figures (pixels drawn, not blank), the table with McNemar,
    the parameter values, and the tuned controller's held-out grasp run again with its values: pictures
    only if the re-run measured exactly what the held-out grasp recorded."""
    d, _, out, result = searched
    report = d / "report"
    assert result["report"] == str(report / "tune.md")
    text = (report / "tune.md").read_text()
    for png in ("trials.png", "heldout.png"):
        assert f"({png})" in text
        from PIL import Image

        with Image.open(report / png) as im:
            colours = np.unique(np.asarray(im.convert("RGB")).reshape(-1, 3), axis=0)
            assert len(colours) > 20, png  # drawn, not a blank canvas
    assert "| tuned | " in text and "| default | " in text and "| ramp | " in text and "McNemar" in text
    assert f"Parameter file: `{out}`" in text and out.read_text() in text  # the file as written
    from hil.render import NO_GL, gl_backends

    held = result["heldout"]["tuned"]["successes"] == 1
    if not gl_backends():
        assert NO_GL in text
        return
    heading = "a held-out grasp that " + ("succeeded" if held else "did not succeed")
    assert heading in text
    assert "re-run differs" not in text  # the tuned values are part of the re-run: it is the same grasp
    stills = sorted(report.glob(f"tuned-{'held' if held else 'failed'}-*.png"))
    assert stills and all(f"({p.name})" in text for p in stills)


def test_a_search_resumes_without_running_finished_trials_again(
    searched: tuple[Path, Path, Path, dict[str, Any]], capsys: pytest.CaptureFixture[str]
) -> None:
    d, storage, out, _ = searched
    rows_before = (d / "t-rows.jsonl").read_text().count("\n")
    argv = ["tune", *REF, "--study", "t", "--storage", str(storage), "-o", str(out), "--jobs", "1"]
    assert main([*argv, "--trials", "2"]) == 2  # the study exists: --resume or another name
    assert "--resume to go on" in capsys.readouterr().err
    assert main([*argv, "--trials", "3", "--resume", "--seed", "1"]) == 2  # another question
    assert "other placements or rules" in capsys.readouterr().err
    assert main([*argv, "--trials", "3", "--resume"]) == 0
    trials = _journal_trials(storage)
    assert len([t for t in trials if t.state in (TrialState.COMPLETE, TrialState.PRUNED)]) == 3
    rows = (d / "t-rows.jsonl").read_text()
    new_rows = rows.count("\n") - rows_before
    # Only the new trial grasped: its training grasp (none when a trial before it already won the one
    # placement: it cannot beat that and is pruned at once) and the held-out grasp of a new best. Which of
    # the two earlier trials won depends on grasps that flip with the machine's rounding.
    third = max(trials, key=lambda t: t.number)
    done = int(third.user_attrs["done"])
    assert done in (0, 1) and (done == 1 or third.state == TrialState.PRUNED)
    assert done <= new_rows <= done + 1, (done, new_rows)


def test_ctrl_c_keeps_the_finished_trials_and_says_the_best(tmp_path: Path) -> None:
    """Two placements, one job: SIGINT while the second trial grasps."""
    storage = tmp_path / "c.journal"
    argv = [
        sys.executable, "-m", "hil.cli.main", "tune", "--diameters-mm", "20", "--x-mm", "40,50",
        "--z-mm=-110,-110", "--grid", "2x1", "--study", "c", "--storage", str(storage), "--trials", "3",
        "--jobs", "1", "--prune", "none",
    ]  # fmt: skip
    proc = subprocess.Popen(argv, cwd=tmp_path, stderr=subprocess.PIPE, text=True, env={**os.environ})
    assert proc.stderr is not None
    lines: list[str] = []
    deadline = time.monotonic() + 600
    try:
        while time.monotonic() < deadline:
            line = proc.stderr.readline()
            assert line, f"tune ended early: {lines}"
            lines.append(line)
            if line.startswith("trial 0:"):
                break
        time.sleep(1.0)  # into the second trial's grasps
        proc.send_signal(signal.SIGINT)
        _, rest = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 130, [*lines, rest]
    assert "interrupted: 1 trial(s) finished" in rest and "best so far" in rest and "--resume" in rest
    trials = _journal_trials(storage, "c")
    assert trials[0].state == TrialState.COMPLETE and trials[0].user_attrs["done"] == 2
    assert all(t.state == TrialState.FAIL for t in trials[1:])
    rows = (tmp_path / "c-rows.jsonl").read_text().splitlines()
    assert len([r for r in rows if r.strip()]) >= 2  # the finished grasps stay


# ---------------------------------------------------------------------- its file and the consumers


def test_spirob_hil_board_takes_the_file(
    searched: tuple[Path, Path, Path, dict[str, Any]], monkeypatch: pytest.MonkeyPatch
) -> None:
    import hil.board

    _, _, out, result = searched
    taken: list[Any] = []

    class Stop(Exception):
        pass

    def fake_board(config: Any, *_: Any, **__: Any) -> Any:
        taken.append(config)
        raise Stop

    monkeypatch.setattr(hil.board, "realtime_board", fake_board)
    with pytest.raises(Stop):
        main(["board", "--params", str(out), "--listen", "socket://127.0.0.1:0"])
    fw = taken[0].firmware
    assert fw.grasp.strategy_on == result["values"]["grasp_strategy_on"]
    assert fw.grasp.wrap_n == result["values"]["grasp_wrap_n"]


def test_a_grasp_campaign_takes_the_file_under_its_own_keys(
    searched: tuple[Path, Path, Path, dict[str, Any]],
) -> None:
    _, _, out, result = searched
    params = load_param_file(out)
    sets = ["kind=grasp", "object.diameter_m=0.02", "object.x_m=0.04", "object.z_m=-0.11"]
    runs = load_campaign(None, [*sets, "controller.grasp_wrap_n=[4.0, 5.0]"], params).runs()
    assert [r.inputs["controller.grasp_wrap_n"] for r in runs] == [4.0, 5.0]  # the campaign's axis wins
    assert all(r.inputs["controller.strategy_on"] == result["values"]["grasp_strategy_on"] for r in runs)
    assert all(
        r.inputs["controller.grasp_contact_dwell_us"] == params["grasp_contact_dwell_us"] for r in runs
    )


def test_consumers_refuse_bad_files_in_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bad = tmp_path / "bad.toml"
    for text, message in (
        ("grasp_wrap_q = 1.0\n", "unknown key 'grasp_wrap_q'"),
        ("grasp_wrap_n = 99.0\n", "grasp_wrap_n: must be 0..tension_max_n"),
        ("grasp_hold_length = 2\n", "grasp_hold_length: expected bool"),
    ):
        bad.write_text(text)
        for argv in (
            ["board", "--params", str(bad), "--listen", "socket://127.0.0.1:0"],
            ["campaign", "--params", str(bad), "--set", "kind=grasp", "-o", str(tmp_path / "x.jsonl")],
        ):
            assert main(argv) == 2
            err = capsys.readouterr().err.strip().splitlines()
            assert len(err) == 1 and message in err[0], (argv, err)
    ok = write_param_file(tmp_path / "ok.toml", {"grasp_wrap_n": 5.0})
    assert main(["campaign", "--params", str(ok), "--set", "kind=scenario", "--set", "scenario.name=rc-loss",
                 "-o", str(tmp_path / "y.jsonl")]) == 2  # fmt: skip
    assert "--params is for grasp and array campaigns" in capsys.readouterr().err


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--grid", "3"], "--grid wants NXxNZ"),
        (["--x-mm", "70,20"], "x range wants LOW <= HIGH"),
        (["--diameters-mm", "0"], "diameters must be > 0"),
        (["--trials", "0"], "--trials must be 1.."),
        (["--jobs", "0"], "--jobs must be 1.."),
        (["--budget-min", "-1"], "--budget-min must be > 0"),
        (["--study", "a/b"], "--study wants letters"),
        (["--resume"], "nothing to resume"),
    ],
)
def test_tune_mistakes_are_one_line_and_status_2(
    extra: list[str], message: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    argv = ["tune", *REF, "--storage", str(tmp_path / "s.journal"), *extra]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0], err


def test_a_local_search_never_imports_ray(tmp_path: Path) -> None:
    code = (
        "import sys; from hil.cli.main import main; "
        f"s = main(['tune', '--study', 'x', '--storage', {str(tmp_path / 'r.journal')!r}, '--resume']); "
        "assert 'ray' not in sys.modules, 'ray imported'; sys.exit(s)"
    )
    proc = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 2 and "nothing to resume" in proc.stderr, proc.stderr


@pytest.mark.ray
def test_ray_tune_searches_with_optunas_sampler_and_resumes(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A local Ray of one CPU: the two baselines, then one more trial after a resume, whose report draws
    the three trials from the Ray search's journal (pictures off: the local search's report films)."""
    storage, out = tmp_path / "r", tmp_path / "r.toml"
    argv = ["tune", *REF, "--ray", "--jobs", "1", "--study", "r", "--storage", str(storage), "-o", str(out)]
    assert main([*argv, "--trials", "2"]) == 0
    trials = _journal_trials(storage / "study.journal", "r")
    assert len(trials) == 2 and {t.params["grasp_strategy_on"] for t in trials} == {True, False}
    assert all(t.value is not None and t.value >= 0 for t in trials)  # both ran their placement
    assert load_param_file(out)["grasp_strategy_on"] in (True, False)
    monkeypatch.setenv("MUJOCO_GL", "disable")
    assert main([*argv, "--trials", "3", "--resume", "--report", str(tmp_path / "report")]) == 0
    assert len(_journal_trials(storage / "study.journal", "r")) == 3
    text = (tmp_path / "report" / "tune.md").read_text()
    assert "(trials.png)" in text and "no OpenGL: pictures skipped" in text
    from hil.tune.ray_search import load_study
    from hil.tune.report import trial_points

    study = load_study(storage, "r")
    assert study is not None and len(trial_points(study, 1)) == 3 and load_study(storage, "other") is None


def test_the_shipped_prototype_file_is_taken_by_every_consumer() -> None:
    from host.param_push import wire_values

    path = ROOT / "examples" / "params_prototype_tuned.toml"
    values = load_param_file(path)
    assert "grasp_strategy_on" in values
    header = path.read_text().split("\n\n")[0]
    assert "Held-out" in header and "Training success" in header and "Wilson" in header
    assert len(wire_values(path)) == len(values)  # all run-time parameters: the host can send them all
    sets = ["kind=grasp", "object.diameter_m=0.02", "object.x_m=0.04", "object.z_m=-0.11"]
    assert load_campaign(None, sets, values).runs()


def test_the_heldout_comparison_grasps_a_shared_run_once_and_pairs_by_placement() -> None:
    import threading

    from hil.tune.heldout import compare_heldout, paired

    spec = TuneSpec(diameters_m=(0.02,), grid=(2, 1))
    test = [(0.03, -0.1, 0.02), (0.05, -0.1, 0.02)]
    ramp = firmware_values(baseline_points()["ramp"])
    given: list[str] = []

    def executor(runs: Any, jobs: int, stop: threading.Event) -> Any:
        for r in runs:
            given.append(r.key)
            ok = r.inputs["controller.strategy_on"] is False and r.inputs["object.x_m"] < 0.04
            yield {"key": r.key, "inputs": dict(r.inputs), "outcome": "success" if ok else "failure"}

    outcomes, ev = compare_heldout(
        spec,
        test,
        {"tuned": ramp, "default": firmware_values(baseline_points()["default"]), "ramp": ramp},
        jobs=1,
        stop=threading.Event(),
        executor=executor,
    )
    assert len(given) == len(set(given)) == 4 and ev.complete
    assert outcomes == {"tuned": [True, False], "default": [False, False], "ramp": [True, False]}
    assert paired(outcomes["tuned"], outcomes["default"]) == {
        "pairs": 2, "only_a": 1, "only_b": 0, "p_value": 1.0,
    }  # fmt: skip


def test_trial_points_read_a_local_and_a_ray_study_alike() -> None:
    """The progress figure's points: a local trial's stored successes; a Ray trial's score (successes over
    the set when it ran it all, negative when its scheduler stopped it)."""
    import optuna

    from hil.tune.report import TrialPoint, trial_points

    optuna.logging.set_verbosity(optuna.logging.WARNING)
    local = optuna.create_study(direction="maximize")
    t = local.ask()
    t.set_user_attr("successes", 3)
    t.set_user_attr("done", 6)
    local.tell(t, state=optuna.trial.TrialState.PRUNED)
    t = local.ask()
    t.set_user_attr("successes", 5)
    t.set_user_attr("done", 9)
    local.tell(t, 5 / 9)
    assert trial_points(local, 9) == [TrialPoint(0, 3, 6, True), TrialPoint(1, 5, 9, False)]
    ray = optuna.create_study(direction="maximize")
    ray.tell(ray.ask(), 4 / 9)
    ray.tell(ray.ask(), (2 - 9) / 9)  # stopped after 2 successes
    ray.ask()  # running: not a point
    assert trial_points(ray, 9) == [TrialPoint(0, 4, 9, False), TrialPoint(1, 2, 9, True)]
