"""All firmware constants in one frozen, validated configuration (units in names).

Facts behind the defaults:

- DJI detect task: RC lost after 30 ms without a valid frame; a motor offline after 10 ms without
  feedback (``RoboMaster/Development-Board-C-Examples``, ``detect_task.c``).
- M2006 P36: 36:1 gearbox; 3 A continuous, 10 A peak. The torque constant is disputed: DJI's M2006
  spec sheet gives 0.18 N·m/A at the output shaft, while "1 N·m rated at 3 A" implies about 0.33 N·m/A;
  the C610 manual's performance curve is the better reference (FIELD-NOTES "M2006 figures disagree").
  We keep 0.18 N·m/A as the default and expose it as a parameter: the plant must use the same value
  for the firmware's tension estimate to be consistent.
- Spool radius 10 mm, current limit 3 A (DESIGN.md section 3).

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

__all__ = ["MOTOR_COUNT", "PARAMS", "PARAM_FIELDS", "FirmwareConfig"]

MOTOR_COUNT = 3
"""Three cables, three M2006 motors on C610 ids 1..3 (CAN feedback 0x201-0x203)."""

_C610_MAX_A = 10.0  # C610: -10000..10000 raw = -10..10 A


@dataclass(frozen=True, slots=True)
class FirmwareConfig:
    """Firmware constants. Frozen; every instance is validated on creation.

    Attributes:
        control_period_us: control task period (1 kHz, the C-board's chassis/gimbal loop rate).
        link_period_us: board-link receive task period (1 kHz: an E-stop acts on the next tick).
        detect_period_us: liveness reporting task period (100 Hz, DJI's detect task).
        telemetry_period_us: ``Telemetry`` + ``MotorFrames`` period (100 Hz).
        status_period_us: ``BoardStatus`` period (2 Hz).
        poses_period_us: ``SimPoses`` period (50 Hz; only when the bus provides poses).
        rc_timeout_us: RC lost after this long without a valid frame (DJI: 30 ms).
        motor_timeout_us: a motor is offline after this long without feedback (DJI: 10 ms).
        host_timeout_us: host lost after this long without a ``Heartbeat`` (when a host is required).
        host_required: start with the host heartbeat required (also settable by command/parameter).
        cable_angles_deg: angular position of cables 1..3 around the arm (120° apart).
        motor_signs: +1 if a positive current reels the cable in (raises tension) on that motor, -1 if
            the motor is mounted mirrored.
        spool_radius_m: cable spool radius.
        torque_constant_nm_per_a: M2006 P36 torque per amp at the output shaft (see module notes).
        gear_ratio: rotor turns per output turn (M2006 P36: 36).
        current_limit_a: |current| never commanded above this (M2006: 3 A continuous).
        pretension_n: tension floor of every active cable (pull-only: never below it while active).
        common_max_n: common (curl) tension at full left stick up.
        bend_max_n: bending tension at full right stick deflection.
        tension_max_n: per-cable tension ceiling.
        slew_n_per_s: largest change of a cable's target tension per second.
        stick_deadband: stick counts (of ±660) treated as centred.
        grasp_strategy_on: True = the bio-inspired strategy of seed Note S4 (pack, reach, detect
            contact, wrap); False = the "off" comparison (plain tension ramp from straight).
        grasp_direction_deg: grasp direction when neither the right stick nor the host gives one.
        grasp_pack_n: curl tension of the packed (coiled) pose the grasp starts from. The prototype
            plant (base joint 0.5 N·m/rad, 12.8 mm hole radius) closes every joint at about 21 N
            (``spirob-hil experiment packing``); with the 0.5 N pretension 18 N stays under the 20 N
            cable ceiling and closes all but the one or two joints nearest the base. (It was 6 N: that
            only curled the distal half, so the reach had little to unroll.)
        grasp_pack_rate_n_per_s: rate at which IDLE winds the pack tension up.
        grasp_reach_n: curl tension the reach phase ramps down to (arm unrolled); below half of
            ``grasp_pack_n`` (the prototype hardly unrolls above half its pack tension).
        grasp_reach_rate_n_per_s: reach ramp-down rate.
        grasp_wrap_n: tension of the wrap / hold phases (strategy on: on the cables opposite the pack
            side, which face the object at contact; off: toward the target).
        grasp_wrap_rate_n_per_s: wrap ramp-up rate.
        grasp_takeup_n: curl tension that reels in the wrap-side cables' slack before the wrap ramp
            (strategy on; 0 = no take-up). Above the drive friction (about 1 N at the cable) minus the
            pretension, so the spools move.
        grasp_takeup_speed_m_per_s: the take-up tension is cut while the slack reels in faster than
            this (a spool carries about 1.3 kg of reflected rotor inertia: a fast one snaps the cable).
        grasp_release_rate_n_per_s: release ramp-down rate.
        grasp_contact_speed_m_per_s: pack-side pay-out speed that shows the arm unrolling; below it
            the cable counts as stalled.
        grasp_contact_slow_ratio: the cable also counts as stalled while its pay-out is below this
            fraction of the fastest pay-out of the present reach (in free space the pay-out only
            speeds up while the reach ramp runs; a body blocked by an object slows it down).
        grasp_contact_dwell_us: stall duration that means contact; also how long a cable must stay
            still for the packed arm to count as settled, the wrap-side slack as taken up, and the
            wrap as closed (HOLD).
        grasp_contact_grace_us: no contact is detected this soon after the reach starts.
        grasp_contact_min_tension_n: the estimated tension must hold at least this for contact.
        grasp_reach_timeout_us: FAILED when no contact within this time after the reach starts.
        grasp_release_dwell_us: time spent uncurled after a release before re-packing (IDLE).
        speed_filter_tau_us: low-pass time constant of the cable speed used for contact detection.
        event_queue_len: capacity of the preallocated event queue (oldest events dropped and counted).
    """

    control_period_us: int = 1_000
    link_period_us: int = 1_000
    detect_period_us: int = 10_000
    telemetry_period_us: int = 10_000
    status_period_us: int = 500_000
    poses_period_us: int = 20_000
    rc_timeout_us: int = 30_000
    motor_timeout_us: int = 10_000
    host_timeout_us: int = 500_000
    host_required: bool = False
    cable_angles_deg: tuple[float, float, float] = (0.0, 120.0, 240.0)
    motor_signs: tuple[int, int, int] = (1, 1, 1)
    spool_radius_m: float = 0.010
    torque_constant_nm_per_a: float = 0.18  # DJI M2006 P36 spec sheet (disputed: see module notes)
    gear_ratio: float = 36.0
    current_limit_a: float = 3.0
    pretension_n: float = 0.5
    common_max_n: float = 8.0
    bend_max_n: float = 8.0
    tension_max_n: float = 20.0
    slew_n_per_s: float = 50.0
    stick_deadband: int = 20
    grasp_strategy_on: bool = True
    grasp_direction_deg: float = 0.0
    grasp_pack_n: float = 18.0
    grasp_pack_rate_n_per_s: float = 12.0
    grasp_reach_n: float = 0.0
    grasp_reach_rate_n_per_s: float = 10.0
    grasp_wrap_n: float = 5.0
    grasp_wrap_rate_n_per_s: float = 8.0
    grasp_takeup_n: float = 1.5
    grasp_takeup_speed_m_per_s: float = 0.08
    grasp_release_rate_n_per_s: float = 8.0
    grasp_contact_speed_m_per_s: float = 0.004
    grasp_contact_slow_ratio: float = 0.7
    grasp_contact_dwell_us: int = 60_000
    grasp_contact_grace_us: int = 200_000
    grasp_contact_min_tension_n: float = 0.3
    grasp_reach_timeout_us: int = 4_000_000
    grasp_release_dwell_us: int = 500_000
    speed_filter_tau_us: int = 20_000
    event_queue_len: int = 64

    def __post_init__(self) -> None:
        self.validate()

    def validate(self) -> None:
        """Check every value and their relations.

        Raises:
            ConfigError: (a ``ValueError``) naming the first bad field and why.
        """
        for f in dataclasses.fields(self):
            _check_type(f.name, getattr(self, f.name))
        for name in ("control_period_us", "link_period_us", "detect_period_us", "telemetry_period_us"):
            _require(name, 100 <= getattr(self, name) <= 1_000_000, "must be 100..1000000 µs")
        for name in ("detect_period_us", "telemetry_period_us", "status_period_us", "poses_period_us"):
            _require(
                name,
                getattr(self, name) % self.control_period_us == 0,
                f"must be a whole number of control periods ({self.control_period_us} µs)",
            )
        _require("status_period_us", 1_000 <= self.status_period_us <= 10_000_000, "must be 1 ms..10 s")
        _require("poses_period_us", 1_000 <= self.poses_period_us <= 1_000_000, "must be 1 ms..1 s")
        _require(
            "rc_timeout_us",
            2 * self.control_period_us <= self.rc_timeout_us <= 1_000_000,
            "must be 2 ticks..1 s",
        )
        _require(
            "motor_timeout_us",
            2 * self.control_period_us <= self.motor_timeout_us <= 1_000_000,
            "must be 2 ticks..1 s",
        )
        _require("host_timeout_us", 10_000 <= self.host_timeout_us <= 60_000_000, "must be 10 ms..60 s")
        _require("cable_angles_deg", len(self.cable_angles_deg) == MOTOR_COUNT, f"needs {MOTOR_COUNT} angles")
        _require("motor_signs", len(self.motor_signs) == MOTOR_COUNT, f"needs {MOTOR_COUNT} signs")
        _require("motor_signs", all(s in (-1, 1) for s in self.motor_signs), "each must be +1 or -1")
        _require("spool_radius_m", 0.001 <= self.spool_radius_m <= 0.1, "must be 1..100 mm")
        _require("torque_constant_nm_per_a", 0.01 <= self.torque_constant_nm_per_a <= 5.0, "must be 0.01..5")
        _require("gear_ratio", 1.0 <= self.gear_ratio <= 1000.0, "must be 1..1000")
        _require("current_limit_a", 0.0 < self.current_limit_a <= _C610_MAX_A, "must be in (0, 10] A (C610)")
        _require("pretension_n", 0.0 <= self.pretension_n <= self.tension_max_n, "must be 0..tension_max_n")
        _require("tension_max_n", 0.0 < self.tension_max_n <= 1000.0, "must be in (0, 1000] N")
        for name in (
            "common_max_n",
            "bend_max_n",
            "grasp_pack_n",
            "grasp_reach_n",
            "grasp_wrap_n",
            "grasp_takeup_n",
        ):
            _require(name, 0.0 <= getattr(self, name) <= self.tension_max_n, "must be 0..tension_max_n")
        _require(
            "grasp_reach_n",
            self.grasp_reach_n < 0.5 * self.grasp_pack_n,
            "must be below half of grasp_pack_n",
        )
        for name in (
            "slew_n_per_s",
            "grasp_pack_rate_n_per_s",
            "grasp_reach_rate_n_per_s",
            "grasp_wrap_rate_n_per_s",
            "grasp_release_rate_n_per_s",
        ):
            _require(name, 0.0 < getattr(self, name) <= 100_000.0, "must be in (0, 100000] N/s")
        _require("stick_deadband", 0 <= self.stick_deadband < 660, "must be 0..659 counts")
        _require(
            "grasp_contact_speed_m_per_s", 0.0 < self.grasp_contact_speed_m_per_s <= 10.0, "must be (0, 10]"
        )
        _require(
            "grasp_takeup_speed_m_per_s", 0.0 < self.grasp_takeup_speed_m_per_s <= 10.0, "must be (0, 10]"
        )
        _require("grasp_contact_slow_ratio", 0.0 <= self.grasp_contact_slow_ratio < 1.0, "must be in [0, 1)")
        _require("grasp_contact_min_tension_n", self.grasp_contact_min_tension_n >= 0.0, "must be >= 0")
        for name in (
            "grasp_contact_dwell_us",
            "grasp_contact_grace_us",
            "grasp_reach_timeout_us",
            "grasp_release_dwell_us",
        ):
            _require(name, 0 <= getattr(self, name) <= 600_000_000, "must be 0..600 s")
        _require(
            "grasp_reach_timeout_us",
            self.grasp_reach_timeout_us > self.grasp_contact_grace_us,
            "must exceed grasp_contact_grace_us",
        )
        _require("speed_filter_tau_us", 0 <= self.speed_filter_tau_us <= 10_000_000, "must be 0..10 s")
        _require("event_queue_len", 1 <= self.event_queue_len <= 4096, "must be 1..4096")

    @property
    def current_limit_raw(self) -> int:
        """Current limit in C610 raw units (1000 per amp)."""
        return int(self.current_limit_a * 1000.0)

    @classmethod
    def from_dict(cls, values: Mapping[str, Any]) -> FirmwareConfig:
        """Build a validated configuration from a mapping (e.g. parsed TOML/JSON); missing keys default.

        Lists are accepted for tuple fields; an integral float is accepted for an int field.

        Raises:
            ConfigError: an unknown key, a value of the wrong type, or a value out of range.
        """
        known = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(values) - known)
        if unknown:
            raise ConfigError(f"unknown configuration key(s): {', '.join(unknown)}")
        return cls(**{k: _coerce(k, v) for k, v in values.items()})

    def to_dict(self) -> dict[str, Any]:
        """Every field by name (tuples as lists), the inverse of :meth:`from_dict`."""
        return {
            f.name: list(v) if isinstance(v := getattr(self, f.name), tuple) else v
            for f in dataclasses.fields(self)
        }

    def get_param(self, name: str) -> float:
        """The value of the runtime parameter ``name`` (a wire name in :data:`PARAMS`) as a float.

        Bools read as 0.0 / 1.0.

        Raises:
            ConfigError: ``name`` is not in :data:`PARAMS`.
        """
        field = PARAM_FIELDS.get(name)
        if field is None:
            raise ConfigError(f"unknown parameter {name!r}")
        return float(getattr(self, field))

    def with_param(self, name: str, value: float) -> FirmwareConfig:
        """A copy with the runtime parameter ``name`` (wire name) set to ``value``, validated.

        Raises:
            ConfigError: unknown parameter, a value of the wrong kind (non-integral for an int, not 0/1
                for a bool, not finite) or one that fails :meth:`validate`.
        """
        field = PARAM_FIELDS.get(name)
        if field is None:
            raise ConfigError(f"unknown parameter {name!r}")
        if not math.isfinite(value):
            raise ConfigError(f"{name}: value must be finite, got {value}")
        kind = type(_DEFAULTS[field])
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
        return dataclasses.replace(self, **{field: new})


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
}
"""Wire name (at most 16 ASCII characters, MAVLink ``param_id`` style) -> ``FirmwareConfig`` field."""

PARAMS: tuple[str, ...] = tuple(PARAM_FIELDS)
"""Wire names of the parameters readable and settable over the board link, in index order."""


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


_DEFAULTS: dict[str, Any] = {
    f.name: f.default for f in dataclasses.fields(FirmwareConfig) if f.default is not dataclasses.MISSING
}
