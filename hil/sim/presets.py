"""Named sets of plant-model choices (actuator, stiffness profile, mounting) with the design they go with.

A preset answers "which model is this result from?" in one word, so any figure can be cross-checked
against another model: ``spirob-hil design/model export/board/run/experiment --preset NAME``, or from code
``hil.sim.presets.preset("authors")`` (a :class:`hil.sim.config.ModelConfig`) and
``PRESETS["authors"].design_preset``. ``docs/plant.md`` tabulates them with their sources.
"""

from __future__ import annotations

from dataclasses import dataclass

from hil.sim.config import ActuatorConfig, ArmConfig, ModelConfig

__all__ = ["PRESETS", "Preset", "preset", "preset_names"]


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
    """

    name: str
    summary: str
    design_preset: str
    cables: int | None
    model: ModelConfig
    source: str


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
    """The plant model of the preset ``name``.

    Raises:
        ValueError: no preset of that name (the message lists them).
    """
    if name not in PRESETS:
        raise ValueError(f"unknown model preset {name!r}; choose from {', '.join(PRESETS)}")
    return PRESETS[name].model
