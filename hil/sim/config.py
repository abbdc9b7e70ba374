"""The plant model's configuration: arm, motors, drone, solver, objects (read by
:func:`hil.sim.mjcf.build_mjcf`).

Frozen dataclasses with SI units in their names; each one's ``validate()`` raises ``ValueError`` on a value
out of range. ``docs/plant.md`` gives the source of every default. ``hil.sim.mjcf`` re-exports them all.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field, replace

from controller.config import MotorDriveConfig
from controller.params import C610_MAX_A

__all__ = [
    "ACTUATOR_KINDS",
    "MOUNTINGS",
    "OBJECT_SHAPES",
    "ActuatorConfig",
    "ArmConfig",
    "ContactConfig",
    "DroneConfig",
    "ModelConfig",
    "MotorConfig",
    "ObjectConfig",
    "SolverConfig",
]

ACTUATOR_KINDS: tuple[str, ...] = ("motor", "tension", "muscle")
"""What pulls the cables (:class:`ActuatorConfig`)."""

MOUNTINGS: tuple[str, ...] = ("hanging", "table", "gravity-off")
"""Where the arm is fixed and whether it has weight (:attr:`ModelConfig.mounting`)."""

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
            ``k_base · β^{−p(i−1)}``. Published identification of a TPU arm: 0.3-0.8 N·m/rad near the
            base; the authors' generator: 0.04 N·m/rad.
        stiffness_exponent: p, the stiffness profile: 3 (stiffness ∝ size³, Note S3's proportionality:
            a bending beam of the unit's section) or 2 (∝ size², the authors' generator); any value in
            1..4 (a fitted model's).
        joint_friction_nm: dry friction of the joint nearest the base, each joint's scaled like its
            stiffness (0: none, the default; :mod:`hil.identify` fits it).
        stiffness_scatter: factors on the joints' stiffness, base first (a printed arm's joint-to-joint
            variation; cycled when shorter than the arm). Empty: the power law alone (the default).
        damping_ratio: ζ of each joint against the inertia it carries (identification: about 0.13).
        cable_offset_ratio: cable hole radius as a fraction of the local half-width.
        cable_mu: capstan friction coefficient of the cable in the holes (0.25-0.4 reproduces the
            base-first uncurling). 0 disables cable friction.
        cable_diameter_m: UHMWPE cable diameter (the paper's Note S1: 0.5 mm); drawing only.
        joint_armature_kg_m2: rotational inertia added to every arm joint. Numerical: with mass ∝ β³ the
            tip joints carry ~1e-9 kg·m², and MuJoCo scales constraint softness by inverse inertia, so
            joint limits and the cable would give way under cable loads; 3e-6 keeps them within about a
            degree / a millimetre at the 1 ms step and leaves the first bending mode unchanged.
        limit_timeconst_s: ``solref`` time constant of the joint limits (unit-on-unit contact of the TPU
            units); at least twice the physics step (``ModelConfig.validate``).
        cable_modulus_pa: tensile modulus of the cable's fibre (Dyneema SK75: 109-132 GPa, DSM's fact
            sheet; the low end, since a braid's fibres are not all along its axis).
        cable_fill_factor: fraction of the cable's nominal cross-section that is fibre (a braid of round
            filaments packs about half its circle).
        cable_damping_ratio: damping ratio of the cable's stretch against the arm it pulls; the viscous
            damping it sets is the cable's, whatever the actuator's mass (a fibre's loss is small; the
            value is a modelling choice, see ``docs/plant.md``).
        cable_timeconst_s: ``None``: the cable's limit is its stretch (the three fields above). A number:
            MuJoCo's time-constant form instead, with no physical stiffness (the model before issue 13;
            the benchmark compares against it).
        self_collision: let non-adjacent units collide. ``None``: the shape's own choice (wedges collide,
            capsules do not: a capsule's rounded ends reach into the packed neighbours' space, so capsules
            rely on the joint limits alone, as Note S3 models units touching).
        geom_friction: sliding friction coefficient of the unit surfaces.
        unit_shape: collision shape of each unit. ``"wedge"``: a convex mesh of the real unit, the solid
            between its two joint faces tilted by ±Δθ/2, tapering from its base-side to its tip-side width
            (2-cable/1-cable arms: a prism-like wedge; 3 cables: a polygonal truncated cone with conical
            faces); closing a joint to its limit brings two faces together. ``"capsule"``: a capsule of
            the unit's mean half-width along its chord.
    """

    total_mass_kg: float = 0.0384
    base_stiffness_nm_per_rad: float = 0.5
    stiffness_exponent: float = 3
    joint_friction_nm: float = 0.0
    stiffness_scatter: tuple[float, ...] = ()
    damping_ratio: float = 0.13
    cable_offset_ratio: float = 0.8
    cable_mu: float = 0.3
    cable_diameter_m: float = 0.0005
    joint_armature_kg_m2: float = 3e-6
    limit_timeconst_s: float = 0.002
    cable_modulus_pa: float = 109e9
    cable_fill_factor: float = 0.5
    cable_damping_ratio: float = 0.5
    cable_timeconst_s: float | None = None
    self_collision: bool | None = None
    geom_friction: float = 0.8
    unit_shape: str = "wedge"

    def validate(self) -> None:
        """Raise ``ValueError`` if a value is out of range."""
        _finite("total_mass_kg", self.total_mass_kg)
        _finite("base_stiffness_nm_per_rad", self.base_stiffness_nm_per_rad, allow_equal=True)
        _check(
            isinstance(self.stiffness_exponent, int | float)
            and not isinstance(self.stiffness_exponent, bool)
            and 1.0 <= self.stiffness_exponent <= 4.0,
            f"stiffness_exponent must be 1..4, got {self.stiffness_exponent!r}",
        )
        _finite("damping_ratio", self.damping_ratio, allow_equal=True)
        _finite("joint_friction_nm", self.joint_friction_nm, allow_equal=True)
        _check(
            all(isinstance(x, int | float) and math.isfinite(x) and x > 0 for x in self.stiffness_scatter),
            f"stiffness_scatter must hold positive factors, got {self.stiffness_scatter!r}",
        )
        _finite("cable_offset_ratio", self.cable_offset_ratio)
        _check(
            self.cable_offset_ratio < 1.0, f"cable_offset_ratio must be < 1, got {self.cable_offset_ratio!r}"
        )
        _finite("cable_mu", self.cable_mu, allow_equal=True)
        _finite("cable_diameter_m", self.cable_diameter_m)
        _finite("joint_armature_kg_m2", self.joint_armature_kg_m2, allow_equal=True)
        _finite("limit_timeconst_s", self.limit_timeconst_s)
        _finite("cable_modulus_pa", self.cable_modulus_pa)
        _finite("cable_fill_factor", self.cable_fill_factor)
        _check(
            self.cable_fill_factor <= 1.0, f"cable_fill_factor must be <= 1, got {self.cable_fill_factor!r}"
        )
        _finite("cable_damping_ratio", self.cable_damping_ratio, allow_equal=True)
        if self.cable_timeconst_s is not None:
            _finite("cable_timeconst_s", self.cable_timeconst_s)
        _finite("geom_friction", self.geom_friction, allow_equal=True)
        _check(
            self.unit_shape in ("wedge", "capsule"),
            f"unit_shape must be 'wedge' or 'capsule', got {self.unit_shape!r}",
        )

    @property
    def units_collide(self) -> bool:
        """Whether non-adjacent units collide (``self_collision``, else the unit shape's choice)."""
        if self.self_collision is None:
            return self.unit_shape == "wedge"
        return self.self_collision

    @property
    def cable_axial_stiffness_n(self) -> float:
        """The cable's ``E·A`` [N]: its stiffness is this over its length."""
        return self.cable_modulus_pa * self.cable_fill_factor * math.pi * (0.5 * self.cable_diameter_m) ** 2


@dataclass(frozen=True)
class ContactConfig:
    """Contact parameters of every arm and object geom (MuJoCo's ``solref``/``solimp``).

    MuJoCo's default (20 ms) lets a pen sink 10 mm into the arm; ``docs/plant.md`` gives the measurements
    behind these defaults.

    Attributes:
        timeconst_s: ``solref`` time constant: how fast a penetration is pushed out. At least twice the
            physics step (``ModelConfig.validate``): a shorter one is not resolved by the integrator.
        damping_ratio: ``solref`` damping ratio (1 = critically damped: no bounce from the contact itself).
        solimp: ``(dmin, dmax, width_m, midpoint, power)``: the constraint impedance rises from ``dmin`` at
            zero depth to ``dmax`` at ``width_m`` deep; (1 − d) of the unconstrained push leaks through.
    """

    timeconst_s: float = 0.002
    damping_ratio: float = 1.0
    solimp: tuple[float, float, float, float, float] = (0.99, 0.995, 0.0005, 0.5, 2.0)

    def validate(self) -> None:
        """Raise ``ValueError`` if a value is out of range."""
        _finite("contact timeconst_s", self.timeconst_s)
        _finite("contact damping_ratio", self.damping_ratio)
        _vector("contact solimp", self.solimp, 5)
        dmin, dmax, width, mid, power = self.solimp
        _check(
            0.0 < dmin <= dmax < 1.0 and width > 0.0 and 0.0 < mid < 1.0 and power >= 1.0,
            f"contact solimp must have 0 < dmin <= dmax < 1, width > 0, 0 < midpoint < 1, power >= 1, "
            f"got {self.solimp!r}",
        )


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
        torque_scale: the motors' true torque constant over ``torque_constant_nm_per_a`` (which the
            firmware estimates tension with): 1 = they agree (a fitted model's may not).
        command_delay_s: from a current setpoint reaching the drives to the motor acting on it (the
            loop and the CAN bus of a real board; a fraction of the 1 ms period interpolates between
            setpoints); 0 = the next control period, as the lockstep board.
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
    torque_scale: float = 1.0
    command_delay_s: float = 0.0
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
    def delivered_force_per_amp_n(self) -> float:
        """Cable force per amp the motor really delivers: :attr:`force_per_amp_n` · ``torque_scale`` [N/A]."""
        return self.force_per_amp_n * self.torque_scale

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
        _finite("torque_scale", self.torque_scale)
        _finite("command_delay_s", self.command_delay_s, allow_equal=True)
        _check(self.command_delay_s <= 0.1, f"command_delay_s must be <= 0.1 s, got {self.command_delay_s!r}")
        _finite("current_noise_raw", self.current_noise_raw, allow_equal=True)
        _check(
            isinstance(self.temperature_c, int) and 0 <= self.temperature_c <= 255,
            f"temperature_c must be an int 0..255, got {self.temperature_c!r}",
        )


@dataclass(frozen=True)
class ActuatorConfig:
    """What pulls each cable: the M2006 motor with its spool, an ideal tension source, or a muscle.

    Whatever the kind, the firmware's side is unchanged: it commands C610 currents and reads C610 frames
    (:class:`hil.sim.drives.Drives`).
    A current ``I`` asks for the tension ``I · kt / r_spool`` (the firmware's
    force per amp, :attr:`MotorConfig.force_per_amp_n`); the angle is the wound cable and the fed-back
    current is the delivered force converted back with the same force per amp. A tension source and a
    muscle only pull: a negative current delivers no force (the arm's stiffness pulls the cable out).

    Attributes:
        kind: ``"motor"`` (the M2006 P36 + C610 + spool of :class:`MotorConfig`: reflected rotor inertia,
            output friction, torque-speed line; the default), ``"tension"`` (an ideal tension source
            behind a first-order lag, e.g. a force-controlled drive) or ``"muscle"`` (MuJoCo's muscle,
            as in the authors' published generator).
        lag_s: time constant of the tension source's first-order lag (``tension`` only).
        reflected_mass_kg: mass of the spool slider for ``tension`` and ``muscle``: the light actuator's
            moving parts seen at the cable. MuJoCo needs a mass on the slider; 10 g is under 1 % of
            the motor's 1.3 kg and of the arm's own inertia seen at the cable.
        friction_n: Coulomb friction at the cable for ``tension`` and ``muscle`` (the authors' tendon
            ``frictionloss``: 0.1 N).
        muscle_force_n: the muscle's peak isometric force F0; ``None`` = the motor's full range
            (``force_per_amp_n · current_limit_a``). The authors' generator: 5 N.
        muscle_timeconst_s: the muscle's activation and deactivation time constants (MuJoCo's defaults,
            which the authors' generator keeps).
        muscle_length_range: the cable's arm-side length over which the muscle's force-length curve is
            spread, as multiples of the arm's length (the authors' generator: 0.4 to 2.5).
    """

    kind: str = "motor"
    lag_s: float = 0.01
    reflected_mass_kg: float = 0.01
    friction_n: float = 0.1
    muscle_force_n: float | None = None
    muscle_timeconst_s: tuple[float, float] = (0.01, 0.04)
    muscle_length_range: tuple[float, float] = (0.4, 2.5)

    def validate(self) -> None:
        """Raise ``ValueError`` if a value is out of range."""
        _check(
            self.kind in ACTUATOR_KINDS,
            f"actuator kind must be one of {', '.join(ACTUATOR_KINDS)}, got {self.kind!r}",
        )
        _finite("lag_s", self.lag_s)
        _finite("reflected_mass_kg", self.reflected_mass_kg)
        _finite("friction_n", self.friction_n, allow_equal=True)
        if self.muscle_force_n is not None:
            _finite("muscle_force_n", self.muscle_force_n)
        _vector("muscle_timeconst_s", self.muscle_timeconst_s, 2)
        _check(
            min(self.muscle_timeconst_s) > 0,
            f"muscle_timeconst_s must be > 0, got {self.muscle_timeconst_s!r}",
        )
        _vector("muscle_length_range", self.muscle_length_range, 2)
        lo, hi = self.muscle_length_range
        _check(0 < lo < hi, f"muscle_length_range must be 0 < low < high, got {self.muscle_length_range!r}")


OBJECT_SHAPES: tuple[str, ...] = ("cylinder", "capsule", "sphere", "box", "ellipsoid", "cone", "mesh")
"""The shapes an :class:`ObjectConfig` can take."""


def _spans_a_volume(points: tuple[tuple[float, float, float], ...]) -> bool:
    """Some four of ``points`` make a tetrahedron of non-negligible volume (relative to their spread)."""
    import numpy as np

    p = np.asarray(points, dtype=float)
    centred = p - p.mean(axis=0)
    if not np.all(np.isfinite(centred)):
        return False
    s = np.linalg.svd(centred, compute_uv=False)
    return bool(s[0] > 0 and s[-1] > 1e-3 * s[0])


@dataclass(frozen=True)
class ObjectConfig:
    """An object to grasp: a cylinder by default, or one of :data:`OBJECT_SHAPES`.

    Attributes:
        name: body name in the model (letters, digits, underscores; not an arm name).
        radius_m: the radius across the axis: a cylinder's, capsule's, sphere's, cone's base, an
            ellipsoid's two equal semi-axes, a box's half-width (its cross-section is square); a mesh's
            characteristic radius (the penetration figures are judged against it).
        length_m: the extent along the axis: a cylinder's or capsule's length, a box's or a cone's height,
            an ellipsoid's length (twice its third semi-axis); a sphere and a mesh ignore it.
        pos_m: where the object's frame is, in world coordinates: the middle of its extent along the axis
            (a cone's base is ``length_m / 2`` below it, its apex as far above); a mesh's vertices' origin.
        axis: direction of the object's axis in world coordinates (normalised here).
        mass_kg: ``None`` = fixed to the world (a branch, a pole); otherwise a free body of this mass,
            with a switchable support (``{name}_support``: a mocap body and a weld to it, inactive at
            start) that :meth:`hil.sim.plant.Plant.hold_object` uses to hold it where it is.
        friction: sliding friction coefficient.
        shape: ``"cylinder"`` (flat ends, convex collision) or ``"capsule"`` (rounded ends, analytic
            collision: cheaper), ``"sphere"``, ``"box"``, ``"ellipsoid"``, ``"cone"`` (a 24-sided
            pyramid, apex towards +axis), ``"mesh"`` (the convex hull of ``vertices``).
        vertices: a mesh's points in its own frame (z along ``axis``), at least 4 not in one plane.
    """

    name: str
    radius_m: float
    length_m: float
    pos_m: tuple[float, float, float]
    axis: tuple[float, float, float] = (0.0, 1.0, 0.0)
    mass_kg: float | None = None
    friction: float = 0.8
    shape: str = "cylinder"
    vertices: tuple[tuple[float, float, float], ...] = ()

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
            self.shape in OBJECT_SHAPES,
            f"shape must be one of {', '.join(OBJECT_SHAPES)}, got {self.shape!r}",
        )
        if self.shape == "mesh":
            _check(
                4 <= len(self.vertices) <= 1000,
                f"a mesh needs 4 to 1000 vertices, got {len(self.vertices)}",
            )
            for v in self.vertices:
                _vector("vertices", v, 3)
            _check(_spans_a_volume(self.vertices), "a mesh's vertices must not lie in one plane")
        else:
            _check(not self.vertices, f"vertices are for a mesh, not a {self.shape}")


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
        jacobian: the constraint Jacobian's storage, ``auto`` (MuJoCo's default: sparse from 60 degrees of
            freedom, which the prototype's 63 just pass), ``dense`` or ``sparse``. Dense is the same physics
            to rounding and faster at this size, but rounding flips grasps whose outcome sits on an edge,
            so the default stays the one every documented figure was measured with (docs/plant.md).
    """

    timestep_s: float = 0.001
    integrator: str = "discrete"
    solver: str = "Newton"
    iterations: int = 20
    ls_iterations: int = 10
    tolerance: float = 1e-8
    cone: str = "pyramidal"
    jacobian: str = "auto"

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
        _check(self.jacobian in ("dense", "sparse", "auto"), f"unknown jacobian {self.jacobian!r}")


@dataclass(frozen=True)
class ModelConfig:
    """Everything :func:`hil.sim.mjcf.build_mjcf` needs besides the spiral design.

    Attributes:
        arm: the arm's body.
        motor: the M2006/C610/spool figures; the firmware's force per amp comes from them whatever the
            actuator.
        drone: the body the arm is fixed to (the drone, or the clamp on the table).
        solver: MuJoCo's numerical settings.
        objects: things to grasp.
        actuator: what pulls the cables.
        mounting: ``"hanging"`` (under the drone, gravity along the arm; the drone's acceleration enters
            as a fictitious force), ``"table"`` (the arm lies flat on a table plane, its base clamped,
            bending in the horizontal plane; gravity presses it on the table) or ``"gravity-off"``
            (hanging pose, no gravity: the authors' choice).
    """

    arm: ArmConfig = field(default_factory=ArmConfig)
    motor: MotorConfig = field(default_factory=MotorConfig)
    drone: DroneConfig = field(default_factory=DroneConfig)
    solver: SolverConfig = field(default_factory=SolverConfig)
    objects: tuple[ObjectConfig, ...] = ()
    actuator: ActuatorConfig = field(default_factory=ActuatorConfig)
    mounting: str = "hanging"
    contact: ContactConfig = field(default_factory=ContactConfig)

    def validate(self) -> None:
        """Raise ``ValueError`` if any part is out of range, object names clash, or a constraint's time
        constant is shorter than two physics steps."""
        self.arm.validate()
        self.contact.validate()
        self.motor.validate()
        self.drone.validate()
        self.solver.validate()
        self.actuator.validate()
        _check(
            self.mounting in MOUNTINGS,
            f"mounting must be one of {', '.join(MOUNTINGS)}, got {self.mounting!r}",
        )
        names = [o.name for o in self.objects]
        _check(len(names) == len(set(names)), f"object names must be unique, got {names}")
        supports = {f"{o.name}_support" for o in self.objects if o.mass_kg is not None}
        _check(not supports & set(names), f"an object name clashes with another's support body: {names}")
        for o in self.objects:
            o.validate()
        step = self.solver.timestep_s
        for what, tau in (
            ("contact.timeconst_s", self.contact.timeconst_s),
            ("arm.limit_timeconst_s", self.arm.limit_timeconst_s),
        ):
            # MuJoCo's soft constraints need the reference dynamics resolved by the step: a time constant
            # under 2 steps makes the correction overshoot within one step (contacts pop, limits chatter).
            _check(
                tau >= 2.0 * step - 1e-12,
                f"{what} = {tau * 1e3:g} ms must be at least twice the physics step "
                f"(solver.timestep_s = {step * 1e3:g} ms): shorten the step or lengthen the time constant",
            )

    @property
    def peak_tension_n(self) -> float:
        """The largest tension the firmware can ask for: ``force_per_amp_n · current_limit_a`` [N]."""
        return self.motor.force_per_amp_n * self.motor.current_limit_a

    @property
    def muscle_force_n(self) -> float:
        """The muscle's peak isometric force F0 (``actuator.muscle_force_n`` or the peak tension) [N]."""
        f0 = self.actuator.muscle_force_n
        return self.peak_tension_n if f0 is None else f0

    def with_physics(self, timestep_s: float) -> ModelConfig:
        """A copy stepped at ``timestep_s`` with its contacts and joint limits as stiff as that step allows.

        The contacts' and the joint limits' ``solref`` time constants become two steps (the shortest
        :meth:`validate` accepts): at 0.25 ms that is 0.5 ms, which keeps a whipping tip's penetration under
        1 mm and the limit overshoot under 1° where the real-time board's 1 ms / 2 ms lets them reach 2.8 mm
        and 8° (``docs/experiments.md``, "Physics of the experiments"). Nothing else changes.
        """
        tau = 2.0 * timestep_s
        return replace(
            self,
            solver=replace(self.solver, timestep_s=timestep_s),
            contact=replace(self.contact, timeconst_s=tau),
            arm=replace(self.arm, limit_timeconst_s=tau),
        )

    def with_objects(self, *objects: ObjectConfig) -> ModelConfig:
        """A copy with ``objects`` appended."""
        return replace(self, objects=self.objects + tuple(objects))


PHYSICS_STEPS_S = {"fine": 0.25e-3, "board": SolverConfig().timestep_s}
"""Named physics settings, their steps (:meth:`ModelConfig.with_physics` sets the constraints from the step):
``fine`` is what the experiments and grasp campaigns run (four steps per 1 ms control tick, contacts and
limits at 0.5 ms); ``board`` is the real-time board's (one step per tick, 2 ms constraints)."""
