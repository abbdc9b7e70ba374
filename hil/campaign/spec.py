"""Campaigns: many runs of one pure function (a grasp trial or a scenario) over a grid or a random sample of
its inputs, described in a small TOML or JSON file (``spirob-hil campaign``, ``docs/campaigns.md``).

This module reads and checks a campaign and expands it into :class:`Run` s, each a flat dict of inputs
(``"design.length_m"``, ``"object.x_m"``, ``"seed"`` ...) with a stable key (a hash of those inputs), so a
results file can say which runs are done whatever order they finished in. :mod:`hil.campaign.runner` runs
them, :mod:`hil.campaign.summary` sums them up.

A value in the file is fixed (a number, a string, a bool), a list (an axis: every value in a grid, one at
random in a sample) or a range table ``{min = .., max = .., n = ..}`` (``n`` evenly spaced values in a
grid; uniform in a sample, where ``n`` is not needed).
"""

from __future__ import annotations

import hashlib
import itertools
import json
import math
import tomllib
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from controller.config import FirmwareConfig
from hil.errors import HilError
from hil.faults import Fault
from hil.sim.config import PHYSICS_STEPS_S, ModelConfig
from hil.sim.presets import resolve
from hil.sim.spiral import SpiralDesign, b_from_taper, taper_from_b
from hil.sim.variants import Variant
from hil.trial.arm_45cm import scaled_model
from hil.trial.grasp import grasp_firmware

__all__ = [
    "KINDS",
    "MAX_RUNS_N",
    "Campaign",
    "CampaignError",
    "Run",
    "apply_override",
    "build_design",
    "build_firmware",
    "load_campaign",
    "parse_campaign",
    "run_key",
]

KINDS = ("grasp", "scenario", "array")
"""What one run is: a grasp trial (:func:`hil.trial.grasp.grasp_trial`), a scenario
(:func:`hil.scenarios.run_scenario`) or an array's grasp (:func:`hil.trial.array_grasp.array_grasp_trial`)."""

MAX_RUNS_N = 1_000_000
"""The most runs a campaign expands to: more is a typo in a grid (each run is seconds of simulation)."""

_MAX_UNITS_N = 1000  # as on the command line (hil.cli.design.MAX_UNITS_N): every unit is a body and a joint

_TOP_KEYS = frozenset(
    {"kind", "sampling", "samples", "seed", "seeds", "design", "object", "controller", "scenario", "array"}
)
_SECTIONS = ("design", "object", "controller", "scenario", "array")
_FLOAT, _INT, _BOOL, _STR = "float", "int", "bool", "str"
_DESIGN_KEYS = {
    "preset": _STR,
    "physics": _STR,
    "variant": _STR,
    "length_m": _FLOAT,
    "tip_width_m": _FLOAT,
    "taper_deg": _FLOAT,
    "b": _FLOAT,
    "dtheta_deg": _FLOAT,
    "cables": _INT,
    "base_stiffness_nm_per_rad": _FLOAT,
    "stiffness_exponent": _FLOAT,
    "cable_mu": _FLOAT,
    "arm_friction": _FLOAT,
    "scale_model": _BOOL,
}
_OBJECT_KEYS = {
    "diameter_m": _FLOAT,
    "x_m": _FLOAT,
    "z_m": _FLOAT,
    "mass_kg": _FLOAT,
    "length_m": _FLOAT,
    "friction": _FLOAT,
    "release_at_touch": _BOOL,
}
_ARRAY_KEYS = {
    "arms": _INT,
    "object": _STR,
    "ring_radius_m": _FLOAT,
    "tilt_deg": _FLOAT,
    "depth_m": _FLOAT,
    "jitter_m": _FLOAT,
    "hold_s": _FLOAT,
}
"""An array run: how many arms, which of the ten objects, the ring (default: the array experiment's,
sized to the object) and its arms' tilt outwards, the object's depth under the bases, its jitter (drawn
from the run's seed) and the hold (:mod:`hil.trial.array_grasp`)."""
_GRASP_CONTROLLER_KEYS = {"strategy_on": _BOOL, "contact_oracle": _BOOL}
"""Controller keys of a grasp trial itself; any other controller key is a firmware configuration name."""
_RIG_FIRMWARE_KEYS = frozenset({"grasp_strategy_on", "grasp_direction_deg"})
"""Firmware keys the grasp trial's rig sets from the trial itself."""
_PHYSICAL = ("length_m", "tip_width_m", "taper_deg", "b", "dtheta_deg")


class CampaignError(HilError, ValueError):
    """A campaign file or override that cannot be run (reported as one line, naming the key)."""


MAX_CAMPAIGN_BYTES = 1 << 20
"""The largest campaign file read (1 MiB; the examples are under 2 KB)."""
MAX_CAMPAIGN_DEPTH = 16
"""The deepest nesting of tables and arrays a campaign may have (a campaign uses 3: file, section, list).
Deeper input is refused in one line, also where the parsers themselves would recurse past Python's limit."""


def _depth(value: Any) -> int:
    """Nesting depth of parsed tables and arrays (a scalar: 0), without recursion."""
    deepest = 0
    stack: list[tuple[Any, int]] = [(value, 0)]
    while stack:
        item, level = stack.pop()
        children = item.values() if isinstance(item, dict) else item if isinstance(item, list) else None
        if children is None:
            continue
        deepest = max(deepest, level + 1)
        if deepest > MAX_CAMPAIGN_DEPTH:
            break
        stack.extend((child, level + 1) for child in children)
    return deepest


def _too_deep(where: str) -> CampaignError:
    return CampaignError(f"{where}nested deeper than {MAX_CAMPAIGN_DEPTH} levels of tables and arrays")


@dataclass(frozen=True)
class Run:
    """One run of a campaign.

    Attributes:
        key: 16 hex digits of the SHA-256 of the inputs' canonical JSON: the same inputs, the same key.
        inputs: ``kind``, ``seed`` and the ``section.name`` values of this run.
    """

    key: str
    inputs: Mapping[str, Any]


@dataclass(frozen=True)
class Campaign:
    """A checked campaign.

    Attributes:
        kind: one of :data:`KINDS`.
        sampling: ``grid`` (every combination) or ``random`` (``samples`` draws).
        samples: draws of a random sample.
        seed: seed of the random draws.
        seeds: the seeds every combination (or draw) runs with.
        axes: ``section.name`` -> a fixed value, a list of values, or a range ``{min, max[, n]}``.
    """

    kind: str
    sampling: str
    samples: int
    seed: int
    seeds: tuple[int, ...]
    axes: Mapping[str, Any]

    def runs(self) -> list[Run]:
        """Every run, in a fixed order (grid: the axes' product in file order, then the seeds)."""
        points = list(self._grid() if self.sampling == "grid" else self._random())
        out: list[Run] = []
        for point in points:
            for s in self.seeds:
                inputs = {"kind": self.kind, **point, "seed": s}
                out.append(Run(run_key(inputs), inputs))
        return out

    def _grid(self) -> Iterator[dict[str, Any]]:
        names = list(self.axes)
        values = [_grid_values(name, self.axes[name]) for name in names]
        for combo in itertools.product(*values):
            yield dict(zip(names, combo, strict=True))

    def _random(self) -> Iterator[dict[str, Any]]:
        rng = np.random.default_rng(self.seed)
        for _ in range(self.samples):
            yield {name: _draw(name, spec, rng) for name, spec in self.axes.items()}


def run_key(inputs: Mapping[str, Any]) -> str:
    """The stable key of a run's inputs (a results file row carries it; ``--resume`` skips it)."""
    text = json.dumps(inputs, sort_keys=True, separators=(",", ":"), allow_nan=False)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def _round(x: float) -> float:
    """12 significant digits: a range's values print, hash and read back alike on every machine."""
    return float(f"{x:.12g}")


def _is_range(spec: Any) -> bool:
    return isinstance(spec, dict)


def _grid_values(name: str, spec: Any) -> list[Any]:
    if _is_range(spec):
        if "n" not in spec:
            raise CampaignError(f"{name}: a range in a grid needs n (how many values)")
        n = spec["n"]
        lo, hi = spec["min"], spec["max"]
        if isinstance(lo, int) and isinstance(hi, int):
            return sorted({round(v) for v in np.linspace(lo, hi, n)})
        return [_round(float(v)) for v in np.linspace(lo, hi, n)]
    return list(spec) if isinstance(spec, list) else [spec]


def _draw(name: str, spec: Any, rng: np.random.Generator) -> Any:
    if _is_range(spec):
        lo, hi = spec["min"], spec["max"]
        if isinstance(lo, int) and isinstance(hi, int):
            return int(rng.integers(lo, hi + 1))
        return _round(float(rng.uniform(lo, hi)))
    values = _grid_values(name, spec)
    return values[int(rng.integers(len(values)))] if len(values) > 1 else values[0]


# ---------------------------------------------------------------------- reading and checking


def load_campaign(
    path: Path | None, overrides: list[str], params: Mapping[str, Any] | None = None
) -> Campaign:
    """Read a campaign file (``.toml`` or ``.json``; None: start empty), apply ``--set`` overrides, check.

    ``params`` (``--params``: a firmware parameter file's values, ``controller.param_file``) are fixed
    ``controller`` keys of a grasp campaign under whatever the file and the overrides set:
    ``grasp_strategy_on`` is the trial's ``strategy_on``; ``grasp_direction_deg`` is the trial's own (the
    object is on cable 0's side) and is left out.

    Raises:
        CampaignError: unreadable file, bad syntax, unknown key, wrong type, impossible design ... (one
            line, naming the file and the key).
    """
    raw: dict[str, Any] = {}
    if path is not None:
        try:
            with path.open("rb") as f:
                data = f.read(MAX_CAMPAIGN_BYTES + 1)
            if len(data) > MAX_CAMPAIGN_BYTES:
                limit = MAX_CAMPAIGN_BYTES >> 20
                raise CampaignError(f"{path}: larger than the {limit} MiB a campaign file may be")
            text = data.decode("utf-8")
        except (OSError, UnicodeDecodeError) as exc:
            reason = exc.strerror if isinstance(exc, OSError) and exc.strerror else str(exc)
            raise CampaignError(f"cannot read {path}: {reason}") from None
        raw = _parse_text(path, text)
    for spec in overrides:
        apply_override(raw, spec)
    if params:
        _apply_params(raw, params)
    if _depth(raw) > MAX_CAMPAIGN_DEPTH:
        raise _too_deep(f"{path}: " if path is not None else "")
    try:
        return parse_campaign(raw)
    except CampaignError as exc:
        where = f"{path}: " if path is not None else ""
        raise CampaignError(f"{where}{exc}") from None


def _apply_params(raw: dict[str, Any], params: Mapping[str, Any]) -> None:
    kind = raw.get("kind")
    if kind not in ("grasp", "array"):
        raise CampaignError("--params is for grasp and array campaigns (a scenario builds its own firmware)")
    section = raw.setdefault("controller", {})
    if not isinstance(section, dict):
        raise CampaignError("controller must be a table")
    for name, value in params.items():
        if name == "grasp_direction_deg" or (kind == "array" and name == "grasp_strategy_on"):
            continue  # the trial's own (an array closes by the plain ramp)
        if isinstance(value, tuple | list):
            raise CampaignError(
                f"--params: {name} is not a scalar key; a campaign run takes scalar keys only"
            )
        section.setdefault("strategy_on" if name == "grasp_strategy_on" else name, value)


def _parse_text(path: Path, text: str) -> dict[str, Any]:
    # Both parsers recurse once per level: deep nesting ends in RecursionError, refused like any depth
    # over the limit (checked on what they return).
    if path.suffix.lower() == ".json":
        try:
            data = json.loads(text)
        except json.JSONDecodeError as exc:
            raise CampaignError(f"{path}: not valid JSON: {exc.msg} (line {exc.lineno})") from None
        except RecursionError:
            raise _too_deep(f"{path}: ") from None
    else:
        try:
            data = tomllib.loads(text)
        except tomllib.TOMLDecodeError as exc:
            raise CampaignError(f"{path}: not valid TOML: {exc}") from None
        except RecursionError:
            raise _too_deep(f"{path}: ") from None
    if not isinstance(data, dict):
        raise CampaignError(f"{path}: a campaign is a table of keys, got {type(data).__name__}")
    return data


def apply_override(raw: dict[str, Any], spec: str) -> None:
    """Apply one ``--set KEY=VALUE`` (``KEY``: ``seeds`` or ``section.name``; ``VALUE``: a TOML value,
    or a bare word taken as a string) to the raw campaign ``raw``.

    Raises:
        CampaignError: no ``=``, or a key with more than one dot.
    """
    key, sep, text = spec.partition("=")
    key = key.strip()
    if not sep or not key:
        raise CampaignError(f"--set wants KEY=VALUE, got {spec!r}")
    try:
        value = tomllib.loads(f"v = {text.strip()}")["v"]
    except tomllib.TOMLDecodeError:
        value = text.strip()  # a bare word: a scenario or preset name
    except RecursionError:
        raise _too_deep(f"--set {key}: ") from None
    parts = key.split(".")
    if len(parts) == 1:
        raw[key] = value
    elif len(parts) == 2:
        section = raw.setdefault(parts[0], {})
        if not isinstance(section, dict):
            raise CampaignError(f"--set {key}: {parts[0]} is not a section")
        section[parts[1]] = value
    else:
        raise CampaignError(f"--set wants KEY or SECTION.KEY, got {key!r}")


def parse_campaign(raw: Mapping[str, Any]) -> Campaign:
    """Check a raw campaign (the file's tables) and build it; every design, firmware and fault set it
    names is built once here, so a mistake is found before the first run.

    Raises:
        CampaignError: the first problem found.
    """
    unknown = sorted(set(raw) - _TOP_KEYS)
    if unknown:
        raise CampaignError(f"unknown key {unknown[0]!r} (known: {', '.join(sorted(_TOP_KEYS))})")
    kind = raw.get("kind")
    if kind not in KINDS:
        raise CampaignError(f"kind must be one of {', '.join(KINDS)}, got {kind!r}")
    sampling = raw.get("sampling", "grid")
    if sampling not in ("grid", "random"):
        raise CampaignError(f"sampling must be grid or random, got {sampling!r}")
    samples = raw.get("samples", 0 if sampling == "grid" else None)
    if sampling == "random" and not (_is_int(samples) and samples >= 1):
        raise CampaignError(f"a random campaign needs samples = a whole number >= 1, got {samples!r}")
    if sampling == "grid" and "samples" in raw:
        raise CampaignError("samples is for sampling = random; a grid runs every combination")
    seed = raw.get("seed", 0)
    if not (_is_int(seed) and seed >= 0):
        raise CampaignError(f"seed must be a whole number >= 0, got {seed!r}")
    seeds = _seeds(raw.get("seeds", 1))
    axes: dict[str, Any] = {}
    for section in _SECTIONS:
        table = raw.get(section, {})
        if not isinstance(table, dict):
            raise CampaignError(f"{section} must be a table, got {type(table).__name__}")
        for name, spec in table.items():
            axes[f"{section}.{name}"] = spec
    _check_axes(kind, axes, sampling)
    axes = {
        name: _as_floats(spec) if _key_type(kind, name) == _FLOAT else spec for name, spec in axes.items()
    }
    campaign = Campaign(kind, sampling, int(samples or 0), int(seed), seeds, axes)
    _check_points(campaign)
    return campaign


def _as_floats(spec: Any) -> Any:
    """A number key's values as floats: ``x_m = 0`` and ``x_m = 0.0`` are the same run, with one key."""
    if isinstance(spec, dict):
        return {k: v if k == "n" else float(v) for k, v in spec.items()}
    if isinstance(spec, list):
        return [float(v) for v in spec]
    return float(spec)


def _is_int(v: Any) -> bool:
    return isinstance(v, int) and not isinstance(v, bool)


def _seeds(spec: Any) -> tuple[int, ...]:
    if _is_int(spec):
        if not 1 <= spec <= MAX_RUNS_N:
            raise CampaignError(f"seeds: a count must be 1..{MAX_RUNS_N}, got {spec}")
        return tuple(range(spec))
    if isinstance(spec, list) and spec and all(_is_int(s) and s >= 0 for s in spec):
        if len(set(spec)) != len(spec):
            raise CampaignError(f"seeds: a list must not repeat a seed, got {spec}")
        return tuple(spec)
    raise CampaignError(f"seeds must be a count or a list of whole numbers >= 0, got {spec!r}")


def _key_type(kind: str, name: str) -> str | None:
    section, _, key = name.partition(".")
    if section == "design":
        return _DESIGN_KEYS.get(key)
    if section == "object":
        return _OBJECT_KEYS.get(key) if kind == "grasp" else None
    if section == "array":
        return _ARRAY_KEYS.get(key) if kind == "array" else None
    if section == "controller":
        if kind == "scenario":
            return None
        if key in _GRASP_CONTROLLER_KEYS:
            if kind == "array":
                return None
            return _GRASP_CONTROLLER_KEYS[key]
        if key in _RIG_FIRMWARE_KEYS:
            raise CampaignError(f"{name}: the grasp trial sets it (use controller.strategy_on)")
        default = FirmwareConfig().to_dict().get(key)
        if default is None or isinstance(default, list):
            raise CampaignError(f"{name}: not a scalar firmware configuration key")
        return _BOOL if isinstance(default, bool) else _INT if isinstance(default, int) else _FLOAT
    if section == "scenario":
        return {"name": _STR, "faults": "faults"}.get(key) if kind == "scenario" else None
    return None


def _check_axes(kind: str, axes: Mapping[str, Any], sampling: str) -> None:
    for name, spec in axes.items():
        typ = _key_type(kind, name)
        if typ is None:
            raise CampaignError(f"{name}: not a key of a {kind} campaign (see docs/campaigns.md)")
        if typ == "faults":
            _check_faults(name, spec)
            continue
        if _is_range(spec):
            _check_range(name, spec, typ, sampling)
            continue
        values = spec if isinstance(spec, list) else [spec]
        if not values:
            raise CampaignError(f"{name}: an empty list gives no run")
        for v in values:
            _check_value(name, v, typ)
    required = {
        "grasp": ("object.diameter_m", "object.x_m", "object.z_m"),
        "scenario": ("scenario.name",),
        "array": ("array.arms", "array.object"),
    }[kind]
    for name in required:
        if name not in axes:
            raise CampaignError(f"a {kind} campaign needs {name}")


def _check_value(name: str, v: Any, typ: str) -> None:
    ok = {
        _FLOAT: (isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)),
        _INT: _is_int(v),
        _BOOL: isinstance(v, bool),
        _STR: isinstance(v, str),
    }[typ]
    if not ok:
        want = {_FLOAT: "a finite number", _INT: "a whole number", _BOOL: "true or false", _STR: "a string"}
        raise CampaignError(f"{name}: want {want[typ]} (or a list of them), got {v!r}")


def _check_range(name: str, spec: Mapping[str, Any], typ: str, sampling: str) -> None:
    extra = set(spec) - {"min", "max", "n"}
    if extra or "min" not in spec or "max" not in spec:
        raise CampaignError(f"{name}: a range is {{min = .., max = .., n = ..}}, got {spec!r}")
    if typ not in (_FLOAT, _INT):
        raise CampaignError(f"{name}: only numbers take a range")
    _check_value(name, spec["min"], typ)
    _check_value(name, spec["max"], typ)
    if spec["min"] > spec["max"]:
        raise CampaignError(f"{name}: min {spec['min']} > max {spec['max']}")
    if "n" in spec and not (_is_int(spec["n"]) and 1 <= spec["n"] <= MAX_RUNS_N):
        raise CampaignError(f"{name}: n must be 1..{MAX_RUNS_N}, got {spec['n']!r}")
    if sampling == "grid" and "n" not in spec:
        raise CampaignError(f"{name}: a range in a grid needs n (how many values)")


def _check_faults(name: str, spec: Any) -> None:
    if not (isinstance(spec, list) and spec and all(isinstance(s, list) for s in spec)):
        raise CampaignError(f"{name}: want a list of fault sets, each a list of specs, e.g. [[], ['...']]")
    for fault_set in spec:
        for text in fault_set:
            if not isinstance(text, str):
                raise CampaignError(f"{name}: a fault is a string KIND@START[-END][:key=value], got {text!r}")
            try:
                Fault.parse(text)
            except ValueError as exc:
                raise CampaignError(f"{name}: {exc}") from None


def _check_points(campaign: Campaign) -> None:
    """Count the runs and build each distinct design, firmware and scenario once."""
    count = campaign.samples if campaign.sampling == "random" else 1
    if campaign.sampling == "grid":
        for name, spec in campaign.axes.items():
            count *= len(_grid_values(name, spec))
            if count * len(campaign.seeds) > MAX_RUNS_N:
                raise CampaignError(f"the campaign has more than {MAX_RUNS_N} runs")
    if count * len(campaign.seeds) > MAX_RUNS_N:
        raise CampaignError(f"the campaign has more than {MAX_RUNS_N} runs")
    from hil.scenarios import SCENARIOS  # the catalogue imports every scenario: only once a campaign is read

    seen: set[str] = set()
    points = campaign._grid() if campaign.sampling == "grid" else campaign._random()
    for point in points:
        sig = json.dumps(point, sort_keys=True)
        if sig in seen:
            continue
        seen.add(sig)
        build_design(point)
        if campaign.kind == "array":
            _check_array_point(point)
        elif campaign.kind == "grasp":
            build_firmware(point)
            for name in ("object.diameter_m", "object.mass_kg", "object.length_m"):
                if name in point and not point[name] > 0:
                    raise CampaignError(f"{name} must be > 0, got {point[name]}")
        elif point["scenario.name"] not in SCENARIOS:
            known = ", ".join(SCENARIOS)
            raise CampaignError(
                f"scenario.name: unknown scenario {point['scenario.name']!r} (known: {known})"
            )


def _check_array_point(point: Mapping[str, Any]) -> None:
    from hil.trial.objects import ARRAY_OBJECTS

    build_firmware(point)
    design, _ = build_design(point)
    if design.cables != 1 and "design.cables" in point:
        raise CampaignError("design.cables: an array's arms have one cable each")
    if not 1 <= point["array.arms"] <= 8:
        raise CampaignError(f"array.arms must be 1..8 (a C-board's motors), got {point['array.arms']}")
    keys = [o.key for o in ARRAY_OBJECTS]
    if point["array.object"] not in keys:
        raise CampaignError(f"array.object: unknown {point['array.object']!r} (known: {', '.join(keys)})")
    limits = {
        "ring_radius_m": (0.0, 1.0),
        "tilt_deg": (-90.0, 90.0),
        "depth_m": (0.0, 2.0),
        "jitter_m": (0.0, 0.1),
        "hold_s": (0.0, 60.0),
    }
    for key, (lo, hi) in limits.items():
        v = point.get(f"array.{key}")
        if v is not None and not lo <= v <= hi:
            raise CampaignError(f"array.{key} must be {lo:g}..{hi:g}, got {v}")


# ---------------------------------------------------------------------- what a run's inputs build


def build_design(inputs: Mapping[str, Any], physics: str = "board") -> tuple[SpiralDesign, ModelConfig]:
    """The arm and the plant model of a run's ``design.*`` inputs.

    ``design.preset`` (default ``prototype``) gives the plant model and, unless physical inputs
    (``length_m``, ``tip_width_m``, ``taper_deg`` or ``b``, ``dtheta_deg``) are given, the design;
    ``cables``, ``base_stiffness_nm_per_rad``, ``stiffness_exponent``, ``cable_mu`` and ``arm_friction``
    change either; ``scale_model`` (default false) then scales the model, which describes the preset's arm,
    to the run's arm in the same material (mass with the volume, the base joint's stiffness with the cube
    of its width: :func:`hil.trial.arm_45cm.scaled_model`), so a given ``base_stiffness_nm_per_rad`` is the
    preset-sized arm's;
    ``design.physics`` (default ``physics``: ``fine`` for grasp trials, as the experiments run them,
    ``board`` for scenarios) names the physics step and constraint stiffness
    (:data:`~hil.sim.config.PHYSICS_STEPS_S`).

    Raises:
        CampaignError: an unknown preset, incomplete physical inputs or values that make no design.
    """
    d = {k.partition(".")[2]: v for k, v in inputs.items() if k.startswith("design.")}
    name = d.get("preset", "prototype")
    try:
        chosen = resolve(str(name))
    except ValueError as exc:
        raise CampaignError(f"design.preset: {exc}") from exc
    physics = d.get("physics", physics)
    if physics not in PHYSICS_STEPS_S:
        raise CampaignError(f"design.physics: unknown {physics!r} (known: {', '.join(PHYSICS_STEPS_S)})")
    try:
        if any(k in d for k in _PHYSICAL):
            design = _physical_design(d)
        else:
            design = chosen.spiral()
            cables = d.get("cables")
            if cables is not None:
                design = design.with_cables(cables)
        if design.units > _MAX_UNITS_N:
            raise CampaignError(f"design has {design.units} units; at most {_MAX_UNITS_N} are modelled")
        arm_changes = {
            "base_stiffness_nm_per_rad": d.get("base_stiffness_nm_per_rad"),
            "stiffness_exponent": d.get("stiffness_exponent"),
            "cable_mu": d.get("cable_mu"),
            "geom_friction": d.get("arm_friction"),
        }
        arm = replace(chosen.model.arm, **{k: v for k, v in arm_changes.items() if v is not None})
        model = replace(chosen.model, arm=arm).with_physics(PHYSICS_STEPS_S[physics])
        if d.get("scale_model", False):
            model = scaled_model(model, design, chosen.spiral())
        if "variant" in d:
            try:
                variant = Variant.parse(d["variant"])
            except ValueError as exc:
                raise CampaignError(f"design.variant: {exc}") from None
            model = variant.apply(model)
        model.validate()
    except CampaignError:
        raise
    except (ValueError, OverflowError) as exc:
        given = ", ".join(f"{k}={v}" for k, v in d.items())
        raise CampaignError(f"design {given or name}: {exc}") from None
    return design, model


def _physical_design(d: Mapping[str, Any]) -> SpiralDesign:
    if "length_m" not in d or "tip_width_m" not in d:
        raise CampaignError("design: physical inputs need length_m and tip_width_m")
    if ("taper_deg" in d) == ("b" in d):
        raise CampaignError("design: give exactly one of taper_deg and b")
    taper = math.radians(d["taper_deg"]) if "taper_deg" in d else taper_from_b(d["b"])
    b_from_taper(taper)  # the same range check and message as the command line's --taper-deg
    return SpiralDesign.from_physical(
        length_m=d["length_m"],
        tip_width_m=d["tip_width_m"],
        taper_rad=taper,
        dtheta_rad=math.radians(d.get("dtheta_deg", 30.0)),
        cables=d.get("cables", 3),
    )


def build_firmware(inputs: Mapping[str, Any]) -> FirmwareConfig:
    """The firmware of a grasp or array run: the grasp experiments' (:func:`hil.trial.grasp.grasp_firmware`)
    with the run's ``controller.*`` firmware keys changed (an array run lays it out as its arms).

    Raises:
        CampaignError: a value the firmware refuses.
    """
    changes = {
        k.partition(".")[2]: v
        for k, v in inputs.items()
        if k.startswith("controller.") and k.partition(".")[2] not in _GRASP_CONTROLLER_KEYS
    }
    try:
        return grasp_firmware(**changes)
    except ValueError as exc:
        raise CampaignError(f"controller: {exc}") from None
