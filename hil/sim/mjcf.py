"""MJCF generator for 1-, 2- and 3-cable SpiRob arms hanging under a drone (the paper's Note S3, Fig. S5).

The generated model (``docs/plant.md`` explains every choice and its source):

- ``drone``: a mocap body; the plant sets its pose (fixed, scripted, or from MAVLink).
- ``unit_00`` (base, fixed to the drone) ... ``unit_NN`` (tip): one body per unit, each ``β`` times its
  tip-side neighbour. Joint ``joint_ii`` lives in ``unit_ii`` and connects it to ``unit_{ii-1}`` (so
  there is no ``joint_00``): a hinge about y for 1-2 cables, a ball joint for 3 cables, limited to ±Δθ
  (ball: rotation angle ≤ Δθ). The joints sit on the central spiral ρc, so with every joint at its limit
  the arm is packed into the logarithmic spiral.
- Mass per unit ∝ β³ (uniform density) scaled to a total mass; joint stiffness ∝ (unit size)³ from a
  base value; damping from a damping ratio against the inertia each joint carries.
- Cable ``k`` is the spatial tendon ``cable_k``: from site ``cable_k_spool`` on the slider body
  ``spool_k`` (inside the drone) through ``cable_k_guide`` on the drone and two holes per unit
  (``cable_k_unit_ii_prox`` / ``_dist``) to the knot on the tip unit. The slider coordinate is the cable
  wound on the spool, ``x = r_spool · φ_output``; the tendon's upper length limit is the cable's fixed
  length, so the cable is pull-only (a unilateral constraint) and its tension is that limit's force
  (sensor ``tension_k``).
- Motor ``motor_k`` pushes slider ``spool_k`` with ``kt · I / r_spool`` (``ctrl`` in amps); the rotor
  inertia reflected through gearbox and spool, ``J_rotor · N² / r_spool²``, is the slider's mass. With
  another ``ActuatorConfig.kind``, ``motor_k`` is an ideal tension source behind a first-order lag
  (``ctrl`` in newtons) or a MuJoCo muscle (``ctrl`` = activation) on a light slider.
- Mounting: hanging under the drone (gravity along the arm), lying on a ``table`` plane (the arm's frame
  ``mount_table`` turned so the hinges are vertical), or hanging with gravity off.
- Capstan friction of the cable in the holes depends on tension and wrap angle, so
  :class:`hil.sim.plant.Plant` sets it each control period as per-joint dry friction; its coefficient travels
  in the model as the custom numeric ``spirob_cable_mu``.
- ``standalone=True`` (``spirob-hil model export``) writes the model for plain MuJoCo: what the plant does
  in Python (the drives' torque-speed line and command delay, the capstan friction) goes into the file
  (:mod:`hil.sim.standalone`).

The configuration it reads (``ModelConfig`` and its parts) lives in :mod:`hil.sim.config` and is
re-exported here.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

from hil.sim.config import (
    ACTUATOR_KINDS,
    MOUNTINGS,
    ArmConfig,
    ModelConfig,
)
from hil.sim.mjcf_text import num as _f
from hil.sim.mjcf_text import vec as _v
from hil.sim.object_shapes import object_mesh_vertices, object_shape_xml
from hil.sim.spiral import SpiralDesign
from hil.sim.standalone import (
    CAPSTAN_REFERENCE_TENSION_N,
    capstan_standin_nm,
    delay_attributes,
    drive_circuit,
)

__all__ = [
    "ARM_CONTYPE",
    "ENV_CONTYPE",
    "GRAVITY_M_S2",
    "TABLE_QUAT_WXYZ",
    "CableLayout",
    "UnitGeometry",
    "build_mjcf",
    "cable_angles_rad",
    "cable_layout",
    "cable_stiffness_n_per_m",
    "joint_friction_nm",
    "unit_geometry",
    "wedge_inset_ratio",
    "wedge_vertices_m",
    "write_mjcf",
]

GRAVITY_M_S2 = 9.80665
"""Standard gravity; the world's gravity points along −z (none with the ``gravity-off`` mounting)."""
TABLE_QUAT_WXYZ = (0.5, 0.5, -0.5, -0.5)
"""Orientation of the arm's frame on the drone for the ``table`` mounting: the arm (local −z) along the
drone's +x, the hinge axes (local y) along its z (vertical), so a 1-2 cable arm bends in the horizontal
plane."""

ARM_CONTYPE = 1
"""Collision bit of arm geoms: they touch the environment, never each other (unless self-collision)."""
ENV_CONTYPE = 2
"""Collision bit of objects and the floor."""

# Constraint impedance close to 1: MuJoCo lets (1 − d) of the unconstrained acceleration leak through a
# soft constraint. 0.9999 breaks ball-joint limits under large torque; 0.99-0.995 holds (docs/plant.md).
_SOLIMP = "0.99 0.995 0.001 0.5 2"
# Placeholder of cable k's solreflimit until the compiled model gives the tendon's inertia.
_CABLE_SOLREF = "@cable_solref_"
# Axial inset of each cable hole beyond the wedge gap, as a fraction of its radius: keeps the two facing
# holes of a closed joint apart, so the cable keeps a moment arm ≈ r at the limit (no kink in the path).
_HOLE_INSET = 0.3
# Sides of the polygon approximating a 3-cable unit's round section: enough that the polygon's flats
# (1 − cos(π/12) = 3.4 % of the radius) stay under a millimetre on the prototype's 32 mm base unit, and few
# enough that the convex collision (support-function searches over the vertices) stays cheap.
_WEDGE_SIDES = 12


@dataclass(frozen=True)
class UnitGeometry:
    """Derived per-unit geometry, index 0 = base unit ``unit_00``; SI units.

    Attributes:
        chord_m: joint-to-joint length of each unit.
        width_base_side_m: width at the unit's base-side joint.
        width_tip_side_m: width at the unit's tip-side joint.
        mass_kg: mass of each unit.
        stiffness_nm_per_rad: stiffness of the joint *in* each unit (index 0 has none: 0.0).
        damping_nms_per_rad: damping of the joint in each unit (index 0: 0.0).
        cable_radius_base_side_m: radius of the cable holes at the base-side face.
        cable_radius_tip_side_m: radius of the cable holes at the tip-side face.
    """

    chord_m: tuple[float, ...]
    width_base_side_m: tuple[float, ...]
    width_tip_side_m: tuple[float, ...]
    mass_kg: tuple[float, ...]
    stiffness_nm_per_rad: tuple[float, ...]
    damping_nms_per_rad: tuple[float, ...]
    cable_radius_base_side_m: tuple[float, ...]
    cable_radius_tip_side_m: tuple[float, ...]

    @property
    def units(self) -> int:
        """Number of units."""
        return len(self.chord_m)

    def capsule_radius_m(self, index: int) -> float:
        """Radius of unit ``index``'s collision capsule (its mean half-width)."""
        return 0.25 * (self.width_base_side_m[index] + self.width_tip_side_m[index])


@dataclass(frozen=True)
class CableLayout:
    """Where the cables run (shared by the generator and the plant).

    Attributes:
        angles_rad: azimuth of each cable around the arm axis.
        hole_offset_ratio: axial distance of a hole from its joint plane, as a fraction of its radius.
        spool_lead_m: length of the spool-to-guide segment when nothing is wound (x = 0).
        travel_in_m: how far the spool may wind in (slider upper limit).
        travel_out_m: how far the spool may pay out (slider lower limit, magnitude).
        taut_length_m: total tendon length with the arm straight and x = 0 (the cable's length).
    """

    angles_rad: tuple[float, ...]
    hole_offset_ratio: float
    spool_lead_m: float
    travel_in_m: float
    travel_out_m: float
    taut_length_m: float


def cable_angles_rad(cables: int) -> tuple[float, ...]:
    """Azimuth of each cable around the arm axis: 0 (1 cable), 0/180° (2), 0/120/240° (3).

    Raises:
        ValueError: ``cables`` is not 1, 2 or 3.
    """
    if isinstance(cables, bool) or cables not in (1, 2, 3):
        raise ValueError(f"cables must be 1, 2 or 3, got {cables!r}")
    return tuple(2.0 * math.pi * k / cables for k in range(cables))


def unit_geometry(design: SpiralDesign, arm: ArmConfig | None = None) -> UnitGeometry:
    """Chords, widths, masses, stiffnesses and damping of every unit (index 0 = base)."""
    arm = arm or ArmConfig()
    arm.validate()
    n = design.units
    chords = design.unit_chords_m()
    widths = design.unit_widths_m()
    masses = tuple(arm.total_mass_kg * f for f in design.unit_mass_fractions())
    wb = tuple(w[0] for w in widths)
    wt = tuple(w[1] for w in widths)
    p = arm.stiffness_exponent
    stiff = [0.0] + [arm.base_stiffness_nm_per_rad * design.beta ** (-p * (i - 1)) for i in range(1, n)]
    scatter = arm.stiffness_scatter
    if scatter:
        stiff = [0.0] + [k * scatter[(i - 1) % len(scatter)] for i, k in enumerate(stiff) if i > 0]
    radii = [0.25 * (wb[i] + wt[i]) for i in range(n)]
    damp = [0.0] * n
    for i in range(1, n):
        # Inertia joint i carries: the straight distal sub-chain about a transverse axis through the joint
        # (each unit a solid cylinder of its mean radius), plus the armature.
        inertia = arm.joint_armature_kg_m2
        z = 0.0
        for m in range(i, n):
            com = z + 0.5 * chords[m]
            inertia += masses[m] * ((3.0 * radii[m] ** 2 + chords[m] ** 2) / 12.0 + com * com)
            z += chords[m]
        damp[i] = 2.0 * arm.damping_ratio * math.sqrt(stiff[i] * inertia)
    rb = tuple(arm.cable_offset_ratio * 0.5 * w for w in wb)
    rt = tuple(arm.cable_offset_ratio * 0.5 * w for w in wt)
    return UnitGeometry(chords, wb, wt, masses, tuple(stiff), tuple(damp), rb, rt)


def joint_friction_nm(arm: ArmConfig, geo: UnitGeometry) -> tuple[float, ...]:
    """Dry friction of the joint in each unit (index 0 has none): the base joint's, scaled like stiffness."""
    k = geo.stiffness_nm_per_rad
    base = k[1] if len(k) > 1 and k[1] > 0 else 1.0
    return tuple(0.0 if i == 0 else arm.joint_friction_nm * k[i] / base for i in range(len(k)))


def wedge_inset_ratio(design: SpiralDesign) -> float:
    """Sagitta of a unit's inner arc as a fraction of its half-width.

    In the packed coil the inner edge of the unit at θ lies at radius ``a·e^{bθ}`` = ``δ(θ)/(e^{2πb} − 1)``
    from the pole (``δ`` the width), and over the unit's Δθ its chord stands ``r·(1 − cos(Δθ/2))`` off
    that arc: ``2·(1 − cos(Δθ/2))/(e^{2πb} − 1)`` of the half-width (4.9 % on the prototype).
    """
    return 2.0 * (1.0 - math.cos(0.5 * design.dtheta_rad)) / math.expm1(2.0 * math.pi * design.b)


def wedge_vertices_m(
    geo: UnitGeometry, index: int, dtheta_rad: float, ball: bool, inset_ratio: float = 0.0
) -> list[tuple[float, float, float]]:
    """Vertices (unit frame: base-side joint at the origin, the unit along −z) of unit ``index``'s wedge.

    The real unit is the solid between two joint faces. Each face is tilted by Δθ/2 from the plane normal
    to the unit's axis, receding from the joint point on the axis, so the open gap between two units is a
    wedge of Δθ on every bending side and closing the joint by Δθ lays the two faces together (the joint
    limit of Note S3 is that contact). Hinged arms (1-2 cables) bend about y: each face is a roof of two
    planes meeting in a ridge along y, and the section is a square of the local width (the units scale in
    all three directions). Ball-jointed arms (3 cables) bend every way: each face is a shallow cone around
    the axis and the section a regular polygon of the local width (corners on the circle). MuJoCo takes the
    convex hull of the vertices, which is the solid itself (both ends are convex).

    The real unit's side facing the inside of the packed coil follows the coil's previous turn: a concave
    arc, which a convex shape can only span by its chord. That chord would stand proud of the arc by its
    sagitta and push the packed turns apart, so every side is set in by it (``inset_ratio`` of the
    half-width, the same all round: an arm curls to any side). Packed, the turns then just touch.
    """
    tilt = math.tan(0.5 * dtheta_rad)
    ell = geo.chord_m[index]
    ends = ((0.0, -1.0, geo.width_base_side_m[index]), (-ell, 1.0, geo.width_tip_side_m[index]))
    keep = 1.0 - inset_ratio
    out: list[tuple[float, float, float]] = []
    for z_joint, inward, width in ends:
        half = 0.5 * width * keep
        z_rim = z_joint + inward * half * tilt  # the face recedes from the joint point into the unit
        if ball:
            out.append((0.0, 0.0, z_joint))
            for k in range(_WEDGE_SIDES):
                phi = 2.0 * math.pi * k / _WEDGE_SIDES
                out.append((half * math.cos(phi), half * math.sin(phi), z_rim))
        else:
            for y in (-half, half):
                out.extend(((0.0, y, z_joint), (-half, y, z_rim), (half, y, z_rim)))
    return out


def _hole_z(geo: UnitGeometry, index: int, ratio: float) -> tuple[float, float]:
    """Axial positions (unit frame, z ≤ 0) of the base-side and tip-side holes of one unit."""
    z_in = -geo.cable_radius_base_side_m[index] * ratio
    last = index == geo.units - 1
    z_out = -geo.chord_m[index] + (0.0 if last else geo.cable_radius_tip_side_m[index] * ratio)
    return z_in, z_out


def cable_layout(design: SpiralDesign, cables: int, config: ModelConfig | None = None) -> CableLayout:
    """Cable routing of ``design`` with ``cables`` cables (see :class:`CableLayout`).

    Raises:
        ValueError: the holes of a unit would overlap (a Δθ too large for the unit proportions).
    """
    cfg = config or ModelConfig()
    geo = unit_geometry(design, cfg.arm)
    angles = cable_angles_rad(cables)
    # Faces are wedges tilted by Δθ/2 about the joint: a hole at radius r sits r·tan(Δθ/2) inside its
    # unit so two facing holes meet as the joint closes; the extra inset keeps them apart at the limit.
    ratio = math.tan(0.5 * design.dtheta_rad) + _HOLE_INSET
    n = geo.units
    for i in range(n):
        z_in, z_out = _hole_z(geo, i, ratio)
        if z_out >= z_in:
            raise ValueError(
                f"unit {i}: cable holes overlap (dtheta = {math.degrees(design.dtheta_rad):g} degrees is too "
                f"large for units {geo.chord_m[i] * 1000:.3g} mm long); reduce dtheta or cable_offset_ratio"
            )
    # The longest pay-out is the cable on the outside of a fully bent arm: 2 R sin(Δθ) per joint.
    payout = sum(
        2.0
        * math.hypot(geo.cable_radius_base_side_m[i], ratio * geo.cable_radius_base_side_m[i])
        * math.sin(design.dtheta_rad)
        for i in range(1, n)
    )
    travel = 1.5 * payout + 0.01
    lead = travel + 0.02  # the spool site never reaches its guide, so the first segment stays monotone
    length = lead + geo.cable_radius_base_side_m[0] * ratio  # spool -> guide -> first hole
    for i in range(n):
        z_in, z_out = _hole_z(geo, i, ratio)
        length += math.hypot(z_in - z_out, geo.cable_radius_base_side_m[i] - geo.cable_radius_tip_side_m[i])
        if i < n - 1:
            length += 2.0 * geo.cable_radius_tip_side_m[i] * ratio  # the open wedge gap to the next unit
    return CableLayout(angles, ratio, lead, travel, travel, length)


def build_mjcf(
    design: SpiralDesign,
    cables: int | None = None,
    config: ModelConfig | None = None,
    *,
    standalone: bool = False,
) -> str:
    """Generate the self-contained MJCF model of an arm under a drone.

    Args:
        design: the spiral design (unit count and geometry).
        cables: 1, 2 or 3; ``None`` uses ``design.cables``.
        config: mechanical, motor, drone, solver and object settings (defaults: the prototype's).
        standalone: the model for plain MuJoCo (``spirob-hil model export``): what the plant does in
            Python is in the file (:mod:`hil.sim.standalone`: the drives as ``dcmotor`` actuators with
            their torque-speed line and command delay, the capstan friction frozen at a reference
            tension). ``False`` (the plant's): the drives and the capstan friction are left to
            :class:`hil.sim.plant.Plant`.

    Returns:
        MJCF XML text; ``mujoco.MjModel.from_xml_string`` (or ``from_xml_path`` once written) loads it
        without any project code and without other files.

    Raises:
        ValueError: a configuration value is out of range, or the design has fewer than 2 units.
    """
    cfg = config or ModelConfig()
    cfg.validate()
    n_cables = design.cables if cables is None else cables
    if design.units < 2:
        raise ValueError("the arm needs at least 2 units (one joint)")
    geo = unit_geometry(design, cfg.arm)
    lay = cable_layout(design, n_cables, cfg)
    arm, motor, drone, sol, act = cfg.arm, cfg.motor, cfg.drone, cfg.solver, cfg.actuator
    n = design.units
    dtheta = design.dtheta_rad
    ball = n_cables == 3

    out: list[str] = []
    add = out.append
    add(f'<mujoco model="spirob_{n_cables}cable_{n}units">')
    add("  <!-- Generated by hil.sim.mjcf.build_mjcf (spirob-teleop); docs/plant.md explains the model. -->")
    if standalone:
        add(
            "  <!-- Standalone export: motor_k is the drive of cable k, ctrl in amps (dcmotor: current "
            "loop and torque-speed line); capstan friction frozen at a reference tension (docs/plant.md, "
            "'The exported model'). -->"
        )
    add('  <compiler angle="radian" autolimits="true"/>')
    add(
        f'  <option timestep="{_f(sol.timestep_s)}" integrator="{sol.integrator}" solver="{sol.solver}" '
        f'iterations="{sol.iterations}" ls_iterations="{sol.ls_iterations}" tolerance="{_f(sol.tolerance)}" '
        f'cone="{sol.cone}" jacobian="{sol.jacobian}" '
        f'gravity="0 0 {0.0 if cfg.mounting == "gravity-off" else -GRAVITY_M_S2:g}"/>'
    )
    add("  <custom>")
    custom = {
        "spirob_cables": n_cables,
        "spirob_units": n,
        "spirob_a_m": design.a_m,
        "spirob_b": design.b,
        "spirob_dtheta_rad": dtheta,
        "spirob_theta0_rad": design.theta0_rad,
        "spirob_cable_mu": arm.cable_mu,
        "spirob_spool_lead_m": lay.spool_lead_m,
        "spirob_torque_constant_nm_per_a": motor.torque_constant_nm_per_a,
        "spirob_gear_ratio": motor.gear_ratio,
        "spirob_spool_radius_m": motor.spool_radius_m,
        "spirob_current_limit_a": motor.current_limit_a,
        "spirob_no_load_speed_rad_s": motor.no_load_speed_rad_s,
        "spirob_stall_current_a": motor.stall_current_a,
        "spirob_actuator_kind": ACTUATOR_KINDS.index(act.kind),
        "spirob_mounting": MOUNTINGS.index(cfg.mounting),
    }
    if standalone:
        custom |= {
            "spirob_standalone": 1,
            "spirob_torque_scale": motor.torque_scale,
            "spirob_command_delay_s": motor.command_delay_s,
            "spirob_joint_friction_nm": arm.joint_friction_nm,
            "spirob_capstan_reference_tension_n": CAPSTAN_REFERENCE_TENSION_N,
        }
    for key, value in custom.items():
        add(f'    <numeric name="{key}" data="{_f(float(value))}"/>')
    add("  </custom>")
    add("  <default>")
    arm_aff = ARM_CONTYPE | ENV_CONTYPE if arm.units_collide else ENV_CONTYPE
    con = cfg.contact
    # Every arm and object geom carries the same stated contact (MuJoCo mixes the two sides' solref).
    contact = f'solref="{_v(con.timeconst_s, con.damping_ratio)}" solimp="{_v(*con.solimp)}"'
    add(
        f'    <geom contype="{ARM_CONTYPE}" conaffinity="{arm_aff}" condim="3" '
        f'friction="{_f(arm.geom_friction)} 0.005 0.0001" {contact}/>'
    )
    add(f'    <site size="{_f(arm.cable_diameter_m)}" rgba="0.9 0.9 0.2 1"/>')
    add("  </default>")
    add("  <asset>")
    add('    <material name="tpu" rgba="0.95 0.55 0.15 1"/>')
    add('    <material name="drone" rgba="0.25 0.25 0.3 1"/>')
    add('    <material name="object" rgba="0.3 0.6 0.9 1"/>')
    if arm.unit_shape == "wedge":
        for i in range(n):
            inset = wedge_inset_ratio(design)
            verts = " ".join(_v(*p) for p in wedge_vertices_m(geo, i, dtheta, ball, inset))
            add(f'    <mesh name="unit_{i:02d}_mesh" vertex="{verts}"/>')
    for obj in cfg.objects:
        points = object_mesh_vertices(obj)
        if points:
            add(f'    <mesh name="{obj.name}_mesh" vertex="{" ".join(_v(*p) for p in points)}"/>')
    add("  </asset>")
    add("  <worldbody>")
    add('    <light name="sun" pos="0 0 3" dir="0 0 -1" directional="true"/>')
    if drone.floor:
        add(
            f'    <geom name="floor" type="plane" size="5 5 0.1" contype="{ENV_CONTYPE}" '
            f'conaffinity="{ARM_CONTYPE | ENV_CONTYPE}" rgba="0.8 0.8 0.8 1"/>'
        )
    table = cfg.mounting == "table"
    if table:
        # The table carries the arm's widest section (the base unit's base-side face).
        table_pos = (drone.pos_m[0], drone.pos_m[1], drone.pos_m[2] - 0.5 * geo.width_base_side_m[0])
        add(
            f'    <geom name="table" type="plane" size="1 1 0.1" pos="{_v(*table_pos)}" '
            f'contype="{ENV_CONTYPE}" conaffinity="{ARM_CONTYPE | ENV_CONTYPE}" rgba="0.6 0.5 0.4 1"/>'
        )
    hx, hy, hz = drone.half_size_m
    add(f'    <body name="drone" pos="{_v(*drone.pos_m)}" quat="{_v(*drone.quat_wxyz)}" mocap="true">')
    add(
        f'      <geom name="drone_body" type="box" size="{_v(hx, hy, hz)}" pos="0 0 {_f(hz)}" '
        f'contype="0" conaffinity="0" material="drone" mass="1"/>'
    )
    if table:
        # The arm lies along the drone's +x with its hinge axes vertical: it bends in the horizontal plane.
        add(f'      <body name="mount_table" quat="{_v(*TABLE_QUAT_WXYZ)}">')
    add(f'      <site name="mount" pos="0 0 {_f(-drone.mount_offset_m)}"/>')
    motor_kind = act.kind == "motor"
    spool_mass_kg = motor.reflected_mass_kg if motor_kind else act.reflected_mass_kg
    spool_friction_n = motor.friction_force_n if motor_kind else act.friction_n
    r0 = geo.cable_radius_base_side_m[0]
    for k, psi in enumerate(lay.angles_rad):
        cx, cy = r0 * math.cos(psi), r0 * math.sin(psi)
        add(f'      <site name="cable_{k}_guide" pos="{_v(cx, cy, -drone.mount_offset_m)}"/>')
        # The spool: a slider whose coordinate is the wound cable and whose mass is the rotor inertia
        # reflected to the cable (a body mass, not armature: MuJoCo's constraint scaling ignores armature on
        # slide joints). gravcomp: that "mass" has no weight.
        add(
            f'      <body name="spool_{k}" pos="{_v(cx, cy, -drone.mount_offset_m + lay.spool_lead_m)}" '
            f'gravcomp="1">'
        )
        add(
            f'        <joint name="spool_{k}" type="slide" axis="0 0 1" '
            f'range="{_v(-lay.travel_out_m, lay.travel_in_m)}" '
            f'frictionloss="{_f(spool_friction_n)}"/>'
        )
        add(
            f'        <geom name="spool_{k}_geom" type="sphere" size="0.004" contype="0" conaffinity="0" '
            f'mass="{_f(spool_mass_kg)}" rgba="0.6 0.6 0.6 1"/>'
        )
        add(f'        <site name="cable_{k}_spool"/>')
        add("      </body>")

    friction_nm = joint_friction_nm(arm, geo)
    if standalone:
        capstan = capstan_standin_nm(
            arm.cable_mu,
            geo.cable_radius_base_side_m[1:],
            CAPSTAN_REFERENCE_TENSION_N,
            dtheta,
        )
        friction_nm = (0.0, *(f + c for f, c in zip(friction_nm[1:], capstan, strict=True)))
    indent = "      "
    for i in range(n):
        name = f"unit_{i:02d}"
        z = -drone.mount_offset_m if i == 0 else -geo.chord_m[i - 1]
        add(f'{indent}<body name="{name}" pos="0 0 {_f(z)}">')
        inner = indent + "  "
        if i > 0:
            common = (
                f'stiffness="{_f(geo.stiffness_nm_per_rad[i])}" damping="{_f(geo.damping_nms_per_rad[i])}" '
                f'armature="{_f(arm.joint_armature_kg_m2)}" '
                f'solreflimit="{_f(arm.limit_timeconst_s)} 1" solimplimit="{_SOLIMP}"'
            )
            if arm.joint_friction_nm > 0 or friction_nm[i] > 0:
                common += f' frictionloss="{_f(friction_nm[i])}"'
            if ball:
                add(f'{inner}<joint name="joint_{i:02d}" type="ball" range="0 {_f(dtheta)}" {common}/>')
            else:
                add(
                    f'{inner}<joint name="joint_{i:02d}" type="hinge" axis="0 1 0" '
                    f'range="{_v(-dtheta, dtheta)}" {common}/>'
                )
        ell = geo.chord_m[i]
        if arm.unit_shape == "wedge":
            shape = f'type="mesh" mesh="{name}_mesh"'
        else:
            shape = f'type="capsule" fromto="0 0 0 0 0 {_f(-ell)}" size="{_f(geo.capsule_radius_m(i))}"'
        add(f'{inner}<geom name="{name}_geom" {shape} mass="{_f(geo.mass_kg[i])}" material="tpu"/>')
        rb, rt = geo.cable_radius_base_side_m[i], geo.cable_radius_tip_side_m[i]
        z_in, z_out = _hole_z(geo, i, lay.hole_offset_ratio)
        for k, psi in enumerate(lay.angles_rad):
            c, s = math.cos(psi), math.sin(psi)
            add(f'{inner}<site name="cable_{k}_unit_{i:02d}_prox" pos="{_v(rb * c, rb * s, z_in)}"/>')
            add(f'{inner}<site name="cable_{k}_unit_{i:02d}_dist" pos="{_v(rt * c, rt * s, z_out)}"/>')
        if i == n - 1:
            add(f'{inner}<site name="tip" pos="0 0 {_f(-ell)}"/>')
        indent = inner
    for _ in range(n):
        indent = indent[:-2]
        add(f"{indent}  </body>")
    if table:
        add("      </body>")
    add("    </body>")

    for obj in cfg.objects:
        geom = (
            f'<geom name="{obj.name}_geom" {object_shape_xml(obj)} '
            f'contype="{ENV_CONTYPE}" conaffinity="{ARM_CONTYPE | ENV_CONTYPE}" '
            f'friction="{_f(obj.friction)} 0.005 0.0001" material="object" {contact}'
        )
        add(f'    <body name="{obj.name}" pos="{_v(*obj.pos_m)}">')
        if obj.mass_kg is None:
            add(f"      {geom}/>")
        else:
            add(f'      <freejoint name="{obj.name}_free"/>')
            add(f'      {geom} mass="{_f(obj.mass_kg)}"/>')
        add("    </body>")
    for obj in cfg.objects:
        if obj.mass_kg is not None:
            # A support the plant can switch on (Plant.hold_object): the object is welded to this mocap body.
            add(f'    <body name="{obj.name}_support" pos="{_v(*obj.pos_m)}" mocap="true"/>')
    add("  </worldbody>")
    free = [o for o in cfg.objects if o.mass_kg is not None]
    if free:
        add("  <equality>")
        for obj in free:
            add(
                f'    <weld name="{obj.name}_support" body1="{obj.name}" body2="{obj.name}_support" '
                f'relpose="0 0 0 1 0 0 0" active="false" solref="0.002 1"/>'
            )
        add("  </equality>")

    add("  <tendon>")
    for k in range(n_cables):
        add(
            f'    <spatial name="cable_{k}" range="0 {_f(lay.taut_length_m)}" '
            f'solreflimit="{_CABLE_SOLREF}{k}" solimplimit="{_SOLIMP}" '
            f'width="{_f(0.5 * arm.cable_diameter_m)}" rgba="0.1 0.1 0.1 1">'
        )
        add(f'      <site site="cable_{k}_spool"/>')
        add(f'      <site site="cable_{k}_guide"/>')
        for i in range(n):
            add(f'      <site site="cable_{k}_unit_{i:02d}_prox"/>')
            add(f'      <site site="cable_{k}_unit_{i:02d}_dist"/>')
        add("    </spatial>")
    add("  </tendon>")

    add("  <actuator>")
    for k in range(n_cables):
        add("    " + _actuator_xml(k, cfg, design, lay, standalone))
    add("  </actuator>")

    add("  <sensor>")
    for k in range(n_cables):
        add(f'    <tendonlimitfrc name="tension_{k}" tendon="cable_{k}"/>')
    add("  </sensor>")
    add("</mujoco>")
    return _with_cable_stretch("\n".join(out) + "\n", n_cables, arm, lay)


def cable_stiffness_n_per_m(arm: ArmConfig, layout: CableLayout) -> float:
    """Axial stiffness ``E·A/L`` of a cable: ``L`` is its free run from the guide on the drone to the knot
    at the tip (the spool's lead in the model is a numerical travel, not cable)."""
    return arm.cable_axial_stiffness_n / (layout.taut_length_m - layout.spool_lead_m)


def _with_cable_stretch(xml: str, n_cables: int, arm: ArmConfig, layout: CableLayout) -> str:
    """Replace each cable's ``solreflimit`` placeholder by its stretch stiffness and damping.

    MuJoCo's direct form ``solref="-k -b"`` sets the constraint's reference acceleration ``−k·r − b·v`` in
    the tendon's own coordinate, i.e. stiffness per unit of the mass the tendon moves. That mass is
    ``1 / tendon_invweight0`` (the tendon's inverse inertia in the straight pose, known after compiling:
    the spool slider and the arm in series), so ``k = K · invweight0`` gives the physical ``K = E·A/L``
    [N/m]. The damping is a property of the cable and the arm it pulls, not of the actuator: a viscous
    ``c = 2ζ·√(K·m_arm)`` [N·s/m], ``m_arm`` the arm's inertia seen at the cable (``invweight0`` less the
    slider's ``1/m``), so ``b = c · invweight0``. A light slider (10 g against the arm's 31 g) then
    damps the stretch mode more than ζ (about 1.0 for ζ = 0.5), where ζ against the series mass would
    leave it ringing at 400 Hz, unload the cable every cycle and slam the slider back into it.
    MuJoCo divides by the impedance ``dmax`` (``k/dmax²``, ``b/dmax``), undone here.
    """
    if arm.cable_timeconst_s is not None:
        for k in range(n_cables):
            xml = xml.replace(f"{_CABLE_SOLREF}{k}", f"{_f(arm.cable_timeconst_s)} 1")
        return xml
    import mujoco  # compile-time only: the generator itself has no MuJoCo dependency otherwise

    first = xml
    for k in range(n_cables):
        first = first.replace(f"{_CABLE_SOLREF}{k}", "0.002 1")
    model = mujoco.MjModel.from_xml_string(first)
    stiffness = cable_stiffness_n_per_m(arm, layout)
    dmax = float(_SOLIMP.split()[1])
    for k in range(n_cables):
        tid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_TENDON, f"cable_{k}")
        jid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, f"spool_{k}")
        inv_mass = float(model.tendon_invweight0[tid])
        # The slider coordinate is the cable length (Jacobian 1) and the slider is apart from the arm in
        # the mass matrix, so its share of the tendon's inverse inertia is its own 1/m.
        inv_arm_mass = inv_mass - float(model.dof_invweight0[model.jnt_dofadr[jid]])
        k_acc = stiffness * inv_mass
        b_acc = 2.0 * arm.cable_damping_ratio * math.sqrt(stiffness / inv_arm_mass) * inv_mass
        xml = xml.replace(f"{_CABLE_SOLREF}{k}", _v(-k_acc * dmax * dmax, -b_acc * dmax))
    return xml


def _actuator_xml(k: int, cfg: ModelConfig, design: SpiralDesign, lay: CableLayout, standalone: bool) -> str:
    """The actuator ``motor_k`` on slider ``spool_k`` (positive generalised force winds the cable in).

    Standalone, it carries the drives' command delay, and the motor is a ``dcmotor`` (the drives' current
    loop and torque-speed line, :func:`hil.sim.standalone.drive_circuit`).
    """
    act, motor = cfg.actuator, cfg.motor
    delay = delay_attributes(motor.command_delay_s, cfg.solver.timestep_s) if standalone else ""
    if act.kind == "tension":
        # ctrl is the asked tension [N]; the force follows it through an exact first-order lag.
        return (
            f'<general name="motor_{k}" joint="spool_{k}" dyntype="filterexact" dynprm="{_f(act.lag_s)}" '
            f'gainprm="1" biasprm="0 0 0" ctrlrange="0 {_f(cfg.peak_tension_n)}"{delay}/>'
        )
    if act.kind == "muscle":
        # ctrl is the activation. gear -1: the muscle's length is the unwound cable, -x, so its
        # contraction winds the cable in. Its length range is the authors' (multiples of the arm's
        # length over the cable's arm-side path), shifted by that path's length with nothing wound.
        arm_path_m = lay.taut_length_m - lay.spool_lead_m
        lo, hi = (r * design.length_m - arm_path_m for r in act.muscle_length_range)
        return (
            f'<muscle name="motor_{k}" joint="spool_{k}" gear="-1" ctrlrange="0 1" '
            f'force="{_f(cfg.muscle_force_n)}" lengthrange="{_v(lo, hi)}" '
            f'timeconst="{_v(*act.muscle_timeconst_s)}"{delay}/>'
        )
    # ctrl in amps; cable force = kt · I / r_spool. The drives apply the torque-speed line on top (in the
    # plant's model) or the dcmotor does (standalone).
    lim = motor.current_limit_a
    if standalone:
        c = drive_circuit(motor)
        return (
            f'<dcmotor name="motor_{k}" joint="spool_{k}" gear="{_f(c.gear)}" ctrlrange="{_v(-lim, lim)}" '
            f'saturation="{_v(c.current_limit_a, 0, 0)}" '
            # All 17 digits: the line's corner is Vmax·K/R, which 9 digits would move by 4e-9 A.
            f'input="ff" motorconst="{c.motorconst!r}" resistance="{c.resistance_ohm!r}" '
            f'controller="0 0 0 0 0 {_f(c.vmax_v)}"{delay}/>'
        )
    return (
        f'<motor name="motor_{k}" joint="spool_{k}" gear="{_f(motor.delivered_force_per_amp_n)}" '
        f'ctrlrange="{_v(-lim, lim)}"/>'
    )


def write_mjcf(
    path: str | Path,
    design: SpiralDesign,
    cables: int | None = None,
    config: ModelConfig | None = None,
    *,
    standalone: bool = False,
) -> Path:
    """Write :func:`build_mjcf`'s model to ``path`` (one file: wedge meshes are inline)."""
    target = Path(path)
    target.write_text(build_mjcf(design, cables, config, standalone=standalone), encoding="utf-8")
    return target
