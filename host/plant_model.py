"""The plant models the host simulates: the virtual board's and the shadow plant's (``--preset``).

``--preset NAME`` is one of ``hil.sim.presets.PRESETS``; ``--preset FILE.toml`` a model fitted by ``spirob-hil
identify`` (``hil.sim.presets.resolve``), which brings the recorded arm's design with it. Without ``--port``
the virtual board is built from it (design and plant model; the ``--object`` objects are placed in that
plant), so the recording's metadata (``BoardConfig.describe``: design, firmware) describes the arm that ran.
With ``--port`` it is the shadow plant's model. hil is imported only here and only when called.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Any

from host.errors import HostError
from host.object_spec import ObjectSpec, plant_objects

__all__ = ["ARMS_MAX", "array_cables", "resolve_preset", "shadow_plant_factory", "virtual_board_config"]

ARMS_MAX = 8
"""Most arms of a virtual board (``--arms``): the C-board drives eight motors, an arm needs one at least."""
_MOTORS = 8
_CABLES_MAX = 3


def array_cables(arms: int) -> int:
    """Cables per arm of a virtual array of ``arms`` arms: the most that fit the board's eight motors, at
    most three (1-2 arms: 3, 3-4: 2, 5-8: 1).

    Raises:
        ValueError: ``arms`` is not 1-8.
    """
    if not 1 <= arms <= ARMS_MAX:
        raise ValueError(f"arms must be 1..{ARMS_MAX}, got {arms}")
    return min(_CABLES_MAX, _MOTORS // arms)


def resolve_preset(spec: str | None) -> Any:
    """The ``hil.sim.presets.Preset`` of ``--preset`` (None without one).

    Raises:
        HostError: an unknown name or a model file that cannot be used (one line).
    """
    if spec is None:
        return None
    from hil.sim.presets import resolve  # type: ignore[import-not-found,unused-ignore]

    try:
        return resolve(spec)
    except ValueError as exc:
        raise HostError(f"--preset {spec}: {exc}") from exc


def virtual_board_config(base: Any, preset: Any, objects: tuple[ObjectSpec, ...], arms: int = 1) -> Any:
    """The virtual board's ``hil.board.BoardConfig``.

    Args:
        base: the configuration to start from (None: the prototype arm, RC over the link).
        preset: a ``Preset`` whose design and plant model replace ``base``'s (None: keep them).
        objects: ``--object`` objects added to the plant, placed in its (the preset's) model.
        arms: ``--arms``: more than one lays the firmware out as that many arms of
            :func:`array_cables` cables and gives the design as many cables (the board builds the plant
            as a ring of them); 1 keeps ``base``'s layout.
    """
    from hil.board import BoardConfig  # type: ignore[import-not-found,unused-ignore]

    config = base if base is not None else BoardConfig(rc="link")
    if preset is not None:
        plant = dataclasses.replace(config.plant, model=preset.model)
        config = dataclasses.replace(config, design=preset.spiral(), plant=plant)
    if arms != 1:
        cables = array_cables(arms)
        config = dataclasses.replace(
            config,
            design=config.design.with_cables(cables),
            firmware=config.firmware.with_arms(arms, cables),
        )
    if objects:
        model = config.plant.model
        model = model.with_objects(*plant_objects(objects, model))
        config = dataclasses.replace(config, plant=dataclasses.replace(config.plant, model=model))
    return config


def shadow_plant_factory(preset: Any) -> Callable[[], Any] | None:
    """What builds the shadow plant of ``preset`` (in the shadow's thread); None: the default plant."""
    if preset is None:
        return None
    design, model = preset.spiral(), preset.model

    def build() -> Any:
        from hil.sim.plant import Plant  # type: ignore[import-not-found,unused-ignore]
        from hil.sim.types import PlantConfig  # type: ignore[import-not-found,unused-ignore]

        return Plant(design, PlantConfig(model=model))

    return build
