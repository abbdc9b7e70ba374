"""MJCF generator (hil.sim.mjcf): self-contained models, stable names, scaling laws, cable routing."""

from __future__ import annotations

import dataclasses
import itertools
import math
from pathlib import Path
from typing import Any

import mujoco
import numpy as np
import pytest

from hil.sim.config import (
    ActuatorConfig,
    ArmConfig,
    ContactConfig,
    DroneConfig,
    ModelConfig,
    MotorConfig,
    ObjectConfig,
    SolverConfig,
)
from hil.sim.mjcf import (
    build_mjcf,
    cable_angles_rad,
    cable_layout,
    cable_stiffness_n_per_m,
    unit_geometry,
    write_mjcf,
)
from hil.sim.spiral import AUTHORS_DEFAULT, PAPER_PROTOTYPE, SpiralDesign


def load(
    design: SpiralDesign = PAPER_PROTOTYPE, cables: int | None = None, config: ModelConfig | None = None
) -> Any:
    return mujoco.MjModel.from_xml_string(build_mjcf(design, cables, config))


def name_id(m: object, kind: object, name: str) -> int:
    return int(mujoco.mj_name2id(m, kind, name))


@pytest.mark.parametrize("cables", [1, 2, 3])
def test_written_file_loads_with_plain_mujoco(tmp_path: Path, cables: int) -> None:
    path = write_mjcf(tmp_path / "arm.xml", PAPER_PROTOTYPE, cables)
    text = path.read_text(encoding="utf-8")
    assert "file=" not in text and "<include" not in text  # nothing else to ship
    m = mujoco.MjModel.from_xml_path(str(path))
    d = mujoco.MjData(m)
    mujoco.mj_step(m, d)
    n = PAPER_PROTOTYPE.units
    assert m.ntendon == cables and m.nu == cables
    assert all(name_id(m, mujoco.mjtObj.mjOBJ_BODY, f"unit_{i:02d}") >= 0 for i in range(n))
    assert name_id(m, mujoco.mjtObj.mjOBJ_JOINT, "joint_00") == -1  # the base unit is fixed to the drone
    for i in range(1, n):
        j = name_id(m, mujoco.mjtObj.mjOBJ_JOINT, f"joint_{i:02d}")
        assert m.jnt_bodyid[j] == name_id(m, mujoco.mjtObj.mjOBJ_BODY, f"unit_{i:02d}")
    for k in range(cables):
        assert name_id(m, mujoco.mjtObj.mjOBJ_TENDON, f"cable_{k}") >= 0
        assert name_id(m, mujoco.mjtObj.mjOBJ_ACTUATOR, f"motor_{k}") >= 0
        assert name_id(m, mujoco.mjtObj.mjOBJ_JOINT, f"spool_{k}") >= 0
        assert name_id(m, mujoco.mjtObj.mjOBJ_SENSOR, f"tension_{k}") >= 0
        for site in (
            f"cable_{k}_spool",
            f"cable_{k}_guide",
            f"cable_{k}_unit_00_prox",
            f"cable_{k}_unit_{n - 1:02d}_dist",
        ):
            assert name_id(m, mujoco.mjtObj.mjOBJ_SITE, site) >= 0
    assert name_id(m, mujoco.mjtObj.mjOBJ_SITE, "tip") >= 0
    assert m.body_mocapid[name_id(m, mujoco.mjtObj.mjOBJ_BODY, "drone")] == 0


@pytest.mark.parametrize(
    ("cables", "kind"),
    [(1, mujoco.mjtJoint.mjJNT_HINGE), (2, mujoco.mjtJoint.mjJNT_HINGE), (3, mujoco.mjtJoint.mjJNT_BALL)],
)
def test_joint_types_and_limits(cables: int, kind: object) -> None:
    m = load(cables=cables)
    dtheta = PAPER_PROTOTYPE.dtheta_rad
    for i in range(1, PAPER_PROTOTYPE.units):
        j = name_id(m, mujoco.mjtObj.mjOBJ_JOINT, f"joint_{i:02d}")
        assert m.jnt_type[j] == kind
        assert m.jnt_limited[j]
        expected = (0.0, dtheta) if cables == 3 else (-dtheta, dtheta)
        assert tuple(m.jnt_range[j]) == pytest.approx(expected, rel=1e-8)


@pytest.mark.parametrize("design", [PAPER_PROTOTYPE, AUTHORS_DEFAULT], ids=["prototype", "authors"])
def test_units_scale_by_beta_and_mass_by_beta_cubed(design: SpiralDesign) -> None:
    m = load(design)
    n = design.units
    bodies = [name_id(m, mujoco.mjtObj.mjOBJ_BODY, f"unit_{i:02d}") for i in range(n)]
    # The distance from one unit's joint to the next is that unit's length.
    lengths = [float(np.linalg.norm(m.body_pos[bodies[i + 1]])) for i in range(n - 1)]
    masses = [float(m.body_mass[b]) for b in bodies]
    for i in range(n - 2):
        assert lengths[i] / lengths[i + 1] == pytest.approx(design.beta, rel=0.01)
    for i in range(n - 1):
        assert masses[i] / masses[i + 1] == pytest.approx(design.beta**3, rel=0.01)
    assert sum(masses) == pytest.approx(ArmConfig().total_mass_kg, rel=1e-6)


def test_stiffness_scales_with_size_cubed_and_damping_is_set() -> None:
    arm = ArmConfig(base_stiffness_nm_per_rad=0.6, damping_ratio=0.2)
    m = load(config=ModelConfig(arm=arm))
    n = PAPER_PROTOTYPE.units
    joints = [name_id(m, mujoco.mjtObj.mjOBJ_JOINT, f"joint_{i:02d}") for i in range(1, n)]
    k = [float(m.jnt_stiffness[j]) for j in joints]
    assert k[0] == pytest.approx(0.6)
    for a, b in itertools.pairwise(k):
        assert a / b == pytest.approx(PAPER_PROTOTYPE.beta**3, rel=1e-6)
    damping = [float(m.dof_damping[m.jnt_dofadr[j]]) for j in joints]
    assert all(c > 0 for c in damping)
    assert damping == sorted(damping, reverse=True)
    geo = unit_geometry(PAPER_PROTOTYPE, arm)
    assert geo.stiffness_nm_per_rad[0] == 0.0 and geo.damping_nms_per_rad[0] == 0.0


def test_cables_are_just_taut_when_straight_and_pull_only() -> None:
    m = load()
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    for k in range(3):
        t = name_id(m, mujoco.mjtObj.mjOBJ_TENDON, f"cable_{k}")
        assert m.tendon_limited[t]
        assert m.tendon_range[t][0] == 0.0
        assert d.ten_length[t] == pytest.approx(m.tendon_range[t][1], abs=1e-7)


def test_cable_holes_are_at_120_degrees() -> None:
    m = load()
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    azimuths = []
    for k in range(3):
        pos = m.site_pos[name_id(m, mujoco.mjtObj.mjOBJ_SITE, f"cable_{k}_unit_05_prox")]
        azimuths.append(math.degrees(math.atan2(pos[1], pos[0])) % 360)
    assert azimuths == pytest.approx([0.0, 120.0, 240.0], abs=1e-6)
    assert cable_angles_rad(2) == pytest.approx((0.0, math.pi))
    with pytest.raises(ValueError):
        cable_angles_rad(0)


def test_motor_gear_and_spool_mass_follow_the_motor_config() -> None:
    motor = MotorConfig(torque_constant_nm_per_a=0.3, spool_radius_m=0.015, rotor_inertia_kg_m2=2e-7)
    m = load(config=ModelConfig(motor=motor))
    a = name_id(m, mujoco.mjtObj.mjOBJ_ACTUATOR, "motor_1")
    assert m.actuator_gear[a][0] == pytest.approx(0.3 / 0.015)
    assert tuple(m.actuator_ctrlrange[a]) == pytest.approx((-10.0, 10.0))
    spool = name_id(m, mujoco.mjtObj.mjOBJ_BODY, "spool_1")
    assert m.body_mass[spool] == pytest.approx(2e-7 * 36**2 / 0.015**2)
    assert motor.reflected_mass_kg == pytest.approx(m.body_mass[spool])


def test_solver_options_are_written() -> None:
    sol = SolverConfig(timestep_s=0.0005, integrator="implicitfast", iterations=7, solver="CG")
    m = load(config=ModelConfig(solver=sol))
    assert m.opt.timestep == pytest.approx(0.0005)
    assert m.opt.integrator == mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    assert m.opt.iterations == 7
    assert m.opt.solver == mujoco.mjtSolver.mjSOL_CG
    default = load()
    assert default.opt.integrator == mujoco.mjtIntegrator.mjINT_DISCRETE


def test_custom_numerics_carry_the_design() -> None:
    m = load(AUTHORS_DEFAULT)
    values = {
        mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_NUMERIC, i): float(m.numeric_data[m.numeric_adr[i]])
        for i in range(m.nnumeric)
    }
    assert values["spirob_b"] == pytest.approx(0.1764)
    assert values["spirob_units"] == 24
    assert values["spirob_cable_mu"] == pytest.approx(ArmConfig().cable_mu)
    assert values["spirob_torque_constant_nm_per_a"] == pytest.approx(0.18)


def test_objects_fixed_and_free() -> None:
    cfg = ModelConfig().with_objects(
        ObjectConfig("branch", 0.02, 0.3, (0.05, 0.0, 0.85)),
        ObjectConfig("can", 0.03, 0.1, (0.0, 0.1, 0.5), axis=(0, 0, 1), mass_kg=0.2, shape="capsule"),
    )
    m = load(config=cfg)
    branch = name_id(m, mujoco.mjtObj.mjOBJ_BODY, "branch")
    can = name_id(m, mujoco.mjtObj.mjOBJ_BODY, "can")
    assert m.body_jntnum[branch] == 0
    assert m.body_jntnum[can] == 1
    assert m.body_mass[can] == pytest.approx(0.2)
    g = name_id(m, mujoco.mjtObj.mjOBJ_GEOM, "can_geom")
    assert m.geom_type[g] == mujoco.mjtGeom.mjGEOM_CAPSULE


def test_wedge_units_collide_with_each_other_by_default_and_capsules_do_not() -> None:
    """Wedges (the default) are the real units: packed turns touch. Capsules' rounded ends reach into the
    packed neighbours' space, so they rely on the joint limits alone unless asked otherwise."""

    def collide(m: mujoco.MjModel) -> bool:
        a, b = (name_id(m, mujoco.mjtObj.mjOBJ_GEOM, f"unit_{i:02d}_geom") for i in (3, 9))
        return bool(m.geom_contype[a] & m.geom_conaffinity[b] or m.geom_contype[b] & m.geom_conaffinity[a])

    assert collide(load())
    assert not collide(load(config=ModelConfig(arm=ArmConfig(unit_shape="capsule"))))
    assert collide(load(config=ModelConfig(arm=ArmConfig(unit_shape="capsule", self_collision=True))))
    assert not collide(load(config=ModelConfig(arm=ArmConfig(self_collision=False))))


WEDGE = ModelConfig(arm=ArmConfig(unit_shape="wedge"))


@pytest.mark.parametrize("cables", [2, 3])
def test_wedge_units_are_inline_meshes_that_collide_with_each_other(cables: int) -> None:
    xml = build_mjcf(PAPER_PROTOTYPE, cables, WEDGE)
    assert "<mesh " in xml and "file=" not in xml  # one self-contained file
    m = mujoco.MjModel.from_xml_string(xml)
    assert m.nmesh == PAPER_PROTOTYPE.units
    a, b = (name_id(m, mujoco.mjtObj.mjOBJ_GEOM, f"unit_{i:02d}_geom") for i in (3, 9))
    assert m.geom_type[a] == mujoco.mjtGeom.mjGEOM_MESH
    assert m.geom_contype[a] & m.geom_conaffinity[b]
    off = ModelConfig(arm=ArmConfig(unit_shape="wedge", self_collision=False))
    m2 = load(cables=cables, config=off)
    assert not m2.geom_contype[a] & m2.geom_conaffinity[b]


@pytest.mark.parametrize("cables", [2, 3])
def test_wedge_faces_meet_when_a_joint_closes_and_packed_turns_just_touch(cables: int) -> None:
    """At the joint limit the two facing wedge faces lie together (what the limit models); packed, the
    coil's turns touch without pushing each other apart, and no two units overlap in the straight arm."""
    m = load(cables=cables, config=WEDGE)
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    assert d.ncon == 0  # straight: nothing touches
    dtheta = PAPER_PROTOTYPE.dtheta_rad
    for j in range(m.njnt):
        if m.jnt_type[j] == mujoco.mjtJoint.mjJNT_BALL:
            adr = m.jnt_qposadr[j]
            d.qpos[adr : adr + 4] = (math.cos(dtheta / 2), 0.0, -math.sin(dtheta / 2), 0.0)
        elif m.jnt_type[j] == mujoco.mjtJoint.mjJNT_HINGE:
            d.qpos[m.jnt_qposadr[j]] = -dtheta  # every joint closed towards +x
    mujoco.mj_forward(m, d)

    def rim_vertex(unit: int, z_sign: float) -> np.ndarray:
        # The wedge vertex on the +x side (the closing side) at one end of the unit, in world coordinates.
        g = name_id(m, mujoco.mjtObj.mjOBJ_GEOM, f"unit_{unit:02d}_geom")
        mesh = m.geom_dataid[g]
        v = m.mesh_vert[m.mesh_vertadr[mesh] : m.mesh_vertadr[mesh] + m.mesh_vertnum[mesh]]
        # MuJoCo stores mesh vertices in the geom's inertial frame: back to world through the geom pose.
        world = d.geom_xpos[g] + v @ d.geom_xmat[g].reshape(3, 3).T
        local = (world - d.xpos[m.geom_bodyid[g]]) @ d.xmat[m.geom_bodyid[g]].reshape(3, 3)
        pick = local[:, 0] > 1e-6
        pick &= np.abs(local[:, 1]) < 1e-9 if cables == 3 else local[:, 1] > 0
        zs = local[pick, 2]
        return np.asarray(world[pick][np.argmax(zs) if z_sign > 0 else np.argmin(zs)])

    for unit in range(1, PAPER_PROTOTYPE.units):
        parent_tip_side = rim_vertex(unit - 1, -1.0)
        child_base_side = rim_vertex(unit, +1.0)
        assert np.linalg.norm(parent_tip_side - child_base_side) < 1e-7
    depth = [d.contact[i].dist for i in range(d.ncon)]
    assert depth  # the turns of the coil touch
    assert min(depth) > -0.1 * 0.001  # and overlap by under 0.1 mm (a chord of the inner arc: see mjcf)


def test_unit_shape_is_validated() -> None:
    with pytest.raises(ValueError, match="unit_shape"):
        ArmConfig(unit_shape="cube").validate()


def test_floor_option() -> None:
    m = load(config=ModelConfig(drone=DroneConfig(floor=True)))
    assert name_id(m, mujoco.mjtObj.mjOBJ_GEOM, "floor") >= 0


@pytest.mark.parametrize(
    ("config", "match"),
    [
        (ModelConfig(arm=ArmConfig(total_mass_kg=0.0)), "total_mass_kg"),
        (ModelConfig(arm=ArmConfig(cable_offset_ratio=1.2)), "cable_offset_ratio"),
        (ModelConfig(arm=ArmConfig(cable_mu=-0.1)), "cable_mu"),
        (ModelConfig(motor=MotorConfig(current_limit_a=12.0)), "current_limit_a"),
        (ModelConfig(motor=MotorConfig(spool_radius_m=0.0)), "spool_radius_m"),
        (ModelConfig(solver=SolverConfig(integrator="leapfrog")), "integrator"),
        (ModelConfig(solver=SolverConfig(timestep_s=-1.0)), "timestep_s"),
        (ModelConfig(drone=DroneConfig(quat_wxyz=(0, 0, 0, 0))), "quat"),
        (ModelConfig(objects=(ObjectConfig("unit_x", 0.01, 0.1, (0, 0, 0)),)), "object name"),
        (ModelConfig(objects=(ObjectConfig("a", 0.01, 0.1, (0, 0, 0)),) * 2), "unique"),
        (ModelConfig(objects=(ObjectConfig("a", -0.01, 0.1, (0, 0, 0)),)), "radius_m"),
        (ModelConfig(objects=(ObjectConfig("a", 0.01, 0.1, (0, 0, 0), axis=(0, 0, 0)),)), "axis"),
        (ModelConfig(arm=ArmConfig(stiffness_exponent=4.5)), "stiffness_exponent"),
        (ModelConfig(actuator=ActuatorConfig(kind="piston")), "actuator kind"),
        (ModelConfig(actuator=ActuatorConfig(lag_s=0.0)), "lag_s"),
        (ModelConfig(actuator=ActuatorConfig(muscle_force_n=-5.0)), "muscle_force_n"),
        (ModelConfig(actuator=ActuatorConfig(muscle_length_range=(2.5, 0.4))), "muscle_length_range"),
        (ModelConfig(mounting="ceiling"), "mounting"),
    ],
)
def test_bad_configuration_is_refused(config: ModelConfig, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        build_mjcf(PAPER_PROTOTYPE, None, config)


def test_designs_the_cables_cannot_fit_are_refused() -> None:
    fat = SpiralDesign.from_params(0.01, 1.2, 2 * math.radians(80), math.radians(80))
    with pytest.raises(ValueError, match="overlap"):
        cable_layout(fat, 3)


def test_single_unit_is_refused() -> None:
    one = SpiralDesign.from_params(0.005, 0.15, math.radians(30), math.radians(30))
    with pytest.raises(ValueError, match="at least 2 units"):
        build_mjcf(one)


def test_stiffness_can_scale_with_size_squared() -> None:
    m = load(config=ModelConfig(arm=ArmConfig(base_stiffness_nm_per_rad=0.04, stiffness_exponent=2)))
    joints = [
        name_id(m, mujoco.mjtObj.mjOBJ_JOINT, f"joint_{i:02d}") for i in range(1, PAPER_PROTOTYPE.units)
    ]
    k = [float(m.jnt_stiffness[j]) for j in joints]
    assert k[0] == pytest.approx(0.04)
    for a, b in itertools.pairwise(k):
        assert a / b == pytest.approx(PAPER_PROTOTYPE.beta**2, rel=1e-6)


def test_actuator_kinds() -> None:
    motor = MotorConfig()
    peak_n = motor.force_per_amp_n * motor.current_limit_a
    m = load(config=ModelConfig(actuator=ActuatorConfig(kind="tension", lag_s=0.02)))
    assert m.actuator_dyntype[0] == mujoco.mjtDyn.mjDYN_FILTEREXACT
    assert m.actuator_dynprm[0][0] == pytest.approx(0.02)
    assert m.actuator_ctrlrange[0].tolist() == pytest.approx([0.0, peak_n])  # pull only, in newtons
    spool = name_id(m, mujoco.mjtObj.mjOBJ_BODY, "spool_0")
    assert m.body_mass[spool] == pytest.approx(0.01)  # light: not the motor's 1.3 kg
    assert m.dof_frictionloss[
        m.jnt_dofadr[name_id(m, mujoco.mjtObj.mjOBJ_JOINT, "spool_0")]
    ] == pytest.approx(0.1)
    m = load(config=ModelConfig(actuator=ActuatorConfig(kind="muscle")))
    assert m.actuator_gaintype[0] == mujoco.mjtGain.mjGAIN_MUSCLE
    assert m.actuator_gear[0][0] == -1.0  # contracting winds the cable in
    assert m.actuator_gainprm[0][2] == pytest.approx(peak_n)  # F0 defaults to the motor's range
    lo, hi = m.actuator_lengthrange[0]
    assert lo < 0.0 < hi  # the straight arm sits inside the force-length range


def test_mountings_set_gravity_and_the_table() -> None:
    design = PAPER_PROTOTYPE.with_cables(2)
    m = load(design, config=ModelConfig(mounting="gravity-off"))
    assert m.opt.gravity.tolist() == [0.0, 0.0, 0.0]
    m = load(design, config=ModelConfig(mounting="table"))
    assert m.opt.gravity.tolist() == pytest.approx([0.0, 0.0, -9.80665])
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    tip = d.site_xpos[name_id(m, mujoco.mjtObj.mjOBJ_SITE, "tip")]
    assert tip[0] > 0.2 and abs(tip[2] - 1.0) < 1e-9  # lying along +x at the clamp's height
    hinge = name_id(m, mujoco.mjtObj.mjOBJ_JOINT, "joint_05")
    assert d.xaxis[hinge].tolist() == pytest.approx([0.0, 0.0, 1.0])  # bends in the horizontal plane
    table = name_id(m, mujoco.mjtObj.mjOBJ_GEOM, "table")
    assert d.geom_xpos[table][2] == pytest.approx(1.0 - 0.5 * unit_geometry(design).width_base_side_m[0])


def test_every_arm_and_object_geom_carries_the_stated_contact() -> None:
    contact = ContactConfig(timeconst_s=0.003, damping_ratio=0.9, solimp=(0.98, 0.99, 0.001, 0.4, 3.0))
    cfg = dataclasses.replace(ModelConfig(), contact=contact).with_objects(
        ObjectConfig("pole", 0.01, 0.1, (0.05, 0, 0.8)),
        ObjectConfig("cup", 0.02, 0.05, (0.1, 0, 0.8), mass_kg=0.05, shape="capsule"),
    )
    m = load(config=cfg)
    checked = 0
    for g in range(m.ngeom):
        name = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_GEOM, g) or ""
        if name.startswith("unit_") or name in ("pole_geom", "cup_geom"):
            assert m.geom_solref[g] == pytest.approx((0.003, 0.9))
            assert m.geom_solimp[g] == pytest.approx((0.98, 0.99, 0.001, 0.4, 3.0))
            checked += 1
    assert checked == PAPER_PROTOTYPE.units + 2


def test_the_cable_limit_is_its_stretch_ea_over_l() -> None:
    """MuJoCo's direct solref is stiffness per unit of the tendon's mass: times its inertia it is E·A/L."""
    arm = ArmConfig()
    m = load(config=ModelConfig(arm=arm))
    lay = cable_layout(PAPER_PROTOTYPE, 3)
    k_phys = cable_stiffness_n_per_m(arm, lay)
    # 0.5 mm Dyneema braid, half of it fibre at 109 GPa, over the ~0.2 m from the drone to the tip
    assert 3e4 < k_phys < 8e4
    dmax = m.tendon_solimp_lim[0][1]
    for k in range(3):
        ref = m.tendon_solref_lim[k]
        assert ref[0] < 0 and ref[1] < 0
        k_acc = -ref[0] / dmax**2
        assert k_acc / m.tendon_invweight0[k] == pytest.approx(k_phys, rel=1e-6)
        # The damping c = 2ζ√(K·m_arm) is the cable's and the arm's: the slider's own 1/m is left out.
        slider = m.jnt_dofadr[name_id(m, mujoco.mjtObj.mjOBJ_JOINT, f"spool_{k}")]
        arm_mass_kg = 1.0 / (m.tendon_invweight0[k] - m.dof_invweight0[slider])
        c_phys = 2 * arm.cable_damping_ratio * math.sqrt(k_phys * arm_mass_kg)
        assert -ref[1] / dmax / m.tendon_invweight0[k] == pytest.approx(c_phys, rel=1e-6)


@pytest.mark.parametrize("kind", ["motor", "tension"])
def test_the_cable_damping_does_not_depend_on_the_actuator_mass(kind: str) -> None:
    """A light slider must not take damping away from the cable (with ζ against the series mass it did)."""
    m = load(config=ModelConfig(actuator=ActuatorConfig(kind=kind)))
    dmax = m.tendon_solimp_lim[0][1]
    c = -m.tendon_solref_lim[0][1] / dmax / m.tendon_invweight0[0]
    ref = load()
    c_motor = -ref.tendon_solref_lim[0][1] / dmax / ref.tendon_invweight0[0]
    assert c == pytest.approx(c_motor, rel=1e-6)


def test_the_old_time_constant_cable_stays_selectable() -> None:
    m = load(config=ModelConfig(arm=ArmConfig(cable_timeconst_s=0.002)))
    assert m.tendon_solref_lim[0] == pytest.approx((0.002, 1.0))
