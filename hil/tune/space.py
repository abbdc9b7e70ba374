"""What ``spirob-hil tune`` searches: the grasp controller's firmware parameters and the structural choices
the firmware already has as parameters, one define-by-run function both Optuna and Ray Tune's Optuna search
call.

Structural choices (categorical): ``grasp_strategy_on`` (the paper's pack, reach, contact, wrap; off: a
plain ramp that curls from the tip), ``grasp_hold_length`` (HOLD holds the pulling cables' length instead
of their tension). When HOLD is declared is ``grasp_contact_dwell_us`` (the pulling cables still this long
at the wrap tension) with ``grasp_wrap_n`` and ``grasp_wrap_rate_n_per_s``. The reach and contact keys
are searched only with the strategy on (define-by-run: they mean nothing to the ramp).

Every range lies inside its row's bounds (``controller.params``); a test checks that every point the
space can give is a valid firmware configuration.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Final, Protocol

from controller.config import FirmwareConfig
from hil.trial.grasp import grasp_firmware

__all__ = [
    "DIMENSIONS",
    "Dimension",
    "SearchTrial",
    "baseline_points",
    "firmware_values",
    "suggest",
]


class SearchTrial(Protocol):
    """The part of ``optuna.trial.Trial`` the space uses (Ray Tune's Optuna search passes the same)."""

    def suggest_categorical(self, name: str, choices: Any) -> Any: ...

    def suggest_float(
        self, name: str, low: float, high: float, *, step: float | None = None, log: bool = False
    ) -> float: ...

    def suggest_int(self, name: str, low: int, high: int, *, step: int = 1, log: bool = False) -> int: ...


@dataclass(frozen=True)
class Dimension:
    """One searched firmware key.

    Attributes:
        name: the flat firmware key (``controller.params``).
        low: lower end (ignored for a categorical).
        high: upper end.
        log: searched on a log scale.
        step: an int key's step (0: a float key).
        choices: a categorical key's choices (empty: a number).
        strategy_only: searched only with the strategy on.
    """

    name: str
    low: float = 0.0
    high: float = 0.0
    log: bool = False
    step: int = 0
    choices: tuple[Any, ...] = ()
    strategy_only: bool = False

    def sample(self, trial: SearchTrial) -> Any:
        """This key's value for ``trial``."""
        if self.choices:
            return trial.suggest_categorical(self.name, list(self.choices))
        if self.step:
            return trial.suggest_int(self.name, int(self.low), int(self.high), step=self.step)
        return trial.suggest_float(self.name, self.low, self.high, log=self.log)


# fmt: off
DIMENSIONS: Final[tuple[Dimension, ...]] = (
    Dimension("grasp_strategy_on", choices=(True, False)),
    Dimension("grasp_hold_length", choices=(False, True)),
    Dimension("grasp_wrap_n", 3.0, 20.0),                      # tension_max_n is 20 N
    Dimension("grasp_wrap_rate_n_per_s", 2.0, 80.0, log=True),
    Dimension("grasp_contact_dwell_us", 20_000, 200_000, step=10_000),  # also when HOLD is declared
    Dimension("slew_n_per_s", 10.0, 200.0, log=True),
    Dimension("grasp_pack_n", 8.0, 20.0, strategy_only=True),
    Dimension("grasp_reach_n", 0.0, 3.5, strategy_only=True),  # below half the smallest pack (4 N)
    Dimension("grasp_reach_rate_n_per_s", 3.0, 40.0, log=True, strategy_only=True),
    Dimension("grasp_takeup_n", 0.0, 4.0, strategy_only=True),
    Dimension("grasp_contact_slow_ratio", 0.3, 0.95, strategy_only=True),
    Dimension("grasp_contact_rest_m", 0.0, 0.1, strategy_only=True),
)
"""The searched keys, in the order they are sampled."""
# fmt: on


def suggest(trial: SearchTrial) -> dict[str, Any]:
    """The searched keys' values for ``trial`` (define-by-run: the strategy's keys only with it on)."""
    values: dict[str, Any] = {}
    for dim in DIMENSIONS:
        if dim.strategy_only and not values["grasp_strategy_on"]:
            continue
        values[dim.name] = dim.sample(trial)
    return values


def firmware_values(searched: Mapping[str, Any]) -> dict[str, Any]:
    """The firmware keys of a searched point: the point, and with the strategy on the reach timeout the
    grasp experiments derive from the reach ramp (the ramp's duration + 0.6 s, :func:`grasp_firmware`).

    Raises:
        ConfigError: values the firmware refuses (checked on top of the experiments' firmware).
    """
    values = dict(searched)
    if values.get("grasp_strategy_on", True):  # written out, so the row's inputs say it
        values["grasp_reach_timeout_us"] = grasp_firmware(**values).grasp.reach_timeout_us
    grasp_firmware(**values)  # the whole point, checked as the trial will build it
    return values


def baseline_points() -> dict[str, dict[str, Any]]:
    """The two controllers every tuning starts from and is judged against, as searched points: the
    firmware's defaults with the strategy on (``default``) and off (``ramp``)."""
    flat = FirmwareConfig().to_dict()
    out: dict[str, dict[str, Any]] = {}
    for label, on in (("default", True), ("ramp", False)):
        point = {"grasp_strategy_on": on}
        for dim in DIMENSIONS[1:]:
            if on or not dim.strategy_only:
                point[dim.name] = flat[dim.name]
        out[label] = point
    return out
