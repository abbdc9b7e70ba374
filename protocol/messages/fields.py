"""Field sizes and limits of the board-link messages and the field codecs the message modules share.

The underscored helpers are the message modules' own (``protocol.messages`` does not re-export them);
:func:`truncate_utf8` is public.
"""

from __future__ import annotations

import struct
from enum import IntEnum
from typing import TypeVar

from protocol.errors import DecodeError

Vec3i = tuple[int, int, int]
Vec4i = tuple[int, int, int, int]
Vec3f = tuple[float, float, float]
Vec4f = tuple[float, float, float, float]

NAME_LEN = 16
"""Parameter names: ASCII, at most 16 bytes, NUL-padded on the wire (like MAVLink param ids)."""
EVENT_TEXT_MAX = 64
"""UTF-8 bytes of an ``Event`` text."""
ACK_TEXT_MAX = 48
"""UTF-8 bytes of a ``CommandAck`` text."""
VERSION_LEN = 16
"""ASCII bytes of the firmware version in ``BoardStatus``."""
TASK_NAME_LEN = 12
"""ASCII bytes of a task name in ``BoardStatus``."""
MAX_TASKS = 32
"""Most task entries in one ``BoardStatus``."""
MAX_SIM_BODIES = 64
"""Most bodies in one ``SimPoses`` (drone + 63 units: 1801 bytes of payload)."""
HOST_TO_BOARD_MAX_PAYLOAD = 20
"""Largest host -> board payload (``ParamSet``). The board's parser caps each id at its own length
(``HOST_TO_BOARD_LENGTHS``), so a corrupted or hostile length stalls its input by at most one such frame."""
PARAM_INDEX_BY_NAME = -1
"""``ParamRequest.index``: look the parameter up by ``name``."""
PARAM_LIST_ALL = -2
"""``ParamRequest.index``: send every parameter (one ``ParamValue`` each)."""


# --- helpers --------------------------------------------------------------------------------------

_E = TypeVar("_E", bound=IntEnum)


def _enum(enum_cls: type[_E], value: int, field: str) -> _E:
    # The value-to-member map directly: a dict lookup instead of EnumType.__call__, about ten times
    # cheaper (every Telemetry frame decodes three of these). Our enums are plain IntEnums, no flags.
    member = enum_cls._value2member_map_.get(value)
    if member is None:
        raise DecodeError(f"{field}: {value} is not a {enum_cls.__name__}")
    return member  # type: ignore[return-value]  # the map holds enum_cls's members


def _check_len(payload: bytes, size: int, name: str) -> None:
    if len(payload) != size:
        raise DecodeError(f"{name} payload is {size} bytes, got {len(payload)}")


def _pack_error(name: str, exc: Exception) -> ValueError:
    return ValueError(f"cannot pack {name}: {exc}")


def truncate_utf8(text: str, max_bytes: int) -> str:
    """Longest prefix of ``text`` whose UTF-8 encoding fits in ``max_bytes`` (never splits a character)."""
    raw = text.encode("utf-8")
    if len(raw) <= max_bytes:
        return text
    return raw[:max_bytes].decode("utf-8", errors="ignore")


def _pack_text(text: str, max_bytes: int, field: str) -> bytes:
    raw = text.encode("utf-8")
    if len(raw) > max_bytes:
        raise ValueError(f"{field} is {len(raw)} UTF-8 bytes, at most {max_bytes} (see truncate_utf8)")
    return bytes((len(raw),)) + raw


def _unpack_text(payload: bytes, at: int, max_bytes: int, field: str) -> str:
    """Decode the length-prefixed text at ``payload[at]``, which must end the payload exactly."""
    n = payload[at]
    if n > max_bytes:
        raise DecodeError(f"{field} length {n} exceeds {max_bytes}")
    if len(payload) != at + 1 + n:
        raise DecodeError(f"{field}: payload is {len(payload)} bytes, text length says {at + 1 + n}")
    try:
        return payload[at + 1 :].decode("utf-8")
    except UnicodeDecodeError as exc:
        raise DecodeError(f"{field} is not UTF-8") from exc


def _pack_name(name: str, size: int, field: str) -> bytes:
    """ASCII, no NUL, at most ``size`` bytes; ``struct``'s ``s`` format NUL-pads it."""
    try:
        raw = name.encode("ascii")
    except UnicodeEncodeError:
        raise ValueError(f"{field} {name!r} is not ASCII") from None
    if len(raw) > size or b"\0" in raw:
        raise ValueError(f"{field} {name!r}: at most {size} ASCII characters, no NUL")
    return raw


def _unpack_name(raw: bytes, field: str) -> str:
    """Inverse of :func:`_pack_name`; only the canonical form (NULs only after the name) decodes."""
    name, _, pad = raw.partition(b"\0")
    if pad.strip(b"\0"):
        raise DecodeError(f"{field}: bytes after the terminating NUL")
    try:
        return name.decode("ascii")
    except UnicodeDecodeError:
        raise DecodeError(f"{field} is not ASCII") from None


# --- poses (SimPoses, ArmPoses) -------------------------------------------------------------------

_POSE_FLOATS = 7
_POSES = tuple(struct.Struct(f"<{_POSE_FLOATS * n}f") for n in range(MAX_SIM_BODIES + 1))
"""One pose on the wire: x, y, z then w, x, y, z (f32 each, 28 bytes); ``_POSES[n]`` packs n of them."""


def _flat_poses(
    positions_m: tuple[Vec3f, ...], quats_wxyz: tuple[Vec4f, ...], what: str
) -> tuple[int, list[float]]:
    """Count and flat floats of poses (x, y, z, w, x, y, z per body), checked for the wire."""
    n = len(positions_m)
    if n != len(quats_wxyz):
        raise ValueError(f"{n} positions but {len(quats_wxyz)} quaternions")
    if n > MAX_SIM_BODIES:
        raise ValueError(f"at most {MAX_SIM_BODIES} {what}, got {n}")
    flat: list[float] = []
    for p, q in zip(positions_m, quats_wxyz, strict=True):
        if len(p) != 3 or len(q) != 4:
            raise ValueError("positions are (x, y, z), quaternions (w, x, y, z)")
        flat += p
        flat += q
    return n, flat


def _unpack_poses(payload: bytes, at: int, n: int) -> tuple[tuple[Vec3f, ...], tuple[Vec4f, ...]]:
    v = _POSES[n].unpack_from(payload, at)
    positions = tuple(v[i : i + 3] for i in range(0, len(v), _POSE_FLOATS))
    quats = tuple(v[i + 3 : i + 7] for i in range(0, len(v), _POSE_FLOATS))
    return positions, quats
