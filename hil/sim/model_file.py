"""A fitted plant model as a file a person can read: the values, their intervals, where they came from.

``spirob-hil identify`` writes one; every command that takes ``--preset NAME`` also takes ``--preset
FILE.toml`` (:func:`hil.sim.presets.resolve`). The file names the preset it was fitted from (the choices the
fit did not touch: actuator kind, mounting, geometry), the arm's design, and one table per identified
parameter::

    format = 1
    preset = "prototype"
    created = "2026-11-27T09:00:00Z"
    tool = "spirob-teleop 0.1.0"

    [design]
    a_m = 0.005002852877095742
    ...

    [parameters.base_stiffness]
    value = 0.65            # what the model uses
    unit = "N·m/rad"
    interval = [0.61, 0.69] # 95 %, autocorrelation-consistent
    identifiable = true
    preset = 0.5            # where the fit started
    note = ""               # why it is not identifiable, when it is not

    [fit]
    fitted_rms_mm = 0.21    # cable lengths, fitted model, on the samples the fit saw
    held_out_rms_mm = 0.26  # ... on the samples it never saw
    nominal_held_out_rms_mm = 6.1
    ...

    [[recordings]]
    name = "excite1.mcap"
    sha256 = "..."
    duration_s = 60.0

Reading checks every key: an unknown parameter, a value outside its physical range, or a file of a newer
format is refused with one line.
"""

from __future__ import annotations

import datetime
import math
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Final

from hil.errors import HilError
from hil.sim.spiral import SpiralDesign

__all__ = ["FORMAT", "FittedParameter", "ModelFile", "ModelFileError", "read_model_file", "write_model_file"]

FORMAT: Final = 1
MAX_BYTES: Final = 1 << 20
"""A model file is a few kilobytes; a bigger one is not ours."""


class ModelFileError(HilError):
    """A model file cannot be read (one line: which file and why)."""


@dataclass(frozen=True, slots=True)
class FittedParameter:
    """One parameter of a fitted model.

    Attributes:
        name: the identified parameter's name (``hil.sim.uncertain``).
        value: what the model uses.
        unit: its SI unit.
        interval: the 95 % interval (NaN, NaN when none was computed).
        identifiable: the data pinned it down.
        preset: the value the fit started from.
        note: why it is not identifiable.
    """

    name: str
    value: float
    unit: str = ""
    interval: tuple[float, float] = (math.nan, math.nan)
    identifiable: bool = True
    preset: float = math.nan
    note: str = ""


@dataclass(frozen=True)
class ModelFile:
    """A fitted model.

    Attributes:
        preset: the named preset it was fitted from.
        design: the arm.
        parameters: the fitted values, by name.
        fit: the fit's figures (residuals, condition number, time...), for people.
        recordings: (name, sha256, duration_s) of each recording it came from.
        created: when (ISO 8601, UTC).
        tool: what wrote it.
    """

    preset: str
    design: SpiralDesign
    parameters: Mapping[str, FittedParameter]
    fit: Mapping[str, float | int | str] = field(default_factory=dict)
    recordings: tuple[tuple[str, str, float], ...] = ()
    created: str = ""
    tool: str = ""

    def values(self) -> dict[str, float]:
        """Every parameter's value, by name."""
        return {name: p.value for name, p in self.parameters.items()}


def _fmt(value: object) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if math.isnan(value):
            return "nan"
        if math.isinf(value):
            return "inf" if value > 0 else "-inf"
        return repr(value)
    if isinstance(value, str):
        escaped = value.replace("\\", "\\\\").replace('"', '\\"').replace("\n", "\\n")
        return f'"{escaped}"'
    if isinstance(value, tuple | list):
        return "[" + ", ".join(_fmt(v) for v in value) + "]"
    raise TypeError(f"cannot write {type(value).__name__} to a model file")


def write_model_file(path: str | Path, model: ModelFile) -> None:
    """Write ``model`` as TOML (replacing the file only once it is complete).

    Raises:
        ModelFileError: the file cannot be written.
    """
    d = model.design
    lines = [
        "# A SpiRob plant model fitted to recordings of a real (or simulated) arm: spirob-hil identify.",
        "# Every command that takes --preset NAME takes this file too. Intervals are 95 %.",
        f"format = {FORMAT}",
        f"preset = {_fmt(model.preset)}",
        f"created = {_fmt(model.created or _now())}",
        f"tool = {_fmt(model.tool)}",
        "",
        "[design]",
        f"a_m = {_fmt(d.a_m)}",
        f"b = {_fmt(d.b)}",
        f"theta0_rad = {_fmt(d.theta0_rad)}",
        f"dtheta_rad = {_fmt(d.dtheta_rad)}",
        f"cables = {_fmt(d.cables)}",
    ]
    for fp in model.parameters.values():
        lines += [
            "",
            f"[parameters.{fp.name}]",
            f"value = {_fmt(fp.value)}",
            f"unit = {_fmt(fp.unit)}",
            f"interval = {_fmt(list(fp.interval))}",
            f"identifiable = {_fmt(fp.identifiable)}",
            f"preset = {_fmt(fp.preset)}",
            f"note = {_fmt(fp.note)}",
        ]
    if model.fit:
        lines += ["", "[fit]"] + [f"{k} = {_fmt(v)}" for k, v in model.fit.items()]
    for name, sha, duration in model.recordings:
        lines += [
            "",
            "[[recordings]]",
            f"name = {_fmt(name)}",
            f"sha256 = {_fmt(sha)}",
            f"duration_s = {_fmt(duration)}",
        ]
    text = "\n".join(lines) + "\n"
    p = Path(path)
    tmp = p.with_name(p.name + ".part")
    try:
        tmp.write_text(text, encoding="utf-8")
        tmp.replace(p)
    except OSError as exc:
        raise ModelFileError(f"cannot write {p}: {exc.strerror or exc}") from exc


def _now() -> str:
    return datetime.datetime.now(datetime.UTC).replace(microsecond=0).isoformat().replace("+00:00", "Z")


def read_model_file(path: str | Path) -> ModelFile:
    """Read a model file.

    Raises:
        ModelFileError: missing, too big, not TOML, a newer format, or a key or value that does not fit.
    """
    p = Path(path)
    try:
        size = p.stat().st_size
        if size > MAX_BYTES:
            raise ModelFileError(f"{p}: {size} bytes is not a model file (at most {MAX_BYTES})")
        doc = tomllib.loads(p.read_text(encoding="utf-8"))
    except FileNotFoundError as exc:
        raise ModelFileError(f"{p}: no such file") from exc
    except OSError as exc:
        raise ModelFileError(f"{p}: {exc.strerror or exc}") from exc
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise ModelFileError(f"{p}: not TOML ({exc})") from exc
    except RecursionError as exc:
        raise ModelFileError(f"{p}: nested too deeply") from exc
    try:
        return _parse(doc)
    except KeyError as exc:
        raise ModelFileError(f"{p}: no {exc} (a model file of spirob-hil identify has it)") from exc
    except (TypeError, ValueError) as exc:
        raise ModelFileError(f"{p}: {exc}") from exc


def _parse(doc: dict[str, Any]) -> ModelFile:
    fmt = doc.get("format")
    if not isinstance(fmt, int) or fmt < 1:
        raise ValueError("no 'format' number: not a model file of spirob-hil identify")
    if fmt > FORMAT:
        raise ValueError(f"format {fmt} is newer than this version reads ({FORMAT}); update spirob-teleop")
    preset = doc["preset"]
    if not isinstance(preset, str):
        raise ValueError("'preset' must be a name")
    dd = doc["design"]
    design = SpiralDesign.from_params(
        float(dd["a_m"]), float(dd["b"]), float(dd["theta0_rad"]), float(dd["dtheta_rad"]), int(dd["cables"])
    )
    params: dict[str, FittedParameter] = {}
    for name, t in dict(doc.get("parameters", {})).items():
        if not isinstance(t, dict):
            raise ValueError(f"parameters.{name} must be a table")
        value = float(t["value"])
        if not math.isfinite(value):
            raise ValueError(f"parameters.{name}.value must be finite")
        lo, hi = (float(x) for x in t.get("interval", [math.nan, math.nan]))
        params[str(name)] = FittedParameter(
            str(name),
            value,
            str(t.get("unit", "")),
            (lo, hi),
            bool(t.get("identifiable", True)),
            float(t.get("preset", math.nan)),
            str(t.get("note", "")),
        )
    fit = {str(k): v for k, v in dict(doc.get("fit", {})).items() if isinstance(v, int | float | str)}
    recs = tuple(
        (str(r["name"]), str(r["sha256"]), float(r.get("duration_s", math.nan)))
        for r in list(doc.get("recordings", []))
    )
    return ModelFile(preset, design, params, fit, recs, str(doc.get("created", "")), str(doc.get("tool", "")))
