"""MAVLink 2 for the drone link: our message set as frozen dataclasses over pymavlink.

Nothing above this package handles pymavlink objects: :class:`MavCodec` turns our dataclasses into
packet bytes and a byte stream into :class:`MavPacket` envelopes. The codec binds a pymavlink
``MAVLink`` object to an in-memory sink, so this package does no I/O and reads no clock; the host's
``host.drone.link`` moves the bytes. Callers import everything from here; the modules are
``dialect`` (MAVLink 2 forced, constants, enums; the only one importing pymavlink), ``messages``
(the dataclasses), ``convert`` (dataclass <-> pymavlink object), ``codec`` (:class:`MavCodec`) and
``signing`` (key and timestamp helpers) and ``param_encoding`` (typed values in ``param_value``).

Facts (pymavlink 2.4.50, MAVProxy 1.8.75, checked on this machine):

- ``MAVLINK20=1`` must be in the environment before ``pymavlink.mavutil`` is first imported, or it
  loads the MAVLink 1 dialect (no signing, no message ids above 255). ``dialect`` sets it and, if
  ``mavutil`` was already imported without it, reloads the current dialect as MAVLink 2. The dialect is
  process-global; the default is ``all``, which has ``MAV_TYPE_GRIPPER`` (48).
- Signing (MAVLink 2): the key is 32 bytes; MAVProxy derives it as SHA-256(passphrase). The signing
  timestamp counts 10 µs units since 2015-01-01 00:00:00 UTC and must never go backwards for a stream.
- pymavlink records a signed stream's timestamp *before* it compares the signature, so one forged
  packet with a far-future timestamp would lock the real sender out (every later packet "too old").
  :meth:`MavCodec.feed` undoes that bookkeeping for packets whose signature fails.
"""

from __future__ import annotations

from protocol.mavlink.codec import MavCodec, decode_packets
from protocol.mavlink.dialect import (
    ACTUATOR_SLOTS,
    DEFAULT_COMPONENT_ID,
    MAV_AUTOPILOT_ARDUPILOTMEGA,
    MAV_AUTOPILOT_INVALID,
    MAV_AUTOPILOT_PX4,
    MAV_CMD_DO_GRIPPER,
    MAV_CMD_REQUEST_MESSAGE,
    MAV_CMD_REQUEST_PROTOCOL_VERSION,
    MAV_COMP_ID_ALL,
    MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
    MAV_MODE_FLAG_SAFETY_ARMED,
    MAV_PROTOCOL_CAPABILITY_COMMAND_INT,
    MAV_PROTOCOL_CAPABILITY_MAVLINK2,
    MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE,
    MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_C_CAST,
    MAV_TYPE_ARM,
    MAVLINK_VERSION_X100,
    MIN_COMPONENT_ID,
    MSG_ID_AUTOPILOT_VERSION,
    MSG_ID_HEARTBEAT,
    MSG_ID_PROTOCOL_VERSION,
    NAMED_VALUE_NAME_MAX,
    PARAM_ID_MAX,
    PARAM_INDEX_NONE,
    SERVO_OUTPUTS_PER_PORT,
    SIGNING_EPOCH_UNIX_S,
    SIGNING_KEY_LEN,
    STATUSTEXT_CHUNK_LEN,
    GripperAction,
    MavResult,
    MavState,
    ParamType,
    Severity,
    dialect,
)
from protocol.mavlink.messages import (
    ActuatorOutputStatus,
    Attitude,
    AutopilotVersion,
    CommandAck,
    CommandInt,
    CommandLong,
    Heartbeat,
    LocalPositionNed,
    MavMessage,
    MavPacket,
    NamedValueFloat,
    ParamRequestList,
    ParamRequestRead,
    ParamSet,
    ParamValue,
    ProtocolVersion,
    ServoOutputRaw,
    StatusText,
    Unhandled,
    statustext_chunks,
)
from protocol.mavlink.param_encoding import decode_param_value, encode_param_value, param_type_range
from protocol.mavlink.signing import (
    signing_key_from_file_bytes,
    signing_key_from_passphrase,
    signing_timestamp_from_unix_us,
)

__all__ = [
    "ACTUATOR_SLOTS",
    "DEFAULT_COMPONENT_ID",
    "MAVLINK_VERSION_X100",
    "MAV_AUTOPILOT_ARDUPILOTMEGA",
    "MAV_AUTOPILOT_INVALID",
    "MAV_AUTOPILOT_PX4",
    "MAV_CMD_DO_GRIPPER",
    "MAV_CMD_REQUEST_MESSAGE",
    "MAV_CMD_REQUEST_PROTOCOL_VERSION",
    "MAV_COMP_ID_ALL",
    "MAV_MODE_FLAG_CUSTOM_MODE_ENABLED",
    "MAV_MODE_FLAG_SAFETY_ARMED",
    "MAV_PROTOCOL_CAPABILITY_COMMAND_INT",
    "MAV_PROTOCOL_CAPABILITY_MAVLINK2",
    "MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE",
    "MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_C_CAST",
    "MAV_TYPE_ARM",
    "MIN_COMPONENT_ID",
    "MSG_ID_AUTOPILOT_VERSION",
    "MSG_ID_HEARTBEAT",
    "MSG_ID_PROTOCOL_VERSION",
    "NAMED_VALUE_NAME_MAX",
    "PARAM_ID_MAX",
    "PARAM_INDEX_NONE",
    "SERVO_OUTPUTS_PER_PORT",
    "SIGNING_EPOCH_UNIX_S",
    "SIGNING_KEY_LEN",
    "STATUSTEXT_CHUNK_LEN",
    "ActuatorOutputStatus",
    "Attitude",
    "AutopilotVersion",
    "CommandAck",
    "CommandInt",
    "CommandLong",
    "GripperAction",
    "Heartbeat",
    "LocalPositionNed",
    "MavCodec",
    "MavMessage",
    "MavPacket",
    "MavResult",
    "MavState",
    "NamedValueFloat",
    "ParamRequestList",
    "ParamRequestRead",
    "ParamSet",
    "ParamType",
    "ParamValue",
    "ProtocolVersion",
    "ServoOutputRaw",
    "Severity",
    "StatusText",
    "Unhandled",
    "decode_packets",
    "decode_param_value",
    "dialect",
    "encode_param_value",
    "param_type_range",
    "signing_key_from_file_bytes",
    "signing_key_from_passphrase",
    "signing_timestamp_from_unix_us",
    "statustext_chunks",
]
