"""Firmware parameter files: TOML of the firmware's flat keys (``controller.params``), with a header comment.

A parameter file is the firmware's configuration as a person (or ``spirob-hil tune``) writes it down::

    # tuned by spirob-hil tune ... (how it was made)
    grasp_strategy_on = false
    grasp_wrap_n = 12.5

Every key is a flat name of the parameter table (:data:`controller.params.FIELD_ROWS`); a key not given
keeps the configuration it is applied to. ``spirob-firmware --params``, ``spirob-hil board --params``,
``spirob-hil campaign --params`` and ``spirob-host --params`` read it with :func:`load_param_file`: an
unknown key, a value of the wrong type or out of its range is one :class:`ConfigError` naming the file and
the key. :func:`dump_param_file` writes one that reads back to the same values.
"""

from __future__ import annotations

import math
import tomllib
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any, Final

from controller.config import FirmwareConfig
from controller.errors import ConfigError
from controller.params import FIELD_ROWS, PARAM_TABLE

__all__ = [
    "MAX_PARAM_FILE_BYTES",
    "apply_param_file",
    "dump_param_file",
    "load_param_file",
    "write_param_file",
]

MAX_PARAM_FILE_BYTES: Final[int] = 64 * 1024
"""The largest parameter file read (the whole table is under 2 KB)."""


def load_param_file(path: str | Path, base: FirmwareConfig | None = None) -> dict[str, Any]:
    """The values of a parameter file by flat name (lists as tuples), checked against the table.

    The values are checked together on top of ``base`` (default: the firmware's defaults), so rules
    between keys (a reach tension below half the pack tension) apply as the firmware applies them.

    Raises:
        ConfigError: ``FILE: ...`` in one line: unreadable, not TOML, a nested table, an unknown key, a
            wrong type, a value out of range.
    """
    path = Path(path)
    try:
        with path.open("rb") as f:
            data = f.read(MAX_PARAM_FILE_BYTES + 1)
    except OSError as exc:
        raise ConfigError(f"cannot read parameter file {path}: {exc.strerror or exc}") from None
    if len(data) > MAX_PARAM_FILE_BYTES:
        kib = MAX_PARAM_FILE_BYTES // 1024
        raise ConfigError(f"{path}: larger than the {kib} KiB a parameter file may be")
    try:
        raw = tomllib.loads(data.decode("utf-8"))
    except UnicodeDecodeError as exc:
        raise ConfigError(f"{path}: not UTF-8 text: {exc.reason}") from None
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{path}: not valid TOML: {exc}") from None
    try:
        values = _check(raw)
        (base or FirmwareConfig()).replaced(**values)
    except ConfigError as exc:
        raise ConfigError(f"{path}: {exc}") from None
    return values


def apply_param_file(path: str | Path, base: FirmwareConfig | None = None) -> FirmwareConfig:
    """``base`` (default: the firmware's defaults) with a parameter file's values.

    Raises:
        ConfigError: as :func:`load_param_file`.
    """
    base = base or FirmwareConfig()
    return base.replaced(**load_param_file(path, base))


def _check(raw: Mapping[str, Any]) -> dict[str, Any]:
    unknown = sorted(set(raw) - set(FIELD_ROWS))
    if unknown:
        raise ConfigError(f"unknown key {unknown[0]!r} (the flat names of docs/parameters.md)")
    out: dict[str, Any] = {}
    for row in PARAM_TABLE:
        if row.name not in raw:
            continue
        value = row.coerce(raw[row.name])
        row.check_type(value)
        out[row.name] = value
    return out


def _toml_value(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if not math.isfinite(value):
            raise ConfigError(f"a parameter file holds finite numbers only, got {value}")
        return repr(value)  # the shortest text that reads back to the same float
    if isinstance(value, tuple | list):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    raise ConfigError(f"not a parameter value: {value!r}")


def dump_param_file(values: Mapping[str, Any], header: Iterable[str] = ()) -> str:
    """The text of a parameter file: ``header`` lines as comments, then one ``key = value`` per value.

    Keys come in the table's order; each is checked as :func:`load_param_file` checks it.

    Raises:
        ConfigError: an unknown key or a value the firmware refuses.
    """
    checked = _check(values)
    FirmwareConfig().replaced(**checked)
    lines = [("# " + line).rstrip() for text in header for line in text.splitlines() or [""]]
    if lines:
        lines.append("")
    lines += [f"{name} = {_toml_value(value)}" for name, value in checked.items()]
    return "\n".join(lines) + "\n"


def write_param_file(path: str | Path, values: Mapping[str, Any], header: Iterable[str] = ()) -> Path:
    """Write :func:`dump_param_file` to ``path`` (through a temporary file: never half a file).

    Raises:
        ConfigError: as :func:`dump_param_file`.
        OSError: the file cannot be written.
    """
    path = Path(path)
    text = dump_param_file(values, header)
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(text, encoding="utf-8")
    tmp.replace(path)
    return path
