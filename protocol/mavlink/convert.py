"""Our dataclasses <-> pymavlink message objects: the builders (with the range checks pymavlink
does not make) and the parser side's field mapping."""

from __future__ import annotations

from typing import Any

from protocol.mavlink.dialect import (
    ACTUATOR_SLOTS,
    NAMED_VALUE_NAME_MAX,
    PARAM_ID_MAX,
    SERVO_OUTPUTS_PER_PORT,
    STATUSTEXT_CHUNK_LEN,
    ProtocolVersionMessage,
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
    NamedValueFloat,
    ParamRequestList,
    ParamRequestRead,
    ParamSet,
    ParamValue,
    ProtocolVersion,
    ServoOutputRaw,
    StatusText,
    Unhandled,
)


def _ascii(text: str, limit: int, what: str) -> bytes:
    try:
        raw = text.encode("ascii")
    except UnicodeEncodeError as exc:
        raise ValueError(f"{what} must be ASCII: {text!r}") from exc
    if len(raw) > limit:
        raise ValueError(f"{what} longer than {limit} characters: {text!r}")
    return raw


def _u8(value: int, what: str) -> int:
    if not 0 <= value <= 0xFF:
        raise ValueError(f"{what} out of range 0..255: {value}")
    return value


def _str(value: Any) -> str:
    if isinstance(value, bytes | bytearray):
        return bytes(value).split(b"\x00", 1)[0].decode("ascii", errors="replace")
    return str(value)


def from_pymavlink(m: Any) -> MavMessage:
    """Turn a pymavlink message into our dataclass (``Unhandled`` for the rest).

    Args:
        m: A message pymavlink parsed.

    Returns:
        Our dataclass for it.
    """
    t = m.get_type()
    if t == "HEARTBEAT":
        return Heartbeat(m.type, m.autopilot, m.base_mode, m.custom_mode, m.system_status, m.mavlink_version)
    if t == "COMMAND_LONG":
        params = (m.param1, m.param2, m.param3, m.param4, m.param5, m.param6, m.param7)
        return CommandLong(m.target_system, m.target_component, m.command, params, m.confirmation)
    if t == "COMMAND_INT":
        params4 = (m.param1, m.param2, m.param3, m.param4)
        return CommandInt(m.target_system, m.target_component, m.command, params4, m.x, m.y, m.z, m.frame)
    if t == "SERVO_OUTPUT_RAW":
        servos = tuple(int(getattr(m, f"servo{i}_raw", 0)) for i in range(1, SERVO_OUTPUTS_PER_PORT + 1))
        return ServoOutputRaw(m.time_usec, m.port, servos)
    if t == "AUTOPILOT_VERSION":
        return AutopilotVersion(m.capabilities, m.flight_sw_version, m.vendor_id, m.product_id)
    if t == "PROTOCOL_VERSION":
        return ProtocolVersion(m.version, m.min_version, m.max_version)
    if t == "COMMAND_ACK":
        return CommandAck(
            m.command, m.result, m.progress, m.result_param2, m.target_system, m.target_component
        )
    if t == "NAMED_VALUE_FLOAT":
        return NamedValueFloat(m.time_boot_ms, _str(m.name), m.value)
    if t == "ACTUATOR_OUTPUT_STATUS":
        return ActuatorOutputStatus(m.time_usec, m.active, tuple(m.actuator))
    if t == "STATUSTEXT":
        return StatusText(m.severity, _str(m.text), m.id, m.chunk_seq)
    if t == "PARAM_REQUEST_LIST":
        return ParamRequestList(m.target_system, m.target_component)
    if t == "PARAM_REQUEST_READ":
        return ParamRequestRead(m.target_system, m.target_component, _str(m.param_id), m.param_index)
    if t == "PARAM_VALUE":
        return ParamValue(_str(m.param_id), m.param_value, m.param_type, m.param_count, m.param_index)
    if t == "PARAM_SET":
        return ParamSet(m.target_system, m.target_component, _str(m.param_id), m.param_value, m.param_type)
    if t == "ATTITUDE":
        return Attitude(m.time_boot_ms, m.roll, m.pitch, m.yaw, m.rollspeed, m.pitchspeed, m.yawspeed)
    if t == "LOCAL_POSITION_NED":
        return LocalPositionNed(m.time_boot_ms, m.x, m.y, m.z, m.vx, m.vy, m.vz)
    return Unhandled(str(t), int(m.get_msgId()))


def to_pymavlink(d: Any, msg: MavMessage) -> Any:
    """Turn our dataclass into a pymavlink message (validating ranges pymavlink would not).

    Args:
        d: The pymavlink dialect module.
        msg: Any message of our set except ``Unhandled``.

    Returns:
        The pymavlink message object.

    Raises:
        ValueError: A field is out of its wire range.
        TypeError: ``msg`` is not one of our messages.
    """
    if isinstance(msg, Heartbeat):
        return d.MAVLink_heartbeat_message(
            _u8(msg.mav_type, "type"),
            _u8(msg.autopilot, "autopilot"),
            _u8(msg.base_mode, "base_mode"),
            msg.custom_mode,
            _u8(msg.system_status, "system_status"),
            _u8(msg.mavlink_version, "mavlink_version"),
        )
    if isinstance(msg, CommandLong):
        if len(msg.params) != 7:
            raise ValueError("COMMAND_LONG takes exactly 7 params")
        return d.MAVLink_command_long_message(
            _u8(msg.target_system, "target_system"),
            _u8(msg.target_component, "target_component"),
            msg.command,
            _u8(msg.confirmation, "confirmation"),
            *(float(p) for p in msg.params),
        )
    if isinstance(msg, CommandAck):
        return d.MAVLink_command_ack_message(
            msg.command,
            _u8(msg.result, "result"),
            _u8(msg.progress, "progress"),
            msg.result_param2,
            _u8(msg.target_system, "target_system"),
            _u8(msg.target_component, "target_component"),
        )
    if isinstance(msg, NamedValueFloat):
        name = _ascii(msg.name, NAMED_VALUE_NAME_MAX, "NAMED_VALUE_FLOAT name")
        return d.MAVLink_named_value_float_message(msg.time_boot_ms, name, float(msg.value))
    if isinstance(msg, ActuatorOutputStatus):
        if len(msg.actuator) > ACTUATOR_SLOTS:
            raise ValueError(f"ACTUATOR_OUTPUT_STATUS has at most {ACTUATOR_SLOTS} outputs")
        values = [float(v) for v in msg.actuator] + [0.0] * (ACTUATOR_SLOTS - len(msg.actuator))
        return d.MAVLink_actuator_output_status_message(msg.time_usec, msg.active, values)
    if isinstance(msg, StatusText):
        text = _ascii(msg.text, STATUSTEXT_CHUNK_LEN, "STATUSTEXT text")
        return d.MAVLink_statustext_message(_u8(msg.severity, "severity"), text, msg.text_id, msg.chunk_seq)
    if isinstance(msg, ParamRequestList):
        return d.MAVLink_param_request_list_message(msg.target_system, msg.target_component)
    if isinstance(msg, ParamRequestRead):
        pid = _ascii(msg.param_id, PARAM_ID_MAX, "param_id")
        return d.MAVLink_param_request_read_message(
            msg.target_system, msg.target_component, pid, msg.param_index
        )
    if isinstance(msg, ParamValue):
        pid = _ascii(msg.param_id, PARAM_ID_MAX, "param_id")
        return d.MAVLink_param_value_message(
            pid, float(msg.param_value), msg.param_type, msg.param_count, msg.param_index
        )
    if isinstance(msg, ParamSet):
        pid = _ascii(msg.param_id, PARAM_ID_MAX, "param_id")
        return d.MAVLink_param_set_message(
            msg.target_system, msg.target_component, pid, float(msg.param_value), msg.param_type
        )
    if isinstance(msg, Attitude):
        return d.MAVLink_attitude_message(
            msg.time_boot_ms,
            msg.roll_rad,
            msg.pitch_rad,
            msg.yaw_rad,
            msg.rollspeed_rad_s,
            msg.pitchspeed_rad_s,
            msg.yawspeed_rad_s,
        )
    if isinstance(msg, LocalPositionNed):
        return d.MAVLink_local_position_ned_message(
            msg.time_boot_ms, msg.x_m, msg.y_m, msg.z_m, msg.vx_m_s, msg.vy_m_s, msg.vz_m_s
        )
    if isinstance(msg, CommandInt):
        return d.MAVLink_command_int_message(
            _u8(msg.target_system, "target_system"),
            _u8(msg.target_component, "target_component"),
            _u8(msg.frame, "frame"),
            msg.command,
            0,
            0,
            *(float(p) for p in msg.params),
            msg.x,
            msg.y,
            float(msg.z),
        )
    if isinstance(msg, ServoOutputRaw):
        if len(msg.servo_raw_us) > SERVO_OUTPUTS_PER_PORT:
            raise ValueError(f"SERVO_OUTPUT_RAW has at most {SERVO_OUTPUTS_PER_PORT} outputs")
        pwm = [int(v) for v in msg.servo_raw_us] + [0] * (SERVO_OUTPUTS_PER_PORT - len(msg.servo_raw_us))
        return d.MAVLink_servo_output_raw_message(msg.time_usec & 0xFFFFFFFF, _u8(msg.port, "port"), *pwm)
    if isinstance(msg, AutopilotVersion):
        return d.MAVLink_autopilot_version_message(
            msg.capabilities,
            msg.flight_sw_version,
            0,
            0,
            0,
            [0] * 8,
            [0] * 8,
            [0] * 8,
            msg.vendor_id,
            msg.product_id,
            0,
        )
    if isinstance(msg, ProtocolVersion):
        return ProtocolVersionMessage(msg.version, msg.min_version, msg.max_version)
    raise TypeError(f"cannot encode {type(msg).__name__}")
