"""host.panel.board_state (latest telemetry, history, poses) and host.panel.history."""

from __future__ import annotations

import numpy as np
import pytest

from host.panel.board_state import BoardState, PoseSource
from host.panel.history import RingBuffer
from protocol.messages import (
    AckResult,
    ArmPoses,
    ArmsTelemetry,
    CommandAck,
    CommandCode,
    Phase,
    SimPoses,
    Telemetry,
    Vec3f,
    Vec4f,
)


def test_telemetry_history() -> None:
    b = BoardState()
    for i in range(5):
        b.on_board_message(Telemetry(time_us=i * 10_000, phase=Phase.OK, commanded_current=(1000, 0, 0)))
    b.on_board_message(Telemetry(time_us=60_000, phase=Phase.RC_LOST))
    data = b.history.snapshot()
    assert data.shape == (6, 16)
    assert data[0, 7] == pytest.approx(1.0)  # commanded current of motor 1 in A
    assert b.telemetry_count == 6 and b.telemetry is not None and b.telemetry.phase == Phase.RC_LOST
    b.on_board_message(Telemetry(time_us=1_000))  # the board restarted: the history starts again
    assert b.history.snapshot().shape == (1, 16)
    ack = CommandAck(CommandCode.ARM, AckResult.ACCEPTED, 3)
    b.on_board_message(ack)
    assert b.last_ack == ack


def test_board_poses_win_over_the_shadow_plants() -> None:
    b = BoardState()
    poses = SimPoses(0, ((0.0, 0.0, 1.0),), ((1.0, 0.0, 0.0, 0.0),))
    assert b.on_shadow_poses(poses) and b.pose_source is PoseSource.SHADOW
    b.on_board_message(poses)
    assert b.pose_source is PoseSource.SIMULATION and b.poses_event.is_set()
    assert not b.on_shadow_poses(poses)
    assert b.pose_source is PoseSource.SIMULATION and b.poses_count == 2


_Q: Vec4f = (1.0, 0.0, 0.0, 0.0)


def _units(arm: int, n: int) -> tuple[tuple[Vec3f, ...], tuple[Vec4f, ...]]:
    return tuple((float(arm), 0.0, -u / 10) for u in range(n)), (_Q,) * n


def _bodies(b: BoardState) -> tuple[np.ndarray, np.ndarray, int]:
    got = b.bodies()
    assert got is not None
    return got


def test_an_arrays_poses_join_simposes_and_armposes_arm_after_arm() -> None:
    b = BoardState()
    assert b.bodies() is None and b.arms == 1
    p0, q0 = _units(0, 3)
    b.on_board_message(SimPoses(5, ((0.0, 0.0, 1.0), *p0), (_Q, *q0)))
    pos, _, arms = _bodies(b)
    assert arms == 1 and pos.shape == (4, 3)  # one arm until the others arrive
    b.on_board_message(ArmPoses(5, 3, 4, *_units(3, 3)))  # arms out of order
    b.on_board_message(ArmPoses(5, 1, 4, *_units(1, 3)))
    b.on_board_message(ArmPoses(5, 2, 4, *_units(2, 2)))  # not as many units as arm 0: left out
    assert b.arms == 4 and b.poses_event.is_set()
    pos, quats, arms = _bodies(b)
    assert arms == 3 and pos.shape == (10, 3) and quats.shape == (10, 4)
    assert pos[1:, 0].tolist() == [0.0] * 3 + [1.0] * 3 + [3.0] * 3  # drone, arm 0, then by arm index
    b.on_board_message(ArmPoses(6, 2, 4, *_units(2, 3)))
    assert _bodies(b)[2] == 4
    b.on_board_message(ArmPoses(7, 1, 2, *_units(1, 3)))  # another plant: the old arms are forgotten
    assert set(b.arm_poses) == {1} and _bodies(b)[2] == 2


def test_an_arrays_layout_comes_from_arms_telemetry() -> None:
    b = BoardState()
    assert b.layout is None
    four = (0,) * 8
    b.on_board_message(
        ArmsTelemetry(1, 4, 2, four, four, four, four, (0.0,) * 8, (0.0,) * 8, (0.0,) * 8, (False,) * 8)
    )
    assert b.layout == (4, 2) and b.arms == 4
    b.on_board_message(Telemetry(time_us=10))
    b.on_board_message(ArmPoses(10, 1, 4, *_units(1, 3)))
    b.on_board_message(Telemetry(time_us=5))  # the board restarted: what it was is forgotten
    assert b.layout is None and b.arm_poses == {} and b.arms == 1


def test_ring_buffer_keeps_newest_and_decimates() -> None:
    rb = RingBuffer(4, 1)
    for i in range(10):
        rb.append(float(i), [float(i * 2)])
    snap = rb.snapshot()
    assert snap[:, 0].tolist() == [6.0, 7.0, 8.0, 9.0]
    assert rb.snapshot(max_points=2)[:, 0].tolist() == [7.0, 9.0]
    with pytest.raises(ValueError):
        RingBuffer(0, 1)
