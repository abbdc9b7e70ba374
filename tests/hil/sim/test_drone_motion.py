"""hil.sim.drone_motion: the scripted acceleration profile, and the lockstep loop applying it to the plant."""

from __future__ import annotations

import pickle

import numpy as np
import pytest

from hil.board import BoardConfig
from hil.environment import Environment, Episode
from hil.sim.drone_motion import AccelSegment, DroneMotion, accelerate_and_brake

MS = 1000


def test_acceleration_at_given_times() -> None:
    motion = DroneMotion(
        (
            *accelerate_and_brake(1000 * MS, (2.0, 0.0, 0.0), 1000 * MS),
            AccelSegment(4000 * MS, 500 * MS, (0.0, -1.5, 0.5)),
        )
    )
    assert motion.accel_at(0) == (0.0, 0.0, 0.0)
    assert motion.accel_at(999_999) == (0.0, 0.0, 0.0)
    assert motion.accel_at(1000 * MS) == (2.0, 0.0, 0.0)  # a segment covers [start, end)
    assert motion.accel_at(1999_999) == (2.0, 0.0, 0.0)
    assert motion.accel_at(2000 * MS) == (-2.0, -0.0, -0.0)  # the braking, as hard and as long
    assert motion.accel_at(2999_999) == (-2.0, -0.0, -0.0)
    assert motion.accel_at(3000 * MS) == (0.0, 0.0, 0.0)
    assert motion.accel_at(4200 * MS) == (0.0, -1.5, 0.5)
    assert motion.accel_at(4500 * MS) == (0.0, 0.0, 0.0)
    assert motion.end_us == 4500 * MS
    # the push and the braking touch: no zero between them; a gap gets one
    assert motion.changes() == (
        (1000 * MS, (2.0, 0.0, 0.0)),
        (2000 * MS, (-2.0, -0.0, -0.0)),
        (3000 * MS, (0.0, 0.0, 0.0)),
        (4000 * MS, (0.0, -1.5, 0.5)),
        (4500 * MS, (0.0, 0.0, 0.0)),
    )


def test_integers_become_floats_and_a_motion_pickles() -> None:
    motion = DroneMotion((AccelSegment(0, 10, (1, 0, 0)),))
    assert motion.segments[0].accel_m_s2 == (1.0, 0.0, 0.0)
    assert isinstance(motion.segments[0].accel_m_s2[0], float)
    assert pickle.loads(pickle.dumps(motion)) == motion


@pytest.mark.parametrize(
    ("make", "message"),
    [
        (lambda: AccelSegment(-1, 10, (0, 0, 0)), "start_us must be >= 0, got -1"),
        (lambda: AccelSegment(0, 0, (0, 0, 0)), "duration_us must be > 0, got 0"),
        (lambda: AccelSegment(0.5, 10, (0, 0, 0)), "start_us must be an integer number of microseconds"),
        (lambda: AccelSegment(0, True, (0, 0, 0)), "duration_us must be an integer number of microseconds"),
        (lambda: AccelSegment(0, 10, (1.0, 2.0)), "accel_m_s2 must be three numbers (x, y, z)"),
        (lambda: AccelSegment(0, 10, (1.0, float("nan"), 0.0)), "accel_m_s2 must be three finite numbers"),
        (lambda: AccelSegment(0, 10, "abc"), "accel_m_s2 must be three numbers (x, y, z)"),
        (lambda: accelerate_and_brake(0, (1.0,), 10), "accel_m_s2 must be three numbers (x, y, z)"),
        (lambda: DroneMotion(()), "a drone motion needs at least one segment"),
        (
            lambda: DroneMotion((AccelSegment(0, 10, (1, 0, 0)), AccelSegment(5, 10, (1, 0, 0)))),
            "drone motion segment 1 starts at 5 us, before segment 0 ends at 10 us",
        ),
    ],
)
def test_bad_profiles_are_refused_in_one_line(make: object, message: str) -> None:
    with pytest.raises(ValueError) as info:
        make()  # type: ignore[operator]
    text = str(info.value)
    assert message in text and "\n" not in text


class _Gravity(Episode):
    """Records the plant's gravity in force during each tick (set before the tick's physics)."""

    def __init__(self) -> None:
        self.gravity: list[tuple[int, tuple[float, ...]]] = []

    def after_tick(self, env: Environment) -> None:
        g = env.board.plant.mj_model.opt.gravity
        self.gravity.append((env.board.plant.time_us - env.period_us, tuple(float(v) for v in g)))


def test_the_loop_applies_the_acceleration_in_plant_time_and_holds_the_pose() -> None:
    spy = _Gravity()
    motion = DroneMotion((AccelSegment(3 * MS, 2 * MS, (8.0, -1.0, 2.0)),))
    with Environment(BoardConfig(), episode=spy, drone=motion) as env:
        pose = env.board.plant.drone_pose()
        g = tuple(float(v) for v in env.board.plant.mj_model.opt.gravity)
        env.run(7 * MS)
        after = env.board.plant.drone_pose()
    pushed = (g[0] - 8.0, g[1] + 1.0, g[2] - 2.0)  # the drone's frame: gravity becomes g - a
    # each entry: the start of the tick's physics step, the gravity it ran with
    assert spy.gravity == [
        (0, g),
        (1 * MS, g),
        (2 * MS, g),
        (3 * MS, pushed),
        (4 * MS, pushed),
        (5 * MS, g),
        (6 * MS, g),
    ]
    assert np.array_equal(after.pos_m, pose.pos_m) and np.array_equal(after.quat_wxyz, pose.quat_wxyz)


def test_a_push_swings_the_hanging_arm_backwards() -> None:
    # The unarmed arm hangs straight; pushing the drone along +x swings the tip towards -x (it lags),
    # and without the push it stays where it hangs.
    motion = DroneMotion((AccelSegment(0, 300 * MS, (8.0, 0.0, 0.0)),))
    with Environment(BoardConfig()) as still:
        x0 = float(still.board.plant.tip_pose().pos_m[0])
        still.run(300 * MS)
        x_still = float(still.board.plant.tip_pose().pos_m[0])
    with Environment(BoardConfig(), drone=motion) as pushed:
        pushed.run(300 * MS)
        x_pushed = float(pushed.board.plant.tip_pose().pos_m[0])
    assert abs(x_still - x0) < 1e-3
    assert x_pushed < x0 - 0.01


def test_a_change_between_two_control_periods_is_refused() -> None:
    # A 0.5 ms blip would fall between two 1 ms periods and never be applied: refused, in one line.
    motion = DroneMotion((AccelSegment(2 * MS, 500, (8.0, 0.0, 0.0)),))
    with pytest.raises(ValueError) as info:
        Environment(BoardConfig(), drone=motion)
    assert str(info.value) == "the drone motion changes at 2500 us, not on the 1000 us control period"
