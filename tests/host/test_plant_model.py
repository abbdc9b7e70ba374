"""host.plant_model: ``--preset NAME|FILE.toml`` is the virtual board's plant model and design (and the
recording says so), or, with ``--port``, the shadow plant's; a bad one is one line at start."""

from __future__ import annotations

import dataclasses
import json
import math
from collections.abc import Callable
from pathlib import Path

import pytest

from hil.board import BoardConfig
from hil.sim.model_file import FittedParameter, ModelFile, write_model_file
from hil.sim.presets import PRESETS, resolve
from hil.sim.spiral import SpiralDesign
from hil.sim.uncertain import nominal
from host.app import HostApp
from host.cli import main
from host.errors import HostError
from host.object_spec import DEFAULT_OBJECT
from host.options import HostOptions
from host.panel.board_state import PoseSource
from host.plant_model import resolve_preset, shadow_plant_factory, virtual_board_config
from tests.support.foxglove_check import check_recording
from tests.support.link_peer import HardwarePeer
from tests.support.realtime_guard import wait_for

UNITS = 18
"""The fitted arm: the prototype's spiral with three units fewer (the prototype has 21)."""


def lab_arm() -> SpiralDesign:
    p = SpiralDesign.paper_prototype()
    return SpiralDesign.from_params(p.a_m, p.b, UNITS * p.dtheta_rad, p.dtheta_rad, 3)


@pytest.fixture
def model_file(tmp_path: Path) -> Path:
    path = tmp_path / "lab-arm.toml"
    params = {"base_stiffness": FittedParameter("base_stiffness", 0.65, "N·m/rad", (0.6, 0.7), True, 0.5)}
    write_model_file(path, ModelFile("prototype", lab_arm(), params, created="2026-11-27T09:00:00Z"))
    return path


def test_a_fitted_file_is_the_virtual_boards_design_and_model(model_file: Path) -> None:
    chosen = resolve_preset(str(model_file))
    config = virtual_board_config(None, chosen, (DEFAULT_OBJECT,))
    assert config.design == lab_arm() and config.rc == "link"
    assert nominal(config.plant.model)["base_stiffness"] == 0.65
    assert [o.name for o in config.plant.model.objects] == ["object1"]  # placed in the fitted model
    described = json.loads(config.describe()["design"])
    assert (
        SpiralDesign.from_params(*(described[k] for k in ("a_m", "b", "theta0_rad", "dtheta_rad")))
        == lab_arm()
    )
    # A named preset brings its own design; no preset leaves the configuration as it was.
    table = virtual_board_config(None, PRESETS["table"], ())
    assert table.design.cables == 2 and table.plant.model.mounting == "table"
    base = BoardConfig(rc="link", seed=3)
    assert virtual_board_config(base, None, ()) is base


def test_a_bad_preset_is_one_line() -> None:
    assert resolve_preset(None) is None
    with pytest.raises(HostError, match=r"^--preset nope: unknown model preset 'nope'"):
        resolve_preset("nope")


def test_the_shadow_plant_is_the_presets(model_file: Path) -> None:
    assert shadow_plant_factory(None) is None
    build = shadow_plant_factory(resolve(str(model_file)))
    assert build is not None
    plant = build()
    assert plant.design == lab_arm()


def _units_in(poses: list[tuple[int, int, object]]) -> int:
    return sum(1 for t in poses[-1][2].transforms if t.child_frame_id.startswith("unit_"))  # type: ignore[attr-defined]


def test_spirob_host_runs_the_virtual_board_from_a_fitted_file(
    model_file: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    rec = tmp_path / "run.mcap"
    argv = ["--headless", "--virtual-rc", "safe", "--preset", str(model_file), "--record", str(rec)]
    assert main([*argv, "--duration", "2"]) == 0, capsys.readouterr().err
    checked = check_recording(rec)
    meta = checked.metadata
    assert meta["preset"] == str(model_file)
    design = json.loads(meta["design"])
    assert math.isclose(design["theta0_rad"], lab_arm().theta0_rad)
    # The board's plant is the fitted arm: its poses carry its units.
    assert _units_in(checked.messages["/tf"]) == UNITS


@pytest.mark.parametrize(
    ("make", "needle"),
    [
        (lambda d: "nope", "unknown preset 'nope'"),
        (lambda d: str(d / "missing.toml"), "missing.toml: no such file"),
        (lambda d: _write(d / "bad.toml", "format = 1\npreset ="), "bad.toml: not TOML"),
    ],
)
def test_a_bad_preset_exits_2_with_one_line(
    make: Callable[[Path], str], needle: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    with pytest.raises(SystemExit) as exc:
        main(["--headless", "--preset", make(tmp_path), "--duration", "1"])
    assert exc.value.code == 2
    lines = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
    assert (
        len(lines) == 1
        and lines[0].startswith("spirob-host: error: argument --preset:")
        and needle in lines[0]
    )


def _write(path: Path, text: str) -> str:
    path.write_text(text, encoding="utf-8")
    return str(path)


def test_with_a_port_the_preset_is_the_shadow_plants(model_file: Path) -> None:
    opts = HostOptions(port="", ui=False, preset=str(model_file))
    with HardwarePeer("socket") as peer, HostApp(dataclasses.replace(opts, port=peer.url)) as app:
        app.start()
        b = app.board_state
        assert b is not None and app.shadow is not None and app.design == lab_arm()
        assert wait_for(lambda: b.pose_source is PoseSource.SHADOW, 20.0)
        assert b.poses is not None and len(b.poses.positions_m) == UNITS + 1  # the drone, then the units


def test_the_panel_draws_the_fitted_arm(model_file: Path) -> None:
    with HostApp(HostOptions(ui_port=0, preset=str(model_file))) as app:
        app.start()
        assert app.panel is not None and app.panel.geometry.units == UNITS
