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

The configuration is nested by concern — :class:`MotorDriveConfig` (``motor``), :class:`MappingConfig`
(``mapping``), :class:`FailsafeConfig` (``failsafe``), :class:`GraspConfig` (``grasp``),
:class:`HoldConfig` (``hold``) — with the task periods at the top. Its flat form
(:meth:`FirmwareConfig.from_dict` / :meth:`~FirmwareConfig.to_dict`, and the field behind each wire
parameter in :data:`PARAM_FIELDS`) names every field by its own name, ``grasp_`` before the grasp
section's (``grasp_pack_n`` is ``grasp.pack_n``) and ``hold_`` before the length-hold section's.

Parameters listed in :data:`PARAMS` can be read and set at run time over the board link (``ParamSet``
changes the firmware's runtime copy, validated; a rejected value is answered with the current one).
Timing, timeouts and the cable geometry are not among them: they are safety facts, fixed at start-up.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from controller.errors import ConfigError
from protocol.c610 import CURRENT_RAW_MAX, M2006_GEAR_RATIO, RAW_PER_AMP

__all__ = [
    "C610_MAX_A",
    "CONTROL_PERIOD_US",
    "M2006_NO_LOAD_RPM",
    "M2006_TORQUE_K_RANGE",
    "MOTOR_COUNT",
    "PARAMS",
    "PARAM_FIELDS",
    "SAFETY_PARAMS",
    "FailsafeConfig",
    "FirmwareConfig",
    "GraspConfig",
    "HoldConfig",
    "MappingConfig",
    "MotorDriveConfig",
    "runtime_refusal",
]

MOTOR_COUNT = 3
"""Three cables, three M2006 motors on C610 ids 1..3 (CAN feedback 0x201-0x203)."""

CONTROL_PERIOD_US = 1_000
"""The control tick (1 kHz, the C-board's chassis/gimbal loop rate): the default of every 1 ms period."""

C610_MAX_A = CURRENT_RAW_MAX / RAW_PER_AMP
"""The largest current a C610 takes (-10000..10000 raw = -10..10 A; DJI's C610 manual: 10 A max)."""
M2006_TORQUE_K_RANGE = (0.1, 0.5)
"""Torque constants (N·m/A, output shaft) a ``ParamSet`` may give: around DJI's two M2006 P36 figures,
0.18 (spec sheet) and about 0.33 (1 N·m rated at 3 A). A smaller value asks more current per newton."""
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
            the motor is mounted mirrored.
        speed_filter_tau_us: low-pass time constant of the cable speed used for contact detection.
        payin_limit_m_per_s: the speed governor (every mode, after the mapping, slew and length-hold):
            while a cable reels in faster than this (from the rotor speed) its tension is cut back toward
            the pretension, linearly, reaching it at twice this speed. A spool carries about 1.3 kg of
            reflected rotor inertia; reeling a slack cable in at the M2006's no-load speed (0.5 m/s) and
            stopping it on a taut cable (about 48 kN/m) gives ``v·sqrt(k·m)`` ≈ 125 N, a third of a
            0.5 mm Dyneema line's breaking load (300-400 N). 0.1 m/s: random DIRECT tensions (<= 20 N,
            30 s) peak at 242 N instead of 689 N; the 45 cm arm's 3 A step meets the pen 21 ms later.
    """

    spool_radius_m: float = 0.010
    torque_constant_nm_per_a: float = 0.18  # DJI M2006 P36 spec sheet (disputed: see module notes)
    gear_ratio: float = float(M2006_GEAR_RATIO)
    current_limit_a: float = 3.0
    motor_signs: tuple[int, int, int] = (1, 1, 1)
    speed_filter_tau_us: int = 20_000
    payin_limit_m_per_s: float = 0.1

    @property
    def current_limit_raw(self) -> int:
        """Current limit in C610 raw units (1000 per amp)."""
        return int(self.current_limit_a * RAW_PER_AMP)


@dataclass(frozen=True, slots=True)
class MappingConfig:
    """Sticks to cable tensions.

    Attributes:
        cable_angles_deg: angular position of cables 1..3 around the arm (120° apart).
        pretension_n: tension floor of every active cable (pull-only: never below it while active).
        common_max_n: common (curl) tension at full left stick up.
        bend_max_n: bending tension at full right stick deflection.
        tension_max_n: per-cable tension ceiling.
        slew_n_per_s: largest change of a cable's target tension per second.
        stick_deadband: stick counts (of ±660) treated as centred.
    """

    cable_angles_deg: tuple[float, float, float] = (0.0, 120.0, 240.0)
    pretension_n: float = 0.5
    common_max_n: float = 8.0
    bend_max_n: float = 8.0
    tension_max_n: float = 20.0
    slew_n_per_s: float = 50.0
    stick_deadband: int = 20


@dataclass(frozen=True, slots=True)
class FailsafeConfig:
    """What counts as lost.

    Attributes:
        rc_timeout_us: RC lost after this long without a valid frame (DJI: 30 ms).
        motor_timeout_us: a motor is offline after this long without feedback (DJI: 10 ms).
        host_timeout_us: host lost after this long without a ``Heartbeat`` (when a host is required).
        host_required: start with the host heartbeat required (also settable by command/parameter).
    """

    rc_timeout_us: int = 30_000
    motor_timeout_us: int = 10_000
    host_timeout_us: int = 500_000
    host_required: bool = False


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
    """

    strategy_on: bool = True
    direction_deg: float = 0.0
    pack_n: float = 18.0
    pack_rate_n_per_s: float = 12.0
    reach_n: float = 0.0
    reach_rate_n_per_s: float = 10.0
    wrap_n: float = 15.0
    wrap_rate_n_per_s: float = 8.0
    takeup_n: float = 1.5
    takeup_speed_m_per_s: float = 0.08
    release_rate_n_per_s: float = 8.0
    contact_speed_m_per_s: float = 0.004
    contact_slow_ratio: float = 0.7
    contact_dwell_us: int = 60_000
    contact_grace_us: int = 200_000
    contact_min_tension_n: float = 0.3
    contact_decel_m_per_s2: float = 1.0  # the free arm slows at up to 0.66 m/s² after the ramp (prototype)
    contact_decel_tau_us: int = 10_000
    contact_wrap_m_per_s: float = 0.0
    contact_rest_m: float = 0.06
    reach_timeout_us: int = 4_000_000
    release_dwell_us: int = 500_000
    hold_length: bool = False


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

    pos_kp_per_s: float = 20.0
    pos_ki_per_s2: float = 0.0
    pos_kd: float = 0.0
    pos_max_m_per_s: float = 0.2
    pos_imax_m_per_s: float = 0.05
    speed_kp_n_s_per_m: float = 150.0
    speed_ki_n_per_m: float = 1500.0
    speed_imax_n: float = 20.0


_SECTIONS: dict[str, type[Any]] = {
    "motor": MotorDriveConfig,
    "mapping": MappingConfig,
    "failsafe": FailsafeConfig,
    "grasp": GraspConfig,
    "hold": HoldConfig,
}
_PREFIX = {"motor": "", "mapping": "", "failsafe": "", "grasp": "grasp_", "hold": "hold_"}


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

    control_period_us: int = CONTROL_PERIOD_US
    link_period_us: int = CONTROL_PERIOD_US
    detect_period_us: int = 10_000
    telemetry_period_us: int = 10_000
    status_period_us: int = 500_000
    poses_period_us: int = 20_000
    event_queue_len: int = 64
    motor: MotorDriveConfig = MotorDriveConfig()
    mapping: MappingConfig = MappingConfig()
    failsafe: FailsafeConfig = FailsafeConfig()
    grasp: GraspConfig = GraspConfig()
    hold: HoldConfig = HoldConfig()

    def __post_init__(self) -> None:
        self.validate()

    def validate(self) -> None:
        """Check every value and their relations (each named by its flat name).

        Raises:
            ConfigError: (a ``ValueError``) naming the first bad field and why.
        """
        for name, section in _TOP.items():
            _require(name, isinstance(getattr(self, name), section), f"expected a {section.__name__}")
        v = self._flat_values()
        for name, value in v.items():
            _check_type(name, value)
        for name in ("control_period_us", "link_period_us", "detect_period_us", "telemetry_period_us"):
            _require(name, 100 <= v[name] <= 1_000_000, "must be 100..1000000 µs")
        control_us = self.control_period_us
        for name in ("detect_period_us", "telemetry_period_us", "status_period_us", "poses_period_us"):
            _require(
                name,
                v[name] % control_us == 0,
                f"must be a whole number of control periods ({control_us} µs)",
            )
        _require("status_period_us", 1_000 <= v["status_period_us"] <= 10_000_000, "must be 1 ms..10 s")
        _require("poses_period_us", 1_000 <= v["poses_period_us"] <= 1_000_000, "must be 1 ms..1 s")
        for name in ("rc_timeout_us", "motor_timeout_us"):
            _require(name, 2 * control_us <= v[name] <= 1_000_000, "must be 2 ticks..1 s")
        _require("host_timeout_us", 10_000 <= v["host_timeout_us"] <= 60_000_000, "must be 10 ms..60 s")
        _require("cable_angles_deg", len(v["cable_angles_deg"]) == MOTOR_COUNT, f"needs {MOTOR_COUNT} angles")
        _require("motor_signs", len(v["motor_signs"]) == MOTOR_COUNT, f"needs {MOTOR_COUNT} signs")
        _require("motor_signs", all(s in (-1, 1) for s in v["motor_signs"]), "each must be +1 or -1")
        _require("spool_radius_m", 0.001 <= v["spool_radius_m"] <= 0.1, "must be 1..100 mm")
        _require("torque_constant_nm_per_a", 0.01 <= v["torque_constant_nm_per_a"] <= 5.0, "must be 0.01..5")
        _require("gear_ratio", 1.0 <= v["gear_ratio"] <= 1000.0, "must be 1..1000")
        _require("current_limit_a", 0.0 < v["current_limit_a"] <= C610_MAX_A, "must be in (0, 10] A (C610)")
        tension_max_n = v["tension_max_n"]
        _require("pretension_n", 0.0 <= v["pretension_n"] <= tension_max_n, "must be 0..tension_max_n")
        _require("tension_max_n", 0.0 < tension_max_n <= 1000.0, "must be in (0, 1000] N")
        for name in (
            "common_max_n",
            "bend_max_n",
            "grasp_pack_n",
            "grasp_reach_n",
            "grasp_wrap_n",
            "grasp_takeup_n",
        ):
            _require(name, 0.0 <= v[name] <= tension_max_n, "must be 0..tension_max_n")
        _require(
            "grasp_reach_n",
            v["grasp_reach_n"] < 0.5 * v["grasp_pack_n"],
            "must be below half of grasp_pack_n",
        )
        for name in (
            "slew_n_per_s",
            "grasp_pack_rate_n_per_s",
            "grasp_reach_rate_n_per_s",
            "grasp_wrap_rate_n_per_s",
            "grasp_release_rate_n_per_s",
        ):
            _require(name, 0.0 < v[name] <= 100_000.0, "must be in (0, 100000] N/s")
        _require("stick_deadband", 0 <= v["stick_deadband"] < 660, "must be 0..659 counts")
        for name in ("grasp_contact_speed_m_per_s", "grasp_takeup_speed_m_per_s"):
            _require(name, 0.0 < v[name] <= 10.0, "must be (0, 10]")
        _require("grasp_contact_slow_ratio", 0.0 <= v["grasp_contact_slow_ratio"] < 1.0, "must be in [0, 1)")
        _require("grasp_contact_min_tension_n", v["grasp_contact_min_tension_n"] >= 0.0, "must be >= 0")
        _require(
            "grasp_contact_decel_m_per_s2", 0.0 <= v["grasp_contact_decel_m_per_s2"] <= 1e4, "must be 0..1e4"
        )
        _require(
            "grasp_contact_decel_tau_us", 0 <= v["grasp_contact_decel_tau_us"] <= 1_000_000, "must be 0..1 s"
        )
        _require(
            "grasp_contact_wrap_m_per_s", 0.0 <= v["grasp_contact_wrap_m_per_s"] <= 10.0, "must be 0..10"
        )
        _require("grasp_contact_rest_m", 0.0 <= v["grasp_contact_rest_m"] <= 10.0, "must be 0..10 m")
        for name in (
            "grasp_contact_dwell_us",
            "grasp_contact_grace_us",
            "grasp_reach_timeout_us",
            "grasp_release_dwell_us",
        ):
            _require(name, 0 <= v[name] <= 600_000_000, "must be 0..600 s")
        _require(
            "grasp_reach_timeout_us",
            v["grasp_reach_timeout_us"] > v["grasp_contact_grace_us"],
            "must exceed grasp_contact_grace_us",
        )
        for name in (
            "hold_pos_kp_per_s",
            "hold_pos_ki_per_s2",
            "hold_pos_kd",
            "hold_speed_kp_n_s_per_m",
            "hold_speed_ki_n_per_m",
        ):
            _require(name, 0.0 <= v[name] <= 1e6, "must be 0..1e6")
        for name in ("hold_pos_max_m_per_s", "hold_pos_imax_m_per_s"):
            _require(name, 0.0 <= v[name] <= 10.0, "must be 0..10 m/s")
        _require("hold_speed_imax_n", 0.0 <= v["hold_speed_imax_n"] <= 1000.0, "must be 0..1000 N")
        _require("speed_filter_tau_us", 0 <= v["speed_filter_tau_us"] <= 10_000_000, "must be 0..10 s")
        _require("payin_limit_m_per_s", 0.0 < v["payin_limit_m_per_s"] <= 10.0, "must be in (0, 10] m/s")
        _require("event_queue_len", 1 <= v["event_queue_len"] <= 4096, "must be 1..4096")

    @classmethod
    def from_dict(cls, values: Mapping[str, Any]) -> FirmwareConfig:
        """Build a validated configuration from a flat mapping (e.g. parsed TOML/JSON); missing keys default.

        Keys are the flat names of :meth:`to_dict`. Lists are accepted for tuple fields; an integral
        float is accepted for an int field.

        Raises:
            ConfigError: an unknown key, a value of the wrong type, or a value out of range.
        """
        unknown = sorted(set(values) - set(_DEFAULTS))
        if unknown:
            raise ConfigError(f"unknown configuration key(s): {', '.join(unknown)}")
        return _DEFAULT.replaced(**{k: _coerce(k, v) for k, v in values.items()})

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
        """The value of the runtime parameter ``name`` (a wire name in :data:`PARAMS`) as a float.

        Bools read as 0.0 / 1.0.

        Raises:
            ConfigError: ``name`` is not in :data:`PARAMS`.
        """
        flat = PARAM_FIELDS.get(name)
        if flat is None:
            raise ConfigError(f"unknown parameter {name!r}")
        section, field = _FLAT[flat]
        return float(getattr(getattr(self, section) if section else self, field))

    def with_param(self, name: str, value: float) -> FirmwareConfig:
        """A copy with the runtime parameter ``name`` (wire name) set to ``value``, validated.

        Raises:
            ConfigError: unknown parameter, a value of the wrong kind (non-integral for an int, not 0/1
                for a bool, not finite) or one that fails :meth:`validate`.
        """
        flat = PARAM_FIELDS.get(name)
        if flat is None:
            raise ConfigError(f"unknown parameter {name!r}")
        if not math.isfinite(value):
            raise ConfigError(f"{name}: value must be finite, got {value}")
        kind = type(_DEFAULTS[flat])
        new: Any
        if kind is bool:
            if value not in (0.0, 1.0):
                raise ConfigError(f"{name}: must be 0 or 1, got {value}")
            new = bool(value)
        elif kind is int:
            if value != int(value):
                raise ConfigError(f"{name}: must be an integer, got {value}")
            new = int(value)
        else:
            new = float(value)
        return self.replaced(**{flat: new})


PARAM_FIELDS: dict[str, str] = {
    "HOST_TIMEOUT_US": "host_timeout_us",
    "HOST_REQUIRED": "host_required",
    "SPOOL_RADIUS_M": "spool_radius_m",
    "TORQUE_K_NM_A": "torque_constant_nm_per_a",
    "CURRENT_LIMIT_A": "current_limit_a",
    "PRETENSION_N": "pretension_n",
    "COMMON_MAX_N": "common_max_n",
    "BEND_MAX_N": "bend_max_n",
    "TENSION_MAX_N": "tension_max_n",
    "SLEW_N_S": "slew_n_per_s",
    "STICK_DEADBAND": "stick_deadband",
    "GRASP_STRATEGY": "grasp_strategy_on",
    "GRASP_DIR_DEG": "grasp_direction_deg",
    "GRASP_PACK_N": "grasp_pack_n",
    "GRASP_REACH_N": "grasp_reach_n",
    "GRASP_REACH_N_S": "grasp_reach_rate_n_per_s",
    "GRASP_WRAP_N": "grasp_wrap_n",
    "GRASP_WRAP_N_S": "grasp_wrap_rate_n_per_s",
    "GRASP_REL_N_S": "grasp_release_rate_n_per_s",
    "GRASP_STALL_M_S": "grasp_contact_speed_m_per_s",
    "GRASP_DWELL_US": "grasp_contact_dwell_us",
    "GRASP_GRACE_US": "grasp_contact_grace_us",
    "GRASP_MIN_T_N": "grasp_contact_min_tension_n",
    "GRASP_TIMEOUT_US": "grasp_reach_timeout_us",
    "GRASP_REL_DW_US": "grasp_release_dwell_us",
    "SPEED_TAU_US": "speed_filter_tau_us",
    "GRASP_PACK_N_S": "grasp_pack_rate_n_per_s",
    "GRASP_SLOW_RATIO": "grasp_contact_slow_ratio",
    "GRASP_TAKEUP_N": "grasp_takeup_n",
    "GRASP_TAKEUP_M_S": "grasp_takeup_speed_m_per_s",
    "GRASP_HOLD_LEN": "grasp_hold_length",
    "HOLD_POS_KP": "hold_pos_kp_per_s",
    "HOLD_POS_KI": "hold_pos_ki_per_s2",
    "HOLD_POS_KD": "hold_pos_kd",
    "HOLD_POS_MAX_M_S": "hold_pos_max_m_per_s",
    "HOLD_POS_IMAX": "hold_pos_imax_m_per_s",
    "HOLD_SPD_KP": "hold_speed_kp_n_s_per_m",
    "HOLD_SPD_KI": "hold_speed_ki_n_per_m",
    "HOLD_SPD_IMAX_N": "hold_speed_imax_n",
    "GRASP_DECEL_M_S2": "grasp_contact_decel_m_per_s2",
    "GRASP_DECEL_TAU": "grasp_contact_decel_tau_us",
    "GRASP_WRAP_M_S": "grasp_contact_wrap_m_per_s",
    "PAYIN_MAX_M_S": "payin_limit_m_per_s",
    "GRASP_REST_M": "grasp_contact_rest_m",
}
"""Wire name (at most 16 ASCII characters, MAVLink ``param_id`` style) -> flat ``FirmwareConfig`` field."""

PARAMS: tuple[str, ...] = tuple(PARAM_FIELDS)
"""Wire names of the parameters readable and settable over the board link, in index order."""

SAFETY_PARAMS: frozenset[str] = frozenset(
    {
        "CURRENT_LIMIT_A",
        "TENSION_MAX_N",
        "SPOOL_RADIUS_M",
        "TORQUE_K_NM_A",
        "HOST_TIMEOUT_US",
        "HOST_REQUIRED",
        "PAYIN_MAX_M_S",
    }
)
"""Parameters that decide how much current flows for a tension, how fast a cable may reel in, or when
the failsafe acts (the host timeout and whether a host is required at all): a ``ParamSet`` or a
``REQUIRE_HOST`` command changes them only in SAFE (zero current), never while the arm moves."""


def runtime_refusal(config: FirmwareConfig, name: str, value: float, safe: bool) -> str | None:
    """Why a run-time ``ParamSet`` of ``name`` (wire name) to ``value`` is refused, or None.

    On top of :meth:`FirmwareConfig.validate` (which also bounds the current limit by the C610's 10 A):
    safety parameters only in SAFE, the torque constant within :data:`M2006_TORQUE_K_RANGE`, the pay-in
    governor at most the M2006's no-load cable speed on the configured spool.
    """
    if name in SAFETY_PARAMS and not safe:
        return "safety parameter: only in SAFE"
    if name == "TORQUE_K_NM_A" and not M2006_TORQUE_K_RANGE[0] <= value <= M2006_TORQUE_K_RANGE[1]:
        lo, hi = M2006_TORQUE_K_RANGE
        return f"must be {lo:g}..{hi:g} N·m/A (M2006 P36)"
    if name == "PAYIN_MAX_M_S":
        top_m_s = M2006_NO_LOAD_RPM / 60.0 * 2.0 * math.pi * config.motor.spool_radius_m
        if value > top_m_s:
            return f"must be <= {top_m_s:.3g} m/s (M2006 no-load speed on the spool)"
    return None


def _require(name: str, ok: bool, why: str) -> None:
    if not ok:
        raise ConfigError(f"{name}: {why}")


def _check_type(name: str, value: object) -> None:
    default = _DEFAULTS[name]
    if isinstance(default, bool):
        ok = isinstance(value, bool)
    elif isinstance(default, int):
        ok = isinstance(value, int) and not isinstance(value, bool)
    elif isinstance(default, float):
        ok = isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)
    else:  # tuple
        elem = type(default[0])
        ok = isinstance(value, tuple) and all(
            isinstance(v, int | float) and not isinstance(v, bool) and (elem is float or isinstance(v, int))
            for v in value
        )
    if not ok:
        raise ConfigError(f"{name}: expected {type(default).__name__} like {default!r}, got {value!r}")


def _coerce(name: str, value: Any) -> Any:
    default = _DEFAULTS[name]
    if isinstance(value, list):
        value = tuple(value)
    if isinstance(default, bool):
        return value
    if isinstance(default, int) and isinstance(value, float) and value.is_integer():
        return int(value)
    if isinstance(default, float) and isinstance(value, int) and not isinstance(value, bool):
        return float(value)
    if isinstance(default, tuple) and isinstance(default[0], float) and isinstance(value, tuple):
        return tuple(float(v) if isinstance(v, int) and not isinstance(v, bool) else v for v in value)
    return value


_TOP: dict[str, type[Any]] = dict(_SECTIONS)
"""Top-level fields that are sections, with their types."""

_FLAT_ORDER = (
    "control_period_us",
    "link_period_us",
    "detect_period_us",
    "telemetry_period_us",
    "status_period_us",
    "poses_period_us",
    "rc_timeout_us",
    "motor_timeout_us",
    "host_timeout_us",
    "host_required",
    "cable_angles_deg",
    "motor_signs",
    "spool_radius_m",
    "torque_constant_nm_per_a",
    "gear_ratio",
    "current_limit_a",
    "pretension_n",
    "common_max_n",
    "bend_max_n",
    "tension_max_n",
    "slew_n_per_s",
    "stick_deadband",
    *(f"grasp_{f.name}" for f in dataclasses.fields(GraspConfig)),
    "speed_filter_tau_us",
    "payin_limit_m_per_s",
    "event_queue_len",
    *(f"hold_{f.name}" for f in dataclasses.fields(HoldConfig)),
)
"""The flat form's key order: the one it had before the nesting (recorded configurations keep their bytes)."""

_FLAT: dict[str, tuple[str | None, str]] = {
    **{f.name: (None, f.name) for f in dataclasses.fields(FirmwareConfig) if f.name not in _SECTIONS},
    **{
        _PREFIX[section] + f.name: (section, f.name)
        for section, cls in _SECTIONS.items()
        for f in dataclasses.fields(cls)
    },
}
_FLAT = {flat: _FLAT[flat] for flat in _FLAT_ORDER}
"""Flat name -> (section or None for a top-level field, field name in it)."""

_DEFAULTS: dict[str, Any] = {
    flat: next(
        f.default
        for f in dataclasses.fields(FirmwareConfig if section is None else _SECTIONS[section])
        if f.name == field
    )
    for flat, (section, field) in _FLAT.items()
}
"""Flat name -> default value (read from the classes: validating an instance needs this table)."""

_DEFAULT = FirmwareConfig()
