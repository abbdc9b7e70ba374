"""The experiments (hil.experiments) at their tiny size, and `spirob-hil experiment`."""

from __future__ import annotations

import json
import pickle
from pathlib import Path
from typing import Any

import pytest

from hil.cli.experiment import NO_GRASP
from hil.cli.main import main
from hil.experiments.base import Conditions
from hil.experiments.catalogue import EXPERIMENTS, run_experiment
from hil.experiments.contact import ContactParams, ReachTrial, contact_jobs
from hil.experiments.convergence import ConvergenceResult
from hil.experiments.geometry import ArmFootprint, design_scale
from hil.experiments.packing import PackingResult
from hil.experiments.strategy import StrategyParams, StrategyResult, arm_of, placements
from hil.experiments.workspace import WorkspaceResult
from hil.render import NO_GL
from hil.sim.config import ArmConfig, ModelConfig
from hil.sim.plant import Plant
from hil.sim.spiral import SpiralDesign
from hil.sim.types import PhysicsExtremes
from hil.sim.variants import Variant
from hil.trial.arm_45cm import paper_arm_45cm, scaled_model

STIFFER = ModelConfig(arm=ArmConfig(base_stiffness_nm_per_rad=1.2 * ArmConfig().base_stiffness_nm_per_rad))
"""A non-default model: every experiment must run on the model it is given."""


def _stiffnesses_from(model: ModelConfig) -> set[float]:
    """Base stiffnesses a rig may show when an experiment runs on ``model``: its own, the sensitivity
    variants' (x0.5, x1.5), and each of them scaled to the dynamic experiment's 45 cm arm."""
    proto = SpiralDesign.paper_prototype()
    out: set[float] = set()
    for f in (0.5, 1.0, 1.5):
        m = Variant("base stiffness", f).apply(model)
        out |= {
            m.arm.base_stiffness_nm_per_rad,
            scaled_model(m, paper_arm_45cm(), proto).arm.base_stiffness_nm_per_rad,
        }
    return out


@pytest.mark.parametrize("name", list(EXPERIMENTS))
def test_each_experiment_runs_tiny_on_a_given_model_reports_and_plots(
    name: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    seen: list[float] = []
    build = Plant.__init__

    def recording_init(self: Plant, *args: Any, **kwargs: Any) -> None:
        build(self, *args, **kwargs)
        seen.append(self.config.model.arm.base_stiffness_nm_per_rad)

    # Every plant an experiment builds (through a Rig or directly) is seen.
    monkeypatch.setattr(Plant, "__init__", recording_init)
    calls: list[tuple[int, int]] = []
    result = run_experiment(
        name, size="tiny", seed=3, progress=lambda d, t: calls.append((d, t)), model=STIFFER
    )
    # every plant ran on the given model (or a variant or scaling of it), none on the default one
    assert seen and set(seen) <= _stiffnesses_from(STIFFER)
    assert not set(seen) & _stiffnesses_from(ModelConfig())
    assert calls and calls[-1][0] == calls[-1][1]  # progress reached its total
    again = pickle.loads(pickle.dumps(result))  # picklable: campaigns can fan out
    assert again.as_dict()["seed"] == 3
    d = result.as_dict()
    json.dumps(d)  # JSON-ready (NaN allowed here; the CLI maps it to null)
    rows = result.table_rows()
    assert rows and all(len(r) == 3 for r in rows)
    assert result.describe_samples()
    png = result.figure(tmp_path)
    assert png.exists() and png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert d["extremes"]["tension_n"] > 0.0  # every experiment reports the worst physics of its trials
    assert any("penetration" in r[0] for r in rows)


def test_required_json_keys_through_the_cli(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    required = {
        "packing": ("b_design", "b_fit"),
        "workspace": ("inside_share",),
        "strategy": ("success_on", "success_off", "success_oracle", "penetration_m"),
    }
    for name, keys in required.items():
        assert (
            main(["experiment", name, "--size", "tiny", "--json", "--jobs", "1", "--report", str(tmp_path)])
            == 0
        )
        out = json.loads(capsys.readouterr().out)
        for key in keys:
            assert isinstance(out[key], float)
        assert out["samples"] and Path(out["figure"]).exists()
        index = Path(out["report"]).read_text()
        if name != "strategy":
            assert NO_GRASP in index and out["pictures"] == []
        elif NO_GL not in index:  # a held grasp and one that failed, each re-run and matching its trial
            assert "re-run differs" not in index
            names = [Path(p).name for p in out["pictures"]]
            assert "strategy-held.gif" in names and "strategy-failed.gif" in names
            assert any(n.startswith("strategy-held-") and "grasp-hold" in n for n in names)
        if name == "strategy":  # intervals per arm, McNemar of each strategy-on arm against off
            assert set(out["arms"]) == {"off", "on", "oracle"}
            assert all(len(a["ci95"]) == 2 and a["n"] == 1 for a in out["arms"].values())
            assert [c["arm"] for c in out["mcnemar"]] == ["on", "oracle"]
            assert all(0.0 <= c["p_value"] <= 1.0 for c in out["mcnemar"])
            # The reference placement clears the arm: no trial starts with the object inside it.
            assert out["placed_inside"] == 0
            assert all(o["placed_overlap_m"] <= 0.001 for o in out["outcomes"])
    assert main(["experiment", "packing", "--size", "tiny", "--jobs", "1"]) == 0
    table = capsys.readouterr().out
    assert "paper" in table and "b_fit" not in table and "fitted spiral b" in table


def test_bad_arguments_are_usage_errors(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["experiment", "nope"]) == 2
    assert main(["experiment", "packing", "--jobs", "0"]) == 2
    assert "error" in capsys.readouterr().err


def test_packing_fits_the_design_spiral_and_curls_from_the_tip() -> None:
    r = run_experiment("packing", size="tiny")
    assert isinstance(r, PackingResult)
    assert r.packed
    assert r.b_fit == pytest.approx(r.b_design, rel=0.03)
    assert r.order_correlation < -0.8  # the tip closes first


def test_workspace_samples_stay_inside_the_envelope() -> None:
    r = run_experiment("workspace", size="tiny", seed=1)
    assert isinstance(r, WorkspaceResult)
    assert r.inside_share == pytest.approx(1.0)
    assert 0.0 < r.runs[0].coverage < 1.0


def test_strategy_on_grasps_the_reference_placement() -> None:
    r = run_experiment("strategy", size="tiny")
    assert isinstance(r, StrategyResult)
    assert sorted(arm_of(o) for o in r.outcomes) == ["off", "on", "oracle"]
    assert len({(o.setup.x_m, o.setup.z_m, o.setup.diameter_m) for o in r.outcomes}) == 1  # paired
    on = next(o for o in r.outcomes if arm_of(o) == "on")
    # Under the stiff contacts the firmware's own grasp holds this object but wraps it less than half way
    # (160°, and 170° on another machine: no success by the paper's criterion). With the true contact the
    # wrap is on the edge of that criterion: 197° and 4 units on one machine, 167° and 3 units on another
    # (an AMD EPYC), the same code and packages. A single grasp's wrap here moves by 30° with the
    # machine's rounding, so this test holds each arm to what both machines showed, not to one's outcome.
    assert on.state == "HOLD" and on.held and on.contact_s > 0
    assert on.max_current_raw <= 3000
    assert on.success == (on.held and on.wrap_deg >= 180.0)
    oracle = next(o for o in r.outcomes if arm_of(o) == "oracle")
    assert oracle.contact_s > 0  # the simulator's contact ended the reach
    assert oracle.state == "HOLD" and oracle.held and oracle.units_after >= 3
    assert oracle.success == (oracle.held and oracle.wrap_deg >= 180.0)


def test_strategy_placements_are_jittered_paired_and_clear_of_the_packed_coil() -> None:
    design = SpiralDesign.paper_prototype()
    p = StrategyParams()
    spots = placements(design, p, seed=0)
    for d in p.diameters_m:
        assert sum(1 for s in spots if s[2] == d) >= 48
    foot = ArmFootprint.of(design, ModelConfig())
    assert all(foot.clearance_m(x, z, d / 2) >= p.clearance_m for x, z, d in spots)
    assert foot.clearance_m(0.03, -0.03, 0.01) < 0  # inside the packed coil
    assert spots == placements(design, p, seed=0) != placements(design, p, seed=1)


def test_convergence_tiny_measures_each_step_and_the_finer_step_meets_the_penetration_goal() -> None:
    r = run_experiment("convergence", size="tiny")
    assert isinstance(r, ConvergenceResult)
    assert [s.timestep_s for s in r.steps] == [0.001, 0.0005]
    for s in r.steps:
        # the stated contacts' goal (docs/plant.md): under 1 mm for a pen pressed by a 54 N curl
        assert s.press_penetration_m < 1e-3
        assert s.random_tension_n > 0.0
    # While the wedge tip whips around the pen (~1.5 m/s) the 1 ms step lets it 1.15 mm in, over the goal
    # (reported as such in docs/plant.md); the 0.5 ms step meets it.
    assert r.steps[0].wrap_penetration_m < 2e-3
    assert r.steps[1].wrap_penetration_m < 1e-3
    rows = r.table_rows()
    assert rows[0][1] == "1 ms | 0.5 ms"


def test_contact_trial_kinds() -> None:
    nan = float("nan")
    none = PhysicsExtremes(0.0, 0.0, 0.0, 0.0)
    kinds = [
        ReachTrial(0, 0, 0, "new", tr, de, "", none).kind for tr, de in ((1, 2), (2, 1), (1, nan), (nan, nan))
    ]
    assert kinds == ["TP", "FP", "FN", "TN"]


def test_contact_reaches_at_the_strategys_placements() -> None:
    design = SpiralDesign.paper_prototype()
    spots = placements(design, StrategyParams(), seed=0)
    jobs = contact_jobs(ContactParams(), Conditions(design, seed=0))
    assert [(s.x_m, s.z_m, s.diameter_m) for s, det, _ in jobs[::2]] == spots
    assert {det for _, det, _ in jobs} == {"old", "new"}


def test_physics_flag_and_a_step_too_coarse_for_fine_constraints(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["experiment", "packing", "--size", "tiny", "--jobs", "1", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert (out["timestep_s"], out["contact_timeconst_s"], out["limit_timeconst_s"]) == (
        0.25e-3,
        0.5e-3,
        0.5e-3,
    )
    assert (
        main(["experiment", "packing", "--size", "tiny", "--jobs", "1", "--json", "--physics", "board"]) == 0
    )
    out = json.loads(capsys.readouterr().out)
    assert (out["timestep_s"], out["contact_timeconst_s"], out["limit_timeconst_s"]) == (1e-3, 2e-3, 2e-3)
    assert main(["experiment", "packing", "--size", "tiny", "--timestep-ms", "1"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--physics board" in err[0] and "Traceback" not in err[0]


@pytest.mark.parametrize("name", ["grasp-range", "load"])
def test_the_grasp_experiments_scale_their_placements_to_a_longer_arm(name: str) -> None:
    # The placements were chosen on the 22 cm prototype: on the authors' 47 cm arm, 92 mm wide at its base,
    # the unscaled gaps (5-45 mm from the axis) all lie inside the arm and no placement cleared it.
    proto = SpiralDesign.paper_prototype()
    authors = SpiralDesign.authors_default()
    s = design_scale(authors)
    assert design_scale(proto) == 1.0
    assert s == pytest.approx(authors.length_m / proto.length_m)
    r = run_experiment(name, design=authors, size="tiny")
    d = r.params.diameters_m[0] if name == "grasp-range" else r.params.diameter_m
    base = EXPERIMENTS[name].sizes.tiny
    assert d == pytest.approx(s * (base.diameters_m[0] if name == "grasp-range" else base.diameter_m))
    for o in r.outcomes:
        assert ArmFootprint.of(authors, o.setup.model).clearance_m(o.setup.x_m, o.setup.z_m, d / 2) > 0.0
