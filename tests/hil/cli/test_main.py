"""`spirob-hil` command line (hil.cli.main): design and model export, one-line errors with status 2."""

from __future__ import annotations

import json
import math
from pathlib import Path

import mujoco
import pytest

from hil.cli.main import COMMANDS, build_parser, main
from hil.sim.spiral import AUTHORS_DEFAULT, PAPER_PROTOTYPE

PAPER_PROTOTYPE_INPUTS = {k: v for k, v in PAPER_PROTOTYPE.inputs}


def run(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    status = main(argv)
    out, err = capsys.readouterr()
    return status, out, err


def assert_one_line_error(status: int, err: str) -> None:
    assert status == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("spirob-hil")
    assert "error:" in lines[0]
    assert "Traceback" not in err


def test_design_json_defaults_to_the_prototype(capsys: pytest.CaptureFixture[str]) -> None:
    status, out, _ = run(["design", "--json"], capsys)
    assert status == 0
    data = json.loads(out)
    assert data.keys() >= PAPER_PROTOTYPE.summary().keys()  # the documented keys: tests/test_spiral.py
    assert data["units"] == PAPER_PROTOTYPE.units
    assert data["b"] == pytest.approx(PAPER_PROTOTYPE.b)
    assert data["inputs"]["length_m"] == 0.23


def test_design_table_for_people(capsys: pytest.CaptureFixture[str]) -> None:
    status, out, _ = run(["design", "--preset", "authors"], capsys)
    assert status == 0
    assert "24 units" in out
    assert "taper angle" in out and "largest graspable diameter" in out


def test_design_from_physical_inputs(capsys: pytest.CaptureFixture[str]) -> None:
    argv = [
        "design",
        "--json",
        "--length",
        "0.3",
        "--tip-width",
        "0.008",
        "--taper-deg",
        "7",
        "--dtheta-deg",
        "20",
    ]
    status, out, _ = run([*argv, "--cables", "2"], capsys)
    assert status == 0
    data = json.loads(out)
    assert data["cables"] == 2
    assert data["tip_width_m"] == pytest.approx(0.008)
    assert data["taper_rad"] == pytest.approx(math.radians(7))
    assert data["dtheta_rad"] == pytest.approx(math.radians(20))
    assert data["inputs"] == {
        "length_m": 0.3,
        "tip_width_m": 0.008,
        "dtheta_rad": pytest.approx(math.radians(20)),
        "taper_rad": pytest.approx(math.radians(7)),
    }


def test_design_from_base_width(capsys: pytest.CaptureFixture[str]) -> None:
    status, out, _ = run(
        ["design", "--json", "--length", "0.2", "--tip-width", "0.007", "--base-width", "0.03"], capsys
    )
    assert status == 0
    data = json.loads(out)
    assert data["base_width_m"] == pytest.approx(0.03, rel=0.06)


def test_design_from_spiral_parameters(capsys: pytest.CaptureFixture[str]) -> None:
    status, out, _ = run(
        ["design", "--json", "--a", "0.00495", "--b", "0.1764", "--theta0-deg", "720", "--dtheta-deg", "30"],
        capsys,
    )
    assert status == 0
    assert json.loads(out)["units"] == AUTHORS_DEFAULT.units
    status, out, _ = run(["design", "--json", "--a", "0.00495", "--b", "0.1764", "--units", "24"], capsys)
    assert status == 0
    assert json.loads(out)["theta0_rad"] == pytest.approx(4 * math.pi)


def test_an_experiment_runs_on_the_preset_it_is_given(capsys: pytest.CaptureFixture[str]) -> None:
    argv = ["experiment", "packing", "--preset", "gravity-off", "--size", "tiny", "--json"]
    status, out, _ = run(argv, capsys)
    assert status == 0
    assert json.loads(out)["preset"] == "gravity-off"
    argv = ["experiment", "packing", "--physics", "board", "--timestep-ms", "0.5", "--size", "tiny", "--json"]
    status, out, _ = run(argv, capsys)
    assert status == 0
    assert json.loads(out)["timestep_s"] == 0.0005


def test_design_from_a_preset_with_single_values_changed(capsys: pytest.CaptureFixture[str]) -> None:
    def design(*argv: str) -> dict[str, object]:
        status, out, _ = run(["design", "--json", *argv], capsys)
        assert status == 0
        data: dict[str, object] = json.loads(out)
        return data

    longer = design("--preset", "prototype", "--length", "0.3")
    # The prototype's own inputs (tip 7 mm, taper 6.5°, Δθ 30°) with the length changed.
    assert longer["inputs"] == {**PAPER_PROTOTYPE_INPUTS, "length_m": 0.3}
    assert longer["b"] == pytest.approx(PAPER_PROTOTYPE.b) and longer["units"] > PAPER_PROTOTYPE.units
    fewer = design("--preset", "authors", "--units", "20")
    assert fewer["units"] == 20 and fewer["a_m"] == pytest.approx(AUTHORS_DEFAULT.a_m)
    assert fewer["b"] == pytest.approx(AUTHORS_DEFAULT.b)
    finer = design("--preset", "prototype", "--dtheta-deg", "20")
    assert finer["dtheta_rad"] == pytest.approx(math.radians(20)) and finer["units"] > PAPER_PROTOTYPE.units
    table = design("--preset", "table", "--tip-width", "0.01")
    assert table["cables"] == 2  # the table preset's cable count stays
    assert design("--preset", "prototype", "--b", "0.2")["b"] == 0.2


def test_design_help_lists_the_valid_combinations(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit):
        main(["design", "--help"])
    out = " ".join(capsys.readouterr().out.split())
    assert "Valid combinations: (1) nothing, or --preset NAME" in out
    assert "(4) --preset NAME with any single values of (2) or of (3), not both" in out


@pytest.mark.parametrize(
    "argv",
    [
        ["design", "--length", "-0.2", "--tip-width", "0.007", "--taper-deg", "6"],
        ["design", "--length", "0.2", "--tip-width", "0.007", "--taper-deg", "0"],
        ["design", "--length", "0.2", "--tip-width", "0.007", "--taper-deg", "90"],
        ["design", "--length", "0.2", "--tip-width", "0.007", "--taper-deg", "120"],
        ["design", "--a", "0.005", "--b", "0.15", "--theta0-deg", "20", "--dtheta-deg", "30"],
        ["design", "--a", "0.005", "--b", "0.15", "--units", "0"],
        ["design", "--length", "0.2", "--tip-width", "0.007"],
        ["design", "--length", "0.2", "--taper-deg", "6"],
        # a preset takes single values of one form, never of both; the result must still be a design
        ["design", "--preset", "authors", "--length", "0.2", "--a", "0.005"],
        ["design", "--preset", "authors", "--theta0-deg", "100"],
        ["design", "--preset", "authors", "--theta0-deg", "720", "--units", "24"],
        ["design", "--preset", "prototype", "--taper-deg", "6", "--base-width", "0.03"],
        ["design", "--preset", "prototype", "--base-width", "0.005"],
        ["design", "--preset", "nope"],
        ["model", "export", "-o", "x.xml", "--preset", "nope"],
        ["experiment", "packing", "--preset", "nope"],
        ["experiment", "packing", "--timestep-ms", "0.3"],
        ["experiment", "packing", "--timestep-ms", "-1"],
        ["design", "--cables", "4"],
        ["design", "--length", "abc"],
        ["design", "--json", "--load-force", "-1"],
        ["design", "--json", "--load-force", "inf"],
        # issue 18: absurd sizes and non-finite numbers are one line, never an OverflowError
        ["design", "--a", "0.01", "--b", "0.2", "--units", "100000"],
        ["design", "--a", "0.01", "--b", "3", "--units", "900"],
        ["design", "--a", "0.001", "--b", "0.001", "--theta0-deg", "360000", "--dtheta-deg", "30"],
        ["design", "--length", "nan", "--tip-width", "0.007", "--taper-deg", "6"],
        ["design", "--a", "inf", "--b", "0.2", "--units", "10"],
        ["model", "export", "-o", "x.xml", "--total-mass", "nan"],
        ["experiment", "packing", "--jobs", "100000"],
        ["experiment", "packing", "--timestep-ms", "nan"],
        # experiments that drive arms of their own refuse design options rather than ignore them
        ["experiment", "workspace", "--length", "0.3"],
        ["experiment", "dynamic", "--cables", "2"],
        ["model", "export"],
        ["model"],
        ["frobnicate"],
        [],
    ],
)
def test_user_mistakes_are_one_line_and_status_2(argv: list[str], capsys: pytest.CaptureFixture[str]) -> None:
    status, out, err = run(argv, capsys)
    assert_one_line_error(status, err)
    assert out == ""


@pytest.mark.parametrize("name", ["workspace", "dynamic", "array", "bands", "convergence"])
def test_an_experiment_on_its_own_arms_names_them_when_given_a_design(
    name: str, capsys: pytest.CaptureFixture[str]
) -> None:
    argv = ["experiment", name, "--size", "tiny", "--preset", "prototype", "--cables", "2"]
    status, _, err = run(argv, capsys)
    assert_one_line_error(status, err)
    assert f"experiment {name} drives" in err and "--cables" in err


@pytest.mark.parametrize("cables", ["1", "2", "3"])
def test_model_export_writes_a_loadable_model(
    tmp_path: Path, cables: str, capsys: pytest.CaptureFixture[str]
) -> None:
    target = tmp_path / "arm.xml"
    status, out, _ = run(["model", "export", "--cables", cables, "-o", str(target)], capsys)
    assert status == 0
    assert str(target) in out
    m = mujoco.MjModel.from_xml_path(str(target))
    assert m.ntendon == int(cables)
    assert mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, "unit_00") >= 0


def test_model_export_options(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    target = tmp_path / "authors.xml"
    argv = [
        "model",
        "export",
        "--preset",
        "authors",
        "-o",
        str(target),
        "--mu",
        "0.35",
        "--torque-constant",
        "0.33",
    ]
    argv += [
        "--total-mass",
        "0.1",
        "--timestep-ms",
        "0.5",
        "--floor",
        "--object",
        "branch,0.05,0,0.7,0.02,0.3",
    ]
    status, _, err = run(argv, capsys)
    assert status == 0, err
    m = mujoco.MjModel.from_xml_path(str(target))
    assert m.opt.timestep == pytest.approx(0.0005)
    assert mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, "branch") >= 0
    assert mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, "floor") >= 0
    assert mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, "unit_23") >= 0
    # --preset authors is the authors' model: 5 N muscles, no gravity; the torque constant still sets
    # the firmware's force per amp, which travels as a custom numeric.
    assert m.actuator_gaintype[0] == mujoco.mjtGain.mjGAIN_MUSCLE
    assert m.actuator_gainprm[0][2] == pytest.approx(5.0)
    assert list(m.opt.gravity) == [0.0, 0.0, 0.0]
    kt = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_NUMERIC, "spirob_torque_constant_nm_per_a")
    assert m.numeric_data[m.numeric_adr[kt]] == pytest.approx(0.33)


def test_model_export_motor_options(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    target = tmp_path / "arm.xml"
    argv = ["model", "export", "-o", str(target), "--torque-constant", "0.33", "--stiffness-exponent", "2"]
    status, _, err = run(argv, capsys)
    assert status == 0, err
    m = mujoco.MjModel.from_xml_path(str(target))
    assert m.actuator_gear[0][0] == pytest.approx(33.0)  # kt / r_spool
    k1 = m.jnt_stiffness[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, "joint_01")]
    k2 = m.jnt_stiffness[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, "joint_02")]
    assert k1 / k2 == pytest.approx(PAPER_PROTOTYPE.beta**2)


@pytest.mark.parametrize("name", ["prototype", "authors", "ideal-tension", "table", "gravity-off"])
def test_design_names_the_model_preset(name: str, capsys: pytest.CaptureFixture[str]) -> None:
    status, out, _ = run(["design", "--json", "--preset", name], capsys)
    assert status == 0
    summary = json.loads(out)
    assert summary["model_preset"] == name
    assert summary["model"]["actuator"] in ("motor", "tension", "muscle")
    if name == "table":
        assert summary["cables"] == 2 and summary["model"]["mounting"] == "table"


def test_preset_help_lists_every_preset(capsys: pytest.CaptureFixture[str]) -> None:
    for command in (["design"], ["model", "export"], ["experiment"]):
        with pytest.raises(SystemExit):
            main([*command, "--help"])
        out = capsys.readouterr().out
        for name in ("prototype", "authors", "ideal-tension", "table", "gravity-off"):
            assert name in out, (command, name)


def test_model_export_table_preset(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    target = tmp_path / "table.xml"
    status, _, err = run(["model", "export", "--preset", "table", "-o", str(target)], capsys)
    assert status == 0, err
    m = mujoco.MjModel.from_xml_path(str(target))
    assert mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, "table") >= 0
    assert m.ntendon == 2


@pytest.mark.parametrize(
    "extra",
    [
        ["--object", "branch,1,2"],
        ["--object", "unit_x,0,0,0,0.01"],
        ["--mu", "-1"],
        ["--current-limit", "20"],
    ],
)
def test_model_export_mistakes(tmp_path: Path, extra: list[str], capsys: pytest.CaptureFixture[str]) -> None:
    status, _, err = run(["model", "export", "-o", str(tmp_path / "x.xml"), *extra], capsys)
    assert_one_line_error(status, err)
    assert not (tmp_path / "x.xml").exists()


def test_unwritable_output_is_a_user_error(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    status, _, err = run(["model", "export", "-o", str(tmp_path / "missing" / "arm.xml")], capsys)
    assert_one_line_error(status, err)
    assert "cannot write" in err


def test_experiment_report_into_a_file_fails_before_the_run(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    afile = tmp_path / "afile"
    afile.write_text("")
    status, out, err = run(["experiment", "packing", "--size", "tiny", "--report", str(afile)], capsys)
    assert_one_line_error(status, err)
    assert "not a directory" in err and out == ""


def test_parser_is_separate_and_lists_every_command(capsys: pytest.CaptureFixture[str]) -> None:
    parser = build_parser()
    args = parser.parse_args(["design", "--preset", "authors"])
    assert args.command == "design" and args.preset == "authors"
    names = [c.name for c in COMMANDS]
    assert names[:2] == ["design", "model"]
    with pytest.raises(SystemExit) as info:
        main(["--help"])
    assert info.value.code == 0
    out = capsys.readouterr().out
    assert all(name in out for name in names)
