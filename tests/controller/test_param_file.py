"""Firmware parameter files (controller.param_file) and spirob-firmware --params."""

from __future__ import annotations

from pathlib import Path

import pytest

from controller.cli import _load_config, main, parse_args
from controller.config import FirmwareConfig
from controller.errors import ConfigError
from controller.param_file import apply_param_file, dump_param_file, load_param_file, write_param_file

TUNED = {
    "grasp_strategy_on": False,
    "grasp_hold_length": True,
    "grasp_wrap_n": 12.345678901234567,
    "grasp_contact_dwell_us": 90_000,
    "slew_n_per_s": 33.3,
    "cable_angles_deg": (0.0, 120.0, 240.0),
    "payin_limit_m_per_s": 0.05,
}


def test_round_trip_keeps_every_value_exactly(tmp_path: Path) -> None:
    path = write_param_file(tmp_path / "p.toml", TUNED, ["made by a test", "second line"])
    text = path.read_text()
    assert text.startswith("# made by a test\n# second line\n\n")
    back = load_param_file(path)
    assert back == TUNED
    assert type(back["grasp_contact_dwell_us"]) is int and type(back["grasp_wrap_n"]) is float
    cfg = apply_param_file(path)
    assert cfg.grasp.wrap_n == TUNED["grasp_wrap_n"] and cfg.grasp.strategy_on is False
    assert cfg.grasp.hold_length is True and cfg.mapping.slew_n_per_s == 33.3
    assert cfg.grasp.pack_n == FirmwareConfig().grasp.pack_n  # keys not given keep the base


def test_a_base_is_kept_where_the_file_is_silent(tmp_path: Path) -> None:
    path = write_param_file(tmp_path / "p.toml", {"grasp_wrap_n": 9.0})
    base = FirmwareConfig().replaced(bend_max_n=3.0)
    cfg = apply_param_file(path, base)
    assert cfg.grasp.wrap_n == 9.0 and cfg.mapping.bend_max_n == 3.0


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("grasp_wrap_x = 3.0\n", "unknown key 'grasp_wrap_x'"),
        ("grasp_wrap_n = 25.0\n", "grasp_wrap_n: must be 0..tension_max_n"),
        ("current_limit_a = 11.0\n", "current_limit_a: must be in (0, 10] A"),
        ('grasp_wrap_n = "high"\n', "grasp_wrap_n: expected float"),
        ("grasp_strategy_on = 1\n", "grasp_strategy_on: expected bool"),
        ("grasp_contact_dwell_us = 1.5\n", "grasp_contact_dwell_us: expected int"),
        ("grasp_reach_n = 10.0\n", "grasp_reach_n: must be below half of grasp_pack_n"),
        ("[grasp]\nwrap_n = 3.0\n", "unknown key 'grasp'"),
        ("grasp_wrap_n = \n", "not valid TOML"),
    ],
)
def test_bad_files_are_one_config_error_naming_the_file(tmp_path: Path, text: str, message: str) -> None:
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(ConfigError) as err:
        load_param_file(path)
    assert str(err.value).startswith(f"{path}: ") and message in str(err.value)
    assert "\n" not in str(err.value)


def test_missing_and_huge_files(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="cannot read parameter file"):
        load_param_file(tmp_path / "none.toml")
    big = tmp_path / "big.toml"
    big.write_text("# " + "x" * 70_000 + "\n")
    with pytest.raises(ConfigError, match="larger than"):
        load_param_file(big)


def test_dump_refuses_what_the_firmware_refuses() -> None:
    with pytest.raises(ConfigError, match="unknown key"):
        dump_param_file({"nope": 1})
    with pytest.raises(ConfigError, match="grasp_wrap_n"):
        dump_param_file({"grasp_wrap_n": 99.0})


def test_spirob_firmware_takes_the_file_over_config(tmp_path: Path) -> None:
    params = write_param_file(tmp_path / "p.toml", {"grasp_wrap_n": 7.5, "grasp_strategy_on": False})
    config = tmp_path / "c.json"
    config.write_text('{"grasp_wrap_n": 4.0, "bend_max_n": 2.0}')
    argv = ["--link", "loop://", "--config", str(config), "--params", str(params), "--require-host"]
    args = parse_args(argv)
    cfg = _load_config(args)
    assert cfg.grasp.wrap_n == 7.5 and cfg.grasp.strategy_on is False
    assert cfg.mapping.bend_max_n == 2.0 and cfg.failsafe.host_required is True


def test_spirob_firmware_refuses_a_bad_file_in_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bad = tmp_path / "bad.toml"
    bad.write_text("grasp_wrap_n = -1.0\n")
    assert main(["--can-interface", "fake", "--link", "loop://", "--params", str(bad)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "grasp_wrap_n: must be 0..tension_max_n" in err[0], err
