"""hil.sim.model_file and hil.sim.presets.resolve: a fitted model file round-trips and works as a preset;
every bad file is one line."""

from __future__ import annotations

import argparse
import dataclasses
import math
from pathlib import Path

import pytest

from hil.cli.design import preset_arg
from hil.sim.model_file import FittedParameter, ModelFile, ModelFileError, read_model_file, write_model_file
from hil.sim.presets import PRESETS, resolve
from hil.sim.spiral import SpiralDesign
from hil.sim.uncertain import nominal


def _model(design: SpiralDesign | None = None, preset: str = "prototype") -> ModelFile:
    return ModelFile(
        preset,
        design or SpiralDesign.paper_prototype(),
        {
            "base_stiffness": FittedParameter("base_stiffness", 0.65, "N·m/rad", (0.6, 0.7), True, 0.5),
            "drive_friction": FittedParameter(
                "drive_friction", 0.012, "N·m", (0.0, 0.03), False, 0.01, 'interval "wide"'
            ),
        },
        {"held_out_rms_mm": 0.21, "iterations": 5},
        (("a.mcap", "ab" * 32, 60.0),),
        "2026-11-27T09:00:00Z",
        "spirob-teleop test",
    )


def test_a_model_file_round_trips(tmp_path: Path) -> None:
    path = tmp_path / "arm.toml"
    m = _model(SpiralDesign.authors_default())
    write_model_file(path, m)
    back = read_model_file(path)
    assert back.preset == m.preset and back.created == m.created and back.tool == m.tool
    assert back.design.a_m == m.design.a_m and back.design.units == m.design.units
    assert back.parameters == m.parameters
    assert back.fit == m.fit and back.recordings == m.recordings
    assert not (tmp_path / "arm.toml.part").exists()


def test_a_model_file_is_a_preset_with_its_values_and_its_design(tmp_path: Path) -> None:
    path = tmp_path / "lab-arm.toml"
    design = SpiralDesign.authors_default()
    write_model_file(path, _model(design))
    chosen = resolve(str(path))
    assert chosen.name == "lab-arm"
    assert chosen.spiral() == design
    values = nominal(chosen.model)
    assert values["base_stiffness"] == 0.65 and values["drive_friction"] == 0.012
    base = nominal(PRESETS["prototype"].model)
    assert all(values[k] == base[k] for k in values if k not in ("base_stiffness", "drive_friction"))
    assert preset_arg(str(path)) == str(path)
    assert resolve("authors") is PRESETS["authors"]


@pytest.mark.parametrize(
    ("text", "why"),
    [
        ("not toml [", "not TOML"),
        ("format = 99\npreset = 'prototype'\n", "newer than this version"),
        ("preset = 'prototype'\n", "no 'format' number"),
        ("format = 1\npreset = 'prototype'\n", "no 'design'"),
    ],
)
def test_bad_files_are_one_line(tmp_path: Path, text: str, why: str) -> None:
    path = tmp_path / "bad.toml"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(ModelFileError, match=why) as info:
        read_model_file(path)
    assert "\n" not in str(info.value)


def test_unusable_models_are_refused_as_presets(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="no such file"):
        resolve(str(tmp_path / "missing.toml"))
    with pytest.raises(ValueError, match="unknown model preset 'nope'"):
        resolve("nope")
    path = tmp_path / "odd.toml"
    write_model_file(path, _model(preset="pterodactyl"))
    with pytest.raises(ValueError, match="unknown preset 'pterodactyl'"):
        resolve(str(path))
    m = _model()
    bad = ModelFile(m.preset, m.design, {"cable_mu": FittedParameter("cable_mu", -1.0)})
    write_model_file(path, bad)
    with pytest.raises(ValueError, match="cable_mu"):
        resolve(str(path))
    with pytest.raises(argparse.ArgumentTypeError, match="cable_mu"):
        preset_arg(str(path))
    huge = tmp_path / "huge.toml"
    huge.write_bytes(b"#" * (2 << 20))
    with pytest.raises(ValueError, match="is not a model file"):
        resolve(str(huge))


def test_nan_intervals_survive(tmp_path: Path) -> None:
    m = _model()
    p = FittedParameter("delay", 0.001)
    write_model_file(tmp_path / "a.toml", ModelFile(m.preset, m.design, {"delay": p}))
    back = read_model_file(tmp_path / "a.toml").parameters["delay"]
    assert all(math.isnan(x) for x in back.interval)


def test_the_shipped_soft_plant_is_the_prototype_with_a_softer_base_joint() -> None:
    """examples/plant_soft_base.toml (the claims map's soft cell, docs/experiments.md) is a model file that
    changes the base joint's stiffness alone: the design, the size law and everything else are the
    prototype's."""
    path = Path(__file__).resolve().parents[3] / "examples" / "plant_soft_base.toml"
    soft = resolve(str(path)).model
    proto = PRESETS["prototype"].model
    assert soft.arm.base_stiffness_nm_per_rad == 0.125
    assert soft.arm.stiffness_exponent == proto.arm.stiffness_exponent == 3.0
    base = proto.arm.base_stiffness_nm_per_rad
    assert dataclasses.replace(soft.arm, base_stiffness_nm_per_rad=base) == proto.arm
    assert soft.motor == proto.motor
