"""The MuJoCo plant: a SpiRob arm under a drone, driven by raw C610 currents, answering C610 feedback.

One :meth:`Plant.step` is one control period (1 ms by default) and a whole number of physics steps.
The firmware side only sees what a real C610 bus shows it: :attr:`Plant.apply_currents` takes the raw
int16 setpoints of a 0x200 frame and :attr:`Plant.feedback` returns one :class:`MotorFeedback` per motor.
Those are the plant's drives (:mod:`hil.sim.drives`: C610 current loop, M2006 rotor and gearbox, spool,
feedback frames); this module is the MuJoCo physics they turn. Everything else is a named accessor for
tests, scenarios and the UI; no caller needs a raw ``qpos`` index.

Per control period the plant also applies what MuJoCo cannot express statically:

- the drives' currents, through the motors' torque-speed line (the drive runs out of voltage towards the
  no-load speed);
- capstan friction of the cables in the unit holes, as per-joint dry friction whose size follows the
  capstan law from the current cable tensions and joint angles (``docs/plant.md``);
- the drone's acceleration (hanging mounting), as a change of gravity (the arm lives in the drone's frame).

Randomness (the encoders' arbitrary zero, current noise) comes only from the ``numpy.random.Generator``
given to the constructor.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import replace
from typing import Any

import mujoco
import numpy as np
from numpy.typing import NDArray

from hil.errors import PlantDivergedError
from hil.sim.array import arm_prefix, build_array_spec
from hil.sim.config import ObjectConfig
from hil.sim.drives import Drives
from hil.sim.mjcf import build_mjcf, cable_layout, joint_friction_nm, unit_geometry
from hil.sim.monitor import ExtremesMonitor, object_radii
from hil.sim.objects import SceneObjects
from hil.sim.spiral import SpiralDesign
from hil.sim.types import (
    BodyPoses,
    Contact,
    PhysicsExtremes,
    PlantConfig,
    Pose,
    finite_vector,
    unit_quat,
)
from protocol.c610 import MotorFeedback

__all__ = ["Plant"]

FloatArray = NDArray[np.float64]

_BADQACC = int(mujoco.mjtWarning.mjWARN_BADQACC)


class Plant:
    """The simulated arm, its three (or one or two) motors and the drone it hangs from; or an array of such
    arms on a ring under the drone (``PlantConfig.ring``), each with its own cables and drives.

    In an array, every per-motor or per-unit value runs arm after arm: motor ``m`` (1-based) drives cable
    ``(m-1) % C`` of arm ``(m-1) // C``; units, joint angles, tensions and lengths are concatenated the same
    way, and names carry the arm's prefix (``a2_unit_05``, :func:`hil.sim.array.arm_prefix`). The drone, the
    objects and a single arm's names are as without a ring.

    Args:
        design: the spiral design; ``None`` = the paper's 3-cable prototype. ``design.cables`` sets the
            number of cables and motors.
        config: plant configuration (defaults: the paper's prototype, see docs/plant.md).
        rng: the only source of randomness (encoder zero offsets, current noise). ``None`` = no
            randomness: encoders start at 0 and ``current_noise_raw`` must be 0.

    Raises:
        ValueError: a configuration value is out of range, or the control period is not a whole number of
            physics steps.
    """

    # The C610 side is the drives' own methods, bound once in __init__: the 1 kHz bus calls them with no
    # extra Python frame in between.
    apply_currents: Callable[[Sequence[int]], tuple[int, ...]]
    """Set the motors' current setpoints, raw, one per cable (``hil.sim.drives.Drives.apply_currents``)."""
    feedback: Callable[[], tuple[MotorFeedback, ...]]
    """One C610 feedback frame per motor now (see :meth:`hil.sim.drives.Drives.feedback`)."""
    feedback_payloads: Callable[[], list[bytes]]
    """The 8 data bytes of each motor's feedback frame (:meth:`~hil.sim.drives.Drives.feedback_payloads`)."""
    commanded_currents_raw: Callable[[], tuple[int, ...]]
    """The setpoints last applied (after clamping), raw units."""
    applied_currents_a: Callable[[], FloatArray]
    """Current each drive delivered in the last period (after the torque-speed line) [A]."""
    # The scene's objects (hil.sim.objects.SceneObjects, rebuilt with the model): see their docstrings.
    set_object_pose: Callable[..., None]
    """Place an object (:meth:`hil.sim.objects.SceneObjects.set_object_pose`)."""
    object_pose: Callable[[str], Pose]
    """Current pose of an object."""
    hold_object: Callable[..., None]
    """Hold a free object still on its support (:meth:`hil.sim.objects.SceneObjects.hold_object`)."""
    release_object: Callable[[str], None]
    """Take a held free object off its support."""
    object_held: Callable[[str], bool]
    """Whether a free object is on its support (fixed objects: always True)."""
    set_object_velocity: Callable[..., None]
    """Give a free object a velocity (:meth:`hil.sim.objects.SceneObjects.set_object_velocity`)."""
    apply_object_force: Callable[[str, Sequence[float]], None]
    """Push a free object with a constant force, world frame [N] (``(0, 0, 0)`` removes it)."""

    def __init__(
        self,
        design: SpiralDesign | None = None,
        config: PlantConfig | None = None,
        rng: np.random.Generator | None = None,
    ) -> None:
        self._design = design if design is not None else SpiralDesign.paper_prototype()
        self._config = config if config is not None else PlantConfig()
        self._config.validate()
        if rng is not None and not isinstance(rng, np.random.Generator):
            raise ValueError(f"rng must be a numpy.random.Generator, got {type(rng).__name__}")
        model = self._config.model
        ring = self._config.ring
        self._arms = 1 if ring is None else ring.arms
        drives = Drives(
            model.motor,
            self._arms * self._design.cables,
            rng,
            model.actuator,
            model.muscle_force_n,
            control_period_s=self._config.control_period_us * 1e-6,
        )
        self._drives = drives
        self._drive = drives.drive
        self.apply_currents = drives.apply_currents
        self.feedback = drives.feedback
        self.feedback_payloads = drives.feedback_payloads
        self.commanded_currents_raw = drives.commanded_currents_raw
        self.applied_currents_a = drives.applied_currents_a
        period_s = self._config.control_period_us * 1e-6
        ratio = period_s / self._config.model.solver.timestep_s
        substeps = round(ratio)
        if substeps < 1 or abs(ratio - substeps) > 1e-9 * max(1.0, ratio):
            raise ValueError(
                f"control period {self._config.control_period_us} us is not a whole number of physics steps "
                f"of {self._config.model.solver.timestep_s * 1e6:g} us"
            )
        self._substeps = substeps
        self._build()
        self.reset()

    # ------------------------------------------------------------------ construction

    def _build(self) -> None:
        cfg = self._config.model
        ring = self._config.ring
        if ring is None:
            xml = build_mjcf(self._design, None, cfg)
            m = mujoco.MjModel.from_xml_string(xml)
            prefixes = [""]
        else:
            spec = build_array_spec(self._design, cfg, ring, standalone=False)
            m = spec.compile()
            xml = spec.to_xml()
            prefixes = [arm_prefix(i) for i in range(ring.arms)]
        # Divergence is reported (PlantDivergedError), never silently reset.
        m.opt.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_AUTORESET)
        self._xml = xml
        self._m = m
        self._d = mujoco.MjData(m)
        n_cables = self._design.cables
        n_units = self._design.units
        arms = len(prefixes)
        self._n_cables = n_cables
        self._geo = unit_geometry(self._design, cfg.arm)
        self._layout = cable_layout(self._design, n_cables, cfg)
        self._r_spool = cfg.motor.spool_radius_m

        def jid(name: str) -> int:
            return int(mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, name))

        def bid(name: str) -> int:
            return int(mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, name))

        def named(kind: Any, name: str) -> int:
            return int(mujoco.mj_name2id(m, kind, name))

        # Every per-cable and per-unit index runs arm after arm (motor m drives cable (m-1) % C of arm
        # (m-1) // C, as the firmware lays out an array).
        spool_j = [jid(f"{p}spool_{k}") for p in prefixes for k in range(n_cables)]
        self._spool_qadr = np.array([m.jnt_qposadr[j] for j in spool_j], dtype=np.intp)
        self._spool_dadr = np.array([m.jnt_dofadr[j] for j in spool_j], dtype=np.intp)
        self._tendon_ids = np.array(
            [named(mujoco.mjtObj.mjOBJ_TENDON, f"{p}cable_{k}") for p in prefixes for k in range(n_cables)],
            dtype=np.intp,
        )
        self._tension_adr = np.array(
            [
                m.sensor_adr[named(mujoco.mjtObj.mjOBJ_SENSOR, f"{p}tension_{k}")]
                for p in prefixes
                for k in range(n_cables)
            ],
            dtype=np.intp,
        )
        self._unit_names = tuple(f"{p}unit_{i:02d}" for p in prefixes for i in range(n_units))
        self._unit_bodies = np.array([bid(name) for name in self._unit_names], dtype=np.intp)
        self._body_name_of = {
            int(b): name for b, name in zip(self._unit_bodies, self._unit_names, strict=True)
        }
        self._drone_body = bid("drone")
        self._drone_mocap = int(m.body_mocapid[self._drone_body])
        self._pose_bodies = np.concatenate([[self._drone_body], self._unit_bodies])
        self._pose_names = ("drone", *self._unit_names)
        self._tip_sites = [named(mujoco.mjtObj.mjOBJ_SITE, f"{p}tip") for p in prefixes]
        arm_j = [jid(f"{p}joint_{i:02d}") for p in prefixes for i in range(1, n_units)]
        self._ball = n_cables == 3
        self._arm_qadr = np.array([m.jnt_qposadr[j] for j in arm_j], dtype=np.intp)
        self._arm_dadr = np.array([m.jnt_dofadr[j] for j in arm_j], dtype=np.intp)
        self._arm_dofs = np.concatenate([self._arm_dadr + k for k in range(3 if self._ball else 1)])
        # Bending dofs (ball: local x and y; the z dof is twist, which does not rub the cable).
        self._bend_dofs = (
            np.stack([self._arm_dadr, self._arm_dadr + 1], axis=1) if self._ball else self._arm_dadr[:, None]
        )
        self._friction_scale = np.array(self._geo.cable_radius_base_side_m[1:], dtype=np.float64)
        self._bend_dofs_flat = self._bend_dofs.ravel()
        # Per joint of every arm, flat (arm after arm) and as rows (one per arm) for the capstan law.
        self._alpha_buf = np.empty(arms * (n_units - 1))
        self._wrap_buf = np.empty(arms * (n_units - 1))
        self._alpha_rows = self._alpha_buf.reshape(arms, n_units - 1)
        self._wrap_rows = self._wrap_buf.reshape(arms, n_units - 1)
        self._totals = np.zeros((arms, 1))
        self._friction_on = False
        self._mu = cfg.arm.cable_mu
        # The joints' own dry friction (a fitted model's; none by default): under the capstan friction.
        self._joint_friction = np.tile(
            np.array(joint_friction_nm(cfg.arm, self._geo)[1:], dtype=np.float64), arms
        )
        self._joint_friction_on = bool(np.any(self._joint_friction > 0.0))
        self._tension_adr_list = [int(a) for a in self._tension_adr]
        self._tension_adr_by_arm = [
            self._tension_adr_list[a * n_cables : (a + 1) * n_cables] for a in range(arms)
        ]
        if arms == 1:  # contiguous: a slice is cheaper than a gather
            self._arm_slice: slice | NDArray[np.intp] = slice(
                int(self._arm_dofs.min()), int(self._arm_dofs.max()) + 1
            )
            self._spool_slice: slice | NDArray[np.intp] = slice(
                int(self._spool_dadr.min()), int(self._spool_dadr.max()) + 1
            )
        else:  # the arms' joints and spools interleave
            self._arm_slice, self._spool_slice = self._arm_dofs, self._spool_dadr
        objects = SceneObjects(m, self._d, cfg.objects)
        self._object_names = objects.names
        self._object_bodies = objects.bodies
        self.set_object_pose = objects.set_object_pose
        self.object_pose = objects.object_pose
        self.hold_object = objects.hold_object
        self.release_object = objects.release_object
        self.object_held = objects.object_held
        self.set_object_velocity = objects.set_object_velocity
        self.apply_object_force = objects.apply_object_force
        self._angles_buf = np.empty(arms * (n_units - 1))
        radii = object_radii(m, [(o.name, o.radius_m) for o in cfg.objects])
        self._monitor = ExtremesMonitor(
            m, self._unit_bodies.tolist(), radii, self._tension_adr_list, self._design.dtheta_rad
        )
        self._drone_accel = np.zeros(3)
        self._gravity = m.opt.gravity.copy()  # the mounting's (hil.sim.mjcf)
        self._accel_gain = 1.0 if cfg.mounting == "hanging" else 0.0
        d = self._d
        qadr, dadr = self._spool_qadr.tolist(), self._spool_dadr.tolist()
        self._drives.attach(d.qpos, d.qvel, d.ctrl, qadr, dadr, d.qfrc_actuator)

    # ------------------------------------------------------------------ properties

    @property
    def design(self) -> SpiralDesign:
        """The spiral design this plant simulates."""
        return self._design

    @property
    def config(self) -> PlantConfig:
        """The plant configuration (objects added with :meth:`add_object` included)."""
        return self._config

    @property
    def cables(self) -> int:
        """Cables of each arm (of the only arm: the number of motors)."""
        return self._n_cables

    @property
    def arms(self) -> int:
        """Arms on the drone (1 without a ring)."""
        return self._arms

    @property
    def motors(self) -> int:
        """Motors (drives): arms x cables."""
        return self._arms * self._n_cables

    @property
    def units_per_arm(self) -> int:
        """Units of each arm."""
        return self._design.units

    @property
    def time_us(self) -> int:
        """Simulated time since :meth:`reset`, in whole microseconds."""
        return self._time_us

    @property
    def control_period_us(self) -> int:
        """Length of one :meth:`step`."""
        return self._config.control_period_us

    @property
    def substeps(self) -> int:
        """Physics steps per control period."""
        return self._substeps

    @property
    def mjcf(self) -> str:
        """The MJCF text of the current model."""
        return self._xml

    @property
    def mj_model(self) -> Any:
        """The underlying ``mujoco.MjModel`` (escape hatch; prefer the named accessors)."""
        return self._m

    @property
    def mj_data(self) -> Any:
        """The underlying ``mujoco.MjData`` (escape hatch; prefer the named accessors)."""
        return self._d

    @property
    def drives(self) -> Drives:
        """The C610/M2006/spool drives that turn the spools (the plant's motor side)."""
        return self._drives

    @property
    def unit_names(self) -> tuple[str, ...]:
        """Body names of the units, base first."""
        return self._unit_names

    @property
    def object_names(self) -> tuple[str, ...]:
        """Names of the objects in the model."""
        return self._object_names

    # ------------------------------------------------------------------ life cycle

    def reset(self) -> None:
        """Back to t = 0: arm straight and at rest, cables just taut, no current, drone at its start pose."""
        m, d = self._m, self._d
        mujoco.mj_resetData(m, d)
        drone = self._config.model.drone
        d.mocap_pos[self._drone_mocap] = drone.pos_m
        d.mocap_quat[self._drone_mocap] = unit_quat(drone.quat_wxyz)
        m.opt.gravity[:] = self._gravity
        self._drone_accel[:] = 0.0
        self._drives.reset()
        self._time_us = 0
        self._rest_friction()
        self._friction_on = False
        self._bad_qacc = 0
        self._monitor.reset()
        mujoco.mj_forward(m, d)

    def step(self) -> None:
        """Advance one control period with the currents last given to :meth:`apply_currents`.

        Raises:
            PlantDivergedError: the physics diverged (NaN/Inf, MuJoCo's bad-acceleration warning, or a joint
                or spool speed beyond the configured bounds). :meth:`reset` before stepping again.
        """
        m, d = self._m, self._d
        self._drive()  # the drives' currents into the spool actuators
        if self._mu > 0:
            self._update_cable_friction()
        for _ in range(self._substeps):
            mujoco.mj_step(m, d)
        self._time_us += self._config.control_period_us
        if self._config.track_extremes:
            self._joint_angles_into(self._angles_buf)
            self._monitor.update(d, self._angles_buf)
        # One cheap test per period; the detailed diagnosis only when it fails.
        qvel = d.qvel
        arm_speed = np.abs(qvel[self._arm_slice]).max()
        spool_speed = np.abs(qvel[self._spool_slice]).max()
        if (
            not (arm_speed <= self._config.max_joint_speed_rad_s)
            or not (spool_speed <= self._config.max_spool_speed_m_s)
            or d.warning[_BADQACC].number != self._bad_qacc
        ):
            self._check_divergence()

    def run(self, duration_us: int) -> None:
        """Step for ``duration_us`` (a whole number of control periods) with the current commands.

        Raises:
            ValueError: ``duration_us`` is negative or not a multiple of the control period.
            PlantDivergedError: see :meth:`step`.
        """
        period = self._config.control_period_us
        if duration_us < 0 or duration_us % period:
            raise ValueError(f"duration {duration_us} us is not a whole number of {period} us periods")
        for _ in range(duration_us // period):
            self.step()

    def extremes(self) -> PhysicsExtremes:
        """Largest penetration, tension and limit overshoot since :meth:`reset` or :meth:`reset_extremes`."""
        return self._monitor.extremes()

    def reset_extremes(self) -> None:
        """Start measuring :meth:`extremes` afresh (e.g. once a trial's setup is over)."""
        self._monitor.reset()

    def _check_divergence(self) -> None:
        d = self._d
        warn = int(d.warning[_BADQACC].number)
        bad = warn > self._bad_qacc
        self._bad_qacc = warn
        reason = ""
        if bad:
            reason = f"MuJoCo reported a bad acceleration at dof {int(d.warning[_BADQACC].lastinfo)}"
        elif not (np.isfinite(d.qpos).all() and np.isfinite(d.qvel).all()):
            reason = "NaN or Inf in the state"
        else:
            joint_speed = float(np.abs(d.qvel[self._arm_dofs]).max(initial=0.0))
            spool_speed = float(np.abs(d.qvel[self._spool_dadr]).max(initial=0.0))
            if joint_speed > self._config.max_joint_speed_rad_s:
                reason = f"arm joint speed {joint_speed:.3g} rad/s"
            elif spool_speed > self._config.max_spool_speed_m_s:
                reason = f"spool speed {spool_speed:.3g} m/s"
        if reason:
            raise PlantDivergedError(f"plant diverged at t = {self._time_us} us: {reason}", self._time_us)

    def _update_cable_friction(self) -> None:
        """Capstan friction in the holes as per-joint dry friction (see docs/plant.md).

        A cable of tension T bent by α at a joint loses ``T(1 − e^{−μα})`` there, and arrives at joint i
        with ``T·e^{−μ Σ_{j<i} α_j}``. Each joint gets the friction torque of all cables at its hole
        radius; MuJoCo's frictionloss makes it a stick-slip constraint, not an explicit force.
        """
        sens = self._d.sensordata
        totals = self._totals  # each arm's cables' tension, an arm's holes rub only its own cables
        tensed = False
        for a, adrs in enumerate(self._tension_adr_by_arm):
            total = 0.0
            for adr in adrs:
                t = sens[adr]
                if t > 0.0:
                    total += t
            totals[a, 0] = -total
            tensed = tensed or total > 0.0
        if not tensed:
            if self._friction_on:
                self._rest_friction()
                self._friction_on = False
            return
        alpha = self._alpha_rows
        wrap = self._wrap_rows
        self._joint_angles_into(self._alpha_buf)
        np.abs(alpha, out=alpha)
        np.cumsum(alpha, axis=1, out=wrap)
        wrap -= alpha
        wrap *= -self._mu
        np.exp(wrap, out=wrap)  # share of the tension arriving at each joint
        alpha *= -self._mu
        np.expm1(alpha, out=alpha)  # −(share lost in that joint's holes)
        wrap *= alpha
        wrap *= self._friction_scale * totals  # cable radius at each joint
        flat = self._wrap_buf
        if self._joint_friction_on:
            flat += self._joint_friction
        self._m.dof_frictionloss[self._bend_dofs] = flat[:, None]
        self._friction_on = True

    def _rest_friction(self) -> None:
        """The bending dofs' friction with no cable tension: the joints' own (none by default)."""
        if self._joint_friction_on:
            self._m.dof_frictionloss[self._bend_dofs] = self._joint_friction[:, None]
        else:
            self._m.dof_frictionloss[self._bend_dofs_flat] = 0.0

    # ------------------------------------------------------------------ named accessors

    def spool_angles_rad(self) -> FloatArray:
        """Output-shaft angle of each spool since reset, multi-turn; positive = cable wound in [rad]."""
        return np.asarray(self._d.qpos[self._spool_qadr] / self._r_spool, dtype=np.float64)

    def spool_speeds_rad_s(self) -> FloatArray:
        """Output-shaft speed of each spool [rad/s]."""
        return np.asarray(self._d.qvel[self._spool_dadr] / self._r_spool, dtype=np.float64)

    def cable_tensions_n(self) -> FloatArray:
        """Tension of each cable at the spool (0 when slack) [N]."""
        return np.maximum(np.asarray(self._d.sensordata[self._tension_adr], dtype=np.float64), 0.0)

    def cable_lengths_m(self) -> FloatArray:
        """Path length of each cable inside the arm, from its guide at the base to the knot at the tip [m].

        When the cable is taut this shortens by exactly ``r_spool · Δangle`` as the spool winds in.
        """
        d = self._d
        total = d.ten_length[self._tendon_ids]
        spool_segment = self._layout.spool_lead_m + d.qpos[self._spool_qadr]
        return np.asarray(total - spool_segment, dtype=np.float64)

    def cable_slack_m(self) -> FloatArray:
        """How much longer each cable is than its path (0 when taut) [m]."""
        d = self._d
        slack = self._layout.taut_length_m - d.ten_length[self._tendon_ids]
        return np.maximum(np.asarray(slack, dtype=np.float64), 0.0)

    def joint_angles_rad(self) -> FloatArray:
        """Bending angle of each joint, base first (``joint_01`` ... ), shape (units − 1,) [rad].

        Hinges (1-2 cables): signed, positive bends towards −x (away from cable 0). Ball joints (3 cables):
        the rotation angle, ≥ 0.
        """
        out = np.empty(len(self._arm_qadr))
        self._joint_angles_into(out)
        return out

    def _joint_angles_into(self, out: FloatArray) -> None:
        q = self._d.qpos
        if self._ball:
            np.take(q, self._arm_qadr, out=out)
            np.abs(out, out=out)
            np.minimum(out, 1.0, out=out)
            np.arccos(out, out=out)
            out *= 2.0
        else:
            np.take(q, self._arm_qadr, out=out)

    def tip_pose(self, arm: int = 0) -> Pose:
        """Pose of an arm's tip (the knot end of its last unit).

        Raises:
            IndexError: no such arm.
        """
        if not 0 <= arm < self._arms:
            raise IndexError(f"arm {arm} outside 0..{self._arms - 1}")
        d = self._d
        last = self._unit_bodies[(arm + 1) * self._design.units - 1]
        return Pose(d.site_xpos[self._tip_sites[arm]].copy(), d.xquat[last].copy())

    def unit_poses(self) -> tuple[FloatArray, FloatArray]:
        """Frames of all units, base first: positions (n, 3) and quaternions w, x, y, z (n, 4).

        A unit's origin is the joint at its base-side face; its axis points along its local −z.
        """
        d = self._d
        return d.xpos[self._unit_bodies].copy(), d.xquat[self._unit_bodies].copy()

    def body_poses(self) -> BodyPoses:
        """Drone and unit frames in one batch (for the UI's batched meshes)."""
        d = self._d
        ids = self._pose_bodies
        return BodyPoses(self._pose_names, d.xpos[ids], d.xquat[ids])  # fancy indexing copies

    def unit_dimensions_m(self) -> tuple[tuple[float, float, float], ...]:
        """``(length, base-side width, tip-side width)`` of each unit, base first [m]."""
        g = self._geo
        return tuple((g.chord_m[i], g.width_base_side_m[i], g.width_tip_side_m[i]) for i in range(g.units))

    def contacts(self) -> list[Contact]:
        """Current contacts between units and anything else (objects, floor), with normal forces."""
        m, d = self._m, self._d
        out: list[Contact] = []
        force = np.zeros(6)
        for i in range(d.ncon):
            con = d.contact[i]
            b1 = int(m.geom_bodyid[con.geom1])
            b2 = int(m.geom_bodyid[con.geom2])
            unit, other = (b1, b2) if b1 in self._body_name_of else (b2, b1)
            if unit not in self._body_name_of:
                continue
            mujoco.mj_contactForce(m, d, i, force)
            name = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_BODY, other) or "world"
            pos = (float(con.pos[0]), float(con.pos[1]), float(con.pos[2]))
            depth = max(0.0, -float(con.dist))
            out.append(Contact(self._body_name_of[unit], name, pos, max(float(force[0]), 0.0), depth))
        return out

    # ------------------------------------------------------------------ drone and objects

    def drone_pose(self) -> Pose:
        """Current drone pose."""
        d = self._d
        return Pose(d.mocap_pos[self._drone_mocap].copy(), d.mocap_quat[self._drone_mocap].copy())

    def set_drone_pose(
        self,
        pos_m: Sequence[float],
        quat_wxyz: Sequence[float] = (1.0, 0.0, 0.0, 0.0),
        accel_m_s2: Sequence[float] = (0.0, 0.0, 0.0),
    ) -> None:
        """Move the drone (kinematically; the arm follows rigidly at its base).

        Args:
            pos_m: drone origin, world frame.
            quat_wxyz: orientation (normalised here).
            accel_m_s2: the drone's linear acceleration, world frame. The arm is simulated in the drone's
                frame, so this enters as the fictitious force ``−m·a`` (gravity becomes ``g − a``);
                hanging mounting only (ignored on a table or without gravity).

        Raises:
            ValueError: wrong shape, a non-finite value, or a zero quaternion.
        """
        pos = finite_vector("pos_m", pos_m, 3)
        acc = finite_vector("accel_m_s2", accel_m_s2, 3)
        quat = unit_quat(quat_wxyz)
        d = self._d
        d.mocap_pos[self._drone_mocap] = pos
        d.mocap_quat[self._drone_mocap] = quat
        self._drone_accel[:] = acc
        self._m.opt.gravity[:] = self._gravity - self._accel_gain * acc
        mujoco.mj_kinematics(self._m, d)

    def add_object(self, obj: ObjectConfig) -> None:
        """Add an object to grasp. The model is rebuilt; the arm's state, time and commands are kept.

        Raises:
            ValueError: invalid object or a duplicate name.
        """
        old_m, old_d = self._m, self._d
        earlier = self._monitor.extremes()
        state = (old_d.qpos.copy(), old_d.qvel.copy(), old_d.mocap_pos.copy(), old_d.mocap_quat.copy())
        eq_active = old_d.eq_active.copy()
        keep = (self._time_us, self._drone_accel.copy(), old_d.time)  # the drives keep their own state
        model = self._config.model.with_objects(obj)
        new_config = replace(self._config, model=model)
        new_config.validate()
        self._config = new_config
        self._build()
        m, d = self._m, self._d
        # Objects come after the drone's subtree, so the arm's coordinates keep their addresses.
        nq, nv = old_m.nq, old_m.nv
        d.qpos[:nq], d.qvel[:nv] = state[0], state[1]
        d.mocap_pos[: len(state[2])], d.mocap_quat[: len(state[3])] = state[2], state[3]
        d.eq_active[: len(eq_active)] = eq_active  # supports come in object order: old ones keep their ids
        for o in model.objects:
            body = self._object_bodies[o.name]
            jnt = int(m.body_jntadr[body])
            if jnt >= 0 and int(m.jnt_qposadr[jnt]) >= nq:
                qa = int(m.jnt_qposadr[jnt])
                d.qpos[qa : qa + 3] = o.pos_m
                d.qpos[qa + 3 : qa + 7] = (1.0, 0.0, 0.0, 0.0)
        self._time_us, acc, d.time = keep
        self._drone_accel[:] = acc
        m.opt.gravity[:] = self._gravity - self._accel_gain * acc
        self._bad_qacc = 0
        self._monitor.include(earlier)
        mujoco.mj_forward(m, d)

    # ------------------------------------------------------------------ poses for tests and scenarios

    def set_packed(self, cable: int = 0) -> None:
        """Put the arm (every arm of an array) kinematically into its packed spiral, curled towards ``cable``,
        at rest.

        Every joint is set to its limit Δθ bending towards that cable (for 1-2 cables the hinge limit on
        that side), and every spool is set so its cable is exactly taut. Currents are unchanged.

        Raises:
            IndexError: no such cable.
        """
        if not 0 <= cable < self._n_cables:
            raise IndexError(f"cable {cable} outside 0..{self._n_cables - 1}")
        d = self._d
        dtheta = self._design.dtheta_rad
        psi = self._layout.angles_rad[cable]
        if self._ball:
            # Bending towards the cable at azimuth ψ: rotate about the axis (−sin ψ, cos ψ, 0)·(−1).
            axis = np.array([math.sin(psi), -math.cos(psi), 0.0])
            quat = np.empty(4)
            mujoco.mju_axisAngle2Quat(quat, axis, dtheta)
            for adr in self._arm_qadr:
                d.qpos[adr : adr + 4] = quat
        else:
            sign = -1.0 if math.cos(psi) > 0 else 1.0  # hinge about y: negative bends towards +x
            d.qpos[self._arm_qadr] = sign * dtheta
        d.qvel[:] = 0.0
        self._make_cables_taut()

    def set_straight(self) -> None:
        """Put the arm straight and at rest with every cable exactly taut (time and currents unchanged)."""
        m, d = self._m, self._d
        d.qpos[:] = m.qpos0
        d.qvel[:] = 0.0
        self._make_cables_taut()

    def _make_cables_taut(self) -> None:
        m, d = self._m, self._d
        d.qpos[self._spool_qadr] = 0.0
        mujoco.mj_kinematics(m, d)
        mujoco.mj_tendon(m, d)
        excess = d.ten_length[self._tendon_ids] - self._layout.taut_length_m
        d.qpos[self._spool_qadr] = -excess
        mujoco.mj_forward(m, d)
