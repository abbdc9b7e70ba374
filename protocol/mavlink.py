"""MAVLink 2 for the drone link: our message set as frozen dataclasses over pymavlink.

Nothing above this module handles pymavlink objects: :class:`MavCodec` turns our dataclasses into
packet bytes and a byte stream into :class:`MavPacket` envelopes. The codec binds a pymavlink
``MAVLink`` object to an in-memory sink, so this module does no I/O and reads no clock; the host's
``host.drone_link`` moves the bytes.

Facts (pymavlink 2.4.50, MAVProxy 1.8.75, checked on this machine):

- ``MAVLINK20=1`` must be in the environment before ``pymavlink.mavutil`` is first imported, or it
  loads the MAVLink 1 dialect (no signing, no message ids above 255). This module sets it and, if
  ``mavutil`` was already imported without it, reloads the current dialect as MAVLink 2. The dialect is
  process-global; the default is ``all``, which has ``MAV_TYPE_GRIPPER`` (48).
- Signing (MAVLink 2): the key is 32 bytes; MAVProxy derives it as SHA-256(passphrase). The signing
  timestamp counts 10 µs units since 2015-01-01 00:00:00 UTC and must never go backwards for a stream.
- pymavlink records a signed stream's timestamp *before* it compares the signature, so one forged
  packet with a far-future timestamp would lock the real sender out (every later packet "too old").
  :meth:`MavCodec.feed` undoes that bookkeeping for packets whose signature fails.
"""

from __future__ import annotations

import hashlib
import os

# Must precede the first pymavlink import (see module docstring).
os.environ["MAVLINK20"] = "1"

from collections.abc import Callable
from dataclasses import dataclass, field
from enum import IntEnum
from typing import Any, Final

from pymavlink import mavutil

if str(mavutil.mavlink.WIRE_PROTOCOL_VERSION) != "2.0":  # imported earlier without MAVLINK20
    mavutil.set_dialect(mavutil.current_dialect)

__all__ = [
    "ACTUATOR_SLOTS",
    "DEFAULT_COMPONENT_ID",
    "MAV_AUTOPILOT_INVALID",
    "MAV_CMD_DO_GRIPPER",
    "MAV_COMP_ID_ALL",
    "MAV_TYPE_ARM",
    "NAMED_VALUE_NAME_MAX",
    "PARAM_ID_MAX",
    "PARAM_INDEX_NONE",
    "SIGNING_EPOCH_UNIX_S",
    "SIGNING_KEY_LEN",
    "STATUSTEXT_CHUNK_LEN",
    "ActuatorOutputStatus",
    "Attitude",
    "CommandAck",
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
    "Severity",
    "StatusText",
    "Unhandled",
    "decode_packets",
    "dialect",
    "signing_key_from_file_bytes",
    "signing_key_from_passphrase",
    "signing_timestamp_from_unix_us",
    "statustext_chunks",
]


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

_MSG_ID_RADIO_STATUS: Final[int] = 109
_MSG_ID_RADIO: Final[int] = 166


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


# --------------------------------------------------------------------------------------------------
# Messages


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
class Unhandled:
    """A well-formed packet of the dialect that is outside our message set."""

    msg_type: str
    msg_id: int


MavMessage = (
    Heartbeat
    | CommandLong
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


# --------------------------------------------------------------------------------------------------
# Signing helpers (pure: the caller reads files and clocks)


def signing_key_from_passphrase(passphrase: str) -> bytes:
    """Return the 32-byte signing key for a passphrase, as MAVProxy derives it (SHA-256).

    Args:
        passphrase: The passphrase (MAVProxy takes ASCII; UTF-8 is used here).

    Returns:
        SHA-256 of the passphrase.
    """
    if not passphrase:
        raise ValueError("empty signing passphrase")
    return hashlib.sha256(passphrase.encode("utf-8")).digest()


def signing_key_from_file_bytes(data: bytes) -> bytes:
    """Interpret a key file's content: exactly 32 bytes is the raw key, anything else a passphrase.

    A passphrase file may end with a newline; surrounding whitespace is stripped before hashing.

    Args:
        data: The whole content of the key file.

    Returns:
        The 32-byte key.

    Raises:
        ValueError: The file is empty or its passphrase is not UTF-8.
    """
    if len(data) == SIGNING_KEY_LEN:
        return bytes(data)
    try:
        passphrase = data.decode("utf-8").strip()
    except UnicodeDecodeError as exc:
        raise ValueError("signing key file is neither 32 raw bytes nor a UTF-8 passphrase") from exc
    return signing_key_from_passphrase(passphrase)


def signing_timestamp_from_unix_us(unix_us: int) -> int:
    """Convert a Unix time in µs to a MAVLink signing timestamp (10 µs units since 2015-01-01).

    Args:
        unix_us: Microseconds since 1970-01-01 UTC.

    Returns:
        The signing timestamp (0 for times before 2015).
    """
    return max(0, (unix_us - SIGNING_EPOCH_UNIX_S * 1_000_000) // 10)


# --------------------------------------------------------------------------------------------------
# Codec


class _Sink:
    """The file-like object pymavlink's ``MAVLink`` writes packed packets into."""

    def __init__(self) -> None:
        self.chunks: list[bytes] = []

    def write(self, data: bytes) -> None:
        self.chunks.append(bytes(data))

    def take(self) -> bytes:
        data = b"".join(self.chunks)
        self.chunks.clear()
        return data


def _str(value: Any) -> str:
    if isinstance(value, bytes | bytearray):
        return bytes(value).split(b"\x00", 1)[0].decode("ascii", errors="replace")
    return str(value)


def _decode(m: Any) -> MavMessage:
    """Turn a pymavlink message into our dataclass (``Unhandled`` for the rest)."""
    t = m.get_type()
    if t == "HEARTBEAT":
        return Heartbeat(m.type, m.autopilot, m.base_mode, m.custom_mode, m.system_status, m.mavlink_version)
    if t == "COMMAND_LONG":
        params = (m.param1, m.param2, m.param3, m.param4, m.param5, m.param6, m.param7)
        return CommandLong(m.target_system, m.target_component, m.command, params, m.confirmation)
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


def _encode(d: Any, msg: MavMessage) -> Any:
    """Turn our dataclass into a pymavlink message (validating ranges pymavlink would not)."""
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
    raise TypeError(f"cannot encode {type(msg).__name__}")


class MavCodec:
    """Encode our messages to MAVLink 2 packets and decode a received byte stream, without I/O.

    One codec per link: it owns the outgoing sequence number and the signing state. ``feed`` never
    raises on bad bytes; it counts them.

    Args:
        src_system: Our system id (1..255).
        src_component: Our component id (1..255).

    Attributes:
        packets_in: Well-formed packets decoded (including ``Unhandled`` ones).
        packets_out: Packets encoded.
        bytes_in: Bytes fed.
        malformed: Garbage runs, bad CRCs, bad lengths and undecodable payloads.
        unknown_ids: Packets whose message id the dialect does not know. They cannot be CRC-checked,
            so they are never delivered and their bytes are rescanned.
        signature_refused: Packets refused by signing (unsigned, wrong key or replayed).
        refused_by_msg_id: The same, by message id (at most 256 ids tracked).
    """

    def __init__(self, src_system: int, src_component: int) -> None:
        if not 1 <= src_system <= 255:
            raise ValueError(f"src_system out of range 1..255: {src_system}")
        if not 1 <= src_component <= 255:
            raise ValueError(f"src_component out of range 1..255: {src_component}")
        self._d = dialect()
        self._sink = _Sink()
        self._mav = self._d.MAVLink(self._sink, srcSystem=src_system, srcComponent=src_component)
        self._mav.robust_parsing = True  # bad bytes come back as BAD_DATA instead of raising
        self._allow_unsigned: Callable[[int], bool] = lambda _msg_id: False
        self.packets_in = 0
        self.packets_out = 0
        self.bytes_in = 0
        self.malformed = 0
        self.unknown_ids = 0
        self.signature_refused = 0
        self.refused_by_msg_id: dict[int, int] = {}

    @property
    def src_system(self) -> int:
        """Our system id."""
        return int(self._mav.srcSystem)

    @property
    def src_component(self) -> int:
        """Our component id."""
        return int(self._mav.srcComponent)

    # ---- signing -------------------------------------------------------------------------------

    def enable_signing(
        self,
        key: bytes,
        *,
        timestamp: int,
        link_id: int = 0,
        allow_unsigned: Callable[[int], bool] | None = None,
    ) -> None:
        """Sign every outgoing packet and refuse incoming ones that are not correctly signed.

        Args:
            key: The 32-byte secret key.
            timestamp: Initial signing timestamp (10 µs units since 2015; see
                :func:`signing_timestamp_from_unix_us`). Pass the larger of the clock and the last
                persisted value so it never goes backwards across restarts.
            link_id: Our signing link id (0..255).
            allow_unsigned: Decides, by message id, whether an unsigned or badly signed packet is
                accepted anyway. Default: only ``RADIO_STATUS`` and ``RADIO`` (from telemetry radios
                that cannot sign), as MAVProxy does.
        """
        if not isinstance(key, bytes) or len(key) != SIGNING_KEY_LEN:
            raise ValueError(f"signing key must be {SIGNING_KEY_LEN} bytes")
        if not 0 <= link_id <= 255:
            raise ValueError(f"link_id out of range 0..255: {link_id}")
        if timestamp < 0:
            raise ValueError("signing timestamp must be >= 0")
        self._allow_unsigned = allow_unsigned or (lambda mid: mid in (_MSG_ID_RADIO_STATUS, _MSG_ID_RADIO))
        s = self._mav.signing
        s.secret_key = key
        s.sign_outgoing = True
        s.link_id = link_id
        s.timestamp = int(timestamp)
        s.allow_unsigned_callback = self._unsigned_callback

    def disable_signing(self) -> None:
        """Stop signing and accept unsigned packets again."""
        s = self._mav.signing
        s.secret_key = None
        s.sign_outgoing = False
        s.allow_unsigned_callback = None
        s.link_id = 0

    @property
    def signing_enabled(self) -> bool:
        """True when a signing key is set."""
        return self._mav.signing.secret_key is not None

    @property
    def signing_timestamp(self) -> int:
        """The next outgoing signing timestamp (10 µs units since 2015); persist it to survive restarts."""
        return int(self._mav.signing.timestamp)

    def advance_signing_timestamp(self, timestamp: int) -> None:
        """Raise the signing timestamp to at least ``timestamp`` (it never goes backwards).

        Args:
            timestamp: A signing timestamp, typically from the clock.
        """
        s = self._mav.signing
        s.timestamp = max(int(s.timestamp), int(timestamp))

    @property
    def signatures_good(self) -> int:
        """Incoming packets whose signature verified."""
        return int(self._mav.signing.goodsig_count)

    @property
    def signatures_bad(self) -> int:
        """Incoming signed packets whose signature (key or timestamp) did not verify."""
        return int(self._mav.signing.badsig_count)

    def _unsigned_callback(self, _mav: Any, msg_id: int) -> bool:
        accepted = bool(self._allow_unsigned(int(msg_id)))
        if not accepted:
            self.signature_refused += 1
            if len(self.refused_by_msg_id) < 256 or msg_id in self.refused_by_msg_id:
                self.refused_by_msg_id[int(msg_id)] = self.refused_by_msg_id.get(int(msg_id), 0) + 1
        return accepted

    # ---- encode / decode -----------------------------------------------------------------------

    def encode(self, msg: MavMessage) -> bytes:
        """Pack one message as a MAVLink 2 packet (signed when signing is on).

        Advances the sequence number (and the signing timestamp when signing).

        Args:
            msg: Any message of our set except ``Unhandled``.

        Returns:
            The packet bytes.

        Raises:
            ValueError: A field is out of its wire range (names too long, non-ASCII, ...).
            TypeError: ``msg`` is not one of our messages.
        """
        m = _encode(self._d, msg)
        self._sink.take()
        self._mav.send(m)
        self.packets_out += 1
        return self._sink.take()

    def discard_partial(self) -> int:
        """Drop an incomplete packet held from earlier input (call at a datagram boundary).

        Over UDP every datagram holds whole packets, so leftovers are garbage; keeping them would let
        one truncated datagram swallow the first packet of the next.

        Returns:
            Bytes dropped (counted once as ``malformed`` when non-zero).
        """
        n = int(self._mav.buf_len())
        if n:
            self.malformed += 1
        self._reset_parser()
        return n

    def _rewind(self, data: bytes) -> None:
        mav_ = self._mav
        mav_.buf = bytearray(data) + mav_.buf[mav_.buf_index :]
        mav_.buf_index = 0
        mav_.expected_length = self._d.HEADER_LEN_V1 + 2

    def _reset_parser(self) -> None:
        self._mav.buf = bytearray()
        self._mav.buf_index = 0
        self._mav.expected_length = self._d.HEADER_LEN_V1 + 2

    def feed(self, data: bytes) -> list[MavPacket]:
        """Decode whatever complete packets ``data`` (plus earlier leftovers) holds.

        Never raises on bad bytes: garbage, bad CRCs and refused signatures are counted and skipped,
        and parsing resumes at the next start marker.

        Args:
            data: Bytes as they arrived (any split: half packets are kept for the next call).

        Returns:
            The good packets in arrival order.
        """
        self.bytes_in += len(data)
        out: list[MavPacket] = []
        signing = self._mav.signing
        chunk: bytes = bytes(data)
        # Each parse step consumes at least one byte for good (a rewind gives back all but the
        # first) or returns None, so this bounds the loop.
        for _ in range(len(data) + self._mav.buf_len() + 2):
            before = dict(signing.stream_timestamps) if signing.secret_key is not None else None
            try:
                m = self._mav.parse_char(chunk)
            except Exception:  # pymavlink may raise outside robust mode paths; never let it escape
                self.malformed += 1
                self._reset_parser()
                break
            chunk = b""
            if m is None:
                break
            mtype = m.get_type()
            if mtype == "BAD_DATA":
                reason = str(getattr(m, "reason", ""))
                if reason.startswith("Invalid signature"):
                    if before is not None:
                        signing.stream_timestamps = before  # see the module docstring
                    continue
                self.malformed += 1
                if reason != "Bad prefix" and len(m.data) > 1:
                    # A false start marker (or a damaged packet) made pymavlink swallow a whole
                    # "packet" of bytes, which may hold the start of a good one: rescan from the byte
                    # after the marker instead of dropping them.
                    self._rewind(bytes(m.data[1:]))
                continue
            if mtype.startswith("UNKNOWN_"):
                # pymavlink returns an unknown message id before checking the CRC (it has no CRC
                # extra for it), so this may be garbage that hides the start of a good packet:
                # count it, never deliver it, and rescan its bytes.
                self.unknown_ids += 1
                self._rewind(bytes(m.get_msgbuf())[1:])
                continue
            try:
                msg = _decode(m)
            except Exception:  # a field pymavlink accepted but we cannot represent
                self.malformed += 1
                continue
            self.packets_in += 1
            out.append(
                MavPacket(
                    msg,
                    int(m.get_srcSystem()),
                    int(m.get_srcComponent()),
                    int(m.get_seq()),
                    bool(m.get_signed()),
                    bytes(m.get_msgbuf()),
                )
            )
        return out


def decode_packets(data: bytes, codec: MavCodec | None = None) -> list[MavPacket]:
    """Decode a byte string with a fresh (or the given) codec; a convenience for tools and tests.

    Args:
        data: Concatenated packets.
        codec: Codec to use (its signing state applies); a new one (ids 255/190) if None.

    Returns:
        The good packets.
    """
    return (codec or MavCodec(255, 190)).feed(data)
