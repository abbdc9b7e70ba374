"""The pymavlink dialect (forced to MAVLink 2) and the constants and enums of our message set.

The only module of the package that imports pymavlink: ``MAVLINK20=1`` must be in the environment
before ``pymavlink.mavutil`` is first imported (see :mod:`protocol.mavlink`).
"""

from __future__ import annotations

import os

# Must precede the first pymavlink import (see the package docstring).
os.environ["MAVLINK20"] = "1"

from enum import IntEnum
from typing import Any, Final

from pymavlink import mavutil

if str(mavutil.mavlink.WIRE_PROTOCOL_VERSION) != "2.0":  # imported earlier without MAVLINK20
    mavutil.set_dialect(mavutil.current_dialect)


def dialect() -> Any:
    """Return the pymavlink dialect module in use (process-global, MAVLink 2)."""
    return mavutil.mavlink


_D = dialect()

MAV_TYPE_ARM: Final[int] = int(getattr(_D, "MAV_TYPE_GRIPPER", _D.MAV_TYPE_ONBOARD_CONTROLLER))
"""``HEARTBEAT.type`` of the arm: ``MAV_TYPE_GRIPPER`` (48), else ``MAV_TYPE_ONBOARD_CONTROLLER``."""
MAV_AUTOPILOT_INVALID: Final[int] = int(_D.MAV_AUTOPILOT_INVALID)
"""8: "not a flight controller"; autopilots and GCSs do not treat us as a vehicle."""
MAV_CMD_DO_GRIPPER: Final[int] = 211
MAV_COMP_ID_ALL: Final[int] = 0
DEFAULT_COMPONENT_ID: Final[int] = 25
"""``MAV_COMP_ID_USER1``: there is no standard gripper component id."""
NAMED_VALUE_NAME_MAX: Final[int] = 10
PARAM_ID_MAX: Final[int] = 16
STATUSTEXT_CHUNK_LEN: Final[int] = 50
ACTUATOR_SLOTS: Final[int] = 32
SIGNING_KEY_LEN: Final[int] = 32
SIGNING_EPOCH_UNIX_S: Final[int] = 1_420_070_400
"""2015-01-01 00:00:00 UTC, the zero of the MAVLink signing timestamp."""
PARAM_INDEX_NONE: Final[int] = 0xFFFF
"""``PARAM_VALUE.param_index`` when the value was not fetched by index (-1 as int16)."""


class MavResult(IntEnum):
    """``MAV_RESULT`` of a ``COMMAND_ACK``."""

    ACCEPTED = 0
    TEMPORARILY_REJECTED = 1
    DENIED = 2
    UNSUPPORTED = 3
    FAILED = 4
    IN_PROGRESS = 5


class GripperAction(IntEnum):
    """``GRIPPER_ACTIONS``: ``MAV_CMD_DO_GRIPPER`` param2."""

    RELEASE = 0
    GRAB = 1
    HOLD = 2


class Severity(IntEnum):
    """``MAV_SEVERITY`` of a ``STATUSTEXT`` (RFC-5424 order: lower is worse)."""

    EMERGENCY = 0
    ALERT = 1
    CRITICAL = 2
    ERROR = 3
    WARNING = 4
    NOTICE = 5
    INFO = 6
    DEBUG = 7


class MavState(IntEnum):
    """``MAV_STATE``: ``HEARTBEAT.system_status``."""

    UNINIT = 0
    BOOT = 1
    CALIBRATING = 2
    STANDBY = 3
    ACTIVE = 4
    CRITICAL = 5
    EMERGENCY = 6
    POWEROFF = 7


class ParamType(IntEnum):
    """``MAV_PARAM_TYPE`` (the firmware's tunables are all ``REAL32``)."""

    UINT8 = 1
    INT8 = 2
    UINT16 = 3
    INT16 = 4
    UINT32 = 5
    INT32 = 6
    UINT64 = 7
    INT64 = 8
    REAL32 = 9
    REAL64 = 10
