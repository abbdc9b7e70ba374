"""Array campaigns (kind = "array"): the ring's radius and the arms' design as axes of array grasps."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from hil.campaign.runner import array_setup, run_one
from hil.campaign.spec import CampaignError, parse_campaign
from hil.cli.main import main
from hil.experiments.array import ArrayParams, ring_radius_m


def _raw(**array: object) -> dict[str, object]:
    return {
        "kind": "array",
        "design": {"physics": "board"},
        "array": {"arms": 4, "object": "sphere", **array},
    }


def test_an_array_campaign_varies_the_ring_and_the_arm() -> None:
    raw = _raw(ring_radius_m=[0.06, 0.09], tilt_deg=10.0)
    raw["design"] = {"physics": "board", "length_m": [0.2, 0.23], "tip_width_m": 0.007, "taper_deg": 6.5}
    runs = parse_campaign(raw).runs()
    assert len(runs) == 4
    setups = [array_setup(r.inputs) for r in runs]
    assert {s.ring_radius_m for s in setups} == {0.06, 0.09}
    assert all(s.tilt_rad == pytest.approx(0.17453292519943295) for s in setups)
    # (a whole number of units: the realised length within a few per cent of the asked one)
    assert sorted({s.arm_design().length_m for s in setups}) == pytest.approx([0.2, 0.23], rel=0.05)
    assert all(s.arm_design().cables == 1 and s.arms == 4 for s in setups)
    # No radius given: the experiment's, sized to the object; the jitter comes from the run's seed.
    rod = array_setup({**runs[0].inputs, "array.object": "rod", "array.ring_radius_m": None})
    assert rod.ring_radius_m == ring_radius_m("rod", ArrayParams(), rod.arm_design()) > 0.1
    assert array_setup(runs[0].inputs).offset_m == setups[0].offset_m


@pytest.mark.parametrize(
    ("raw", "says"),
    [
        ({"kind": "array", "array": {"object": "sphere"}}, "needs array.arms"),
        (_raw(object="teapot"), "array.object: unknown 'teapot'"),
        (_raw(arms=9), "array.arms must be 1..8"),
        ({**_raw(), "design": {"cables": 2}}, "one cable each"),
        ({**_raw(), "controller": {"strategy_on": True}}, "controller.strategy_on: not a key of a array"),
        (_raw(ring_radius_m=-0.1), "array.ring_radius_m must be"),
        (_raw(tilt_deg=95.0), "array.tilt_deg must be"),
        ({"kind": "grasp", "array": {"arms": 2}}, "array.arms: not a key of a grasp"),
    ],
)
def test_bad_array_campaigns_are_one_line(raw: dict[str, object], says: str) -> None:
    with pytest.raises(CampaignError, match=says.replace(".", r"\.")):
        parse_campaign(raw)


def test_an_array_run_is_a_row_and_the_cli_sums_it_up(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    run = parse_campaign(_raw(hold_s=0.5)).runs()[0]
    row = run_one(run)
    assert row["outcome"] in ("success", "failure") and "error" not in row
    assert row["measured"]["ring_radius_m"] == 0.06 and len(row["measured"]["offset_m"]) == 3
    out = tmp_path / "rows.jsonl"
    argv = ["campaign", "--set", "kind=array", "--set", "array.arms=2", "--set", "array.object=cube"]
    argv += [
        "--set",
        "design.physics=board",
        "--set",
        "array.hold_s=0.5",
        "-o",
        str(out),
        "--jobs",
        "1",
        "--json",
    ]
    assert main(argv) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["kind"] == "array"
    (only,) = [json.loads(line) for line in out.read_text().splitlines()]
    assert only["inputs"]["array.object"] == "cube" and only["outcome"] in ("success", "failure")
