"""The board's parameters as the panel edits them: metadata, a host-side check, and the read-back.

Everything about a parameter (unit, kind, default, bounds, description, whether it changes only in SAFE)
is read from the firmware's parameter table (``controller.params``). A value is checked with the rule the
board applies to every ``ParamSet`` (``FirmwareConfig.with_param``) against the board's other values, so
what the panel refuses the board would refuse too, in the same words.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

from controller.config import FirmwareConfig
from controller.errors import ConfigError
from controller.params import PARAMS, WIRE_ROWS

__all__ = [
    "PARAM_CONFIRM_S",
    "PARAM_NAMES",
    "ParamInfo",
    "ParamStatus",
    "param_check",
    "param_info",
]

PARAM_NAMES: tuple[str, ...] = PARAMS
"""Parameter wire names in the board's index order (a ``PARAM`` event's code is the index)."""

PARAM_CONFIRM_S = 2.0
"""A parameter set the board has not answered by then is shown as unanswered."""


@dataclass(frozen=True, slots=True)
class ParamInfo:
    """What the editor shows about one parameter (its row of the firmware's table).

    Attributes:
        name: wire name.
        field: the flat name of the firmware config field it sets.
        unit: unit text ("" when dimensionless).
        kind: ``float``, ``int`` or ``bool`` (0 / 1).
        default: the firmware default.
        bounds: the range a set must meet, as the firmware words it (e.g. ``must be 0..tension_max_n``;
            the run-time range where a hardware figure applies).
        doc: one line on what it does.
        safety: the board changes it only in SAFE.
    """

    name: str
    field: str
    unit: str
    kind: str
    default: float
    bounds: str
    doc: str
    safety: bool


@functools.cache
def param_info(name: str) -> ParamInfo:
    """Unit, kind, default, bounds, description and SAFE-only flag of parameter ``name``.

    Raises:
        KeyError: not a parameter of the board.
    """
    row = WIRE_ROWS[name]
    bounds = row.bounds_text() if row.runtime is None else row.runtime.text(row.unit)
    return ParamInfo(
        name, row.name, row.unit, row.kind.value, float(row.default), bounds, row.doc, row.safety
    )


def param_check(values: dict[str, float], name: str, value: float) -> str | None:
    """Check a value with the board's own rule before it is sent.

    ``values`` are the board's values read so far (over the firmware defaults), so bounds that depend
    on another parameter (``PRETENSION_N`` <= ``TENSION_MAX_N``) use the board's. Whether the arm is in
    SAFE is the board's to judge (it refuses a safety parameter otherwise, and says so).

    Returns:
        None if the board would take it, else the reason (``ConfigError`` text).
    """
    others = {n: v for n, v in values.items() if n != name}
    try:
        # All at once: the board's values only fit together (a lower TENSION_MAX_N with lower targets).
        cfg = FirmwareConfig().with_board_values(others)
    except ConfigError:
        cfg = FirmwareConfig()  # an incomplete read that does not fit the defaults: their bounds
    try:
        cfg.with_param(name, value, safe=True)
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
