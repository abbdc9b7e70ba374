"""hil.identify.tracker: a simulated motion-capture tracker records the tip as a lab's would, the
identification reads it, and the rest of the recording is the same with or without it."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from hil import recording
from hil.identify.motor_data import load_motor_data
from hil.identify.rollout import RolloutJob, simulate
from hil.identify.synthetic import SensorLimits, record_truth
from hil.identify.tracker import TIP_TOPIC, TipTracker
from hil.identify.windows import LEN, TIP, at_samples, prepare_window
from hil.sim.config import ModelConfig
from hil.sim.uncertain import apply

TRUTH = {"base_stiffness": 0.65, "torque_scale": 1.2}
NOISE_M = 3e-4


@pytest.mark.parametrize(
    ("kwargs", "why"),
    [
        ({"noise_m": -1e-4}, "noise"),
        ({"noise_m": math.nan}, "noise"),
        ({"rate_hz": 0.0}, "rate"),
        ({"rate_hz": 2000.0}, "rate"),
    ],
)
def test_a_tracker_refuses_impossible_settings(kwargs: dict[str, float], why: str) -> None:
    with pytest.raises(ValueError, match=why):
        TipTracker(**kwargs)


def test_a_tracked_tip_is_the_plant_s_tip_within_its_noise_and_changes_nothing_else(tmp_path: Path) -> None:
    limits = SensorLimits(20.0, 0.0, 0)
    tracked, plain = tmp_path / "tracked.mcap", tmp_path / "plain.mcap"
    record_truth(tracked, TRUTH, seed=5, profile_name="tiny", limits=limits, tip_noise_m=NOISE_M)
    record_truth(plain, TRUTH, seed=5, profile_name="tiny", limits=limits)
    poses = [r for r in recording.read_records(tracked) if r.topic == TIP_TOPIC]
    d, p = load_motor_data(tracked), load_motor_data(plain)
    # 100 Hz of board time, as foxglove.PoseInFrame in the drone's frame.
    assert len(poses) == pytest.approx(100 * d.t_s[-1], abs=2)
    assert poses[0].json()["frame_id"] == "drone"
    # The motors' data are the same to the bit: the tracker's noise has its own random stream.
    assert p.tip_m is None and d.tip_m is not None and not np.isnan(d.tip_m).any()
    for name in ("t_s", "current_cmd_a", "length_m", "speed_m_s", "current_a"):
        assert np.array_equal(getattr(d, name), getattr(p, name)), name
    # The truth's rollout from the recorded commands puts the tip where the tracker saw it, to its noise;
    # the preset's, centimetres away (what the tracked tip tells a fit).
    w = prepare_window(d, len(d.t_s), 0.01)
    err = {}
    for name, model in (("truth", apply(ModelConfig(), TRUTH)), ("preset", ModelConfig())):
        sim = at_samples(w, simulate(RolloutJob(d.design, model, w.currents_a)))
        err[name] = np.sqrt(np.mean((sim[:, TIP] - w.measured[:, TIP]) ** 2, axis=0))
        if name == "truth":
            assert np.sqrt(np.nanmean((sim[:, LEN] - w.measured[:, LEN]) ** 2)) < 5e-6
    assert np.all(np.abs(err["truth"] / NOISE_M - 1.0) < 0.15), err["truth"]
    assert err["preset"].max() > 10 * NOISE_M, err["preset"]
