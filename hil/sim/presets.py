"""Named sets of plant-model choices (actuator, stiffness profile, mounting) with the design they go with,
and fitted models read from files (``spirob-hil identify``): :func:`resolve` takes either.

A preset answers "which model is this result from?" in one word, so any figure can be cross-checked
against another model: ``spirob-hil design/model export/board/run/experiment --preset NAME``, or from code
``hil.sim.presets.preset("authors")`` (a :class:`hil.sim.config.ModelConfig`) and
``PRESETS["authors"].design_preset``. ``docs/plant.md`` tabulates them with their sources.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from hil.sim.config import ActuatorConfig, ArmConfig, ModelConfig
from hil.sim.model_file import ModelFileError, read_model_file
from hil.sim.spiral import SpiralDesign
from hil.sim.uncertain import apply

__all__ = ["PRESETS", "Preset", "is_model_file", "preset", "preset_names", "resolve"]


@dataclass(frozen=True)
class Preset:
    """A named model choice.

    Attributes:
        name: the preset's name.
        summary: one line for help texts.
        design_preset: the design it goes with (``hil.sim.spiral.SpiralDesign.preset``).
        cables: the cable count it sets on that design (``None``: the design's own).
        model: the plant model.
        source: where its choices come from.
        design: the design itself, when it is not a named one (a fitted model's: the recorded arm).
    """

    name: str
    summary: str
    design_preset: str
    cables: int | None
    model: ModelConfig
    source: str
    design: SpiralDesign | None = None

    def spiral(self) -> SpiralDesign:
        """The design it goes with."""
        if self.design is not None:
            return self.design
        base = SpiralDesign.preset(self.design_preset)
        return base if self.cables is None else base.with_cables(self.cables)


_AUTHORS_MODEL = ModelConfig(
    arm=ArmConfig(base_stiffness_nm_per_rad=0.04, stiffness_exponent=2),
    actuator=ActuatorConfig(kind="muscle", muscle_force_n=5.0, friction_n=0.1),
    mounting="gravity-off",
)

PRESETS: dict[str, Preset] = {
    p.name: p
    for p in (
        Preset(
            "prototype",
            "the paper's 3-cable prototype under the drone, M2006 motors (the default)",
            "prototype",
            None,
            ModelConfig(),
            "the paper's supplement and DJI's M2006 P36 figures (docs/plant.md)",
        ),
        Preset(
            "authors",
            "the authors' published model: their default design, muscles of 5 N, stiffness ∝ size², "
            "0.04 N·m/rad, gravity off",
            "authors",
            None,
            _AUTHORS_MODEL,
            "ZhanchiWang/Open-Spiral-Robots, design-tool/xml_generator.py",
        ),
        Preset(
            "ideal-tension",
            "the prototype driven by ideal tension sources (10 ms lag, 10 g, 0.1 N friction)",
            "prototype",
            None,
            ModelConfig(actuator=ActuatorConfig(kind="tension")),
            "the authors' kind of actuator: a light tension source (docs/plant.md)",
        ),
        Preset(
            "table",
            "the prototype as a 2-cable planar arm lying on a table, M2006 motors",
            "prototype",
            2,
            ModelConfig(mounting="table"),
            "a planar arm lying flat: its weight rests on the table instead of bending its joints",
        ),
        Preset(
            "gravity-off",
            "the prototype under the drone with gravity off, M2006 motors",
            "prototype",
            None,
            ModelConfig(mounting="gravity-off"),
            "the authors' gravity choice on our model, to tell gravity's effect apart",
        ),
    )
}
"""Every preset by name, ``prototype`` (the default) first."""


def preset_names() -> tuple[str, ...]:
    """The presets' names, the default first."""
    return tuple(PRESETS)


def preset(name: str) -> ModelConfig:
    """The plant model of the preset ``name``, or of a fitted model file (:func:`resolve`).

    Raises:
        ValueError: no preset of that name, or a model file that cannot be used (one line).
    """
    return resolve(name).model


def is_model_file(spec: str) -> bool:
    """``spec`` names a fitted model file rather than a preset (it ends in ``.toml``)."""
    return spec.lower().endswith(".toml")


def resolve(spec: str) -> Preset:
    """A named preset, or a fitted model file (``arm.toml``, written by ``spirob-hil identify``) as one.

    A model file names the preset it was fitted from; its fitted values replace that preset's, and its
    design (the recorded arm) replaces the preset's design.

    Raises:
        ValueError: an unknown name (the message lists the presets), or a model file that is missing,
            malformed, names an unknown preset or holds a value the model refuses (one line each).
    """
    if spec in PRESETS:
        return PRESETS[spec]
    if not is_model_file(spec):
        raise ValueError(
            f"unknown model preset {spec!r}; choose from {', '.join(PRESETS)} or a fitted model .toml"
        )
    try:
        fitted = read_model_file(spec)
    except ModelFileError as exc:
        raise ValueError(str(exc)) from exc
    base = PRESETS.get(fitted.preset)
    if base is None:
        raise ValueError(f"{spec}: fitted from an unknown preset {fitted.preset!r}")
    try:
        model = apply(base.model, fitted.values())
    except ValueError as exc:
        raise ValueError(f"{spec}: {exc}") from exc
    return Preset(
        Path(spec).stem,
        f"fitted to {len(fitted.recordings)} recording(s) from the {fitted.preset} preset",
        base.design_preset,
        None,
        model,
        f"spirob-hil identify, {fitted.created or 'undated'} ({spec})",
        fitted.design,
    )
