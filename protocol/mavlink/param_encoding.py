"""``PARAM_VALUE`` / ``PARAM_SET`` value encoding: the float field carrying typed parameters.

MAVLink's parameter protocol sends every value in a float field. A component advertises how an
integer parameter is put there (``AUTOPILOT_VERSION.capabilities``):

- bytewise (``MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE``, PX4 and the protocol's default): the
  integer's little-endian bytes are the float's bytes (a UINT8 in the first byte, the rest zero);
- C cast (``MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_C_CAST``, ArduPilot): the float is the integer's value.

Ground stations pick the decoding per system from its autopilot (MAVProxy decodes bytewise only for a
PX4 system), so the link encodes the way the drone's own autopilot does.
"""

from __future__ import annotations

import math
import struct
from typing import Final

from protocol.mavlink.dialect import ParamType

__all__ = ["decode_param_value", "encode_param_value", "param_type_range"]

_BYTEWISE: Final[dict[ParamType, str]] = {
    ParamType.UINT8: "<B3x",
    ParamType.INT8: "<b3x",
    ParamType.UINT16: "<H2x",
    ParamType.INT16: "<h2x",
    ParamType.UINT32: "<I",
    ParamType.INT32: "<i",
}
_FLOAT: Final = struct.Struct("<f")


def param_type_range(param_type: ParamType) -> tuple[int, int] | None:
    """The value range of an integer parameter type (None for the float types and 64-bit ones).

    Args:
        param_type: ``MAV_PARAM_TYPE``.

    Returns:
        ``(lowest, highest)`` or None.
    """
    fmt = _BYTEWISE.get(param_type)
    if fmt is None:
        return None
    bits = struct.calcsize(fmt[:2]) * 8
    if fmt[1].isupper():
        return 0, (1 << bits) - 1
    return -(1 << (bits - 1)), (1 << (bits - 1)) - 1


def encode_param_value(value: float, param_type: ParamType, *, bytewise: bool) -> float:
    """The float to put in ``param_value`` for a parameter's value.

    Args:
        value: The value (integral for the integer types; clamped into the type's range).
        param_type: The parameter's type.
        bytewise: Bytewise encoding, else C cast.

    Returns:
        The wire float (for bytewise encoding, possibly a denormal or NaN with that bit pattern).
    """
    fmt = _BYTEWISE.get(param_type)
    if fmt is None or not bytewise:
        return float(value)
    lo_hi = param_type_range(param_type)
    assert lo_hi is not None
    n = min(max(round(value), lo_hi[0]), lo_hi[1]) if math.isfinite(value) else 0
    return float(_FLOAT.unpack(struct.pack(fmt, n))[0])


def decode_param_value(wire: float, param_type: int, *, bytewise: bool) -> float:
    """The value a received ``param_value`` stands for.

    Args:
        wire: The float field as received.
        param_type: The ``param_type`` field as received (``REAL32`` from a sender that casts).
        bytewise: Bytewise encoding in force, else C cast.

    Returns:
        The value (NaN for a value the bytes cannot stand for).
    """
    try:
        ptype = ParamType(param_type)
    except ValueError:
        return math.nan
    fmt = _BYTEWISE.get(ptype)
    if fmt is None or not bytewise:
        return float(wire)
    try:
        raw = _FLOAT.pack(wire)
    except (OverflowError, struct.error):
        return math.nan
    return float(struct.unpack(fmt, raw)[0])
