"""hil.sim.plant.Plant with a ring: an array of arms, each with its own cables, drives and capstan friction,
laid out as the firmware lays out an array (motor m drives cable (m-1) % C of arm (m-1) // C)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from controller.config import FirmwareConfig
from hil.board import BoardConfig, VirtualBoard, board_plant_config
from hil.canbus import SimMotorBus
from hil.sim.config import ObjectConfig
from hil.sim.plant import Plant
from hil.sim.spiral import SpiralDesign
from hil.sim.types import PlantConfig, RingConfig

ONE_CABLE = dataclasses.replace(SpiralDesign.paper_prototype(), cables=1)


def _array(arms: int, design: SpiralDesign = ONE_CABLE, **ring: float) -> Plant:
    return Plant(design, PlantConfig(ring=RingConfig(arms=arms, **ring)))  # type: ignore[arg-type]


def _horizontal(v: np.ndarray) -> np.ndarray:
    return np.array([v[0], v[1], 0.0])


def test_an_array_is_laid_out_arm_after_arm() -> None:
    p = _array(4, dataclasses.replace(ONE_CABLE, cables=2), ring_radius_m=0.1)
    assert (p.arms, p.cables, p.motors, p.units_per_arm) == (4, 2, 8, 21)
    assert len(p.feedback()) == 8 and p.cable_lengths_m().shape == (8,)
    assert p.joint_angles_rad().shape == (4 * 20,)
    names = p.body_poses().names
    assert names[:3] == ("drone", "a0_unit_00", "a0_unit_01") and names[-1] == "a3_unit_20"
    assert len(names) == 1 + 4 * 21
    drone = p.drone_pose().pos_m
    for i in range(4):  # each tip hangs plumb under its place on the ring
        assert np.linalg.norm(_horizontal(p.tip_pose(i).pos_m - drone)) == pytest.approx(0.1, abs=1e-9)
    with pytest.raises(IndexError, match="arm 4"):
        p.tip_pose(4)


def test_more_motors_than_a_c_board_drives_are_refused() -> None:
    with pytest.raises(ValueError, match=r"1\.\.8 motors"):
        _array(4, SpiralDesign.paper_prototype())  # 12


def test_a_motor_curls_only_its_own_arm_inwards_and_only_its_holes_rub() -> None:
    p = _array(4)
    drone = p.drone_pose().pos_m
    before = [p.tip_pose(i).pos_m for i in range(4)]
    p.apply_currents([0, 0, 1500, 0])  # motor 3: arm 2's cable
    p.run(400_000)
    moved = [float(np.linalg.norm(p.tip_pose(i).pos_m - before[i])) for i in range(4)]
    assert moved[2] > 0.05, moved
    assert max(moved[:2] + moved[3:]) < 1e-4, moved
    start, tip = _horizontal(before[2] - drone), _horizontal(p.tip_pose(2).pos_m - drone)
    assert (tip - start) @ (-start / np.linalg.norm(start)) > 0.02  # towards the drone's axis
    tensions = p.cable_tensions_n()
    assert tensions[2] > 1.0 and tensions[[0, 1, 3]].max() < 1e-6  # the idle cables just taut
    # Capstan friction: only arm 2's joints carry a cable under tension.
    friction = p.mj_model.dof_frictionloss
    per_arm = p._bend_dofs.reshape(4, -1)
    ours = friction[per_arm[2]].max()
    assert ours > 0.0
    assert friction[np.concatenate([per_arm[0], per_arm[1], per_arm[3]])].max() < 1e-6 * ours


def test_one_arm_on_a_ring_of_radius_zero_is_the_lone_plant() -> None:
    """The same arm, its friction and drives: the same curl under the same current (not to the bit: the
    attached arm's wrapper body orders MuJoCo's sums differently, as in tests/hil/sim/test_array.py)."""
    lone = Plant(ONE_CABLE)
    one = _array(1, ring_radius_m=0.0)
    for p in (lone, one):
        p.apply_currents([1200])
        p.run(300_000)
    assert lone.tip_pose().pos_m == pytest.approx(one.tip_pose().pos_m, abs=2e-4)
    assert lone.cable_tensions_n() == pytest.approx(one.cable_tensions_n(), rel=1e-2)


def test_set_packed_packs_every_arm_and_an_object_keeps_the_arms_state() -> None:
    p = _array(2)
    p.set_packed(0)
    angles = p.joint_angles_rad()
    assert np.abs(angles) == pytest.approx(np.full(40, ONE_CABLE.dtheta_rad))
    tips = [p.tip_pose(i).pos_m for i in range(2)]
    p.add_object(ObjectConfig(name="ball", radius_m=0.02, length_m=0.04, pos_m=(0.0, 0.0, 0.6), mass_kg=0.02))
    assert p.joint_angles_rad() == pytest.approx(angles)
    assert [p.tip_pose(i).pos_m for i in range(2)] == [pytest.approx(t) for t in tips]
    assert p.object_pose("ball").pos_m == pytest.approx([0.0, 0.0, 0.6])


class _Spy:
    def __init__(self) -> None:
        self.applied: list[tuple[int, ...]] = []

    def apply_currents(self, raw: tuple[int, ...]) -> None:
        self.applied.append(tuple(raw))

    def feedback(self) -> list[object]:
        return []


def test_eight_motors_take_both_command_frames_and_a_lost_high_frame_keeps_its_setpoints() -> None:
    spy = _Spy()
    bus = SimMotorBus(spy, lambda: 0, motor_count=8)  # type: ignore[arg-type]
    bus.send_currents([1, 2, 3, 4, 5, 6, 7, 8])
    bus.deliver_command()
    assert spy.applied == [(1, 2, 3, 4, 5, 6, 7, 8)]
    bus._send_frame(0x200, bytes(8))
    bus.deliver_command()
    assert spy.applied[-1] == (0, 0, 0, 0, 5, 6, 7, 8)
    bus.deliver_command()  # nothing new: nothing applied
    assert len(spy.applied) == 2


def test_a_board_drives_an_array_of_its_firmwares_arms() -> None:
    cfg = BoardConfig(design=ONE_CABLE, firmware=FirmwareConfig().with_arms(8, 1))
    assert board_plant_config(cfg).ring == RingConfig(arms=8)
    board = VirtualBoard(cfg)
    board.run(50_000)
    assert board.plant.motors == 8 and len(board.bus.applied) == 8
    with pytest.raises(ValueError, match="2 arm"):
        board_plant_config(dataclasses.replace(cfg, firmware=FirmwareConfig().with_arms(2, 3)))
