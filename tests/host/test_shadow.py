"""host.shadow: the shadow plant that poses the arm from a real board's measured motor currents.

Synthetic ``Telemetry`` frames stand in for the board (a unit-test fake input); the plant is the real
``hil.sim.plant.Plant`` except where a counting stub makes the step bookkeeping exact.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable, Iterator
from typing import Any

import numpy as np
import pytest

from host.app import HostApp
from host.options import HostOptions
from host.panel.board_state import BoardState, PoseSource
from host.shadow import ShadowConfig, ShadowPlant, ShadowState, reel_in_currents
from protocol.messages import ArmsTelemetry, SimPoses, Telemetry, TelemetryFlags
from tests.support.link_peer import HardwarePeer, LinkPeer
from tests.support.realtime_guard import wait_for

FRAME_US = 10_000  # the board's telemetry period (100 Hz)


def telemetry(
    time_us: int, currents: tuple[int, int, int], *, sim: bool = False, online: int = 0b111
) -> Telemetry:
    """A frame as the board sends it: measured currents and the tension estimated from them."""
    n_per_raw = 0.18 / 0.01 / 1000.0  # K_t / r_spool per raw unit: the firmware's default constants
    return Telemetry(
        time_us=time_us,
        flags=TelemetryFlags.SIM if sim else TelemetryFlags.NONE,
        motors_online=online,
        motor_current=currents,
        tension_est_n=(currents[0] * n_per_raw, currents[1] * n_per_raw, currents[2] * n_per_raw),
    )


class Published:
    """Collects what the shadow publishes."""

    def __init__(self) -> None:
        self.poses: list[SimPoses] = []

    def __call__(self, poses: SimPoses) -> None:
        self.poses.append(poses)


def feed(shadow: ShadowPlant, frames: list[Telemetry]) -> None:
    """One frame at a time, each applied before the next (the thread keeps only the newest)."""
    for frame in frames:
        before = shadow.stats().updates
        shadow.on_board_message(frame)
        assert _wait(lambda n=before: shadow.stats().updates > n), f"frame at {frame.time_us} us not applied"


@pytest.fixture
def published() -> Published:
    return Published()


@pytest.fixture
def shadow(published: Published) -> Iterator[ShadowPlant]:
    with ShadowPlant(published) as s:
        yield s


# ---------------------------------------------------------------------- currents in


def test_reel_in_currents_sign_and_offline_motors() -> None:
    assert reel_in_currents(telemetry(0, (800, -300, 0))) == (800, -300, 0)
    # A mirrored motor (motor_signs -1): negative current, positive tension estimate = reeling in.
    mirrored = dataclasses.replace(telemetry(0, (-800, 0, 0)), tension_est_n=(14.4, 0.0, 0.0))
    assert reel_in_currents(mirrored) == (800, 0, 0)
    # Motor 2 offline: its last reading is stale.
    assert reel_in_currents(telemetry(0, (500, 500, 500), online=0b101)) == (500, 0, 500)


# ---------------------------------------------------------------------- the arm follows the currents


def test_constant_current_on_cable_1_bends_the_arm_toward_cable_1(
    shadow: ShadowPlant, published: Published
) -> None:
    feed(shadow, [telemetry(5_000_000 + k * FRAME_US, (800, 0, 0)) for k in range(81)])
    st = shadow.stats()
    assert st.state is ShadowState.RUNNING
    assert st.updates == 81 and st.steps == 800  # 0.8 s of board time, 1 ms per step
    assert st.board_time_us == 5_800_000 and st.skipped_us == 0
    first, last = published.poses[0], published.poses[-1]
    assert last.time_us == 5_800_000
    assert len(last.positions_m) == len(first.positions_m) >= 10  # drone + units
    base = np.asarray(first.positions_m[1])
    tip0 = np.asarray(first.positions_m[-1])
    tip = np.asarray(last.positions_m[-1])
    assert abs(tip0[0] - base[0]) < 1e-6 and abs(tip0[1] - base[1]) < 1e-6  # hanging straight at first
    # Cable 1 runs at azimuth 0 (hil.sim.mjcf.cable_angles_rad): +x. The tip swings that way and rises.
    side = np.array([math.cos(0.0), math.sin(0.0)])
    moved = tip[:2] - base[:2]
    assert float(moved @ side) > 0.02
    assert abs(float(moved[0] * side[1] - moved[1] * side[0])) < 0.2 * float(moved @ side)
    assert tip[2] > tip0[2] + 0.01


def test_no_current_keeps_the_arm_hanging(shadow: ShadowPlant, published: Published) -> None:
    feed(shadow, [telemetry(k * FRAME_US, (0, 0, 0)) for k in range(21)])
    tip = np.asarray(published.poses[-1].positions_m[-1])
    base = np.asarray(published.poses[-1].positions_m[1])
    assert np.hypot(*(tip[:2] - base[:2])) < 1e-3


# ---------------------------------------------------------------------- board time, bounded


class CountingPlant:
    """Stand-in with the plant's interface that counts steps (exact bookkeeping, no physics)."""

    control_period_us = 1000

    def __init__(self) -> None:
        self.steps = 0
        self.currents: list[tuple[int, ...]] = []

    def step(self) -> None:
        self.steps += 1

    def reset(self) -> None:
        pass

    def apply_currents(self, raw: tuple[int, ...]) -> tuple[int, ...]:
        self.currents.append(tuple(raw))
        return tuple(raw)

    def body_poses(self) -> Any:
        class _Poses:
            positions_m = np.zeros((3, 3))
            quats_wxyz = np.tile([1.0, 0.0, 0.0, 0.0], (3, 1))

        return _Poses()


def test_steps_follow_board_time_bounded_and_resync_on_restart(published: Published) -> None:
    plant = CountingPlant()
    with ShadowPlant(published, plant_factory=lambda: plant, config=ShadowConfig(max_step_us=50_000)) as s:
        feed(s, [telemetry(1_000_000, (100, 0, 0))])
        assert plant.steps == 0  # the first frame only sets the clock
        feed(s, [telemetry(1_012_500, (200, 0, 0))])
        assert plant.steps == 12  # 12.5 ms: 12 whole periods, the half carries over
        feed(s, [telemetry(1_020_000, (300, 0, 0))])
        assert plant.steps == 20
        feed(s, [telemetry(3_020_000, (300, 0, 0))])  # a 2 s gap: at most 50 ms simulated
        assert plant.steps == 70
        assert s.stats().skipped_us == 1_950_000
        feed(s, [telemetry(10_000, (0, 0, 0))])  # board restarted: resync, no steps
        assert plant.steps == 70 and s.stats().resyncs == 1
        feed(s, [telemetry(20_000, (0, 0, 0))])
        assert plant.steps == 80
    # Zero-order hold: each frame's currents are applied after stepping through the interval before it.
    assert plant.currents[:3] == [(100, 0, 0), (200, 0, 0), (300, 0, 0)]
    assert s.state is ShadowState.STOPPED


# ---------------------------------------------------------------------- SimPoses switch it off


def test_sim_poses_switch_the_shadow_off() -> None:
    model = BoardState()
    with ShadowPlant(model.on_shadow_poses) as shadow:
        feed(shadow, [telemetry(k * FRAME_US, (500, 0, 0)) for k in range(5)])
        assert model.pose_source is PoseSource.SHADOW
        shadow_poses = model.poses
        assert shadow_poses is not None
        board_poses = SimPoses(60_000, ((0.0, 0.0, 1.0), (0.0, 0.0, 0.98)), ((1.0, 0.0, 0.0, 0.0),) * 2)
        for listener in (model.on_board_message, shadow.on_board_message):
            listener(board_poses)
        assert _wait(lambda: shadow.state is ShadowState.OFF_SIM_POSES)
        n = shadow.stats().updates
        shadow.on_board_message(telemetry(70_000, (500, 0, 0)))
        time.sleep(0.05)
        assert shadow.stats().updates == n and not shadow.active
        assert model.pose_source is PoseSource.SIMULATION and model.poses is board_poses
        # A late shadow pose never replaces the board's own.
        assert not model.on_shadow_poses(shadow_poses) and model.poses is board_poses
    assert shadow.state is ShadowState.OFF_SIM_POSES  # stop() keeps the reason


def test_a_simulating_board_gets_time_to_send_its_poses_before_a_plant_is_built() -> None:
    built: list[CountingPlant] = []

    def factory() -> CountingPlant:
        built.append(CountingPlant())
        return built[-1]

    with ShadowPlant(Published(), plant_factory=factory, config=ShadowConfig(sim_grace_us=300_000)) as s:
        for k in range(20):  # 200 ms of SIM telemetry, then the board's poses
            s.on_board_message(telemetry(k * FRAME_US, (0, 0, 0), sim=True))
        time.sleep(0.05)
        s.on_board_message(SimPoses(200_000, ((0.0, 0.0, 1.0),), ((1.0, 0.0, 0.0, 0.0),)))
        assert _wait(lambda: s.state is ShadowState.OFF_SIM_POSES)
    assert built == []


def _arms_telemetry(time_us: int) -> ArmsTelemetry:
    four = (0,) * 4
    return ArmsTelemetry(
        time_us, 4, 1, four, four, four, four, (0.0,) * 4, (0.0,) * 4, (0.0,) * 4, (False,) * 4
    )


@pytest.mark.parametrize("slow_build", [False, True])
def test_an_array_board_switches_the_shadow_off_with_its_reason(slow_build: bool) -> None:
    """Motors 1-3 of an array are cables of different arms: the one-arm shadow would draw a wrong shape.
    ArmsTelemetry comes right after each Telemetry: a plant built meanwhile never publishes."""
    built: list[CountingPlant] = []

    def factory() -> CountingPlant:
        if slow_build:
            time.sleep(0.2)  # ArmsTelemetry arrives while the plant is built
        built.append(CountingPlant())
        return built[-1]

    published = Published()
    with ShadowPlant(published, plant_factory=factory) as s:
        if slow_build:  # the first Telemetry starts the build before its ArmsTelemetry is in
            s.on_board_message(telemetry(0, (500, 0, 0)))
            time.sleep(0.05)
        s.on_board_message(_arms_telemetry(0))
        s.on_board_message(telemetry(FRAME_US, (500, 0, 0)))
        assert _wait(lambda: s.state is ShadowState.OFF_ARRAY)
        assert not s.active and published.poses == []
        assert "array" in s.stats().describe() and "one arm" in s.stats().describe()
    assert s.state is ShadowState.OFF_ARRAY  # stop() keeps the reason


def test_a_plant_that_cannot_be_built_fails_in_one_line() -> None:
    def broken() -> Any:
        raise RuntimeError("no MuJoCo here")

    with ShadowPlant(Published(), plant_factory=broken) as s:
        s.on_board_message(telemetry(0, (0, 0, 0)))
        assert _wait(lambda: s.state is ShadowState.FAILED)
        assert "no MuJoCo here" in s.stats().describe()


# ---------------------------------------------------------------------- in spirob-host


def test_host_poses_a_hardware_board_from_the_shadow_plant() -> None:
    with HardwarePeer("socket") as peer, HostApp(HostOptions(port=peer.url, ui=False)) as app:
        app.start()
        assert app.shadow is not None
        assert _wait(lambda: app.board_state.pose_source is PoseSource.SHADOW, 20.0)
        assert app.board_state.poses is not None and len(app.board_state.poses.positions_m) >= 10
        assert "real time" in app._shadow_status()
    assert app.shadow is None  # stopped and released by close()


def test_host_switches_the_shadow_off_for_a_board_with_sim_poses() -> None:
    with LinkPeer("socket") as peer, HostApp(HostOptions(port=peer.url, ui=False)) as app:
        app.start()
        shadow = app.shadow
        assert shadow is not None
        assert _wait(lambda: shadow.state is ShadowState.OFF_SIM_POSES, 20.0)
        assert app.board_state.pose_source is PoseSource.SIMULATION


def test_no_shadow_flag() -> None:
    with LinkPeer("socket") as peer, HostApp(HostOptions(port=peer.url, ui=False, shadow=False)) as app:
        app.start()
        assert app.shadow is None


def _wait(cond: Callable[[], bool], timeout_s: float = 10.0) -> bool:
    return wait_for(cond, timeout_s, 0.002)
