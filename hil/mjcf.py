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
  inertia reflected through gearbox and spool, ``J_rotor · N² / r_spool²``, is the slider's mass.
- Capstan friction of the cable in the holes depends on tension and wrap angle, so
  :class:`hil.plant.Plant` sets it each control period as per-joint dry friction; its coefficient travels
  in the model as the custom numeric ``spirob_cable_mu``.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from pathlib import Path

from controller.config import C610_MAX_A, MotorDriveConfig
from hil.spiral import SpiralDesign

__all__ = [
    "ARM_CONTYPE",
    "ENV_CONTYPE",
    "ArmConfig",
    "CableLayout",
    "DroneConfig",
    "ModelConfig",
    "MotorConfig",
    "ObjectConfig",
    "SolverConfig",
    "UnitGeometry",
    "build_mjcf",
    "cable_angles_rad",
    "cable_layout",
    "unit_geometry",
    "write_mjcf",
]

ARM_CONTYPE = 1
"""Collision bit of arm geoms: they touch the environment, never each other (unless self-collision)."""
ENV_CONTYPE = 2
"""Collision bit of objects and the floor."""

# Constraint impedance close to 1: MuJoCo lets (1 − d) of the unconstrained acceleration leak through a
# soft constraint. 0.9999 breaks ball-joint limits under large torque; 0.99-0.995 holds (docs/plant.md).
_SOLIMP = "0.99 0.995 0.001 0.5 2"
# Axial inset of each cable hole beyond the wedge gap, as a fraction of its radius: keeps the two facing
# holes of a closed joint apart, so the cable keeps a moment arm ≈ r at the limit (no kink in the path).
_HOLE_INSET = 0.3
_NAME = re.compile(r"^[A-Za-z][A-Za-z0-9_]{0,40}$")
_RESERVED = re.compile(r"^(unit|joint|cable|spool|motor|tension|drone|tip|mount|floor|sun)")


def _check(cond: bool, message: str) -> None:
    if not cond:
        raise ValueError(message)


def _finite(name: str, value: float, *, minimum: float = 0.0, allow_equal: bool = False) -> None:
    ok = isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)
    ok = ok and (value >= minimum if allow_equal else value > minimum)
    _check(ok, f"{name} must be a finite number {'>=' if allow_equal else '>'} {minimum:g}, got {value!r}")


def _vector(name: str, value: tuple[float, ...], n: int) -> None:
    ok = len(value) == n and all(isinstance(v, int | float) and math.isfinite(v) for v in value)
    _check(ok, f"{name} must be {n} finite numbers, got {value!r}")


@dataclass(frozen=True)
class ArmConfig:
    """Mechanical parameters of the arm body.

    Attributes:
        total_mass_kg: mass of all units together, split ∝ β³ (uniform density). Prototype: 38.4 g
            (a reconstruction of the paper's STL files in TPU 95A).
        base_stiffness_nm_per_rad: stiffness of the joint nearest the base; joint i has
            ``k_base · β^{−3(i−1)}`` (stiffness ∝ size³, Note S3's proportionality). Published
            identification of a TPU arm: 0.3-0.8 N·m/rad near the base.
        damping_ratio: ζ of each joint against the inertia it carries (identification: about 0.13).
        cable_offset_ratio: cable hole radius as a fraction of the local half-width.
        cable_mu: capstan friction coefficient of the cable in the holes (0.25-0.4 reproduces the
            base-first uncurling). 0 disables cable friction.
        cable_diameter_m: UHMWPE cable diameter (the paper's Note S1: 0.5 mm); drawing only.
        joint_armature_kg_m2: rotational inertia added to every arm joint. Numerical: with mass ∝ β³ the
            tip joints carry ~1e-9 kg·m², and MuJoCo scales constraint softness by inverse inertia, so
            joint limits and the cable would give way under cable loads; 3e-6 keeps them within about a
            degree / a millimetre at the 1 ms step and leaves the first bending mode unchanged.
        limit_timeconst_s: ``solref`` time constant of the joint limits (unit-on-unit contact).
        cable_timeconst_s: ``solref`` time constant of the cable (tendon length limit).
        self_collision: let non-adjacent units collide. Off by default: Note S3 models units touching by
            the joint limits, which keeps the packed pose cheap and exact.
        geom_friction: sliding friction coefficient of the unit surfaces.
    """

    total_mass_kg: float = 0.0384
    base_stiffness_nm_per_rad: float = 0.5
    damping_ratio: float = 0.13
    cable_offset_ratio: float = 0.8
    cable_mu: float = 0.3
    cable_diameter_m: float = 0.0005
    joint_armature_kg_m2: float = 3e-6
    limit_timeconst_s: float = 0.002
    cable_timeconst_s: float = 0.002
    self_collision: bool = False
    geom_friction: float = 0.8

    def validate(self) -> None:
        """Raise ``ValueError`` if a value is out of range."""
        _finite("total_mass_kg", self.total_mass_kg)
        _finite("base_stiffness_nm_per_rad", self.base_stiffness_nm_per_rad, allow_equal=True)
        _finite("damping_ratio", self.damping_ratio, allow_equal=True)
        _finite("cable_offset_ratio", self.cable_offset_ratio)
        _check(
            self.cable_offset_ratio < 1.0, f"cable_offset_ratio must be < 1, got {self.cable_offset_ratio!r}"
        )
        _finite("cable_mu", self.cable_mu, allow_equal=True)
        _finite("cable_diameter_m", self.cable_diameter_m)
        _finite("joint_armature_kg_m2", self.joint_armature_kg_m2, allow_equal=True)
        _finite("limit_timeconst_s", self.limit_timeconst_s)
        _finite("cable_timeconst_s", self.cable_timeconst_s)
        _finite("geom_friction", self.geom_friction, allow_equal=True)


_DRIVE = MotorDriveConfig()
"""The firmware's drive constants: the one source of the torque constant, gear ratio and spool radius."""


@dataclass(frozen=True)
class MotorConfig:
    """DJI M2006 P36 + C610 + spool, one per cable (DJI's M2006 P36 and C610 documents).

    Attributes:
        torque_constant_nm_per_a: output-shaft torque per amp; default the firmware's
            (``controller.config.MotorDriveConfig``), as are ``gear_ratio`` and ``spool_radius_m``, so
            the plant and the firmware's tension estimate agree. 0.18 N·m/A: DJI's M2006 P36 figure
            on its product page. DJI also states "1 N·m rated at 3 A" (about
            0.33 N·m/A); the C610 manual's curve is the better reference. The firmware must estimate
            tension with the same constant as the plant.
        gear_ratio: rotor turns per output turn (P36: 36).
        rotor_inertia_kg_m2: rotor inertia before the gearbox. No published figure; 1e-7 kg·m² is the
            estimate for a Ø10 × 15 mm steel/NdFeB inner rotor (1.3 kg seen at the cable with a 10 mm
            spool).
        spool_radius_m: cable spool radius (10 mm, the prototype's).
        current_limit_a: largest |current| the plant accepts (C610: 10 A peak = raw 10000, from
            ``protocol.c610``).
        no_load_speed_rad_s: output speed at zero torque (500 rpm, DJI's M2006 P36 figure).
        stall_current_a: current the drive could push at standstill; with the no-load speed it sets the
            torque-speed line ``I_avail = I_stall · (1 − ω/ω_nl)``. 18 A puts DJI's rated point (3 A at
            416 rpm) on that line.
        output_friction_nm: Coulomb friction of gearbox and spool at the output shaft.
        current_noise_raw: standard deviation of the fed-back current, raw units (0 = exact).
        temperature_c: temperature reported in every feedback frame.
    """

    torque_constant_nm_per_a: float = _DRIVE.torque_constant_nm_per_a
    gear_ratio: float = _DRIVE.gear_ratio
    rotor_inertia_kg_m2: float = 1.0e-7
    spool_radius_m: float = _DRIVE.spool_radius_m
    current_limit_a: float = C610_MAX_A
    no_load_speed_rad_s: float = 500.0 * 2.0 * math.pi / 60.0
    stall_current_a: float = 18.0
    output_friction_nm: float = 0.01
    current_noise_raw: float = 0.0
    temperature_c: int = 30

    @property
    def reflected_mass_kg(self) -> float:
        """Rotor inertia seen at the cable: ``J_rotor · N² / r_spool²`` [kg]."""
        return self.rotor_inertia_kg_m2 * self.gear_ratio**2 / self.spool_radius_m**2

    @property
    def force_per_amp_n(self) -> float:
        """Cable force per amp at standstill: ``kt / r_spool`` [N/A]."""
        return self.torque_constant_nm_per_a / self.spool_radius_m

    @property
    def friction_force_n(self) -> float:
        """Output friction seen at the cable [N]."""
        return self.output_friction_nm / self.spool_radius_m

    def validate(self) -> None:
        """Raise ``ValueError`` if a value is out of range."""
        _finite("torque_constant_nm_per_a", self.torque_constant_nm_per_a)
        _finite("gear_ratio", self.gear_ratio)
        _finite("rotor_inertia_kg_m2", self.rotor_inertia_kg_m2)
        _finite("spool_radius_m", self.spool_radius_m)
        _finite("current_limit_a", self.current_limit_a)
        _check(
            self.current_limit_a <= C610_MAX_A,
            f"current_limit_a must be <= 10 A (C610), got {self.current_limit_a!r}",
        )
        _finite("no_load_speed_rad_s", self.no_load_speed_rad_s)
        _finite("stall_current_a", self.stall_current_a)
        _finite("output_friction_nm", self.output_friction_nm, allow_equal=True)
        _finite("current_noise_raw", self.current_noise_raw, allow_equal=True)
        _check(
            isinstance(self.temperature_c, int) and 0 <= self.temperature_c <= 255,
            f"temperature_c must be an int 0..255, got {self.temperature_c!r}",
        )


@dataclass(frozen=True)
class ObjectConfig:
    """A cylinder to grasp.

    Attributes:
        name: body name in the model (letters, digits, underscores; not an arm name).
        radius_m: cylinder radius.
        length_m: cylinder length.
        pos_m: centre in world coordinates.
        axis: direction of the cylinder axis in world coordinates (normalised here).
        mass_kg: ``None`` = fixed to the world (a branch, a pole); otherwise a free body of this mass,
            with a switchable support (``{name}_support``: a mocap body and a weld to it, inactive at
            start) that :meth:`hil.plant.Plant.hold_object` uses to hold it where it is.
        friction: sliding friction coefficient.
        shape: ``"cylinder"`` (flat ends, convex collision) or ``"capsule"`` (rounded ends, analytic
            collision: cheaper).
    """

    name: str
    radius_m: float
    length_m: float
    pos_m: tuple[float, float, float]
    axis: tuple[float, float, float] = (0.0, 1.0, 0.0)
    mass_kg: float | None = None
    friction: float = 0.8
    shape: str = "cylinder"

    def validate(self) -> None:
        """Raise ``ValueError`` if a value is out of range."""
        _check(
            isinstance(self.name, str) and bool(_NAME.match(self.name)) and not _RESERVED.match(self.name),
            f"object name must be an identifier not starting like an arm name, got {self.name!r}",
        )
        _finite("radius_m", self.radius_m)
        _finite("length_m", self.length_m)
        _vector("pos_m", self.pos_m, 3)
        _vector("axis", self.axis, 3)
        _check(any(v != 0 for v in self.axis), f"axis must be non-zero, got {self.axis!r}")
        if self.mass_kg is not None:
            _finite("mass_kg", self.mass_kg)
        _finite("friction", self.friction, allow_equal=True)
        _check(
            self.shape in ("cylinder", "capsule"),
            f"shape must be 'cylinder' or 'capsule', got {self.shape!r}",
        )


@dataclass(frozen=True)
class DroneConfig:
    """The body the arm hangs from.

    Attributes:
        pos_m: initial position of the drone's origin (world frame, z up).
        quat_wxyz: initial orientation (normalised here).
        mount_offset_m: distance from the drone origin down to the base of the arm.
        half_size_m: half extents of the drone's box (drawing only; it does not collide).
        floor: add a ground plane at z = 0.
    """

    pos_m: tuple[float, float, float] = (0.0, 0.0, 1.0)
    quat_wxyz: tuple[float, float, float, float] = (1.0, 0.0, 0.0, 0.0)
    mount_offset_m: float = 0.02
    half_size_m: tuple[float, float, float] = (0.12, 0.12, 0.03)
    floor: bool = False

    def validate(self) -> None:
        """Raise ``ValueError`` if a value is out of range."""
        _vector("pos_m", self.pos_m, 3)
        _vector("quat_wxyz", self.quat_wxyz, 4)
        _check(any(v != 0 for v in self.quat_wxyz), "quat_wxyz must be non-zero")
        _finite("mount_offset_m", self.mount_offset_m)
        _vector("half_size_m", self.half_size_m, 3)
        _check(all(v > 0 for v in self.half_size_m), f"half_size_m must be > 0, got {self.half_size_m!r}")


@dataclass(frozen=True)
class SolverConfig:
    """MuJoCo numerical settings (``<option>``); the choice is explained in ``docs/plant.md``.

    Attributes:
        timestep_s: physics step; the control period must be a whole number of these.
        integrator: ``discrete`` (MuJoCo >= 3.13: joint stiffness, damping and constraints in the implicit
            step, stable far beyond the explicit limit), ``implicitfast``, ``implicit``, ``Euler`` or ``RK4``.
        solver: ``Newton``, ``CG`` or ``PGS``.
        iterations: constraint solver iterations.
        ls_iterations: line-search iterations.
        tolerance: solver tolerance.
        cone: friction cone, ``pyramidal`` or ``elliptic``.
    """

    timestep_s: float = 0.001
    integrator: str = "discrete"
    solver: str = "Newton"
    iterations: int = 20
    ls_iterations: int = 10
    tolerance: float = 1e-8
    cone: str = "pyramidal"

    def validate(self) -> None:
        """Raise ``ValueError`` if a value is out of range."""
        _finite("timestep_s", self.timestep_s)
        _check(
            self.integrator in ("discrete", "implicitfast", "implicit", "Euler", "RK4"),
            f"unknown integrator {self.integrator!r}",
        )
        _check(self.solver in ("Newton", "CG", "PGS"), f"unknown solver {self.solver!r}")
        _check(
            isinstance(self.iterations, int) and isinstance(self.ls_iterations, int),
            "iterations must be ints",
        )
        _check(self.iterations >= 1 and self.ls_iterations >= 1, "iterations must be >= 1")
        _finite("tolerance", self.tolerance, allow_equal=True)
        _check(self.cone in ("pyramidal", "elliptic"), f"unknown cone {self.cone!r}")


@dataclass(frozen=True)
class ModelConfig:
    """Everything :func:`build_mjcf` needs besides the spiral design."""

    arm: ArmConfig = field(default_factory=ArmConfig)
    motor: MotorConfig = field(default_factory=MotorConfig)
    drone: DroneConfig = field(default_factory=DroneConfig)
    solver: SolverConfig = field(default_factory=SolverConfig)
    objects: tuple[ObjectConfig, ...] = ()

    def validate(self) -> None:
        """Raise ``ValueError`` if any part is out of range or object names clash."""
        self.arm.validate()
        self.motor.validate()
        self.drone.validate()
        self.solver.validate()
        names = [o.name for o in self.objects]
        _check(len(names) == len(set(names)), f"object names must be unique, got {names}")
        supports = {f"{o.name}_support" for o in self.objects if o.mass_kg is not None}
        _check(not supports & set(names), f"an object name clashes with another's support body: {names}")
        for o in self.objects:
            o.validate()

    def with_objects(self, *objects: ObjectConfig) -> ModelConfig:
        """A copy with ``objects`` appended."""
        return ModelConfig(self.arm, self.motor, self.drone, self.solver, self.objects + tuple(objects))


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
    stiff = [0.0] + [arm.base_stiffness_nm_per_rad * design.beta ** (-3.0 * (i - 1)) for i in range(1, n)]
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


def _f(x: float) -> str:
    return f"{x:.9g}"


def _v(*xs: float) -> str:
    return " ".join(_f(x) for x in xs)


def build_mjcf(design: SpiralDesign, cables: int | None = None, config: ModelConfig | None = None) -> str:
    """Generate the self-contained MJCF model of an arm under a drone.

    Args:
        design: the spiral design (unit count and geometry).
        cables: 1, 2 or 3; ``None`` uses ``design.cables``.
        config: mechanical, motor, drone, solver and object settings (defaults: the prototype's).

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
    arm, motor, drone, sol = cfg.arm, cfg.motor, cfg.drone, cfg.solver
    n = design.units
    dtheta = design.dtheta_rad
    ball = n_cables == 3

    out: list[str] = []
    add = out.append
    add(f'<mujoco model="spirob_{n_cables}cable_{n}units">')
    add("  <!-- Generated by hil.mjcf.build_mjcf (spirob-teleop); docs/plant.md explains the model. -->")
    add('  <compiler angle="radian" autolimits="true"/>')
    add(
        f'  <option timestep="{_f(sol.timestep_s)}" integrator="{sol.integrator}" solver="{sol.solver}" '
        f'iterations="{sol.iterations}" ls_iterations="{sol.ls_iterations}" tolerance="{_f(sol.tolerance)}" '
        f'cone="{sol.cone}" gravity="0 0 -9.80665"/>'
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
    }
    for key, value in custom.items():
        add(f'    <numeric name="{key}" data="{_f(float(value))}"/>')
    add("  </custom>")
    add("  <default>")
    arm_aff = ARM_CONTYPE | ENV_CONTYPE if arm.self_collision else ENV_CONTYPE
    add(
        f'    <geom contype="{ARM_CONTYPE}" conaffinity="{arm_aff}" condim="3" '
        f'friction="{_f(arm.geom_friction)} 0.005 0.0001"/>'
    )
    add(f'    <site size="{_f(arm.cable_diameter_m)}" rgba="0.9 0.9 0.2 1"/>')
    add("  </default>")
    add("  <asset>")
    add('    <material name="tpu" rgba="0.95 0.55 0.15 1"/>')
    add('    <material name="drone" rgba="0.25 0.25 0.3 1"/>')
    add('    <material name="object" rgba="0.3 0.6 0.9 1"/>')
    add("  </asset>")
    add("  <worldbody>")
    add('    <light name="sun" pos="0 0 3" dir="0 0 -1" directional="true"/>')
    if drone.floor:
        add(
            f'    <geom name="floor" type="plane" size="5 5 0.1" contype="{ENV_CONTYPE}" '
            f'conaffinity="{ARM_CONTYPE | ENV_CONTYPE}" rgba="0.8 0.8 0.8 1"/>'
        )
    hx, hy, hz = drone.half_size_m
    add(f'    <body name="drone" pos="{_v(*drone.pos_m)}" quat="{_v(*drone.quat_wxyz)}" mocap="true">')
    add(
        f'      <geom name="drone_body" type="box" size="{_v(hx, hy, hz)}" pos="0 0 {_f(hz)}" '
        f'contype="0" conaffinity="0" material="drone" mass="1"/>'
    )
    add(f'      <site name="mount" pos="0 0 {_f(-drone.mount_offset_m)}"/>')
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
            f'frictionloss="{_f(motor.friction_force_n)}"/>'
        )
        add(
            f'        <geom name="spool_{k}_geom" type="sphere" size="0.004" contype="0" conaffinity="0" '
            f'mass="{_f(motor.reflected_mass_kg)}" rgba="0.6 0.6 0.6 1"/>'
        )
        add(f'        <site name="cable_{k}_spool"/>')
        add("      </body>")

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
            if ball:
                add(f'{inner}<joint name="joint_{i:02d}" type="ball" range="0 {_f(dtheta)}" {common}/>')
            else:
                add(
                    f'{inner}<joint name="joint_{i:02d}" type="hinge" axis="0 1 0" '
                    f'range="{_v(-dtheta, dtheta)}" {common}/>'
                )
        ell = geo.chord_m[i]
        add(
            f'{inner}<geom name="{name}_geom" type="capsule" fromto="0 0 0 0 0 {_f(-ell)}" '
            f'size="{_f(geo.capsule_radius_m(i))}" mass="{_f(geo.mass_kg[i])}" material="tpu"/>'
        )
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
    add("    </body>")

    for obj in cfg.objects:
        norm = math.sqrt(sum(v * v for v in obj.axis))
        half = 0.5 * obj.length_m
        ends = [v / norm * -half for v in obj.axis] + [v / norm * half for v in obj.axis]
        geom = (
            f'<geom name="{obj.name}_geom" type="{obj.shape}" fromto="{_v(*ends)}" size="{_f(obj.radius_m)}" '
            f'contype="{ENV_CONTYPE}" conaffinity="{ARM_CONTYPE | ENV_CONTYPE}" '
            f'friction="{_f(obj.friction)} 0.005 0.0001" material="object"'
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
            f'solreflimit="{_f(arm.cable_timeconst_s)} 1" solimplimit="{_SOLIMP}" '
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
    lim = motor.current_limit_a
    for k in range(n_cables):
        # ctrl in amps; cable force = kt · I / r_spool. The plant applies the torque-speed line on top.
        add(
            f'    <motor name="motor_{k}" joint="spool_{k}" gear="{_f(motor.force_per_amp_n)}" '
            f'ctrlrange="{_v(-lim, lim)}"/>'
        )
    add("  </actuator>")

    add("  <sensor>")
    for k in range(n_cables):
        add(f'    <tendonlimitfrc name="tension_{k}" tendon="cable_{k}"/>')
    add("  </sensor>")
    add("</mujoco>")
    return "\n".join(out) + "\n"


def write_mjcf(
    path: str | Path, design: SpiralDesign, cables: int | None = None, config: ModelConfig | None = None
) -> Path:
    """Write :func:`build_mjcf`'s model to ``path`` (one file: the model has no meshes)."""
    target = Path(path)
    target.write_text(build_mjcf(design, cables, config), encoding="utf-8")
    return target
