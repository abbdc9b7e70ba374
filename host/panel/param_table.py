"""The board's parameters as the panel edits them: units, bounds, a host-side check, and the read-back.

Names, types and bounds come from the firmware's own table (``controller.config``): the host checks a
value with the same ``FirmwareConfig.with_param`` the board runs, so what the panel refuses the board
would refuse too, and the text is the same.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

from controller.config import PARAM_FIELDS, FirmwareConfig
from controller.errors import ConfigError

__all__ = [
    "PARAM_CONFIRM_S",
    "PARAM_NAMES",
    "ParamInfo",
    "ParamStatus",
    "param_check",
    "param_info",
]

PARAM_NAMES: tuple[str, ...] = tuple(PARAM_FIELDS)
"""Parameter wire names in the board's index order (a ``PARAM`` event's code is the index)."""

PARAM_CONFIRM_S = 2.0
"""A parameter set the board has not answered by then is shown as unanswered."""

_UNITS = (
    # Longest suffix first: "_m_per_s2" before "_m_per_s" before "_m".
    ("_n_s_per_m", "N·s/m"),
    ("_nm_per_a", "N·m/A"),
    ("_m_per_s2", "m/s²"),
    ("_n_per_s", "N/s"),
    ("_n_per_m", "N/m"),
    ("_m_per_s", "m/s"),
    ("_per_s2", "1/s²"),
    ("_per_s", "1/s"),
    ("_deg", "°"),
    ("_us", "µs"),
    ("_n", "N"),
    ("_m", "m"),
    ("_a", "A"),
    ("_deadband", "counts"),
)


@dataclass(frozen=True, slots=True)
class ParamInfo:
    """What the editor shows about one parameter.

    Attributes:
        name: wire name.
        field: the firmware config field it sets.
        unit: unit text ("" when dimensionless).
        kind: ``float``, ``int`` or ``bool`` (0 / 1).
        default: the firmware default.
        bounds: the firmware's range rule, e.g. ``must be 0..tension_max_n``.
    """

    name: str
    field: str
    unit: str
    kind: str
    default: float
    bounds: str


def _unit(field: str, kind: str) -> str:
    if kind == "bool":
        return "0/1"
    return next((u for suffix, u in _UNITS if field.endswith(suffix)), "")


def _bounds(cfg: FirmwareConfig, name: str, field: str, kind: str) -> str:
    """The firmware's own range text: what it says about a value far outside any range.

    Only its rule for this field (a value can break another field's rule first, e.g. a huge
    ``TENSION_MAX_N`` is fine but a negative one makes ``pretension_n`` complain).
    """
    if kind == "bool":
        return "0 or 1"
    texts = []
    for probe in (-1e12, 1e12):
        try:
            cfg.with_param(name, probe)
        except ConfigError as exc:
            prefix, _, text = str(exc).partition(": ")
            if prefix == field and text not in texts:
                texts.append(text)
    return "; ".join(texts) or "any finite value"


@functools.cache
def param_info(name: str) -> ParamInfo:
    """Units, kind, default and bounds of parameter ``name`` (computed once).

    Raises:
        KeyError: not a parameter of the board.
    """
    field = PARAM_FIELDS[name]
    cfg = FirmwareConfig()
    default = cfg.get_param(name)
    raw = cfg.to_dict()[field]
    kind = "bool" if isinstance(raw, bool) else "int" if isinstance(raw, int) else "float"
    return ParamInfo(name, field, _unit(field, kind), kind, default, _bounds(cfg, name, field, kind))


def param_check(values: dict[str, float], name: str, value: float) -> str | None:
    """Check a value against the firmware's bounds before it is sent.

    ``values`` are the board's values read so far (over the firmware defaults), so bounds that depend
    on another parameter (``PRETENSION_N`` <= ``TENSION_MAX_N``) use the board's.

    Returns:
        None if the board would take it, else the reason (``ConfigError`` text).
    """
    changes: dict[str, float | int | bool] = {}
    for other, v in values.items():
        if other in PARAM_FIELDS and other != name:
            kind = param_info(other).kind
            changes[PARAM_FIELDS[other]] = bool(v) if kind == "bool" else int(v) if kind == "int" else v
    try:
        # All at once: the board's values only fit together (a lower TENSION_MAX_N with lower targets).
        cfg = FirmwareConfig().replaced(**changes)
    except (ConfigError, ValueError, OverflowError):
        cfg = FirmwareConfig()  # an incomplete read that does not fit the defaults: their bounds
    try:
        cfg.with_param(name, value)
    except ConfigError as exc:
        return str(exc)
    return None


@dataclass(frozen=True, slots=True)
class ParamStatus:
    """The fate of the last value a tab asked the board to take for one parameter.

    Attributes:
        requested: the value sent.
        sent_s: host time (monotonic, s) it was sent.
        confirmed: the value the board read back (None until it answered).
        note: the board's reason when it kept another value (its ``PARAM`` event), or "".
    """

    requested: float
    sent_s: float
    confirmed: float | None = None
    note: str = ""

    @property
    def accepted(self) -> bool:
        """The board read back the value asked for (float32 on the wire: compared to 6 digits)."""
        c = self.confirmed
        return c is not None and math.isclose(c, self.requested, rel_tol=1e-6, abs_tol=1e-9)
