"""Exceptions of the controller package (one small tree, like ``protocol.errors``).

Bad arguments raise plain ``ValueError`` (configuration errors are also ``ValueError``); faults the
firmware survives (a lost motor, a bad RC frame) are never exceptions: they are phases and counters.
"""

from __future__ import annotations

__all__ = ["BusError", "ClockError", "ConfigError", "ControllerError", "PortError"]


class ControllerError(Exception):
    """Base class of every exception raised by ``controller``."""


class ConfigError(ControllerError, ValueError):
    """A :class:`~controller.config.FirmwareConfig` value is out of range or of the wrong type."""


class ClockError(ControllerError):
    """A clock was asked to do something it cannot (e.g. step a lockstep clock backwards)."""


class PortError(ControllerError, OSError):
    """A serial port or CAN channel could not be opened (missing, busy, or not permitted)."""


class BusError(ControllerError):
    """A motor bus back end failed to send or receive (counted by ``MotorBus``, never fatal to the loop)."""
