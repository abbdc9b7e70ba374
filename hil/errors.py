"""Exceptions of the hil package (one small tree, like ``protocol.errors`` and ``controller.errors``).

Bad arguments raise plain ``ValueError``; everything the harness itself detects derives from
:class:`HilError`.
"""

from __future__ import annotations

__all__ = ["HilError", "PlantDivergedError"]


class HilError(Exception):
    """Base class of the exceptions raised by ``hil``."""


class PlantDivergedError(HilError):
    """The physics produced NaN/Inf or an absurd velocity: the plant's state is no longer meaningful.

    Call :meth:`hil.sim.plant.Plant.reset` before stepping again.

    Attributes:
        time_us: simulated time of the control period in which the divergence was detected.
    """

    def __init__(self, message: str, time_us: int) -> None:
        super().__init__(message)
        self.time_us = time_us

    def __reduce__(self) -> tuple[type[PlantDivergedError], tuple[str, int]]:
        # Picklable with its time: a worker process's divergence reaches the parent (multiprocessing
        # rebuilds an exception from its args, which lack the time).
        return (type(self), (str(self), self.time_us))
