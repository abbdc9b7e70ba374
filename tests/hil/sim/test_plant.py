"""The MuJoCo plant (hil.sim.plant): the C610 seam, named accessors, and the physical sanity checks
of issue 3."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from hil.errors import HilError, PlantDivergedError
from hil.experiments.geometry import fit_log_spiral
from hil.sim.config import ArmConfig, ModelConfig, MotorConfig, ObjectConfig, SolverConfig
from hil.sim.plant import Plant
from hil.sim.spiral import PAPER_PROTOTYPE, SpiralDesign
from hil.sim.types import PlantConfig
from protocol.c610 import ANGLE_COUNTS, M2006_GEAR_RATIO, MotorFeedback, angle_delta_counts

TWO_CABLE = PAPER_PROTOTYPE.with_cables(2)
MOTOR = MotorConfig()


def amps(a: float) -> int:
    return round(a * 1000)


def joint_points_xz(plant: Plant) -> np.ndarray:
    pos, _ = plant.unit_poses()
    pts = np.vstack([pos, plant.tip_pose().pos_m])
    return pts[:, 0] + 1j * pts[:, 2]


# ---------------------------------------------------------------------- construction and the C610 seam


def test_control_period_must_be_whole_physics_steps() -> None:
    with pytest.raises(ValueError, match="whole number of physics steps"):
        Plant(config=PlantConfig(control_period_us=1500))
    with pytest.raises(ValueError, match="whole number of physics steps"):
        Plant(config=PlantConfig(control_period_us=250))
    plant = Plant(
        config=PlantConfig(control_period_us=2000, model=ModelConfig(solver=SolverConfig(timestep_s=0.0005)))
    )
    assert plant.substeps == 4
    plant.step()
    assert plant.time_us == 2000
    with pytest.raises(ValueError):
        Plant(config=PlantConfig(control_period_us=0))


def test_rng_is_the_only_randomness() -> None:
    with pytest.raises(ValueError, match="rng"):
        Plant(config=PlantConfig(model=ModelConfig(motor=MotorConfig(current_noise_raw=5.0))))
    with pytest.raises(ValueError, match="Generator"):
        Plant(rng=42)  # type: ignore[arg-type]

    def trace(seed: int) -> list[tuple[MotorFeedback, ...]]:
        noisy = PlantConfig(model=ModelConfig(motor=MotorConfig(current_noise_raw=5.0)))
        plant = Plant(config=noisy, rng=np.random.default_rng(seed))
        plant.apply_currents([amps(0.5), 0, amps(0.2)])
        out = []
        for _ in range(20):
            plant.step()
            out.append(plant.feedback())
        return out

    assert trace(7) == trace(7)
    assert trace(7) != trace(8)
    quiet = Plant()
    assert [f.angle for f in quiet.feedback()] == [0, 0, 0]


def test_feedback_frames_follow_the_spool_state() -> None:
    """Each frame against the documented formulas, computed here from the MuJoCo state with numpy."""
    plant = Plant(rng=np.random.default_rng(4))
    plant.apply_currents([amps(2.0), amps(-1.0), amps(0.3)])
    r, gear = plant.drives.spool_radius_m, plant.drives.gear_ratio
    offsets = list(plant.drives.angle_offsets_counts)
    for _ in range(100):
        plant.step()
        pos = plant._d.qpos[plant._spool_qadr]
        vel = plant._d.qvel[plant._spool_dadr]
        angle = (np.rint(pos * gear * 8192 / (2 * np.pi * r)).astype(int) + offsets) % 8192
        rpm = np.rint(vel * gear * 60 / (2 * np.pi * r)).astype(int)
        current = np.rint(plant.applied_currents_a() * 1000).astype(int)
        frames = plant.feedback()
        assert [f.angle for f in frames] == angle.tolist()
        assert [f.speed_rpm for f in frames] == rpm.tolist()
        assert [f.current for f in frames] == current.tolist()
        assert plant.feedback_payloads() == [f.pack() for f in frames]


def test_apply_currents_clamps_and_checks() -> None:
    plant = Plant(config=PlantConfig(model=ModelConfig(motor=MotorConfig(current_limit_a=3.0))))
    assert plant.apply_currents([5000, -4000, np.int16(1200)]) == (3000, -3000, 1200)  # type: ignore[list-item]
    assert plant.commanded_currents_raw() == (3000, -3000, 1200)
    with pytest.raises(ValueError, match="expected 3"):
        plant.apply_currents([0, 0])
    with pytest.raises(ValueError, match="expected 3"):
        plant.apply_currents([0, 0, 0, 0, 0])
    assert plant.apply_currents([100, 200, 300, 0]) == (100, 200, 300)  # a whole 0x200 frame
    with pytest.raises(ValueError, match="int"):
        plant.apply_currents([0.5, 0, 0])  # type: ignore[list-item]
    with pytest.raises(ValueError, match="int"):
        plant.apply_currents([True, 0, 0])


def test_feedback_is_c610_shaped_and_follows_the_spool() -> None:
    plant = Plant(rng=np.random.default_rng(3))
    start = plant.feedback()
    assert len(start) == 3 and all(isinstance(f, MotorFeedback) for f in start)
    assert all(0 <= f.angle < ANGLE_COUNTS for f in start)
    unwrapped = [0, 0, 0]
    previous = [f.angle for f in start]
    plant.apply_currents([amps(1.0), 0, 0])
    saw_speed = False
    for _ in range(150):
        plant.step()
        fb = plant.feedback()
        for k in range(3):
            unwrapped[k] += angle_delta_counts(previous[k], fb[k].angle)
            previous[k] = fb[k].angle
        saw_speed |= fb[0].speed_rpm > 1000
        fb[0].pack()  # every frame fits the wire format
    assert saw_speed
    # Near no-load speed the drive delivers less than the setpoint; the frame reports what it delivers.
    assert 0 < fb[0].current <= 1000
    assert fb[0].current == round(plant.applied_currents_a()[0] * 1000)
    # Rotor counts = output angle x 36 x 8192 / 2π (the angle wraps once per rotor turn).
    expected = plant.spool_angles_rad() * M2006_GEAR_RATIO * ANGLE_COUNTS / (2 * math.pi)
    assert unwrapped == pytest.approx(list(expected), abs=1.0)
    assert unwrapped[0] > 10 * ANGLE_COUNTS  # many rotor turns: the wrap really happened


def test_torque_speed_line_caps_the_delivered_current() -> None:
    plant = Plant(design=PAPER_PROTOTYPE.with_cables(1))
    plant.apply_currents([amps(-3.0)])  # pay out: the cable goes slack, only gearbox friction loads the motor
    plant.run(100_000)
    omega = abs(float(plant.spool_speeds_rad_s()[0]))
    assert omega == pytest.approx(MOTOR.no_load_speed_rad_s, rel=0.01)
    assert omega < MOTOR.no_load_speed_rad_s
    # At that speed the drive only delivers what overcomes the friction, whatever the setpoint.
    friction_amps = MOTOR.friction_force_n / MOTOR.force_per_amp_n
    assert plant.feedback()[0].current == pytest.approx(-friction_amps * 1000, abs=5)
    assert plant.cable_slack_m()[0] > 0.04


# ---------------------------------------------------------------------- physical sanity (issue 3)


def test_steady_tension_matches_torque_constant_over_spool_radius() -> None:
    plant = Plant()
    plant.apply_currents([amps(1.0), 0, 0])
    # 1.5 s: the cable's stretch (E·A/L) adds a compliant mode against the 1.3 kg spool, so the curl
    # settles more slowly than with the old rigid cable limit (0.6 s sufficed then).
    plant.run(1_500_000)
    expected = 1.0 * MOTOR.torque_constant_nm_per_a / MOTOR.spool_radius_m  # 18 N
    tension = float(plant.cable_tensions_n()[0])
    assert abs(tension - expected) <= 0.05 * expected + MOTOR.friction_force_n
    assert abs(float(plant.spool_speeds_rad_s()[0])) < 0.01  # steady (dry friction lets it creep)


@pytest.mark.parametrize("design", [TWO_CABLE, PAPER_PROTOTYPE], ids=["2-cable", "3-cable"])
def test_pulled_cable_packs_the_arm_into_the_design_spiral(design: SpiralDesign) -> None:
    plant = Plant(design=design)
    plant.apply_currents([amps(2.5)] + [0] * (design.cables - 1))
    plant.run(700_000)
    angles = plant.joint_angles_rad()
    assert np.all(np.abs(np.abs(angles) - design.dtheta_rad) < math.radians(1.0))  # every joint at its limit
    b_fit, _, turn = fit_log_spiral(joint_points_xz(plant))  # cable 0 bends the arm in the x-z plane
    assert b_fit == pytest.approx(design.b, rel=0.02)
    assert abs(turn) == pytest.approx(design.dtheta_rad, rel=0.02)


def test_releasing_the_cable_uncurls_base_first() -> None:
    """Note S4 / Fig. S6: from the packed pose, lowering the tension opens the joints from the base."""
    plant = Plant(design=TWO_CABLE)
    plant.apply_currents([amps(2.5), 0])
    plant.run(600_000)
    for k in range(800):  # ramp 2.5 A -> 0.5 A over 0.8 s
        plant.apply_currents([amps(2.5 - 2.0 * k / 800), 0])
        plant.step()
    angles = np.abs(plant.joint_angles_rad())
    limit = TWO_CABLE.dtheta_rad
    assert angles[0] < limit - math.radians(5)  # the base has opened
    assert np.all(angles[-5:] > limit - math.radians(1))  # the tip is still curled
    assert np.all(np.diff(angles[:4]) > 0)  # opening grows towards the base


def test_kinematic_packed_pose_is_exactly_the_central_spiral() -> None:
    for design in (PAPER_PROTOTYPE, TWO_CABLE):
        plant = Plant(design=design)
        plant.set_packed(0)
        pts = joint_points_xz(plant)
        b_fit, pole, _ = fit_log_spiral(pts)
        assert b_fit == pytest.approx(design.b, rel=1e-6)
        # The joints sit on ρc: base joint at θ0, tip at 0.
        assert abs(pts[0] - pole) == pytest.approx(design.rho_c_m(design.theta0_rad), rel=1e-6)
        assert abs(pts[-1] - pole) == pytest.approx(design.rho_c_m(0.0), rel=1e-6)
        assert np.all(plant.cable_slack_m() < 1e-9)


def test_unit_length_and_mass_ratios() -> None:
    plant = Plant()
    dims = plant.unit_dimensions_m()
    lengths = [d[0] for d in dims]
    masses = [float(plant.mj_model.body_mass[plant.mj_model.body(n).id]) for n in plant.unit_names]
    for i in range(len(dims) - 1):
        assert lengths[i] / lengths[i + 1] == pytest.approx(PAPER_PROTOTYPE.beta, rel=0.01)
        assert masses[i] / masses[i + 1] == pytest.approx(PAPER_PROTOTYPE.beta**3, rel=0.01)
    # Measured on the simulated bodies too: distance between consecutive joints.
    pos, _ = plant.unit_poses()
    gaps = np.linalg.norm(np.diff(pos, axis=0), axis=1)
    assert gaps[0] / gaps[1] == pytest.approx(PAPER_PROTOTYPE.beta, rel=0.01)


@pytest.mark.parametrize("cable", [0, 1, 2])
def test_pulling_one_cable_bends_towards_it(cable: int) -> None:
    plant = Plant()
    drone = plant.drone_pose().pos_m
    currents = [0, 0, 0]
    currents[cable] = amps(0.8)
    plant.apply_currents(currents)
    plant.run(250_000)
    offset = plant.tip_pose().pos_m - drone
    horizontal = offset[:2]
    assert np.linalg.norm(horizontal) > 0.02
    azimuth = math.degrees(math.atan2(horizontal[1], horizontal[0]))
    target = 120.0 * cable
    assert abs((azimuth - target + 180) % 360 - 180) < 10.0


def test_tip_stays_inside_the_workspace_envelope() -> None:
    """Random cable forces on a 2-cable arm: the tip stays within ρw (Table S1) up to 1/η − 1 (eq. 11).

    The envelope is the involute of the packed central spiral about its pole; one per bending side.
    """
    design = TWO_CABLE
    plant = Plant(design=design, rng=np.random.default_rng(11))
    poles = []
    for side in (0, 1):
        plant.set_packed(side)
        pts = joint_points_xz(plant)
        _, pole, _ = fit_log_spiral(pts)
        w = pts - pole
        base_angle = float(np.angle(w[0]))
        sense = 1.0 if np.angle(w[1] / w[0]) < 0 else -1.0  # polar angle grows from tip to base by `sense`
        poles.append((pole, base_angle, sense))
    plant.set_straight()
    tolerance = 1.0 / design.eta - 1.0

    def ratio(tip: complex) -> float:
        best = math.inf
        for pole, base_angle, sense in poles:
            w = tip - pole
            phi = float(np.angle(w))
            radius = 0.0
            for k in range(-4, 5):
                # Spiral parameter θ whose involute point lies at this polar angle (a quarter turn behind).
                theta = design.theta0_rad + sense * (phi - base_angle) + 2 * math.pi * k + math.pi / 2
                if 0.0 <= theta <= design.theta0_rad:
                    radius = max(radius, design.rho_w_m(theta + math.pi / 2))
            if radius > 0:
                best = min(best, abs(w) / radius)
        return best

    rng = np.random.default_rng(5)
    worst = 0.0
    for period in range(2000):
        if period % 100 == 0:
            plant.apply_currents([int(v) for v in rng.integers(0, 4000, size=2)])
        plant.step()
        if period % 5 == 0:
            p = plant.tip_pose().pos_m
            worst = max(worst, ratio(complex(p[0], p[2])))
    assert worst <= 1.0 + tolerance


# ---------------------------------------------------------------------- accessors, drone, objects, divergence


def test_accessors_shapes_and_names() -> None:
    plant = Plant()
    n = PAPER_PROTOTYPE.units
    poses = plant.body_poses()
    assert poses.names[0] == "drone" and poses.names[1] == "unit_00" and len(poses.names) == n + 1
    assert poses.positions_m.shape == (n + 1, 3) and poses.quats_wxyz.shape == (n + 1, 4)
    assert np.allclose(np.linalg.norm(poses.quats_wxyz, axis=1), 1.0)
    assert plant.joint_angles_rad().shape == (n - 1,)
    assert plant.cable_lengths_m().shape == (3,)
    assert plant.cable_tensions_n().shape == (3,)
    assert plant.tip_pose().pos_m[2] < plant.drone_pose().pos_m[2]
    assert plant.contacts() == []
    assert plant.time_us == 0 and plant.control_period_us == 1000
    plant.run(5000)
    assert plant.time_us == 5000
    with pytest.raises(ValueError):
        plant.run(1500)


def test_cable_length_shortens_by_wound_length() -> None:
    plant = Plant()
    before = plant.cable_lengths_m()[0]
    plant.apply_currents([amps(0.6), 0, 0])
    plant.run(200_000)
    wound = float(plant.spool_angles_rad()[0] * MOTOR.spool_radius_m)
    assert wound > 0.01
    assert before - plant.cable_lengths_m()[0] == pytest.approx(wound, abs=5e-4)


def test_reset_restores_the_start() -> None:
    plant = Plant(rng=np.random.default_rng(1))
    start = plant.body_poses().positions_m
    plant.apply_currents([amps(1.0), 0, 0])
    plant.run(100_000)
    plant.reset()
    assert plant.time_us == 0
    assert plant.commanded_currents_raw() == (0, 0, 0)
    assert np.allclose(plant.body_poses().positions_m, start)


def test_drone_pose_moves_the_arm_and_acceleration_swings_it() -> None:
    plant = Plant()
    plant.set_drone_pose((1.0, 2.0, 3.0))
    assert plant.body_poses().positions_m[1] == pytest.approx([1.0, 2.0, 3.0 - 0.02])
    tilted = Plant()
    tilted.set_drone_pose((0.0, 0.0, 1.0), (1.0, 0.0, 0.0, 0.0), accel_m_s2=(4.0, 0.0, 0.0))
    tilted.run(300_000)
    assert tilted.tip_pose().pos_m[0] < -0.004  # accelerating along +x, the arm trails behind
    turned = Plant()
    quarter = (math.cos(math.pi / 8), math.sin(math.pi / 8), 0.0, 0.0)  # 45° about x
    turned.set_drone_pose((0.0, 0.0, 1.0), quarter)
    at_once = turned.tip_pose().pos_m
    assert at_once[1] > 0.15  # the arm rotates with the drone at once
    turned.run(500_000)
    assert turned.tip_pose().pos_m[2] < at_once[2] - 0.005  # and then sags under gravity
    with pytest.raises(ValueError):
        plant.set_drone_pose((0.0, 0.0))
    with pytest.raises(ValueError):
        plant.set_drone_pose((0.0, 0.0, 1.0), (0.0, 0.0, 0.0, 0.0))


def test_added_object_is_touched_by_the_curling_arm() -> None:
    plant = Plant(design=TWO_CABLE)
    plant.set_packed(0)
    _, pole, _ = fit_log_spiral(joint_points_xz(plant))  # the centre the arm curls around
    plant.set_straight()
    plant.run(10_000)
    plant.add_object(ObjectConfig("pole", radius_m=0.012, length_m=0.1, pos_m=(pole.real, 0.0, pole.imag)))
    assert plant.time_us == 10_000
    assert plant.object_names == ("pole",)
    plant.apply_currents([amps(1.5), 0])
    plant.run(500_000)
    touching = [c for c in plant.contacts() if c.other == "pole"]
    assert touching and max(c.normal_force_n for c in touching) > 0
    plant.set_object_pose("pole", (0.5, 0.0, 0.5))
    assert plant.object_pose("pole").pos_m == pytest.approx([0.5, 0.0, 0.5])
    with pytest.raises(KeyError):
        plant.set_object_pose("nope", (0, 0, 0))
    with pytest.raises(ValueError, match="unique"):
        plant.add_object(ObjectConfig("pole", radius_m=0.01, length_m=0.1, pos_m=(0.0, 0.0, 0.0)))
    plant.step()  # still usable


def test_divergence_is_reported_not_hidden(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)  # MuJoCo logs its warning to ./MUJOCO_LOG.TXT
    plant = Plant()
    plant.mj_data.qvel[5] = float("nan")
    with pytest.raises(PlantDivergedError) as info:
        plant.step()
    assert isinstance(info.value, HilError)
    assert info.value.time_us == 1000
    plant.reset()
    plant.step()  # usable again after reset
    fast = Plant()
    fast.mj_data.qvel[5] = 1e5
    with pytest.raises(PlantDivergedError, match="speed"):
        fast.step()


def test_random_currents_up_to_the_limit_stay_stable() -> None:
    plant = Plant(rng=np.random.default_rng(2))
    rng = np.random.default_rng(9)
    limit = round(MOTOR.current_limit_a * 1000)
    for period in range(2000):
        if period % 150 == 0:
            plant.apply_currents([int(v) for v in rng.integers(-limit, limit + 1, size=3)])
        plant.step()
    assert np.all(np.isfinite(plant.body_poses().positions_m))
    assert np.all(plant.joint_angles_rad() < PAPER_PROTOTYPE.dtheta_rad + math.radians(10))


@pytest.mark.parametrize("cables", [1, 2])
def test_one_and_two_cable_arms(cables: int) -> None:
    plant = Plant(design=PAPER_PROTOTYPE.with_cables(cables))
    assert plant.cables == cables and len(plant.feedback()) == cables
    assert plant.apply_currents([amps(1.0), 0, 0]) == (amps(1.0),) + (0,) * (cables - 1)
    plant.run(200_000)
    assert plant.tip_pose().pos_m[0] > 0.02  # cable 0 sits at +x


def test_friction_off_still_packs() -> None:
    plant = Plant(design=TWO_CABLE, config=PlantConfig(model=ModelConfig(arm=ArmConfig(cable_mu=0.0))))
    plant.apply_currents([amps(2.5), 0])
    plant.run(500_000)
    assert np.all(np.abs(plant.joint_angles_rad()) > TWO_CABLE.dtheta_rad - math.radians(1.0))


def test_authors_design_runs() -> None:
    plant = Plant(design=SpiralDesign.authors_default())
    plant.apply_currents([amps(1.0), 0, 0])
    plant.run(100_000)
    assert plant.cable_tensions_n()[0] > 0


def test_free_object_support_hold_release_throw_and_load() -> None:
    plant = Plant(design=TWO_CABLE)
    plant.add_object(ObjectConfig("can", radius_m=0.01, length_m=0.06, pos_m=(0.3, 0.0, 0.5), mass_kg=0.02))
    assert not plant.object_held("can")
    plant.hold_object("can", (0.3, 0.1, 0.6))
    assert plant.object_held("can")
    plant.run(200_000)
    assert plant.object_pose("can").pos_m == pytest.approx([0.3, 0.1, 0.6], abs=1e-4)  # held still
    plant.release_object("can")
    plant.run(100_000)
    z = float(plant.object_pose("can").pos_m[2])
    assert z == pytest.approx(0.6 - 0.5 * 9.80665 * 0.1**2, abs=2e-3)  # free fall
    plant.hold_object("can")  # where it is now
    plant.run(50_000)
    assert float(plant.object_pose("can").pos_m[2]) == pytest.approx(z, abs=1e-3)
    plant.release_object("can")
    x0 = float(plant.object_pose("can").pos_m[0])
    plant.set_object_velocity("can", (1.0, 0.0, 0.0))
    plant.run(10_000)
    assert float(plant.object_pose("can").pos_m[0]) - x0 == pytest.approx(0.009, abs=0.002)  # ~1 m/s
    plant.hold_object("can", (0.3, 0.0, 0.5))
    plant.apply_object_force("can", (0.0, 0.0, 0.0))
    plant.release_object("can")
    plant.apply_object_force("can", (0.0, 0.0, 0.02 * 9.80665))  # cancels its weight
    plant.run(100_000)
    assert float(plant.object_pose("can").pos_m[2]) == pytest.approx(0.5, abs=1e-3)
    with pytest.raises(KeyError):
        plant.hold_object("nope")
    plant.add_object(ObjectConfig("pole", radius_m=0.01, length_m=0.1, pos_m=(-0.3, 0.0, 0.5)))
    assert plant.object_held("pole")  # fixed objects are always held
    with pytest.raises(KeyError):
        plant.release_object("pole")
    with pytest.raises(ValueError, match="support"):
        ModelConfig().with_objects(
            ObjectConfig("a", radius_m=0.01, length_m=0.1, pos_m=(0, 0, 0), mass_kg=0.01),
            ObjectConfig("a_support", radius_m=0.01, length_m=0.1, pos_m=(0, 0, 0)),
        ).validate()


def test_joint_friction_sits_under_the_capstan_friction_and_is_none_by_default() -> None:
    from hil.sim.config import ArmConfig, ModelConfig
    from hil.sim.mjcf import joint_friction_nm, unit_geometry
    from hil.sim.types import PlantConfig

    default = Plant()
    dm = default.mj_model
    arm_dofs = [dm.jnt_dofadr[dm.joint(f"joint_{i:02d}").id] for i in range(1, default.design.units)]
    assert float(dm.dof_frictionloss[arm_dofs].max()) == 0.0  # before any tension
    arm = ArmConfig(joint_friction_nm=0.002)
    plant = Plant(config=PlantConfig(model=ModelConfig(arm=arm)))
    design = plant.design
    expected = joint_friction_nm(arm, unit_geometry(design, arm))
    assert expected[1] == pytest.approx(0.002) and expected[-1] < expected[1]  # scales like stiffness
    m = plant.mj_model
    for i in range(1, design.units):
        dof = m.jnt_dofadr[m.joint(f"joint_{i:02d}").id]
        assert m.dof_frictionloss[dof] == pytest.approx(expected[i])
    plant.apply_currents([1000, 0, 0])
    for _ in range(200):
        plant.step()
    dof1 = m.jnt_dofadr[m.joint("joint_01").id]
    assert m.dof_frictionloss[dof1] > expected[1]  # the capstan friction on top of it


def test_a_divergence_crosses_process_boundaries_with_its_time() -> None:
    """A worker's diverged plant reaches the parent whole (multiprocessing pickles the exception): an
    unpicklable one killed the pool's result thread and hung the experiment that met it."""
    import pickle

    again = pickle.loads(pickle.dumps(PlantDivergedError("plant diverged at t = 7 us: NaN", 7)))
    assert isinstance(again, PlantDivergedError) and again.time_us == 7 and "t = 7 us" in str(again)
