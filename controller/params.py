"""The parameter table: one row per firmware setting, and everything else reads the row.

Like Betaflight's settings table (``src/main/cli/settings.c``) and ArduPilot's ``AP_GROUPINFO``, a row
holds all there is to know about one setting: its flat name (``grasp_pack_n``, the key of a configuration
file), the field it fills (``grasp.pack_n`` in :class:`~controller.config.FirmwareConfig`), its type, unit,
default and bounds, and, for the settings a ``ParamSet`` may change at run time, its wire name
(``GRASP_PACK_N``) and board-link index, whether it changes only in SAFE, and a tighter run-time range
where a hardware figure applies. Validation (:meth:`FirmwareConfig.validate`), the host's parameter editor,
the MAVLink parameter types and ``docs/parameters.md`` (``python -m controller.params``) read the rows;
the rules that tie one field to another stay in ``FirmwareConfig.validate``.

Rows are in the flat order of a configuration file (recorded configurations keep their bytes); a run-time
parameter's ``index`` is its place in the board's parameter list (recordings keep their bytes).
"""

from __future__ import annotations

import enum
import math
import sys
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Final

from controller.errors import ConfigError
from protocol.c610 import CURRENT_RAW_MAX, M2006_GEAR_RATIO, RAW_PER_AMP

__all__ = [
    "C610_MAX_A",
    "FIELD_ROWS",
    "PARAMS",
    "PARAM_FIELDS",
    "PARAM_TABLE",
    "SAFETY_PARAMS",
    "WIRE_ROWS",
    "Kind",
    "Param",
    "Range",
    "default",
    "markdown",
]

C610_MAX_A: Final[float] = CURRENT_RAW_MAX / RAW_PER_AMP
"""The largest current a C610 takes (-10000..10000 raw = -10..10 A; DJI's C610 manual: 10 A max)."""


class Kind(enum.Enum):
    """What a setting holds (a tuple has one element per motor)."""

    BOOL = "bool"
    INT = "int"
    FLOAT = "float"
    INTS = "int tuple"
    FLOATS = "float tuple"


@dataclass(frozen=True, slots=True)
class Range:
    """Bounds of a value: each end a number, the flat name of another setting, or None (unbounded).

    Attributes:
        lo: lower end.
        hi: upper end.
        lo_open: the lower end itself is outside.
        hi_open: the upper end itself is outside.
        source: where the figure comes from (shown in brackets after the range, e.g. ``C610``).
    """

    lo: float | str | None = None
    hi: float | str | None = None
    lo_open: bool = False
    hi_open: bool = False
    source: str = ""

    def contains(self, value: float, values: Mapping[str, Any]) -> bool:
        """``value`` lies in the range; a named end is read from ``values`` (flat name -> value)."""
        lo = values[self.lo] if isinstance(self.lo, str) else self.lo
        hi = values[self.hi] if isinstance(self.hi, str) else self.hi
        if lo is not None and (value <= lo if self.lo_open else value < lo):
            return False
        return hi is None or (value < hi if self.hi_open else value <= hi)

    def text(self, unit: str) -> str:
        """The rule as an error message says it: ``must be 0..tension_max_n``, ``must be in (0, 10] A``."""
        lo, hi = (_end(end, unit) for end in (self.lo, self.hi))
        plain = unit and unit != "µs" and not isinstance(self.lo, str) and not isinstance(self.hi, str)
        tail = (f" {unit}" if plain else "") + (f" ({self.source})" if self.source else "")
        if lo and hi:
            if not (self.lo_open or self.hi_open):
                return f"must be {lo}..{hi}{tail}"
            left, right = "(" if self.lo_open else "[", ")" if self.hi_open else "]"
            return f"must be in {left}{lo}, {hi}{right}{tail}"
        if lo:
            return f"must be {'>' if self.lo_open else '>='} {lo}{tail}"
        if hi:
            return f"must be {'<' if self.hi_open else '<='} {hi}{tail}"
        return "any finite value"


def _end(end: float | str | None, unit: str) -> str:
    if end is None or isinstance(end, str):
        return end or ""
    if unit == "µs" and end:
        for scale, name in ((1_000_000, "s"), (1_000, "ms"), (1, "µs")):
            if end % scale == 0:
                return f"{_number(end / scale)} {name}"
    return _number(end)


def _number(x: float) -> str:
    """``100000``, ``0.004``, ``1e6``: whole numbers in full below a million, else ``:g`` without ``+0``."""
    if float(x).is_integer() and abs(x) < 1e6:
        return str(int(x))
    return f"{x:g}".replace("e+0", "e").replace("e+", "e")


@dataclass(frozen=True, slots=True)
class Param:
    """One firmware setting: everything the firmware, the host and the docs know about it.

    Attributes:
        name: flat name, the key in a configuration file (``grasp_pack_n``).
        field: the :class:`~controller.config.FirmwareConfig` field it fills, dotted (``grasp.pack_n``).
        kind: what it holds.
        unit: unit text ("" when dimensionless).
        default: the default value (the dataclasses read it from here).
        bounds: the range any value must lie in (None: any finite value); rules between fields are in
            :meth:`FirmwareConfig.validate`.
        doc: one line on what it does (the dataclass docstrings give the reasons behind the defaults).
        wire: board-link / MAVLink name (at most 16 ASCII characters), or None: set at start-up only.
        index: its place in the board's parameter list (``ParamValue.index``), with ``wire``.
        safety: a ``ParamSet`` changes it only in SAFE (zero current): it decides how much current a
            tension takes, how fast a cable may reel in, or when the failsafe acts.
        runtime: a tighter range a ``ParamSet`` must also meet (a hardware figure), or None.
    """

    name: str
    field: str
    kind: Kind
    unit: str
    default: Any
    bounds: Range | None
    doc: str
    wire: str | None = None
    index: int | None = None
    safety: bool = False
    runtime: Range | None = None

    def bounds_text(self) -> str:
        """The static range as an error message says it (``0 or 1`` for a bool)."""
        if self.kind is Kind.BOOL:
            return "0 or 1"
        if self.kind in (Kind.INTS, Kind.FLOATS):
            return "one value per motor"
        return (self.bounds or Range()).text(self.unit)

    def check_type(self, value: object) -> None:
        """Raise :class:`ConfigError` unless ``value`` is of this setting's kind (finite numbers only).

        Raises:
            ConfigError: ``name: expected <type> like <default>, got <value>``.
        """
        kind = self.kind
        if kind is Kind.BOOL:
            ok = isinstance(value, bool)
        elif kind is Kind.INT:
            ok = _is_int(value)
        elif kind is Kind.FLOAT:
            ok = _is_number(value) and math.isfinite(value)  # type: ignore[arg-type]
        else:
            elem = _is_int if kind is Kind.INTS else _is_number
            ok = isinstance(value, tuple) and all(elem(v) for v in value)
        if not ok:
            raise ConfigError(
                f"{self.name}: expected {type(self.default).__name__} like {self.default!r}, got {value!r}"
            )

    def check_bounds(self, values: Mapping[str, Any]) -> None:
        """Raise :class:`ConfigError` unless this setting's value in ``values`` (flat names) is in bounds.

        Raises:
            ConfigError: ``name: must be ...``.
        """
        bounds = self.bounds
        if bounds is not None and not bounds.contains(values[self.name], values):
            raise ConfigError(f"{self.name}: {bounds.text(self.unit)}")

    def coerce(self, value: Any) -> Any:
        """A value read from a file (JSON, TOML) as this kind: lists as tuples, 30000.0 as an int, 1 as 1.0.

        Anything that does not convert is returned as it is, for :meth:`check_type` to refuse.
        """
        if isinstance(value, list):
            value = tuple(value)
        kind = self.kind
        if kind is Kind.INT and isinstance(value, float) and value.is_integer():
            return int(value)
        if kind is Kind.FLOAT and _is_int(value):
            return float(value)
        if kind is Kind.FLOATS and isinstance(value, tuple):
            return tuple(float(v) if _is_int(v) else v for v in value)
        return value

    def from_wire(self, value: float) -> bool | int | float:
        """A board-link / MAVLink value (a float) as this kind.

        Raises:
            ConfigError: not finite, not 0 or 1 for a bool, not integral for an int (named by wire name).
        """
        name = self.wire or self.name
        if not math.isfinite(value):
            raise ConfigError(f"{name}: value must be finite, got {value}")
        if self.kind is Kind.BOOL:
            if value not in (0.0, 1.0):
                raise ConfigError(f"{name}: must be 0 or 1, got {value}")
            return bool(value)
        if self.kind is Kind.INT:
            if value != int(value):
                raise ConfigError(f"{name}: must be an integer, got {value}")
            return int(value)
        return float(value)


def _is_int(value: object) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def _is_number(value: object) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool)


_US = "µs"
_TENSION = Range(0.0, "tension_max_n")
_RATE = Range(0.0, 100_000.0, lo_open=True)
_SPEED = Range(0.0, 10.0, lo_open=True)
_GAIN = Range(0.0, 1e6)
_DURATION = Range(0, 600_000_000)
_PERIOD = Range(100, 1_000_000)
_TIMEOUT = Range(0, 1_000_000, lo_open=True)  # and at least two control periods (FirmwareConfig.validate)
_B, _I, _F = Kind.BOOL, Kind.INT, Kind.FLOAT

# fmt: off
PARAM_TABLE: Final[tuple[Param, ...]] = (
    # name, field, kind, unit, default, bounds, doc; wire name and index for the run-time parameters.
    Param("control_period_us", "control_period_us", _I, _US, 1_000, _PERIOD,
          "control task period (1 kHz, the C-board's chassis/gimbal loop rate)"),
    Param("link_period_us", "link_period_us", _I, _US, 1_000, _PERIOD,
          "board-link receive task period (an E-stop acts on the next tick)"),
    Param("detect_period_us", "detect_period_us", _I, _US, 10_000, _PERIOD,
          "liveness reporting task period (DJI's detect task); whole control periods"),
    Param("telemetry_period_us", "telemetry_period_us", _I, _US, 10_000, _PERIOD,
          "Telemetry + MotorFrames period; whole control periods"),
    Param("status_period_us", "status_period_us", _I, _US, 500_000, Range(1_000, 10_000_000),
          "BoardStatus period; whole control periods"),
    Param("poses_period_us", "poses_period_us", _I, _US, 20_000, Range(1_000, 1_000_000),
          "SimPoses period (only when the bus provides poses); whole control periods"),
    Param("rc_timeout_us", "failsafe.rc_timeout_us", _I, _US, 30_000, _TIMEOUT,
          "RC lost after this long without a valid frame (DJI: 30 ms); at least 2 control periods"),
    Param("motor_timeout_us", "failsafe.motor_timeout_us", _I, _US, 10_000, _TIMEOUT,
          "a motor is offline after this long without feedback (DJI: 10 ms); at least 2 control periods"),
    Param("host_timeout_us", "failsafe.host_timeout_us", _I, _US, 500_000, Range(10_000, 60_000_000),
          "host lost after this long without a Heartbeat (when a host is required)",
          wire="HOST_TIMEOUT_US", index=0, safety=True),
    Param("host_required", "failsafe.host_required", _B, "", False, None,
          "the host heartbeat is required (also set by the REQUIRE_HOST command)",
          wire="HOST_REQUIRED", index=1, safety=True),
    Param("cable_angles_deg", "mapping.cable_angles_deg", Kind.FLOATS, "°", (0.0, 120.0, 240.0), None,
          "angular position of each cable around an arm (1-3 cables; every arm of an array alike)"),
    Param("motor_signs", "motor.motor_signs", Kind.INTS, "", (1, 1, 1), None,
          "+1 if a positive current reels its cable in, -1 if mounted mirrored; one per motor (1-8)"),
    Param("spool_radius_m", "motor.spool_radius_m", _F, "m", 0.010, Range(0.001, 0.1),
          "cable spool radius",
          wire="SPOOL_RADIUS_M", index=2, safety=True),
    # 0.18 N·m/A: DJI's M2006 P36 spec sheet; "1 N·m rated at 3 A" implies 0.33 (controller.config notes).
    Param("torque_constant_nm_per_a", "motor.torque_constant_nm_per_a", _F, "N·m/A", 0.18, Range(0.01, 5.0),
          "M2006 P36 torque per amp at the output shaft (DJI spec sheet; disputed)",
          wire="TORQUE_K_NM_A", index=3, safety=True, runtime=Range(0.1, 0.5, source="M2006 P36")),
    Param("gear_ratio", "motor.gear_ratio", _F, "", float(M2006_GEAR_RATIO), Range(1.0, 1000.0),
          "rotor turns per output turn (M2006 P36: 36)"),
    Param("current_limit_a", "motor.current_limit_a", _F, "A", 3.0,
          Range(0.0, C610_MAX_A, lo_open=True, source="C610"),
          "|current| never commanded above this (M2006: 3 A continuous)",
          wire="CURRENT_LIMIT_A", index=4, safety=True),
    Param("pretension_n", "mapping.pretension_n", _F, "N", 0.5, _TENSION,
          "tension floor of every active cable (pull-only)",
          wire="PRETENSION_N", index=5),
    Param("common_max_n", "mapping.common_max_n", _F, "N", 8.0, _TENSION,
          "common (curl) tension at full left stick up",
          wire="COMMON_MAX_N", index=6),
    Param("bend_max_n", "mapping.bend_max_n", _F, "N", 8.0, _TENSION,
          "bending tension at full right stick deflection",
          wire="BEND_MAX_N", index=7),
    Param("tension_max_n", "mapping.tension_max_n", _F, "N", 20.0, Range(0.0, 1000.0, lo_open=True),
          "per-cable tension ceiling",
          wire="TENSION_MAX_N", index=8, safety=True),
    Param("slew_n_per_s", "mapping.slew_n_per_s", _F, "N/s", 50.0, _RATE,
          "largest change of a cable's target tension per second",
          wire="SLEW_N_S", index=9),
    Param("stick_deadband", "mapping.stick_deadband", _I, "counts", 20, Range(0, 659),
          "stick counts (of ±660) treated as centred",
          wire="STICK_DEADBAND", index=10),
    Param("grasp_strategy_on", "grasp.strategy_on", _B, "", True, None,
          "the SpiRobs strategy (pack, reach, contact, wrap); off: a plain tension ramp from straight",
          wire="GRASP_STRATEGY", index=11),
    Param("grasp_direction_deg", "grasp.direction_deg", _F, "°", 0.0, None,
          "grasp direction when neither the right stick nor the host gives one",
          wire="GRASP_DIR_DEG", index=12),
    Param("grasp_pack_n", "grasp.pack_n", _F, "N", 18.0, _TENSION,
          "curl tension of the packed (coiled) pose the grasp starts from",
          wire="GRASP_PACK_N", index=13),
    Param("grasp_pack_rate_n_per_s", "grasp.pack_rate_n_per_s", _F, "N/s", 12.0, _RATE,
          "rate at which IDLE winds the pack tension up",
          wire="GRASP_PACK_N_S", index=26),
    Param("grasp_reach_n", "grasp.reach_n", _F, "N", 0.0, _TENSION,
          "curl tension the reach ramps down to (arm unrolled); below half of grasp_pack_n",
          wire="GRASP_REACH_N", index=14),
    Param("grasp_reach_rate_n_per_s", "grasp.reach_rate_n_per_s", _F, "N/s", 10.0, _RATE,
          "reach ramp-down rate",
          wire="GRASP_REACH_N_S", index=15),
    Param("grasp_wrap_n", "grasp.wrap_n", _F, "N", 15.0, _TENSION,
          "tension of the wrap and hold phases",
          wire="GRASP_WRAP_N", index=16),
    Param("grasp_wrap_rate_n_per_s", "grasp.wrap_rate_n_per_s", _F, "N/s", 8.0, _RATE,
          "wrap ramp-up rate",
          wire="GRASP_WRAP_N_S", index=17),
    Param("grasp_takeup_n", "grasp.takeup_n", _F, "N", 1.5, _TENSION,
          "curl tension that reels in the wrap-side slack before the wrap (0 = no take-up)",
          wire="GRASP_TAKEUP_N", index=28),
    Param("grasp_takeup_speed_m_per_s", "grasp.takeup_speed_m_per_s", _F, "m/s", 0.08, _SPEED,
          "the take-up tension is cut while the slack reels in faster than this",
          wire="GRASP_TAKEUP_M_S", index=29),
    Param("grasp_release_rate_n_per_s", "grasp.release_rate_n_per_s", _F, "N/s", 8.0, _RATE,
          "release ramp-down rate",
          wire="GRASP_REL_N_S", index=18),
    Param("grasp_contact_speed_m_per_s", "grasp.contact_speed_m_per_s", _F, "m/s", 0.004, _SPEED,
          "pack-side pay-out speed below which the cable counts as stalled",
          wire="GRASP_STALL_M_S", index=19),
    Param("grasp_contact_slow_ratio", "grasp.contact_slow_ratio", _F, "", 0.7, Range(0.0, 1.0, hi_open=True),
          "also stalled below this fraction of the reach's fastest pay-out",
          wire="GRASP_SLOW_RATIO", index=27),
    Param("grasp_contact_dwell_us", "grasp.contact_dwell_us", _I, _US, 60_000, _DURATION,
          "stall duration that means contact (also settled, taken up, closed)",
          wire="GRASP_DWELL_US", index=20),
    Param("grasp_contact_grace_us", "grasp.contact_grace_us", _I, _US, 200_000, _DURATION,
          "no contact is detected this soon after the reach starts",
          wire="GRASP_GRACE_US", index=21),
    Param("grasp_contact_min_tension_n", "grasp.contact_min_tension_n", _F, "N", 0.3, Range(0.0),
          "the estimated tension must hold at least this for contact",
          wire="GRASP_MIN_T_N", index=22),
    # 1 m/s²: the free prototype arm slows at up to 0.66 m/s² after the reach ramp.
    Param("grasp_contact_decel_m_per_s2", "grasp.contact_decel_m_per_s2", _F, "m/s²", 1.0, Range(0.0, 1e4),
          "contact when the pack-side pay-out decelerates faster than this (0 = rule off)",
          wire="GRASP_DECEL_M_S2", index=39),
    Param("grasp_contact_decel_tau_us", "grasp.contact_decel_tau_us", _I, _US, 10_000, Range(0, 1_000_000),
          "low-pass time constant of that deceleration",
          wire="GRASP_DECEL_TAU", index=40),
    Param("grasp_contact_wrap_m_per_s", "grasp.contact_wrap_m_per_s", _F, "m/s", 0.0, Range(0.0, 10.0),
          "contact when the wrap side pays out faster than this while the pack side slowed (0 = off)",
          wire="GRASP_WRAP_M_S", index=41),
    Param("grasp_contact_rest_m", "grasp.contact_rest_m", _F, "m", 0.06, Range(0.0, 10.0),
          "contact when the pack side rests having paid out less than this since the reach (0 = off)",
          wire="GRASP_REST_M", index=43),
    Param("grasp_reach_timeout_us", "grasp.reach_timeout_us", _I, _US, 4_000_000, _DURATION,
          "FAILED when no contact this long after the reach starts; above grasp_contact_grace_us",
          wire="GRASP_TIMEOUT_US", index=23),
    Param("grasp_release_dwell_us", "grasp.release_dwell_us", _I, _US, 500_000, _DURATION,
          "time spent uncurled after a release before re-packing (IDLE)",
          wire="GRASP_REL_DW_US", index=24),
    Param("grasp_hold_length", "grasp.hold_length", _B, "", False, None,
          "HOLD freezes the pulling cables' length instead of their tension",
          wire="GRASP_HOLD_LEN", index=30),
    # Off by default: every documented grasp figure was measured without them (docs/grasping.md).
    Param("grasp_hold_min_payin_m", "grasp.hold_min_payin_m", _F, "m", 0.0, Range(0.0, 10.0),
          "HOLD needs the wrap side to have paid in this since the wrap began, else FAILED (0 = off)",
          wire="GRASP_HOLD_MIN_M", index=44),
    Param("grasp_hold_max_payin_m", "grasp.hold_max_payin_m", _F, "m", 0.0, Range(0.0, 10.0),
          "FAILED instead of HOLD past this pay-in since the wrap began: an empty curl (0 = off)",
          wire="GRASP_HOLD_MAX_M", index=45),
    Param("speed_filter_tau_us", "motor.speed_filter_tau_us", _I, _US, 20_000, Range(0, 10_000_000),
          "low-pass time constant of the cable speed used for contact detection",
          wire="SPEED_TAU_US", index=25),
    Param("payin_limit_m_per_s", "motor.payin_limit_m_per_s", _F, "m/s", 0.1, _SPEED,
          "tension cut back toward the pretension while a cable reels in faster than this",
          wire="PAYIN_MAX_M_S", index=42, safety=True),
    Param("event_queue_len", "event_queue_len", _I, "events", 64, Range(1, 4096),
          "capacity of the preallocated event queue (oldest events dropped and counted)"),
    Param("hold_pos_kp_per_s", "hold.pos_kp_per_s", _F, "1/s", 20.0, _GAIN,
          "length-hold: length error -> speed set-point gain",
          wire="HOLD_POS_KP", index=31),
    Param("hold_pos_ki_per_s2", "hold.pos_ki_per_s2", _F, "1/s²", 0.0, _GAIN,
          "length-hold: its integral gain (0 = none)",
          wire="HOLD_POS_KI", index=32),
    Param("hold_pos_kd", "hold.pos_kd", _F, "", 0.0, _GAIN,
          "length-hold: its derivative gain",
          wire="HOLD_POS_KD", index=33),
    Param("hold_pos_max_m_per_s", "hold.pos_max_m_per_s", _F, "m/s", 0.2, Range(0.0, 10.0),
          "length-hold: speed set-point limit",
          wire="HOLD_POS_MAX_M_S", index=34),
    Param("hold_pos_imax_m_per_s", "hold.pos_imax_m_per_s", _F, "m/s", 0.05, Range(0.0, 10.0),
          "length-hold: the position loop's integral-term limit",
          wire="HOLD_POS_IMAX", index=35),
    Param("hold_speed_kp_n_s_per_m", "hold.speed_kp_n_s_per_m", _F, "N·s/m", 150.0, _GAIN,
          "length-hold: speed error -> tension gain",
          wire="HOLD_SPD_KP", index=36),
    Param("hold_speed_ki_n_per_m", "hold.speed_ki_n_per_m", _F, "N/m", 1500.0, _GAIN,
          "length-hold: its integral gain",
          wire="HOLD_SPD_KI", index=37),
    Param("hold_speed_imax_n", "hold.speed_imax_n", _F, "N", 20.0, Range(0.0, 1000.0),
          "length-hold: the speed loop's integral-term limit",
          wire="HOLD_SPD_IMAX_N", index=38),
)
"""Every :class:`~controller.config.FirmwareConfig` setting, in the flat order of a configuration file."""
# fmt: on

FIELD_ROWS: Final[Mapping[str, Param]] = {p.name: p for p in PARAM_TABLE}
"""Flat name -> row."""

_BY_PATH: Final[Mapping[str, Param]] = {p.field: p for p in PARAM_TABLE}

WIRE_ROWS: Final[Mapping[str, Param]] = {
    p.wire: p for p in sorted(PARAM_TABLE, key=lambda p: -1 if p.index is None else p.index) if p.wire
}
"""Wire name -> row, for the parameters a ``ParamSet`` may change, in board-link index order."""

PARAMS: Final[tuple[str, ...]] = tuple(WIRE_ROWS)
"""Wire names of the parameters readable and settable over the board link, in index order."""

PARAM_FIELDS: Final[Mapping[str, str]] = {wire: p.name for wire, p in WIRE_ROWS.items()}
"""Wire name -> flat name."""

SAFETY_PARAMS: Final[frozenset[str]] = frozenset(w for w, p in WIRE_ROWS.items() if p.safety)
"""Wire names of the parameters a ``ParamSet`` (or the ``REQUIRE_HOST`` command) changes only in SAFE."""


def default(field: str) -> Any:
    """The default of the ``FirmwareConfig`` field ``field`` (dotted: ``grasp.pack_n``), from its row.

    Raises:
        KeyError: no such field in the table.
    """
    return _BY_PATH[field].default


def _cell(value: Any) -> str:
    if isinstance(value, bool):
        return str(int(value))
    if isinstance(value, tuple):
        return ", ".join(_cell(v) for v in value)
    return _number(value)


def _range_cell(p: Param) -> str:
    text = p.bounds_text().removeprefix("must be ").removeprefix("in ")
    if p.runtime is not None:
        text += "; at run time " + p.runtime.text(p.unit).removeprefix("must be ").removeprefix("in ")
    return _escape(text)


def _escape(text: str) -> str:
    return text.replace("|", "\\|")


def markdown() -> str:
    """``docs/parameters.md``: the table as Markdown (a test keeps the file equal to this)."""
    lines = [
        "# Parameters",
        "",
        "<!-- Generated from controller/params.py by `python -m controller.params > docs/parameters.md`;",
        "     tests/test_docs.py fails when this file and the table differ. -->",
        "",
        "Every firmware setting is one row of the table in `controller/params.py` (`PARAM_TABLE`): its name",
        "in a configuration file (`spirob-firmware --config FILE`, `FirmwareConfig.from_dict`), type, unit,",
        "default and range. `FirmwareConfig` validates against the rows; the host's parameter editor, the",
        "MAVLink parameter types (`bool` UINT8, `int` INT32, `float` REAL32) and this page read them.",
        "Rules between settings (a reach tension below half the pack tension, whole control periods...)",
        "are in `FirmwareConfig.validate` and named in the descriptions.",
        "",
        "## Run-time parameters",
        "",
        "Read and set over the board link (`ParamRequest` / `ParamSet`, [board-link.md](board-link.md))",
        "and MAVLink's parameter protocol ([mavlink.md](mavlink.md)), by wire name, in index order. The",
        "board validates every set and answers with the value it took. **SAFE only**: changed only in SAFE",
        "(zero current); set while the arm may move, it is refused with `safety parameter: only in SAFE`.",
        "A range *at run time* is a hardware figure a `ParamSet` must also meet; `PAYIN_MAX_M_S` must",
        "also stay at or below the M2006's no-load cable speed on the spool.",
        "",
        "| index | name | field | type | unit | default | range | SAFE only | meaning |",
        "| --- | --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    for wire, p in WIRE_ROWS.items():
        safe = "yes" if p.safety else ""
        lines.append(
            f"| {p.index} | `{wire}` | `{p.name}` | {p.kind.value} | {p.unit} | {_cell(p.default)} "
            f"| {_range_cell(p)} | {safe} | {_escape(p.doc)} |"
        )
    lines += [
        "",
        "## Start-up settings",
        "",
        "Taken only at start-up, from the configuration: task periods, timeouts other than the host's,",
        "the cable geometry and the motors' mounting are facts the firmware is built around.",
        "",
        "| name | type | unit | default | range | meaning |",
        "| --- | --- | --- | --- | --- | --- |",
    ]
    for p in PARAM_TABLE:
        if p.wire is None:
            lines.append(
                f"| `{p.name}` | {p.kind.value} | {p.unit} | {_cell(p.default)} | {_range_cell(p)} "
                f"| {_escape(p.doc)} |"
            )
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    sys.stdout.write(markdown())
