"""``spirob-hil identify`` on the command line: ``--known`` (a parameter the lab gives, not fitted), its
mistakes in one line each, and the model file that carries the given value."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from hil.cli.identify import KNOWN_NOTE, _horizons, local_minimum_hint
from hil.cli.main import main
from hil.sim.model_file import read_model_file
from hil.sim.presets import PRESETS, resolve
from hil.sim.uncertain import by_name


@pytest.mark.parametrize(
    ("argv", "says"),
    [
        (["--known", "torque_scale"], "--known wants NAME=VALUE"),
        (["--known", "no_such=1"], "--known wants NAME=VALUE"),
        (["--known", "torque_scale=abc"], "not a number"),
        (["--known", "torque_scale=nan"], "not a finite number"),
        (["--known", "torque_scale=1", "--known", "torque_scale=1.1"], "gives a parameter twice"),
        (["--known", "torque_scale=1", "--params", "torque_scale,delay"], "both name torque_scale"),
        (["--known", "torque_scale=-3"], "--known: "),
        (["--explained-within-mm", "0"], "--explained-within-mm must be above 0"),
        (["--explained-within-mm", "inf"], "must be a finite number"),
        (["--restarts", "-1"], "--restarts must be 0..16"),
        (["--restarts", "17"], "--restarts must be 0..16"),
        (["--horizons", "3,x"], "--horizons: seconds S,S,... or 'none'"),
        (["--horizons", "0,6"], "every horizon must be above 0"),
    ],
)
def test_known_mistakes_are_one_line_and_status_2(
    argv: list[str], says: str, preset_recording: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    try:  # argparse's own refusals exit; the command's return their status
        code = main(["identify", str(preset_recording), "-o", str(tmp_path / "arm.toml"), *argv])
    except SystemExit as exc:
        code = exc.code  # type: ignore[assignment]
    assert code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) <= 2 and says in err[-1], err  # argparse's usage line, then the one line
    assert not (tmp_path / "arm.toml").exists()


def test_a_known_parameter_is_set_not_fitted_and_the_file_carries_it(
    truth_recording: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "arm.toml"
    preset = by_name("torque_scale").read(PRESETS["prototype"].model)
    given = 0.97 * preset  # as a bench test with a known weight might find it
    argv = ["identify", str(truth_recording), "-o", str(out), "--params", "base_stiffness,damping_ratio"]
    argv += ["--known", f"torque_scale={given!r}", "--max-iters", "1", "--budget-s", "6", "--jobs", "2"]
    assert main([*argv, "--json"]) == 0
    result = json.loads(capsys.readouterr().out)
    assert result["known"] == {"torque_scale": given}
    assert result["horizons_s"] == [3.0, 6.0, 10.0]  # the default with the torque constant given
    assert [p["name"] for p in result["parameters"]] == ["base_stiffness", "damping_ratio"]  # not fitted
    fitted = read_model_file(out).parameters["torque_scale"]
    assert fitted.value == given and fitted.preset == preset and fitted.note == KNOWN_NOTE
    assert by_name("torque_scale").read(resolve(str(out)).model) == pytest.approx(given)


def test_the_report_draws_the_fit_and_holds_mujocos_own_report(
    preset_recording: Path, tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    """``--report DIR``: the page, its three figures drawn (not blank canvases) and MuJoCo's own report in
    ``DIR/sysid`` (once lost to a ``str / str`` inside ``mujoco.sysid.default_report``, only logged)."""
    from PIL import Image

    report = tmp_path / "fit"
    argv = ["identify", str(preset_recording), "-o", str(tmp_path / "arm.toml"), "--params", "damping_ratio"]
    argv += ["--max-iters", "1", "--budget-s", "4", "--jobs", "2", "--report", str(report)]
    with caplog.at_level("WARNING"):
        assert main(argv) == 0
    assert not [r for r in caplog.records if "report failed" in r.getMessage()], caplog.text
    page = (report / "index.html").read_text()
    for png in ("traces.png", "residuals.png", "parameters.png"):
        assert png in page
        with Image.open(report / png) as im:
            assert len(np.unique(np.asarray(im.convert("RGB")).reshape(-1, 3), axis=0)) > 20, png
    assert (report / "sysid" / "report.html").stat().st_size > 0
    assert "sysid/report.html" in page


def test_a_fit_that_left_more_than_the_encoders_noise_says_what_to_do() -> None:
    settled = 0.6e-6
    assert local_minimum_hint([(0.01, 0.06e-6)], settled, 0) is None  # at the encoders' noise
    assert local_minimum_hint([(1e3, 50e-6), (0.01, 0.06e-6)], settled, 2) is None  # the best start counts
    assert local_minimum_hint([], settled, 0) is None
    assert local_minimum_hint([(1.0, 1e-3)], math.nan, 0) is None  # no recording says its quantum
    hint = local_minimum_hint([(14424.0, 0.19e-3)], settled, 0)
    assert hint is not None
    assert "0.19 mm" in hint and "0.0006 mm" in hint and "--restarts 2" in hint and "0.5 and 3.5 ms" in hint
    assert "real arm" in hint  # it does not claim a local minimum where no model could do better
    # A fit without the delay (--params) restarts from scattered points only: the hint does not promise cells.
    other = local_minimum_hint([(14424.0, 0.19e-3)], settled, 0, delay_fitted=False)
    assert other is not None and "--restarts 2" in other and "delay" not in other
    after = local_minimum_hint([(14424.0, 0.19e-3), (2925.0, 0.086e-3)], settled, 2)
    assert after is not None and "0.086 mm" in after and "after 2 starts" in after
    assert "--restarts" not in after
    # With the default bound (the sensors' noise) it says why nothing is identified; with a bound the user
    # set it does not.
    assert "no parameter is called identified" in after and "ten times the encoders' quantization" in after
    weaker = local_minimum_hint([(14424.0, 0.19e-3)], settled, 2, bound_is_noise=False)
    assert weaker is not None and "identified" not in weaker
    # Horizon continuation is offered to a fit that ran without it, not to one that ran with it.
    assert "--horizons 3,6,10" in hint and "--horizons" in after
    with_horizons = local_minimum_hint([(14424.0, 0.19e-3)], settled, 0, horizons=True)
    assert with_horizons is not None and "--horizons" not in with_horizons
    # A fit of the torque constant is told it can give it, and to continue over horizons if it did not.
    tied = local_minimum_hint([(14424.0, 0.19e-3)], settled, 0, scale_tied=True)
    assert tied is not None and "--known torque_scale=" in tied and "--horizons 3,6,10" in tied
    tied_h = local_minimum_hint([(14424.0, 0.19e-3)], settled, 0, horizons=True, scale_tied=True)
    assert tied_h is not None and "--known torque_scale=" in tied_h and "--horizons" not in tied_h
    assert "--known" not in hint


def test_horizons_asked_for_win_over_the_default() -> None:
    """The default itself is tested where it lives (test_starts.py) and through ``--json`` above."""
    assert _horizons("none", ["torque_scale"]) == ()
    assert _horizons("2,4", []) == (2.0, 4.0)
