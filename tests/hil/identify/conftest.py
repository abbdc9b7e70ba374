"""Recordings the identification tests share (made once per session: each is a lockstep run)."""

from __future__ import annotations

from pathlib import Path

import pytest

from hil.identify.synthetic import SensorLimits, record_truth

TRUTH = {"base_stiffness": 0.65, "damping_ratio": 0.2}
"""Two parameters off the prototype's (0.5 N·m/rad, 0.13): the fast fit's hidden truth."""


@pytest.fixture(scope="session")
def truth_recording(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The ``tiny`` excitation on a plant with :data:`TRUTH`, seen through the C610's resolution and its
    current noise (the bus's and the loop's timing, which act as a delay, are the benchmark's: it fits the
    delay too)."""
    path = tmp_path_factory.mktemp("identify") / "truth.mcap"
    record_truth(path, TRUTH, seed=3, profile_name="tiny", limits=SensorLimits(20.0, 0.0, 0))
    return path


@pytest.fixture(scope="session")
def preset_recording(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The ``tiny`` excitation on the prototype itself, exact sensors but for the C610's resolution."""
    path = tmp_path_factory.mktemp("identify") / "preset.mcap"
    record_truth(path, {}, seed=4, profile_name="tiny", limits=SensorLimits(0.0, 0.0, 0))
    return path
