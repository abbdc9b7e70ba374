"""Our MAVLink message set as frozen dataclasses, the received-packet envelope and STATUSTEXT chunking."""

from __future__ import annotations

from dataclasses import dataclass, field

from protocol.mavlink.dialect import MAV_AUTOPILOT_INVALID, STATUSTEXT_CHUNK_LEN, MavState, ParamType


@dataclass(frozen=True)
class Heartbeat:
    """``HEARTBEAT`` (0): presence and state of a component, 1 Hz."""

    mav_type: int
    autopilot: int = MAV_AUTOPILOT_INVALID
    base_mode: int = 0
    custom_mode: int = 0
    system_status: int = MavState.STANDBY
    mavlink_version: int = 3


@dataclass(frozen=True)
class CommandLong:
    """``COMMAND_LONG`` (76): a command with seven float parameters."""

    target_system: int
    target_component: int
    command: int
    params: tuple[float, float, float, float, float, float, float] = (0.0,) * 7
    confirmation: int = 0


@dataclass(frozen=True)
class CommandInt:
    """``COMMAND_INT`` (75): a command with four float and three integer parameters (x, y scaled)."""

    target_system: int
    target_component: int
    command: int
    params: tuple[float, float, float, float] = (0.0,) * 4
    x: int = 0
    y: int = 0
    z: float = 0.0
    frame: int = 0

    def as_long(self) -> CommandLong:
        """The same command as a ``COMMAND_LONG`` (x, y as plain numbers; the frame dropped).

        Returns:
            The equivalent ``COMMAND_LONG`` (confirmation 0: ``COMMAND_INT`` has none).
        """
        p = self.params
        return CommandLong(
            self.target_system,
            self.target_component,
            self.command,
            (p[0], p[1], p[2], p[3], float(self.x), float(self.y), self.z),
        )


@dataclass(frozen=True)
class CommandAck:
    """``COMMAND_ACK`` (77). ``target_*`` name the commander so a GCS knows the reply is for it."""

    command: int
    result: int
    progress: int = 0
    result_param2: int = 0
    target_system: int = 0
    target_component: int = 0


@dataclass(frozen=True)
class NamedValueFloat:
    """``NAMED_VALUE_FLOAT`` (251): one named float (name at most 10 ASCII characters)."""

    time_boot_ms: int
    name: str
    value: float


@dataclass(frozen=True)
class ActuatorOutputStatus:
    """``ACTUATOR_OUTPUT_STATUS`` (375): up to 32 output values; ``active`` = outputs in use (PX4)."""

    time_usec: int
    active: int
    actuator: tuple[float, ...]


@dataclass(frozen=True)
class StatusText:
    """``STATUSTEXT`` (253): one chunk of at most 50 characters; ``text_id`` > 0 joins chunks."""

    severity: int
    text: str
    text_id: int = 0
    chunk_seq: int = 0


@dataclass(frozen=True)
class ParamRequestList:
    """``PARAM_REQUEST_LIST`` (21): send every parameter."""

    target_system: int
    target_component: int


@dataclass(frozen=True)
class ParamRequestRead:
    """``PARAM_REQUEST_READ`` (20): one parameter, by ``param_index`` or (index -1) by ``param_id``."""

    target_system: int
    target_component: int
    param_id: str
    param_index: int = -1


@dataclass(frozen=True)
class ParamValue:
    """``PARAM_VALUE`` (22): a parameter's current value (``param_index`` 65535 = not by index)."""

    param_id: str
    param_value: float
    param_type: int
    param_count: int
    param_index: int


@dataclass(frozen=True)
class ParamSet:
    """``PARAM_SET`` (23): ask a component to take a value; it answers with ``PARAM_VALUE``."""

    target_system: int
    target_component: int
    param_id: str
    param_value: float
    param_type: int = ParamType.REAL32


@dataclass(frozen=True)
class Attitude:
    """``ATTITUDE`` (30): the drone's attitude (FRD body, NED world)."""

    time_boot_ms: int
    roll_rad: float
    pitch_rad: float
    yaw_rad: float
    rollspeed_rad_s: float = 0.0
    pitchspeed_rad_s: float = 0.0
    yawspeed_rad_s: float = 0.0


@dataclass(frozen=True)
class LocalPositionNed:
    """``LOCAL_POSITION_NED`` (32): the drone's position and velocity in the local NED frame."""

    time_boot_ms: int
    x_m: float
    y_m: float
    z_m: float
    vx_m_s: float = 0.0
    vy_m_s: float = 0.0
    vz_m_s: float = 0.0


@dataclass(frozen=True)
class ServoOutputRaw:
    """``SERVO_OUTPUT_RAW`` (36): an autopilot's output PWM in µs, outputs ``16 * port + 1`` onwards."""

    time_usec: int
    port: int
    servo_raw_us: tuple[int, ...]


@dataclass(frozen=True)
class AutopilotVersion:
    """``AUTOPILOT_VERSION`` (148): capabilities and software version (the rest zero)."""

    capabilities: int
    flight_sw_version: int = 0
    vendor_id: int = 0
    product_id: int = 0


@dataclass(frozen=True)
class ProtocolVersion:
    """``PROTOCOL_VERSION`` (300): MAVLink versions spoken (times 100)."""

    version: int
    min_version: int
    max_version: int


@dataclass(frozen=True)
class Unhandled:
    """A well-formed packet of the dialect that is outside our message set."""

    msg_type: str
    msg_id: int


MavMessage = (
    Heartbeat
    | CommandLong
    | CommandInt
    | CommandAck
    | NamedValueFloat
    | ActuatorOutputStatus
    | StatusText
    | ParamRequestList
    | ParamRequestRead
    | ParamValue
    | ParamSet
    | Attitude
    | LocalPositionNed
    | ServoOutputRaw
    | AutopilotVersion
    | ProtocolVersion
    | Unhandled
)
"""Every message type this module decodes (``Unhandled`` is decode-only)."""


@dataclass(frozen=True)
class MavPacket:
    """One received packet: the decoded message and its header.

    Attributes:
        msg: The decoded message.
        src_system: Sender's system id.
        src_component: Sender's component id.
        seq: Sender's packet sequence number.
        signed: True when the packet carried a signature that verified.
        raw: The packet's bytes exactly as received (for the ``.tlog``).
    """

    msg: MavMessage
    src_system: int
    src_component: int
    seq: int
    signed: bool
    raw: bytes = field(repr=False)


def statustext_chunks(severity: int, text: str, text_id: int) -> list[StatusText]:
    """Split a text into ``STATUSTEXT`` chunks (MAVLink 2 chunking).

    A text of at most 50 characters is one chunk with id 0. A longer one is sent as chunks sharing
    ``text_id`` (1..65535) with ``chunk_seq`` 0, 1, ...; a receiver joins them until a chunk shorter
    than 50 characters, so a text whose length is a multiple of 50 ends with an empty chunk.
    Non-ASCII characters become ``?``.

    Args:
        severity: ``MAV_SEVERITY`` value.
        text: The message.
        text_id: Id shared by the chunks of a long text (ignored for a short one).

    Returns:
        The chunks in order (at most 256; longer texts are cut).
    """
    ascii_text = text.encode("ascii", errors="replace").decode("ascii")
    if len(ascii_text) <= STATUSTEXT_CHUNK_LEN:
        return [StatusText(int(severity), ascii_text)]
    if not 1 <= text_id <= 0xFFFF:
        raise ValueError(f"text_id out of range 1..65535: {text_id}")
    ascii_text = ascii_text[: STATUSTEXT_CHUNK_LEN * 256 - 1]
    chunks = [
        StatusText(int(severity), ascii_text[i : i + STATUSTEXT_CHUNK_LEN], text_id, n)
        for n, i in enumerate(range(0, len(ascii_text), STATUSTEXT_CHUNK_LEN))
    ]
    if len(ascii_text) % STATUSTEXT_CHUNK_LEN == 0:
        chunks.append(StatusText(int(severity), "", text_id, len(chunks)))
    return chunks
