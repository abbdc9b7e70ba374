"""A claim's map from a paired campaign (hil.campaign.claims, ``spirob-hil campaign --paired``)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from PIL import Image

from hil.campaign.claims import arm_values, claim_map, paired_cells, verdict
from hil.cli.main import main


def _row(stiff: float, law: float, x: float, on: bool, success: bool, error: bool = False) -> dict[str, Any]:
    inputs = {
        "kind": "grasp",
        "design.base_stiffness_nm_per_rad": stiff,
        "design.stiffness_exponent": law,
        "object.x_m": x,
        "controller.strategy_on": on,
        "seed": 0,
    }
    outcome = "error" if error else "success" if success else "failure"
    return {"inputs": inputs, "outcome": outcome, "measured": {"extremes": {"penetration_m": 2e-4 * x * 100}}}


def _rows() -> list[dict[str, Any]]:
    rows = []
    xs = [0.02, 0.03, 0.04, 0.05, 0.06, 0.07]
    for x in xs:  # soft, size^2: the strategy wins all six placements the ramp loses
        rows += [_row(0.25, 2.0, x, True, True), _row(0.25, 2.0, x, False, False)]
    for i, x in enumerate(xs):  # stiff, size^3: the ramp wins four, one pair has an error
        rows += [_row(0.5, 3.0, x, True, i == 5, error=i == 4), _row(0.5, 3.0, x, False, i < 4)]
    return rows


def test_runs_pair_by_placement_per_cell_and_the_rule_is_mcnemar() -> None:
    rows = _rows()
    assert arm_values(rows, "controller.strategy_on") == (True, False)
    cells = {
        c.inputs["design.base_stiffness_nm_per_rad"]: c for c in paired_cells(rows, "controller.strategy_on")
    }
    soft, stiff = cells[0.25], cells[0.5]
    assert (soft.pairs, soft.a_successes, soft.b_successes, soft.only_a, soft.only_b) == (6, 6, 0, 6, 0)
    assert soft.p == pytest.approx(2 / 64) and soft.holds
    assert soft.penetration_m == pytest.approx(2e-4 * 7)
    assert (stiff.pairs, stiff.only_a, stiff.only_b) == (5, 1, 4)  # the error's pair left out
    assert not stiff.holds
    assert "controller.strategy_on" not in soft.inputs and "object.x_m" not in soft.inputs
    text = verdict(list(cells.values()), "controller.strategy_on", True)
    assert text.startswith("strategy_on=true wins in 1 of 2 cells (pooled 7 / 4 discordant pairs")
    assert text.endswith("holds when base_stiffness_nm_per_rad=0.25, stiffness_exponent=2")
    lost = verdict([stiff], "controller.strategy_on", True)
    assert "wins in none of 1 cells" in lost and "the claim holds nowhere in this range" in lost


def test_runs_whose_object_was_put_into_the_arm_are_counted_and_named_in_the_verdict() -> None:
    rows = _rows()
    for r in rows:
        r["inputs"]["object.diameter_m"] = 0.02
        r["measured"]["placed_overlap_m"] = 0.0
    soft_on = [r for r in rows if r["inputs"]["design.base_stiffness_nm_per_rad"] == 0.25][:4:2]
    soft_on[0]["measured"]["placed_overlap_m"] = 0.004  # beyond 1 mm and 10 % of the 10 mm radius
    soft_on[1]["measured"]["placed_overlap_m"] = 0.0009  # within the goal
    cells = {
        c.inputs["design.base_stiffness_nm_per_rad"]: c for c in paired_cells(rows, "controller.strategy_on")
    }
    assert (cells[0.25].placed_inside, cells[0.5].placed_inside) == (1, 0)
    text = verdict(list(cells.values()), "controller.strategy_on", True)
    assert "holds when base_stiffness_nm_per_rad=0.25" in text
    assert text.endswith(
        "; but 1 runs in 1 cells put the object inside the arm (overlapping it beyond the penetration goal "
        "when placed), which is not a grasp: base_stiffness_nm_per_rad=0.25, stiffness_exponent=2 (1)"
    )
    # Rows written before the trial measured it count as placed clear.
    assert all(c.placed_inside == 0 for c in paired_cells(_rows(), "controller.strategy_on"))


def test_the_map_colours_a_winning_cell_blue_and_a_losing_one_red(tmp_path: Path) -> None:
    cells = paired_cells(_rows(), "controller.strategy_on")
    path = claim_map(cells, tmp_path / "map.png", "strategy on minus off")
    assert path is not None and path.is_file()
    rgb = np.asarray(Image.open(path).convert("RGB")).astype(int)
    blue = ((rgb[..., 2] - rgb[..., 0]) > 80).sum()
    red = ((rgb[..., 0] - rgb[..., 2]) > 80).sum()
    assert blue > 500 and red > 500  # +1 (soft) is deep blue, -3/5 (stiff) red
    assert claim_map([], tmp_path / "none.png", "nothing varies") is None


ONE_GRASP = [
    "campaign", "--set", "kind=grasp", "--set", "object.diameter_m=0.02", "--set", "object.x_m=0.04",
    "--set", "object.z_m=-0.11", "--set", "design.physics=board",
]  # fmt: skip


def test_a_single_valued_or_missing_axis_is_refused_before_any_run(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    with pytest.raises(ValueError, match=r"controller\.strategy_on must take exactly two values"):
        arm_values([_row(0.5, 3.0, 0.03, True, True)], "controller.strategy_on")
    for key in ("controller.strategy_on", "design.nope"):
        out = tmp_path / "r.jsonl"
        status = main([*ONE_GRASP, "--out", str(out), "--paired", key])
        err = capsys.readouterr().err.strip().splitlines()
        assert status == 2 and len(err) == 1 and "--paired:" in err[0] and "exactly two values" in err[0], err
        assert not out.exists() or out.stat().st_size == 0  # nothing ran


def test_the_cli_prints_the_cells_and_the_verdict_in_json(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    args = [
        "--set",
        "controller.strategy_on=[true, false]",
        "--out",
        str(tmp_path / "r.jsonl"),
        "--jobs",
        "1",
    ]
    status = main([*ONE_GRASP, *args, "--paired", "controller.strategy_on", "--json"])
    assert status == 0, capsys.readouterr().err
    paired = json.loads(capsys.readouterr().out)["paired"]
    assert paired["arm"] == "controller.strategy_on" and paired["a"] is True and paired["b"] is False
    (cell,) = paired["cells"]
    assert cell["pairs"] == 1 and cell["p"] == 1.0 and not cell["holds"]
    assert cell["placed_inside"] == 0 and 0.0 <= cell["penetration_m"] < 0.001  # real grasps, clean contacts
    assert paired["verdict"].startswith("strategy_on=true wins in none of 1 cells")
    assert "inside the arm" not in paired["verdict"]
