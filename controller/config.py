"""All firmware constants in one frozen, validated configuration (units in names).

Facts behind the defaults:

- DJI detect task: RC lost after 30 ms without a valid frame; a motor offline after 10 ms without
  feedback (``RoboMaster/Development-Board-C-Examples``, ``detect_task.c``).
- M2006 P36: 36:1 gearbox; 3 A continuous, 10 A peak. The torque constant is disputed: DJI's M2006
  spec sheet gives 0.18 N·m/A at the output shaft, while "1 N·m rated at 3 A" implies about 0.33 N·m/A;
  the C610 manual's performance curve is the better reference (docs/plant.md, motor table).
  We keep 0.18 N·m/A as the default and expose it as a parameter: the plant must use the same value
  for the firmware's tension estimate to be consistent.
- Spool radius 10 mm (the prototype's), current limit 3 A (the M2006's continuous rating).

Arms and cables (an array of SpiRobs on one board): ``cable_angles_deg`` holds one angle per cable of an
arm (1-3 cables: the same for every arm) and ``motor_signs`` one sign per motor (1-8: a CAN bus carries
C610 ids 1-8, commands 0x200 and 0x1FF). Motor ``m`` (1-based) drives cable ``(m - 1) % cables`` of arm
``(m - 1) // cables``: arm 1's cables first, then arm 2's. The default (three angles, three signs) is the
paper's one three-cable arm; eight one-cable arms, four two-cable arms or two three-cable arms fill a
board (:meth:`FirmwareConfig.with_arms`). Every arm gets the same tensions (``controller.cables``).

The configuration is nested by concern — :class:`MotorDriveConfig` (``motor``), :class:`MappingConfig`
(``mapping``), :class:`FailsafeConfig` (``failsafe``), :class:`GraspConfig` (``grasp``),
:class:`HoldConfig` (``hold``) — with the task periods at the top. Its flat form
(:meth:`FirmwareConfig.from_dict` / :meth:`~FirmwareConfig.to_dict`) names every field by its own name,
``grasp_`` before the grasp section's (``grasp_pack_n`` is ``grasp.pack_n``) and ``hold_`` before the
length-hold section's.

Every field is a row of the parameter table (:mod:`controller.params`): its default, type, unit and
bounds are declared there once, and :meth:`FirmwareConfig.validate` checks them row by row; only the
rules that tie one field to another are written out here. The rows with a wire name can be read and set
at run time over the board link (``ParamSet`` goes through :meth:`FirmwareConfig.with_param`: validated,
a rejected value is answered with the current one). Timing, most timeouts and the cable geometry are
not among them: they are fixed at start-up.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from controller.errors import ConfigError
from controller.params import FIELD_ROWS, PARAM_TABLE, WIRE_ROWS, default
from protocol.c610 import MOTORS_MAX, RAW_PER_AMP

__all__ = [
    "CABLES_PER_ARM_MAX",
    "CONTROL_PERIOD_US",
    "M2006_NO_LOAD_RPM",
    "MOTOR_COUNT",
    "FailsafeConfig",
    "FirmwareConfig",
    "GraspConfig",
    "HoldConfig",
    "MappingConfig",
    "MotorDriveConfig",
]

MOTOR_COUNT = 3
"""The default board: one arm of three cables, three M2006 motors on C610 ids 1..3 (feedback 0x201-0x203).
A configuration's own count is :attr:`FirmwareConfig.motor_count` (1..8, see the module notes)."""

CABLES_PER_ARM_MAX = 3
"""SpiRobs have one, two or three cables (the supplement's Note S3 and Fig. S5)."""

CONTROL_PERIOD_US: int = default("control_period_us")
"""The control tick (1 kHz, the C-board's chassis/gimbal loop rate): the default of every 1 ms period."""

M2006_NO_LOAD_RPM = 500.0
"""M2006 P36 no-load output speed (DJI's figure): no cable moves faster than this times the spool's
circumference, so a pay-in governor above it is no governor (a ``ParamSet`` ceiling)."""


@dataclass(frozen=True, slots=True)
class MotorDriveConfig:
    """M2006 P36 + C610 + spool: the constants the firmware and the plant share.

    Attributes:
        spool_radius_m: cable spool radius.
        torque_constant_nm_per_a: M2006 P36 torque per amp at the output shaft (see module notes).
        gear_ratio: rotor turns per output turn (M2006 P36: 36).
        current_limit_a: |current| never commanded above this (M2006: 3 A continuous).
        motor_signs: +1 if a positive current reels the cable in (raises tension) on that motor, -1 if
            the motor is mounted mirrored; one per motor (1-8: their count is the board's motor count).
        speed_filter_tau_us: low-pass time constant of the cable speed used for contact detection.
        payin_limit_m_per_s: the speed governor (every mode, after the mapping, slew and length-hold):
            while a cable reels in faster than this (from the rotor speed) its tension is cut back toward
            the pretension, linearly, reaching it at twice this speed. A spool carries about 1.3 kg of
            reflected rotor inertia; reeling a slack cable in at the M2006's no-load speed (0.5 m/s) and
            stopping it on a taut cable (about 48 kN/m) gives ``v·sqrt(k·m)`` ≈ 125 N, a third of a
            0.5 mm Dyneema line's breaking load (300-400 N). 0.1 m/s: random DIRECT tensions (<= 20 N,
            30 s) peak at 242 N instead of 689 N; the 45 cm arm's 3 A step meets the pen 21 ms later.
    """

    spool_radius_m: float = default("motor.spool_radius_m")
    torque_constant_nm_per_a: float = default("motor.torque_constant_nm_per_a")
    gear_ratio: float = default("motor.gear_ratio")
    current_limit_a: float = default("motor.current_limit_a")
    motor_signs: tuple[int, ...] = default("motor.motor_signs")
    speed_filter_tau_us: int = default("motor.speed_filter_tau_us")
    payin_limit_m_per_s: float = default("motor.payin_limit_m_per_s")

    @property
    def current_limit_raw(self) -> int:
        """Current limit in C610 raw units (1000 per amp)."""
        return int(self.current_limit_a * RAW_PER_AMP)


@dataclass(frozen=True, slots=True)
class MappingConfig:
    """Sticks to cable tensions.

    Attributes:
        cable_angles_deg: angular position of each cable around an arm (three at 120°; one to three
            cables, the same for every arm of an array).
        pretension_n: tension floor of every active cable (pull-only: never below it while active).
        common_max_n: common (curl) tension at full left stick up.
        bend_max_n: bending tension at full right stick deflection.
        tension_max_n: per-cable tension ceiling.
        slew_n_per_s: largest change of a cable's target tension per second.
        stick_deadband: stick counts (of ±660) treated as centred.
    """

    cable_angles_deg: tuple[float, ...] = default("mapping.cable_angles_deg")
    pretension_n: float = default("mapping.pretension_n")
    common_max_n: float = default("mapping.common_max_n")
    bend_max_n: float = default("mapping.bend_max_n")
    tension_max_n: float = default("mapping.tension_max_n")
    slew_n_per_s: float = default("mapping.slew_n_per_s")
    stick_deadband: int = default("mapping.stick_deadband")


@dataclass(frozen=True, slots=True)
class FailsafeConfig:
    """What counts as lost.

    Attributes:
        rc_timeout_us: RC lost after this long without a valid frame (DJI: 30 ms).
        motor_timeout_us: a motor is offline after this long without feedback (DJI: 10 ms).
        host_timeout_us: host lost after this long without a ``Heartbeat`` (when a host is required).
        host_required: start with the host heartbeat required (also settable by command/parameter).
    """

    rc_timeout_us: int = default("failsafe.rc_timeout_us")
    motor_timeout_us: int = default("failsafe.motor_timeout_us")
    host_timeout_us: int = default("failsafe.host_timeout_us")
    host_required: bool = default("failsafe.host_required")


@dataclass(frozen=True, slots=True)
class GraspConfig:
    """The grasp state machine (flat names: ``grasp_`` + the field name).

    Attributes:
        strategy_on: True = the bio-inspired strategy of the SpiRobs supplement's Note S4 (pack, reach,
            detect contact, wrap); False = the "off" comparison (plain tension ramp from straight).
        direction_deg: grasp direction when neither the right stick nor the host gives one.
        pack_n: curl tension of the packed (coiled) pose the grasp starts from. The prototype plant
            (base joint 0.5 N·m/rad, 12.8 mm hole radius) closes every joint at about 21 N
            (``spirob-hil experiment packing``); with the 0.5 N pretension 18 N stays under the 20 N
            cable ceiling and closes all but the one or two joints nearest the base. (It was 6 N: that
            only curled the distal half, so the reach had little to unroll.)
        pack_rate_n_per_s: rate at which IDLE winds the pack tension up.
        reach_n: curl tension the reach phase ramps down to (arm unrolled); below half of ``pack_n``
            (the prototype hardly unrolls above half its pack tension).
        reach_rate_n_per_s: reach ramp-down rate.
        wrap_n: tension of the wrap / hold phases (strategy on: on the cables opposite the pack side,
            which face the object at contact; off: toward the target). It must close the joints that lie
            on the object, not only the tip: a joint's closing tension scales with its size² (the
            prototype's base closes at 21 N, its tip at 4.5 N; ``spirob-hil experiment packing``), so the
            mid-arm joints that meet an object 100-120 mm under the base close at about 9-12 N. At 5 N only
            the last joints closed: the tip coiled on itself and pinched the object against the unit that
            touched it (2-3 units, 100-140° at HOLD), and the object slipped out once its support went.
            15 N (under the 20 N ceiling) closes the arm around it; 18 N snapped the cables (135-290 N).
        wrap_rate_n_per_s: wrap ramp-up rate.
        takeup_n: curl tension that reels in the wrap-side cables' slack before the wrap ramp
            (strategy on; 0 = no take-up). Above the drive friction (about 1 N at the cable) minus the
            pretension, so the spools move.
        takeup_speed_m_per_s: the take-up tension is cut while the slack reels in faster than this (a
            spool carries about 1.3 kg of reflected rotor inertia: a fast one snaps the cable).
        release_rate_n_per_s: release ramp-down rate.
        contact_speed_m_per_s: pack-side pay-out speed that shows the arm unrolling; below it the
            cable counts as stalled.
        contact_slow_ratio: the cable also counts as stalled while its pay-out is below this fraction
            of the fastest pay-out of the present reach (in free space the pay-out only speeds up while
            the reach ramp runs; a body blocked by an object slows it down).
        contact_dwell_us: stall duration that means contact; also how long a cable must stay still for
            the packed arm to count as settled, the wrap-side slack as taken up, and the wrap as closed
            (HOLD).
        contact_grace_us: no contact is detected this soon after the reach starts.
        contact_min_tension_n: the estimated tension must hold at least this for contact.
        contact_decel_m_per_s2: contact when the pack-side pay-out decelerates faster than this while
            the arm still moves (``controller.contact``; catches contacts after the reach ramp ended);
            0 = rule off.
        contact_decel_tau_us: low-pass time constant of that deceleration.
        contact_wrap_m_per_s: contact when the wrap-side cables pay out faster than this while the
            pack side has slowed (the object pushes the coil's outer face back); 0 = rule off.
        contact_rest_m: contact when, after the reach ramp, the pack-side cable has stayed still for
            ``contact_dwell_us`` having paid out less than this since the reach began (the arm came to
            rest against something short of its free unroll: 65 mm on the prototype from the 18 N pack);
            0 = rule off.
        reach_timeout_us: FAILED when no contact within this time after the reach starts.
        release_dwell_us: time spent uncurled after a release before re-packing (IDLE).
        hold_length: HOLD freezes the pulling cables' length (``controller.lengthhold``) instead of
            their tension: a grasped load stays still instead of sagging until the tension balances it.
        hold_min_payin_m: HOLD is evidence the wrap has closed, from the motors alone: the pulling cables
            must have paid in at least this since the wrap began (strategy on: since contact) when they
            come to rest at the wrap tension; short of it the wrap stalled open and the grasp is FAILED
            (its tension kept). 0 = off. On the prototype it does not separate held from dropped
            grasps (docs/grasping.md): measured, not recommended.
        hold_max_payin_m: FAILED instead of HOLD when the pulling cables paid in more than this since the
            wrap began: nothing blocked the curl (an empty curl pays in the most). 0 = off; a lab sets it
            a little under the pay-in of a grasp in the air (``bench/hold.py`` measures it).
    """

    strategy_on: bool = default("grasp.strategy_on")
    direction_deg: float = default("grasp.direction_deg")
    pack_n: float = default("grasp.pack_n")
    pack_rate_n_per_s: float = default("grasp.pack_rate_n_per_s")
    reach_n: float = default("grasp.reach_n")
    reach_rate_n_per_s: float = default("grasp.reach_rate_n_per_s")
    wrap_n: float = default("grasp.wrap_n")
    wrap_rate_n_per_s: float = default("grasp.wrap_rate_n_per_s")
    takeup_n: float = default("grasp.takeup_n")
    takeup_speed_m_per_s: float = default("grasp.takeup_speed_m_per_s")
    release_rate_n_per_s: float = default("grasp.release_rate_n_per_s")
    contact_speed_m_per_s: float = default("grasp.contact_speed_m_per_s")
    contact_slow_ratio: float = default("grasp.contact_slow_ratio")
    contact_dwell_us: int = default("grasp.contact_dwell_us")
    contact_grace_us: int = default("grasp.contact_grace_us")
    contact_min_tension_n: float = default("grasp.contact_min_tension_n")
    contact_decel_m_per_s2: float = default("grasp.contact_decel_m_per_s2")
    contact_decel_tau_us: int = default("grasp.contact_decel_tau_us")
    contact_wrap_m_per_s: float = default("grasp.contact_wrap_m_per_s")
    contact_rest_m: float = default("grasp.contact_rest_m")
    reach_timeout_us: int = default("grasp.reach_timeout_us")
    release_dwell_us: int = default("grasp.release_dwell_us")
    hold_length: bool = default("grasp.hold_length")
    hold_min_payin_m: float = default("grasp.hold_min_payin_m")
    hold_max_payin_m: float = default("grasp.hold_max_payin_m")


@dataclass(frozen=True, slots=True)
class HoldConfig:
    """The length-hold cascade (``controller.lengthhold``; flat names: ``hold_`` + the field name).

    Two PID loops per held cable, as DJI's C-board motor examples cascade them (angle -> speed ->
    current): the length error gives a speed set-point, the speed error gives the cable tension (then
    the current). The defaults suit the M2006 P36 on a 10 mm spool: about 1.3 kg of rotor inertia
    reflected to the cable and 1 N of drive friction. With the position loop proportional only, the
    speed loop's integral holds a steady load with no length error (it integrates the speed error,
    i.e. the length error). Speed loop bandwidth about ``speed_kp / 1.3 kg`` (115 rad/s), the position
    loop's ``pos_kp`` (20 rad/s) well inside it.

    Attributes:
        pos_kp_per_s: length error -> speed set-point gain (1/s).
        pos_ki_per_s2: its integral gain (1/s²; 0 = none, the speed loop's integral already removes a
            steady error).
        pos_kd: its derivative gain (dimensionless).
        pos_max_m_per_s: speed set-point limit (the loop's output limit).
        pos_imax_m_per_s: the position loop's integral-term limit.
        speed_kp_n_s_per_m: speed error -> tension gain (N per m/s).
        speed_ki_n_per_m: its integral gain (N per m of accumulated speed error).
        speed_imax_n: the speed loop's integral-term limit (the output is also clamped to
            [pretension_n, tension_max_n] and then to the current limit).
    """

    pos_kp_per_s: float = default("hold.pos_kp_per_s")
    pos_ki_per_s2: float = default("hold.pos_ki_per_s2")
    pos_kd: float = default("hold.pos_kd")
    pos_max_m_per_s: float = default("hold.pos_max_m_per_s")
    pos_imax_m_per_s: float = default("hold.pos_imax_m_per_s")
    speed_kp_n_s_per_m: float = default("hold.speed_kp_n_s_per_m")
    speed_ki_n_per_m: float = default("hold.speed_ki_n_per_m")
    speed_imax_n: float = default("hold.speed_imax_n")


_SECTIONS: dict[str, type[Any]] = {
    "motor": MotorDriveConfig,
    "mapping": MappingConfig,
    "failsafe": FailsafeConfig,
    "grasp": GraspConfig,
    "hold": HoldConfig,
}


@dataclass(frozen=True, slots=True)
class FirmwareConfig:
    """Firmware constants, nested by concern. Frozen; every instance is validated on creation.

    Attributes:
        control_period_us: control task period (1 kHz, the C-board's chassis/gimbal loop rate).
        link_period_us: board-link receive task period (1 kHz: an E-stop acts on the next tick).
        detect_period_us: liveness reporting task period (100 Hz, DJI's detect task).
        telemetry_period_us: ``Telemetry`` + ``MotorFrames`` period (100 Hz).
        status_period_us: ``BoardStatus`` period (2 Hz).
        poses_period_us: ``SimPoses`` period (50 Hz; only when the bus provides poses).
        event_queue_len: capacity of the preallocated event queue (oldest events dropped and counted).
        motor: the drive and spool (:class:`MotorDriveConfig`).
        mapping: sticks to tensions (:class:`MappingConfig`).
        failsafe: timeouts and the host requirement (:class:`FailsafeConfig`).
        grasp: the grasp state machine (:class:`GraspConfig`).
        hold: the length-hold cascade (:class:`HoldConfig`).
    """

    control_period_us: int = default("control_period_us")
    link_period_us: int = default("link_period_us")
    detect_period_us: int = default("detect_period_us")
    telemetry_period_us: int = default("telemetry_period_us")
    status_period_us: int = default("status_period_us")
    poses_period_us: int = default("poses_period_us")
    event_queue_len: int = default("event_queue_len")
    motor: MotorDriveConfig = MotorDriveConfig()
    mapping: MappingConfig = MappingConfig()
    failsafe: FailsafeConfig = FailsafeConfig()
    grasp: GraspConfig = GraspConfig()
    hold: HoldConfig = HoldConfig()

    def __post_init__(self) -> None:
        self.validate()

    def validate(self) -> None:
        """Check every value against its row of the parameter table, then the rules between fields.

        Each value is named by its flat name.

        Raises:
            ConfigError: (a ``ValueError``) naming the first bad field and why.
        """
        for name, section in _SECTIONS.items():
            _require(name, isinstance(getattr(self, name), section), f"expected a {section.__name__}")
        v = self._flat_values()
        for row in PARAM_TABLE:
            row.check_type(v[row.name])
        for row in PARAM_TABLE:
            row.check_bounds(v)
        # Rules between fields.
        control_us = self.control_period_us
        for name in ("detect_period_us", "telemetry_period_us", "status_period_us", "poses_period_us"):
            _require(
                name,
                v[name] % control_us == 0,
                f"must be a whole number of control periods ({control_us} µs)",
            )
        for name in ("rc_timeout_us", "motor_timeout_us"):
            _require(name, v[name] >= 2 * control_us, f"must be at least 2 control periods ({control_us} µs)")
        cables = len(v["cable_angles_deg"])
        motors = len(v["motor_signs"])
        _require(
            "cable_angles_deg",
            1 <= cables <= CABLES_PER_ARM_MAX,
            f"one angle per cable of an arm: 1..{CABLES_PER_ARM_MAX}, got {cables}",
        )
        _require(
            "motor_signs",
            1 <= motors <= MOTORS_MAX and motors % cables == 0,
            f"one sign per motor: 1..{MOTORS_MAX} motors, whole {cables}-cable arms, got {motors}",
        )
        _require("motor_signs", all(s in (-1, 1) for s in v["motor_signs"]), "each must be +1 or -1")
        _require(
            "grasp_reach_n",
            v["grasp_reach_n"] < 0.5 * v["grasp_pack_n"],
            "must be below half of grasp_pack_n",
        )
        _require(
            "grasp_reach_timeout_us",
            v["grasp_reach_timeout_us"] > v["grasp_contact_grace_us"],
            "must exceed grasp_contact_grace_us",
        )
        lo, hi = v["grasp_hold_min_payin_m"], v["grasp_hold_max_payin_m"]
        _require(
            "grasp_hold_max_payin_m",
            hi == 0.0 or hi > lo,
            f"must exceed grasp_hold_min_payin_m ({lo:g} m) or be 0 (off)",
        )

    @property
    def motor_count(self) -> int:
        """Motors on the board (C610 ids 1..n): one per ``motor_signs`` entry."""
        return len(self.motor.motor_signs)

    @property
    def cables_per_arm(self) -> int:
        """Cables of each arm: one per ``cable_angles_deg`` entry."""
        return len(self.mapping.cable_angles_deg)

    @property
    def arm_count(self) -> int:
        """Arms on the board: motors / cables per arm (motor m drives cable (m-1) % C of arm (m-1) // C)."""
        return len(self.motor.motor_signs) // len(self.mapping.cable_angles_deg)

    def with_arms(self, arms: int, cables_per_arm: int | None = None) -> FirmwareConfig:
        """A copy laid out as ``arms`` arms of ``cables_per_arm`` cables (default: this one's).

        The cable angles are kept when their count is ``cables_per_arm``, else spread evenly (0°; 0° and
        180°; 0°, 120° and 240°). The motor signs are kept when there is one per motor; signs all +1 are
        repeated for every motor; mirrored motors of another layout are refused (no guess at which motor
        of the new layout is mirrored).

        Raises:
            ConfigError: more than eight motors, an unknown cable count, or signs that do not fit.
        """
        cables = self.cables_per_arm if cables_per_arm is None else cables_per_arm
        if not 1 <= cables <= CABLES_PER_ARM_MAX:
            raise ConfigError(f"cables per arm: 1..{CABLES_PER_ARM_MAX}, got {cables}")
        motors = arms * cables
        if arms < 1 or motors > MOTORS_MAX:
            raise ConfigError(
                f"{arms} arm(s) of {cables} cable(s) need {motors} motors: a C-board drives 1..{MOTORS_MAX}"
            )
        angles = self.mapping.cable_angles_deg
        if len(angles) != cables:
            angles = tuple(360.0 * i / cables for i in range(cables))
        signs = self.motor.motor_signs
        if len(signs) != motors:
            if any(s != 1 for s in signs):
                raise ConfigError(
                    f"motor_signs has {len(signs)} entries with mirrored motors; {arms} arm(s) of {cables} "
                    f"cable(s) need {motors}: give them in the configuration"
                )
            signs = (1,) * motors
        return self.replaced(cable_angles_deg=angles, motor_signs=signs)

    @classmethod
    def from_dict(cls, values: Mapping[str, Any]) -> FirmwareConfig:
        """Build a validated configuration from a flat mapping (e.g. parsed TOML/JSON); missing keys default.

        Keys are the flat names of :meth:`to_dict`. Lists are accepted for tuple fields; an integral
        float is accepted for an int field.

        Raises:
            ConfigError: an unknown key, a value of the wrong type, or a value out of range.
        """
        unknown = sorted(set(values) - set(FIELD_ROWS))
        if unknown:
            raise ConfigError(f"unknown configuration key(s): {', '.join(unknown)}")
        return _DEFAULT.replaced(**{k: FIELD_ROWS[k].coerce(v) for k, v in values.items()})

    def to_dict(self) -> dict[str, Any]:
        """Every field by its flat name (tuples as lists), the inverse of :meth:`from_dict`."""
        return {k: list(v) if isinstance(v, tuple) else v for k, v in self._flat_values().items()}

    def _flat_values(self) -> dict[str, Any]:
        return {
            flat: getattr(self if section is None else getattr(self, section), field)
            for flat, (section, field) in _FLAT.items()
        }

    def replaced(self, **changes: Any) -> FirmwareConfig:
        """A validated copy with the fields named by their flat names (as in :meth:`to_dict`) changed.

        Raises:
            ConfigError: an unknown name, or a value that fails :meth:`validate`.
        """
        top: dict[str, Any] = {}
        nested: dict[str, dict[str, Any]] = {}
        for flat, value in changes.items():
            where = _FLAT.get(flat)
            if where is None:
                raise ConfigError(f"unknown configuration key {flat!r}")
            section, field = where
            if section is None:
                top[field] = value
            else:
                nested.setdefault(section, {})[field] = value
        for section, fields in nested.items():
            top[section] = dataclasses.replace(getattr(self, section), **fields)
        return dataclasses.replace(self, **top)

    def get_param(self, name: str) -> float:
        """The value of the run-time parameter ``name`` (a wire name in ``controller.params.PARAMS``).

        Bools read as 0.0 / 1.0.

        Raises:
            ConfigError: ``name`` is not a run-time parameter.
        """
        row = WIRE_ROWS.get(name)
        if row is None:
            raise ConfigError(f"unknown parameter {name!r}")
        section, field = _FLAT[row.name]
        return float(getattr(getattr(self, section) if section else self, field))

    def with_param(self, name: str, value: float, *, safe: bool = True) -> FirmwareConfig:
        """A copy with the run-time parameter ``name`` (wire name) set to ``value``: a ``ParamSet``'s rule.

        The board applies it to every ``ParamSet`` and the host to check a value before sending it, so
        both refuse the same values with the same words. Beyond :meth:`validate`: a safety parameter
        changes only in SAFE, a value must meet its row's run-time range (a hardware figure), and the
        pay-in governor must stay at or below the M2006's no-load cable speed on the configured spool.

        Args:
            name: wire name.
            value: the value as it travels (float32 on the wire).
            safe: the arm is in SAFE (zero current); the host, which does not decide that, passes True
                and leaves the SAFE-only refusal to the board.

        Raises:
            ConfigError: unknown parameter, a safety parameter outside SAFE (``safety parameter: only in
                SAFE``), a value of the wrong kind (non-integral for an int, not 0/1 for a bool, not
                finite), or one outside a range.
        """
        row = WIRE_ROWS.get(name)
        if row is None:
            raise ConfigError(f"unknown parameter {name!r}")
        if row.safety and not safe:
            raise ConfigError("safety parameter: only in SAFE")
        new = row.from_wire(value)
        if row.runtime is not None and not row.runtime.contains(new, {}):
            raise ConfigError(f"{row.name}: {row.runtime.text(row.unit)}")
        if row.name == "payin_limit_m_per_s":
            top_m_s = M2006_NO_LOAD_RPM / 60.0 * 2.0 * math.pi * self.motor.spool_radius_m
            if new > top_m_s:
                raise ConfigError(
                    f"{row.name}: must be <= {top_m_s:.3g} m/s (M2006 no-load speed on the spool)"
                )
        return self.replaced(**{row.name: new})

    def with_board_values(self, values: Mapping[str, float]) -> FirmwareConfig:
        """A copy with the run-time parameters a board reported (wire name -> value), validated together.

        Names that are not run-time parameters are skipped; no run-time rule applies (the board took
        these values already).

        Raises:
            ConfigError: a value of the wrong kind, or values that fail :meth:`validate` together.
        """
        return self.replaced(
            **{WIRE_ROWS[n].name: WIRE_ROWS[n].from_wire(v) for n, v in values.items() if n in WIRE_ROWS}
        )


def _require(name: str, ok: bool, why: str) -> None:
    if not ok:
        raise ConfigError(f"{name}: {why}")


_FLAT: dict[str, tuple[str | None, str]] = {
    row.name: (section or None, field)
    for row in PARAM_TABLE
    for section, _, field in [row.field.rpartition(".")]
}
"""Flat name -> (section or None for a top-level field, field name in it), in the table's order."""

_DEFAULT = FirmwareConfig()
