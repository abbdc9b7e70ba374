"""The pymavlink dialect (forced to MAVLink 2) and the constants and enums of our message set.

The only module of the package that imports pymavlink: ``MAVLINK20=1`` must be in the environment
before ``pymavlink.mavutil`` is first imported (see :mod:`protocol.mavlink`).
"""

from __future__ import annotations

import os
import struct

# Must precede the first pymavlink import (see the package docstring).
os.environ["MAVLINK20"] = "1"

from enum import IntEnum
from typing import Any, ClassVar, Final

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
MAV_AUTOPILOT_ARDUPILOTMEGA: Final[int] = int(_D.MAV_AUTOPILOT_ARDUPILOTMEGA)
MAV_AUTOPILOT_PX4: Final[int] = int(_D.MAV_AUTOPILOT_PX4)
MAV_MODE_FLAG_CUSTOM_MODE_ENABLED: Final[int] = int(_D.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED)
MAV_MODE_FLAG_SAFETY_ARMED: Final[int] = int(_D.MAV_MODE_FLAG_SAFETY_ARMED)
MAV_CMD_DO_GRIPPER: Final[int] = int(_D.MAV_CMD_DO_GRIPPER)
MAV_CMD_REQUEST_MESSAGE: Final[int] = int(_D.MAV_CMD_REQUEST_MESSAGE)
MAV_CMD_REQUEST_PROTOCOL_VERSION: Final[int] = int(_D.MAV_CMD_REQUEST_PROTOCOL_VERSION)
MAV_COMP_ID_ALL: Final[int] = int(_D.MAV_COMP_ID_ALL)
MIN_COMPONENT_ID: Final[int] = 7
"""The lowest component id we may take: MAVLink reserves 0..6 (0 broadcast, 1 the autopilot, 2..6
reserved by the payload guidance), so a gripper must not use them."""
DEFAULT_COMPONENT_ID: Final[int] = int(_D.MAV_COMP_ID_USER1)
"""``MAV_COMP_ID_USER1`` (25): there is no standard gripper component id."""
MSG_ID_HEARTBEAT: Final[int] = int(_D.MAVLINK_MSG_ID_HEARTBEAT)
MSG_ID_AUTOPILOT_VERSION: Final[int] = int(_D.MAVLINK_MSG_ID_AUTOPILOT_VERSION)
MSG_ID_PROTOCOL_VERSION: Final[int] = 300
"""``PROTOCOL_VERSION``: in MAVLink's ``minimal.xml`` but not in pymavlink's generated dialects, so
:class:`ProtocolVersionMessage` below supplies it."""
MAV_PROTOCOL_CAPABILITY_MAVLINK2: Final[int] = int(_D.MAV_PROTOCOL_CAPABILITY_MAVLINK2)
MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE: Final[int] = int(
    _D.MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE
)
MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_C_CAST: Final[int] = int(_D.MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_C_CAST)
MAV_PROTOCOL_CAPABILITY_COMMAND_INT: Final[int] = int(_D.MAV_PROTOCOL_CAPABILITY_COMMAND_INT)
MAVLINK_VERSION_X100: Final[int] = 200
"""``PROTOCOL_VERSION.version``: MAVLink 2.0 times 100."""
NAMED_VALUE_NAME_MAX: Final[int] = 10
PARAM_ID_MAX: Final[int] = 16
STATUSTEXT_CHUNK_LEN: Final[int] = 50
ACTUATOR_SLOTS: Final[int] = 32
SERVO_OUTPUTS_PER_PORT: Final[int] = 16
"""``SERVO_OUTPUT_RAW`` carries 16 outputs; ``port`` selects the group (0 = outputs 1..16)."""
SIGNING_KEY_LEN: Final[int] = 32
SIGNING_EPOCH_UNIX_S: Final[int] = 1_420_070_400
"""2015-01-01 00:00:00 UTC, the zero of the MAVLink signing timestamp."""
PARAM_INDEX_NONE: Final[int] = 0xFFFF
"""``PARAM_VALUE.param_index`` when the value was not fetched by index (-1 as int16)."""


class MavResult(IntEnum):
    """``MAV_RESULT`` of a ``COMMAND_ACK`` (values from the dialect)."""

    ACCEPTED = int(_D.MAV_RESULT_ACCEPTED)
    TEMPORARILY_REJECTED = int(_D.MAV_RESULT_TEMPORARILY_REJECTED)
    DENIED = int(_D.MAV_RESULT_DENIED)
    UNSUPPORTED = int(_D.MAV_RESULT_UNSUPPORTED)
    FAILED = int(_D.MAV_RESULT_FAILED)
    IN_PROGRESS = int(_D.MAV_RESULT_IN_PROGRESS)
    COMMAND_LONG_ONLY = int(_D.MAV_RESULT_COMMAND_LONG_ONLY)
    COMMAND_INT_ONLY = int(_D.MAV_RESULT_COMMAND_INT_ONLY)


class GripperAction(IntEnum):
    """``GRIPPER_ACTIONS``: ``MAV_CMD_DO_GRIPPER`` param2 (values from the dialect)."""

    RELEASE = int(_D.GRIPPER_ACTION_RELEASE)
    GRAB = int(_D.GRIPPER_ACTION_GRAB)
    HOLD = int(_D.GRIPPER_ACTION_HOLD)


class Severity(IntEnum):
    """``MAV_SEVERITY`` of a ``STATUSTEXT`` (RFC-5424 order: lower is worse; values from the dialect)."""

    EMERGENCY = int(_D.MAV_SEVERITY_EMERGENCY)
    ALERT = int(_D.MAV_SEVERITY_ALERT)
    CRITICAL = int(_D.MAV_SEVERITY_CRITICAL)
    ERROR = int(_D.MAV_SEVERITY_ERROR)
    WARNING = int(_D.MAV_SEVERITY_WARNING)
    NOTICE = int(_D.MAV_SEVERITY_NOTICE)
    INFO = int(_D.MAV_SEVERITY_INFO)
    DEBUG = int(_D.MAV_SEVERITY_DEBUG)


class MavState(IntEnum):
    """``MAV_STATE``: ``HEARTBEAT.system_status`` (values from the dialect)."""

    UNINIT = int(_D.MAV_STATE_UNINIT)
    BOOT = int(_D.MAV_STATE_BOOT)
    CALIBRATING = int(_D.MAV_STATE_CALIBRATING)
    STANDBY = int(_D.MAV_STATE_STANDBY)
    ACTIVE = int(_D.MAV_STATE_ACTIVE)
    CRITICAL = int(_D.MAV_STATE_CRITICAL)
    EMERGENCY = int(_D.MAV_STATE_EMERGENCY)
    POWEROFF = int(_D.MAV_STATE_POWEROFF)
    FLIGHT_TERMINATION = int(_D.MAV_STATE_FLIGHT_TERMINATION)


class ParamType(IntEnum):
    """``MAV_PARAM_TYPE`` (values from the dialect)."""

    UINT8 = int(_D.MAV_PARAM_TYPE_UINT8)
    INT8 = int(_D.MAV_PARAM_TYPE_INT8)
    UINT16 = int(_D.MAV_PARAM_TYPE_UINT16)
    INT16 = int(_D.MAV_PARAM_TYPE_INT16)
    UINT32 = int(_D.MAV_PARAM_TYPE_UINT32)
    INT32 = int(_D.MAV_PARAM_TYPE_INT32)
    UINT64 = int(_D.MAV_PARAM_TYPE_UINT64)
    INT64 = int(_D.MAV_PARAM_TYPE_INT64)
    REAL32 = int(_D.MAV_PARAM_TYPE_REAL32)
    REAL64 = int(_D.MAV_PARAM_TYPE_REAL64)


class ProtocolVersionMessage(_D.MAVLink_message):  # type: ignore[misc,name-defined]
    """``PROTOCOL_VERSION`` (300) as a pymavlink message (pymavlink generates no class for it).

    Wire layout and CRC extra (217) as MAVLink's ``minimal.xml`` defines them; registered in the
    dialect's message map so the codec decodes it too.
    """

    id = MSG_ID_PROTOCOL_VERSION
    msgname = "PROTOCOL_VERSION"
    fieldnames: ClassVar[list[str]] = [
        "version",
        "min_version",
        "max_version",
        "spec_version_hash",
        "library_version_hash",
    ]
    ordered_fieldnames: ClassVar[list[str]] = fieldnames
    fieldtypes: ClassVar[list[str]] = ["uint16_t", "uint16_t", "uint16_t", "uint8_t", "uint8_t"]
    fielddisplays_by_name: ClassVar[dict[str, str]] = {}
    fieldenums_by_name: ClassVar[dict[str, str]] = {}
    fieldunits_by_name: ClassVar[dict[str, str]] = {}
    native_format = bytearray(b"<HHHBB")
    orders: ClassVar[list[int]] = [0, 1, 2, 3, 4]
    lengths: ClassVar[list[int]] = [1, 1, 1, 1, 1]  # the hashes unpack as one 8-byte string each
    array_lengths: ClassVar[list[int]] = [0, 0, 0, 8, 8]
    crc_extra = 217
    unpacker = struct.Struct("<HHH8s8s")
    instance_field = None
    instance_offset = -1

    def __init__(
        self,
        version: int,
        min_version: int,
        max_version: int,
        spec_version_hash: bytes = bytes(8),
        library_version_hash: bytes = bytes(8),
    ) -> None:
        _D.MAVLink_message.__init__(self, MSG_ID_PROTOCOL_VERSION, "PROTOCOL_VERSION")
        self._fieldnames = ProtocolVersionMessage.fieldnames
        self._instance_field = None
        self._instance_offset = -1
        self.version = version
        self.min_version = min_version
        self.max_version = max_version
        self.spec_version_hash = spec_version_hash
        self.library_version_hash = library_version_hash

    def pack(self, mav: Any, force_mavlink1: bool = False) -> bytes:
        """Pack for pymavlink's ``MAVLink.send`` (the signature pymavlink's generated classes have)."""
        payload = self.unpacker.pack(
            self.version,
            self.min_version,
            self.max_version,
            bytes(self.spec_version_hash),
            bytes(self.library_version_hash),
        )
        return bytes(self._pack(mav, self.crc_extra, payload, force_mavlink1=force_mavlink1))


_D.mavlink_map.setdefault(MSG_ID_PROTOCOL_VERSION, ProtocolVersionMessage)
