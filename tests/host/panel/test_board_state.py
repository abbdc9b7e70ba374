"""host.panel.board_state (latest telemetry, history, poses) and host.panel.history."""

from __future__ import annotations

import pytest

from host.panel.board_state import BoardState, PoseSource
from host.panel.history import RingBuffer
from protocol.messages import AckResult, CommandAck, CommandCode, Phase, SimPoses, Telemetry


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


def test_ring_buffer_keeps_newest_and_decimates() -> None:
    rb = RingBuffer(4, 1)
    for i in range(10):
        rb.append(float(i), [float(i * 2)])
    snap = rb.snapshot()
    assert snap[:, 0].tolist() == [6.0, 7.0, 8.0, 9.0]
    assert rb.snapshot(max_points=2)[:, 0].tolist() == [7.0, 9.0]
    with pytest.raises(ValueError):
        RingBuffer(0, 1)
