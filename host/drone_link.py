"""The MAVLink drone link: the arm as a gripper component on the drone's MAVLink network.

:class:`DroneLink` owns one pymavlink connection (any ``mavutil.mavlink_connection`` string:
``udpout:127.0.0.1:14550``, ``udpin:...``, ``tcp:...``, a serial device) and runs it in its own thread.
It speaks as component ``compid`` (default 25) of the drone's system ``sysid`` (default 1):

- out: ``HEARTBEAT`` at 1 Hz (``MAV_TYPE_GRIPPER``, ``MAV_AUTOPILOT_INVALID``); ``NAMED_VALUE_FLOAT``
  tensions, mode, failsafe phase and grasp state, and ``ACTUATOR_OUTPUT_STATUS`` motor currents, at
  ``telemetry_rate_hz`` (10 Hz); ``STATUSTEXT`` for board events, refusals and grasp results;
- in: ``COMMAND_LONG`` ``MAV_CMD_DO_GRIPPER`` (grab / release / hold) with the ACK sequence of
  docs/mavlink.md (``IN_PROGRESS`` then ``ACCEPTED`` / ``FAILED``; ``TEMPORARILY_REJECTED`` while busy;
  ``DENIED`` for bad params or when the radio does not allow it; ``UNSUPPORTED`` for other commands);
  the parameter protocol mirroring the firmware's parameters; the drone's ``ATTITUDE`` and
  ``LOCAL_POSITION_NED`` for the panel;
- optional MAVLink 2 signing (unsigned or wrongly signed packets refused and counted, the signing
  timestamp persisted across restarts) and a ``.tlog`` of every packet in and out.

The board side is decoupled: the host feeds every board message to :meth:`DroneLink.on_board_message`
(``protocol.messages`` objects; thread-safe) and the link sends ``Command`` / ``ParamRequest`` /
``ParamSet`` through the ``send_to_board`` callable it was given (called from the link thread).

The radio stays the master enable: DO_GRIPPER acts only while the latest telemetry shows the board
armed, failsafe phase OK and mode GRASP (right lever UP), and a job in progress fails on any failsafe.
"""

from __future__ import annotations

import contextlib
import logging
import math
import os
import queue
import struct
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path
from types import TracebackType
from typing import IO, Any, Final

from protocol import mavlink as mav
from protocol import messages as bm

__all__ = [
    "TLOG_LINK_IN",
    "TLOG_LINK_OUT",
    "DroneLink",
    "DroneLinkConfig",
    "DroneLinkCounters",
    "DroneLinkError",
    "DroneLinkState",
    "DronePose",
    "GripperCommand",
    "PeerInfo",
    "TlogWriter",
    "gripper_denial",
    "load_signing_key",
]

TLOG_LINK_IN: Final[int] = 0
"""Low two bits of a ``.tlog`` timestamp for a received packet (MAVProxy puts the link number there)."""
TLOG_LINK_OUT: Final[int] = 3
"""Low two bits for a packet we sent (MAVProxy's value for its own outgoing packets)."""

_MAV_MODE_FLAG_CUSTOM_MODE_ENABLED: Final[int] = 1
_MAV_MODE_FLAG_SAFETY_ARMED: Final[int] = 128
_US_PER_S: Final[int] = 1_000_000
_MAX_PEERS: Final[int] = 64
_BOARD_QUEUE_LEN: Final[int] = 4096
_BOARD_MSGS_PER_CYCLE: Final[int] = 512
_READS_PER_CYCLE: Final[int] = 64
_PARAMS_PER_CYCLE: Final[int] = 10
_STATUSTEXT_PER_S: Final[int] = 10
_SIGNING_PERSIST_PERIOD_US: Final[int] = 10 * _US_PER_S
_SIGNING_RESTART_MARGIN: Final[int] = 2 * _SIGNING_PERSIST_PERIOD_US // 10
"""Added to a persisted signing timestamp on start (10 µs units): 2 persist periods' worth, far more
than the +1 per packet we can have sent after the last save."""
_ACK_REPLAY_WINDOW_US: Final[int] = 3 * _US_PER_S

_FAILSAFE_PHASES: Final = frozenset({bm.Phase.RC_LOST, bm.Phase.MOTOR_FAULT, bm.Phase.HOST_LOST})
_BUSY_STATES: Final = frozenset({bm.GraspState.REACH, bm.GraspState.WRAP, bm.GraspState.RELEASE})
_PROGRESS_PCT: Final[dict[bm.GraspState, int]] = {
    bm.GraspState.IDLE: 0,
    bm.GraspState.REACH: 30,
    bm.GraspState.WRAP: 70,
    bm.GraspState.HOLD: 100,
    bm.GraspState.RELEASE: 50,
    bm.GraspState.FAILED: 0,
}


_log = logging.getLogger(__name__)


class DroneLinkError(Exception):
    """The drone link could not be opened or configured."""


def _now_us() -> int:
    return time.monotonic_ns() // 1000


def _wall_us() -> int:
    return time.time_ns() // 1000


# --------------------------------------------------------------------------------------------------
# Configuration


@dataclass(frozen=True)
class DroneLinkConfig:
    """Configuration of one drone link (validated on creation).

    Attributes:
        url: pymavlink connection string (``udpout:127.0.0.1:14550``, ``udpin:...``, ``tcp:...``,
            ``/dev/ttyUSB0``).
        sysid: Our system id: the drone's (1..255, default 1).
        compid: Our component id (2..255; never 0 = broadcast or 1 = autopilot; default 25).
        autopilot_compid: Component whose ``ATTITUDE`` / ``LOCAL_POSITION_NED`` pose the drone.
        baud: Serial baud rate (serial devices only).
        heartbeat_period_us: ``HEARTBEAT`` period (1 Hz).
        telemetry_rate_hz: Rate of ``NAMED_VALUE_FLOAT`` and ``ACTUATOR_OUTPUT_STATUS`` (10 Hz).
        board_stale_us: Board telemetry older than this counts as "no board" (DO_GRIPPER denied).
        grasp_timeout_us: A gripper job not finished by then fails.
        param_confirm_timeout_us: A ``PARAM_SET`` the board has not confirmed by then is answered with
            the value in force.
        peer_timeout_us: A peer silent this long is shown as lost.
        poll_period_us: Longest wait of the link thread between two looks at the board queue.
        signing_key: 32-byte MAVLink 2 signing key (None = no signing).
        signing_link_id: Our signing link id.
        signing_timestamp_path: File persisting the signing timestamp across restarts (None = not
            persisted; see :meth:`with_signing_key_file`).
        tlog_path: ``.tlog`` of every packet in and out (None = no log).
    """

    url: str
    sysid: int = 1
    compid: int = mav.DEFAULT_COMPONENT_ID
    autopilot_compid: int = 1
    baud: int = 115_200
    heartbeat_period_us: int = 1_000_000
    telemetry_rate_hz: float = 10.0
    board_stale_us: int = 500_000
    grasp_timeout_us: int = 30_000_000
    param_confirm_timeout_us: int = 1_000_000
    peer_timeout_us: int = 5_000_000
    poll_period_us: int = 5_000
    signing_key: bytes | None = field(default=None, repr=False)
    signing_link_id: int = 0
    signing_timestamp_path: Path | None = None
    tlog_path: Path | None = None

    def __post_init__(self) -> None:
        if not self.url:
            raise ValueError("url is empty")
        if not 1 <= self.sysid <= 255:
            raise ValueError(f"sysid out of range 1..255: {self.sysid}")
        if not 2 <= self.compid <= 255:
            raise ValueError(f"compid must be 2..255 (0 is broadcast, 1 the autopilot): {self.compid}")
        if not 1 <= self.autopilot_compid <= 255:
            raise ValueError(f"autopilot_compid out of range 1..255: {self.autopilot_compid}")
        if not 0.1 <= self.telemetry_rate_hz <= 100.0:
            raise ValueError(f"telemetry_rate_hz out of range 0.1..100: {self.telemetry_rate_hz}")
        for name in (
            "heartbeat_period_us",
            "board_stale_us",
            "grasp_timeout_us",
            "param_confirm_timeout_us",
            "peer_timeout_us",
            "poll_period_us",
        ):
            if getattr(self, name) <= 0:
                raise ValueError(f"{name} must be > 0")
        if not 1_000 <= self.poll_period_us <= 100_000:
            raise ValueError(f"poll_period_us out of range 1000..100000: {self.poll_period_us}")
        if self.signing_key is not None and len(self.signing_key) != mav.SIGNING_KEY_LEN:
            raise ValueError(f"signing_key must be {mav.SIGNING_KEY_LEN} bytes")
        if not 0 <= self.signing_link_id <= 255:
            raise ValueError(f"signing_link_id out of range 0..255: {self.signing_link_id}")

    @property
    def telemetry_period_us(self) -> int:
        """Period of the telemetry messages."""
        return round(_US_PER_S / self.telemetry_rate_hz)

    def with_signing_key_file(self, key_file: Path, timestamp_path: Path | None = None) -> DroneLinkConfig:
        """A copy that signs with the key in ``key_file`` (see :func:`load_signing_key`).

        Args:
            key_file: 32 raw bytes, or a passphrase (hashed with SHA-256 as MAVProxy does).
            timestamp_path: Where to persist the signing timestamp; default ``<key_file>.timestamp``.

        Returns:
            The new configuration.

        Raises:
            DroneLinkError: The key file cannot be read or is empty.
        """
        ts_path = timestamp_path or key_file.with_name(key_file.name + ".timestamp")
        return replace(self, signing_key=load_signing_key(key_file), signing_timestamp_path=ts_path)


def load_signing_key(path: Path) -> bytes:
    """Read a signing key file: exactly 32 bytes = the raw key, otherwise a passphrase.

    Args:
        path: The key file.

    Returns:
        The 32-byte key.

    Raises:
        DroneLinkError: Unreadable, empty or not a UTF-8 passphrase.
    """
    try:
        data = Path(path).read_bytes()
    except OSError as exc:
        raise DroneLinkError(f"cannot read signing key {path}: {exc}") from exc
    try:
        return mav.signing_key_from_file_bytes(data)
    except ValueError as exc:
        raise DroneLinkError(f"bad signing key file {path}: {exc}") from exc


# --------------------------------------------------------------------------------------------------
# State for observers (immutable snapshots)


@dataclass(frozen=True)
class PeerInfo:
    """One MAVLink node heard on the link.

    Attributes:
        sysid: Its system id.
        compid: Its component id.
        mav_type: ``HEARTBEAT.type`` (None until it sent a heartbeat).
        autopilot: ``HEARTBEAT.autopilot`` (None until it sent a heartbeat).
        packets: Packets received from it.
        rate_hz: Packets per second over the last full second.
        last_seen_us: Link-clock time of its last packet.
        alive: Heard within ``peer_timeout_us``.
        signed: Its last packet was signed (and verified).
    """

    sysid: int
    compid: int
    mav_type: int | None
    autopilot: int | None
    packets: int
    rate_hz: float
    last_seen_us: int
    alive: bool
    signed: bool


@dataclass(frozen=True)
class DronePose:
    """Latest drone attitude and local position from the autopilot (either may be None).

    Attributes:
        attitude: Latest ``ATTITUDE``.
        position: Latest ``LOCAL_POSITION_NED``.
        attitude_time_us: Link-clock time it arrived.
        position_time_us: Link-clock time it arrived.
    """

    attitude: mav.Attitude | None = None
    position: mav.LocalPositionNed | None = None
    attitude_time_us: int = 0
    position_time_us: int = 0


@dataclass(frozen=True)
class GripperCommand:
    """The last ``DO_GRIPPER`` (or other command) handled, for the panel.

    Attributes:
        time_us: Link-clock time of the latest ACK.
        src_system: Commander's system id.
        src_component: Commander's component id.
        command: ``MAV_CMD`` number.
        action: ``GripperAction`` value (param2), -1 for other commands.
        result: Latest ``MAV_RESULT`` sent.
        text: Why (for refusals and failures), else empty.
    """

    time_us: int
    src_system: int
    src_component: int
    command: int
    action: int
    result: int
    text: str = ""


@dataclass(frozen=True)
class DroneLinkCounters:
    """Traffic and error counters (monotonic since start).

    Attributes:
        packets_in: Well-formed packets received.
        packets_out: Packets sent.
        bytes_in: Bytes received.
        bytes_out: Bytes sent.
        malformed: Garbage, bad CRC, bad length, undecodable.
        unknown_msg_id: Well-formed packets of message ids the dialect does not know.
        unexpected: Well-formed packets we do not act on (other types, acks, values from peers).
        not_for_us: Commands / parameter requests addressed to another system or component.
        signature_refused: Unsigned or wrongly signed packets refused (signing on).
        own_id_conflicts: Packets claiming our own system and component id.
        board_queue_dropped: Board messages dropped because the queue was full.
        board_unexpected: Board messages of types the link does not use.
        statustext_dropped: STATUSTEXTs dropped by the rate limit.
        io_errors: Read/write errors of the connection, the board callback or the signing file, and
            messages that could not be encoded.
        tlog_records: Records written to the ``.tlog``.
        internal_errors: Link cycles that raised (a bug; logged, the link carries on).
    """

    packets_in: int = 0
    packets_out: int = 0
    bytes_in: int = 0
    bytes_out: int = 0
    malformed: int = 0
    unknown_msg_id: int = 0
    unexpected: int = 0
    not_for_us: int = 0
    signature_refused: int = 0
    own_id_conflicts: int = 0
    board_queue_dropped: int = 0
    board_unexpected: int = 0
    statustext_dropped: int = 0
    io_errors: int = 0
    tlog_records: int = 0
    internal_errors: int = 0


@dataclass(frozen=True)
class DroneLinkState:
    """Everything the panel shows about the MAVLink link.

    Attributes:
        running: The link thread is running.
        url: Connection string.
        sysid: Our system id.
        compid: Our component id.
        signing: Signing is on.
        peers: Nodes heard (sorted by sysid, compid).
        drone: Latest drone pose.
        last_command: Latest command handled (None before any).
        gripper_busy: A DO_GRIPPER job is in progress.
        rx_rate_hz: Packets received per second (last second).
        tx_rate_hz: Packets sent per second (last second).
        params_known: Board parameters mirrored.
        counters: Traffic and error counters.
    """

    running: bool
    url: str
    sysid: int
    compid: int
    signing: bool
    peers: tuple[PeerInfo, ...]
    drone: DronePose
    last_command: GripperCommand | None
    gripper_busy: bool
    rx_rate_hz: float
    tx_rate_hz: float
    params_known: int
    counters: DroneLinkCounters


# --------------------------------------------------------------------------------------------------
# .tlog


class TlogWriter:
    """Append packets to a ``.tlog``: 8-byte big-endian µs Unix timestamp, then the raw packet.

    The timestamp's two low bits carry the direction (:data:`TLOG_LINK_IN` / :data:`TLOG_LINK_OUT`),
    as MAVProxy stores a link number there. ``mavlogdump.py`` and ``mavutil.mavlink_connection(path)``
    read the file back.

    Args:
        path: File to create (truncated if it exists; parent directories are created).
    """

    def __init__(self, path: Path) -> None:
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        self.path = path
        self._file: IO[bytes] | None = open(path, "wb")  # noqa: SIM115 - closed by close()
        self.records = 0

    def write(self, packet: bytes, unix_us: int, link: int) -> None:
        """Write one record (no-op after :meth:`close`).

        Args:
            packet: The raw packet.
            unix_us: Unix time in µs.
            link: :data:`TLOG_LINK_IN` or :data:`TLOG_LINK_OUT`.
        """
        if self._file is None:
            return
        self._file.write(struct.pack(">Q", (unix_us & ~3) | (link & 3)) + packet)
        self.records += 1

    def flush(self) -> None:
        """Flush buffered records to the OS."""
        if self._file is not None:
            self._file.flush()

    def close(self) -> None:
        """Flush and close (safe twice)."""
        if self._file is not None:
            self._file.close()
            self._file = None


# --------------------------------------------------------------------------------------------------
# Gripper gating and jobs


def gripper_denial(telemetry: bm.Telemetry | None, age_us: int, stale_us: int) -> str | None:
    """Why a DO_GRIPPER must be refused given the latest board telemetry, or None if it may act.

    The radio is the master enable: the board must be armed, in failsafe phase OK and in GRASP mode
    (right lever UP).

    Args:
        telemetry: Latest board telemetry (None if none yet).
        age_us: How old it is.
        stale_us: Older than this counts as no telemetry.

    Returns:
        A short reason (fits one STATUSTEXT), or None.
    """
    if telemetry is None or age_us > stale_us:
        return "gripper denied: no board telemetry"
    if telemetry.phase == bm.Phase.GATE:
        return "gripper denied: start-up gate (lever DOWN first)"
    if telemetry.phase != bm.Phase.OK:
        return f"gripper denied: failsafe {_name(bm.Phase, telemetry.phase)}"
    if not telemetry.flags & bm.TelemetryFlags.ARMED:
        return "gripper denied: arm not armed"
    if telemetry.mode != bm.Mode.GRASP:
        return f"gripper denied: mode {_name(bm.Mode, telemetry.mode)}, lever not UP"
    return None


def _name(enum_cls: Any, value: int) -> str:
    try:
        return str(enum_cls(value).name)
    except ValueError:
        return str(value)


_ACTION_TO_BOARD: Final = {
    mav.GripperAction.GRAB: (bm.CommandCode.GRASP, bm.GraspState.HOLD),
    mav.GripperAction.RELEASE: (bm.CommandCode.RELEASE, bm.GraspState.IDLE),
    mav.GripperAction.HOLD: (bm.CommandCode.HOLD, bm.GraspState.HOLD),
}


@dataclass
class _GripperJob:
    """A DO_GRIPPER being carried out (mutable, link thread only)."""

    action: mav.GripperAction
    code: bm.CommandCode
    target: bm.GraspState
    requester: tuple[int, int]
    start_state: bm.GraspState
    deadline_us: int
    progressed: bool = False
    last_state: bm.GraspState = bm.GraspState.IDLE


@dataclass
class _Peer:
    sysid: int
    compid: int
    mav_type: int | None = None
    autopilot: int | None = None
    packets: int = 0
    window_start_packets: int = 0
    rate_hz: float = 0.0
    last_seen_us: int = 0
    signed: bool = False


@dataclass
class _PendingParamSet:
    name: str
    deadline_us: int


# --------------------------------------------------------------------------------------------------
# The link


class DroneLink:
    """The arm's MAVLink component: one connection, one thread, bounded work per cycle.

    Args:
        config: Link configuration.
        send_to_board: Called (from the link thread) with each ``protocol.messages`` message for the
            board (``Command``, ``ParamRequest``, ``ParamSet``). Must not block for long.
        clock_us: Monotonic clock in µs (injectable for tests).
        wall_clock_us: Unix time in µs, for ``.tlog`` stamps and signing timestamps.
        connect: Opens the connection (injectable); default ``mavutil.mavlink_connection``.

    Use as a context manager, or call :meth:`start` and :meth:`close`.
    """

    def __init__(
        self,
        config: DroneLinkConfig,
        send_to_board: Callable[[bm.Message], None],
        *,
        clock_us: Callable[[], int] = _now_us,
        wall_clock_us: Callable[[], int] = _wall_us,
        connect: Callable[[DroneLinkConfig], Any] | None = None,
    ) -> None:
        self.config = config
        self._send_to_board = send_to_board
        self._clock = clock_us
        self._wall = wall_clock_us
        self._connect = connect or _mavutil_connect
        self._codec = mav.MavCodec(config.sysid, config.compid)
        self._datagram = config.url.split(":", 1)[0].lower() in {"udp", "udpin", "udpout", "udpbcast"}
        self._conn: Any = None
        self._tlog: TlogWriter | None = None
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        self._lock = threading.RLock()  # RLock: send_to_board may call back into the link
        self._board_q: queue.Queue[bm.Message] = queue.Queue(maxsize=_BOARD_QUEUE_LEN)
        self._text_q: queue.Queue[tuple[int, str]] = queue.Queue(maxsize=256)
        self._closed = False
        # --- state below: written by the link thread under self._lock --------------------------
        self._c: dict[str, int] = dict.fromkeys(DroneLinkCounters.__dataclass_fields__, 0)
        self._peers: dict[tuple[int, int], _Peer] = {}
        self._pose = DronePose()
        self._last_command: GripperCommand | None = None
        self._telemetry: bm.Telemetry | None = None
        self._telemetry_at_us = 0
        self._job: _GripperJob | None = None
        self._last_final: tuple[tuple[int, int], int, int, int] | None = None  # requester, action, result, t
        self._params: dict[str, tuple[int, float]] = {}  # board name -> (index, value)
        self._param_by_index: dict[int, str] = {}
        self._param_by_upper: dict[str, str] = {}
        self._param_count: int | None = None
        self._param_tx: deque[str] = deque()
        self._param_pending: dict[str, _PendingParamSet] = {}
        self._param_list_asked_us: int | None = None
        self._text_id = 0
        self._text_budget = _STATUSTEXT_PER_S
        self._rx_rate_hz = 0.0
        self._tx_rate_hz = 0.0
        self._rate_window = (0, 0, 0)  # start time, packets_in, packets_out

    # ---- lifecycle -------------------------------------------------------------------------------

    def start(self) -> None:
        """Open the connection (and the ``.tlog``), set up signing and start the link thread.

        Raises:
            DroneLinkError: The connection or the log cannot be opened, or the link was closed.
        """
        if self._closed:
            raise DroneLinkError("DroneLink was closed; create a new one")
        if self._thread is not None:
            return
        cfg = self.config
        if cfg.signing_key is not None:
            self._codec.enable_signing(
                cfg.signing_key, timestamp=self._initial_signing_timestamp(), link_id=cfg.signing_link_id
            )
        try:
            self._conn = self._connect(cfg)
        except Exception as exc:
            raise DroneLinkError(f"cannot open MAVLink connection {cfg.url!r}: {exc}") from exc
        if cfg.tlog_path is not None:
            try:
                self._tlog = TlogWriter(cfg.tlog_path)
            except OSError as exc:
                self._close_conn()
                raise DroneLinkError(f"cannot open tlog {cfg.tlog_path}: {exc}") from exc
        now = self._clock()
        self._rate_window = (now, 0, 0)
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, name="drone-link", daemon=True)
        self._thread.start()

    def close(self) -> None:
        """Stop the thread, persist the signing timestamp, close the log and connection (safe twice)."""
        self._closed = True
        self._stop.set()
        thread, self._thread = self._thread, None
        if thread is not None:
            thread.join(timeout=5.0)
        self._persist_signing_timestamp()
        if self._tlog is not None:
            self._tlog.close()
        self._close_conn()

    def __enter__(self) -> DroneLink:
        self.start()
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    @property
    def running(self) -> bool:
        """True while the link thread runs."""
        t = self._thread
        return t is not None and t.is_alive()

    # ---- inputs from other threads ---------------------------------------------------------------

    def on_board_message(self, msg: bm.Message) -> None:
        """Feed one board message (``Telemetry``, ``Event``, ``ParamValue``, ``CommandAck``, ...).

        Thread-safe and non-blocking; messages are handled by the link thread in order. When the
        queue is full the message is dropped and counted.

        Args:
            msg: A decoded board-link message.
        """
        try:
            self._board_q.put_nowait(msg)
        except queue.Full:
            with self._lock:
                self._c["board_queue_dropped"] += 1

    def send_statustext(self, text: str, severity: int = mav.Severity.INFO) -> None:
        """Queue a ``STATUSTEXT`` (thread-safe; long texts are chunked; rate limited).

        Args:
            text: The message.
            severity: ``MAV_SEVERITY``.
        """
        try:
            self._text_q.put_nowait((int(severity), text))
        except queue.Full:
            with self._lock:
                self._c["statustext_dropped"] += 1

    # ---- observers ----------------------------------------------------------------------------

    def state(self) -> DroneLinkState:
        """A consistent snapshot of the link state for the panel (thread-safe)."""
        with self._lock:
            now = self._clock()
            peers = tuple(
                PeerInfo(
                    p.sysid,
                    p.compid,
                    p.mav_type,
                    p.autopilot,
                    p.packets,
                    p.rate_hz,
                    p.last_seen_us,
                    now - p.last_seen_us <= self.config.peer_timeout_us,
                    p.signed,
                )
                for _, p in sorted(self._peers.items())
            )
            return DroneLinkState(
                running=self.running,
                url=self.config.url,
                sysid=self.config.sysid,
                compid=self.config.compid,
                signing=self._codec.signing_enabled,
                peers=peers,
                drone=self._pose,
                last_command=self._last_command,
                gripper_busy=self._job is not None,
                rx_rate_hz=self._rx_rate_hz,
                tx_rate_hz=self._tx_rate_hz,
                params_known=len(self._params),
                counters=self._counters_locked(),
            )

    @property
    def counters(self) -> DroneLinkCounters:
        """Traffic and error counters (thread-safe snapshot)."""
        with self._lock:
            return self._counters_locked()

    @property
    def signature_refusals(self) -> dict[int, int]:
        """Packets refused by signing, by MAVLink message id (thread-safe copy)."""
        with self._lock:
            return dict(self._codec.refused_by_msg_id)

    @property
    def drone_pose(self) -> DronePose:
        """Latest drone attitude and position."""
        with self._lock:
            return self._pose

    @property
    def signing_timestamp(self) -> int:
        """Current outgoing signing timestamp (10 µs units since 2015; 0 without signing)."""
        with self._lock:
            return self._codec.signing_timestamp if self._codec.signing_enabled else 0

    def _counters_locked(self) -> DroneLinkCounters:
        c = dict(self._c)
        codec = self._codec
        c.update(
            packets_in=codec.packets_in,
            packets_out=codec.packets_out,
            bytes_in=codec.bytes_in,
            malformed=codec.malformed,
            unknown_msg_id=codec.unknown_ids,
            signature_refused=codec.signature_refused,
            tlog_records=self._tlog.records if self._tlog is not None else 0,
        )
        return DroneLinkCounters(**c)

    # ---- the thread ----------------------------------------------------------------------------

    def _run(self) -> None:
        cfg = self.config
        now = self._clock()
        next_hb = now
        next_tel = now + cfg.telemetry_period_us
        next_second = now + _US_PER_S
        next_persist = now + _SIGNING_PERSIST_PERIOD_US
        with self._lock:
            if self._param_count is None:
                self._ask_board_for_all(now)
        wait_s = cfg.poll_period_us / _US_PER_S
        while not self._stop.is_set():
            # Read outside the lock: a stream transport may block while it reconnects, and the
            # panel's state() must not wait for that.
            chunks, read_errors = self._recv_chunks()
            with self._lock:
                try:
                    self._c["io_errors"] += read_errors
                    self._drain_board()
                    for chunk in chunks:
                        self._on_bytes(chunk)
                    self._drain_texts()
                    now = self._clock()
                    if now >= next_hb:
                        next_hb = _next_deadline(next_hb, cfg.heartbeat_period_us, now)
                        self._send(self._heartbeat(now))
                    if now >= next_tel:
                        next_tel = _next_deadline(next_tel, cfg.telemetry_period_us, now)
                        self._send_telemetry(now)
                    self._send_params()
                    self._check_timeouts(now)
                    if now >= next_second:
                        next_second = _next_deadline(next_second, _US_PER_S, now)
                        self._every_second(now)
                    if now >= next_persist:
                        next_persist = now + _SIGNING_PERSIST_PERIOD_US
                        self._codec.advance_signing_timestamp(
                            mav.signing_timestamp_from_unix_us(self._wall())
                        )
                        self._persist_signing_timestamp()
                except Exception:  # a bug must not silence the drone link: count, log, carry on
                    self._c["internal_errors"] += 1
                    if self._c["internal_errors"] <= 10:
                        _log.exception("drone link cycle failed")
            self._wait(wait_s)

    def _wait(self, timeout_s: float) -> None:
        conn = self._conn
        try:
            if conn is not None and getattr(conn, "fd", None) is not None:
                conn.select(timeout_s)
            else:
                self._stop.wait(timeout_s)
        except (OSError, ValueError):
            self._stop.wait(timeout_s)

    # ---- I/O -----------------------------------------------------------------------------------

    def _recv_chunks(self) -> tuple[list[bytes], int]:
        """Whatever the connection has (at most 64 reads), and how many reads failed."""
        chunks: list[bytes] = []
        conn = self._conn
        if conn is None:
            return chunks, 0
        for _ in range(_READS_PER_CYCLE):
            try:
                data = conn.recv(4096)
            except Exception:  # socket reset, serial unplugged: count, keep the thread alive
                return chunks, 1
            if not data:
                break
            chunks.append(data.encode("latin-1") if isinstance(data, str) else bytes(data))
        return chunks, 0

    def _on_bytes(self, data: bytes) -> None:
        packets = self._codec.feed(data)
        if self._datagram:
            self._codec.discard_partial()
        for pkt in packets:
            self._on_packet(pkt)

    def _send(self, msg: mav.MavMessage) -> None:
        try:
            data = self._codec.encode(msg)
        except (ValueError, TypeError):  # a value we cannot put on the wire: count, never crash the link
            self._c["io_errors"] += 1
            return
        try:
            self._conn.write(data)
        except Exception:
            self._c["io_errors"] += 1
            return
        self._c["bytes_out"] += len(data)
        if self._tlog is not None:
            self._tlog.write(data, self._wall(), TLOG_LINK_OUT)

    def _board(self, msg: bm.Message) -> None:
        try:
            self._send_to_board(msg)
        except Exception:
            self._c["io_errors"] += 1

    def _close_conn(self) -> None:
        conn, self._conn = self._conn, None
        if conn is not None:
            with contextlib.suppress(Exception):
                conn.close()

    # ---- signing persistence -------------------------------------------------------------------

    def _initial_signing_timestamp(self) -> int:
        ts = mav.signing_timestamp_from_unix_us(self._wall())
        path = self.config.signing_timestamp_path
        if path is not None:
            with contextlib.suppress(OSError, ValueError):
                saved = int(Path(path).read_text(encoding="ascii").strip())
                ts = max(ts, saved + _SIGNING_RESTART_MARGIN)
        return ts

    def _persist_signing_timestamp(self) -> None:
        path = self.config.signing_timestamp_path
        if path is None or not self._codec.signing_enabled:
            return
        path = Path(path)
        tmp = path.with_name(path.name + ".tmp")
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            tmp.write_text(f"{self._codec.signing_timestamp}\n", encoding="ascii")
            os.replace(tmp, path)
        except OSError:
            self._c["io_errors"] += 1

    # ---- incoming MAVLink ----------------------------------------------------------------------

    def _on_packet(self, pkt: mav.MavPacket) -> None:
        now = self._clock()
        if self._tlog is not None:
            self._tlog.write(pkt.raw, self._wall(), TLOG_LINK_IN)
        key = (pkt.src_system, pkt.src_component)
        if key == (self.config.sysid, self.config.compid):
            self._c["own_id_conflicts"] += 1
            return
        self._note_peer(key, pkt, now)
        msg = pkt.msg
        if isinstance(msg, mav.CommandLong):
            self._on_command(msg, key, now)
        elif isinstance(msg, mav.ParamRequestList):
            if self._for_us(msg.target_system, msg.target_component):
                self._on_param_request_list(now)
        elif isinstance(msg, mav.ParamRequestRead):
            if self._for_us(msg.target_system, msg.target_component):
                self._on_param_request_read(msg)
        elif isinstance(msg, mav.ParamSet):
            if self._for_us(msg.target_system, msg.target_component):
                self._on_param_set(msg, now)
        elif isinstance(msg, mav.Attitude) and self._from_autopilot(key):
            self._pose = replace(self._pose, attitude=msg, attitude_time_us=now)
        elif isinstance(msg, mav.LocalPositionNed) and self._from_autopilot(key):
            self._pose = replace(self._pose, position=msg, position_time_us=now)
        elif not isinstance(msg, mav.Heartbeat):
            self._c["unexpected"] += 1

    def _note_peer(self, key: tuple[int, int], pkt: mav.MavPacket, now: int) -> None:
        peer = self._peers.get(key)
        if peer is None:
            if len(self._peers) >= _MAX_PEERS:
                return
            peer = self._peers[key] = _Peer(*key)
        peer.packets += 1
        peer.last_seen_us = now
        peer.signed = pkt.signed
        if isinstance(pkt.msg, mav.Heartbeat):
            peer.mav_type = pkt.msg.mav_type
            peer.autopilot = pkt.msg.autopilot

    def _for_us(self, target_system: int, target_component: int) -> bool:
        cfg = self.config
        ok = target_system in (0, cfg.sysid) and target_component in (mav.MAV_COMP_ID_ALL, cfg.compid)
        if not ok:
            self._c["not_for_us"] += 1
        return ok

    def _from_autopilot(self, key: tuple[int, int]) -> bool:
        return key == (self.config.sysid, self.config.autopilot_compid)

    # ---- commands ------------------------------------------------------------------------------

    def _on_command(self, cmd: mav.CommandLong, requester: tuple[int, int], now: int) -> None:
        if not self._for_us(cmd.target_system, cmd.target_component):
            return
        if cmd.command != mav.MAV_CMD_DO_GRIPPER:
            if cmd.target_component == mav.MAV_COMP_ID_ALL:
                # A broadcast command we do not implement is for someone else: stay silent (MAVLink
                # command protocol: only components that support a broadcast command answer it).
                self._c["unexpected"] += 1
                return
            self._ack(requester, cmd.command, mav.MavResult.UNSUPPORTED, -1, now, "unsupported command")
            return
        instance, action_f = cmd.params[0], cmd.params[1]
        action = _gripper_action(action_f)
        if not (math.isfinite(instance) and instance in (0.0, float(self.config.compid))) or action is None:
            why = f"gripper denied: bad params {instance:g} {action_f:g}"
            self._ack(requester, cmd.command, mav.MavResult.DENIED, -1, now, why)
            self._text(mav.Severity.WARNING, why)
            return
        job = self._job
        if job is not None:
            if cmd.confirmation > 0 and job.requester == requester and job.action == action:
                # A retransmission of the command we are carrying out: it is still in progress.
                self._ack(requester, cmd.command, mav.MavResult.IN_PROGRESS, int(action), now, "")
            else:
                self._ack(
                    requester, cmd.command, mav.MavResult.TEMPORARILY_REJECTED, int(action), now, "busy"
                )
            return
        last = self._last_final
        if (
            cmd.confirmation > 0
            and last is not None
            and last[0] == requester
            and last[1] == int(action)
            and now - last[3] <= _ACK_REPLAY_WINDOW_US
        ):
            # Our final ACK was lost and the commander retransmits: repeat it, do not act twice.
            self._ack(requester, cmd.command, last[2], int(action), now, "repeated")
            return
        tel = self._telemetry
        denial = gripper_denial(tel, now - self._telemetry_at_us, self.config.board_stale_us)
        if denial is not None or tel is None:
            reason = denial or "gripper denied: no board telemetry"
            self._ack(requester, cmd.command, mav.MavResult.DENIED, int(action), now, reason)
            self._text(mav.Severity.WARNING, reason)
            return
        state = bm.GraspState(tel.grasp_state)
        if state in _BUSY_STATES:
            self._ack(
                requester,
                cmd.command,
                mav.MavResult.TEMPORARILY_REJECTED,
                int(action),
                now,
                f"busy: grasp {state.name}",
            )
            return
        code, target = _ACTION_TO_BOARD[action]
        if state == target:
            # Nothing to do (already holding, already released): done.
            self._final(requester, int(action), mav.MavResult.ACCEPTED, now, f"gripper: already {state.name}")
            return
        self._board(bm.Command(code))
        self._job = _GripperJob(
            action, code, target, requester, state, now + self.config.grasp_timeout_us, last_state=state
        )
        self._ack(requester, cmd.command, mav.MavResult.IN_PROGRESS, int(action), now, "", progress=0)
        self._text(mav.Severity.INFO, f"gripper: {action.name.lower()} started")

    def _ack(
        self,
        requester: tuple[int, int],
        command: int,
        result: int,
        action: int,
        now: int,
        text: str,
        *,
        progress: int = 0,
    ) -> None:
        # Target = the commander, so a GCS recognises the reply as its own (MAVProxy only prints ACKs
        # targeted at its own ids or at 0).
        self._send(mav.CommandAck(command, int(result), progress, 0, requester[0], requester[1]))
        self._last_command = GripperCommand(
            now, requester[0], requester[1], command, action, int(result), text
        )

    def _final(self, requester: tuple[int, int], action: int, result: int, now: int, text: str) -> None:
        self._ack(requester, mav.MAV_CMD_DO_GRIPPER, result, action, now, text, progress=100)
        self._last_final = (requester, action, int(result), now)
        severity = mav.Severity.INFO if result == mav.MavResult.ACCEPTED else mav.Severity.WARNING
        self._text(severity, text)

    def _finish_job(self, result: int, text: str, now: int) -> None:
        job, self._job = self._job, None
        if job is not None:
            self._final(job.requester, int(job.action), result, now, text)

    def _update_job(self, tel: bm.Telemetry, now: int) -> None:
        job = self._job
        if job is None:
            return
        verb = job.action.name.lower()
        if tel.phase != bm.Phase.OK:
            self._finish_job(
                mav.MavResult.FAILED, f"gripper: {verb} failed: failsafe {_name(bm.Phase, tel.phase)}", now
            )
            return
        if not tel.flags & bm.TelemetryFlags.ARMED:
            self._finish_job(mav.MavResult.FAILED, f"gripper: {verb} failed: disarmed", now)
            return
        if tel.mode != bm.Mode.GRASP:
            self._finish_job(
                mav.MavResult.FAILED, f"gripper: {verb} failed: mode {_name(bm.Mode, tel.mode)}", now
            )
            return
        state = bm.GraspState(tel.grasp_state)
        if state != job.start_state:
            job.progressed = True
        if state == job.target:
            self._finish_job(mav.MavResult.ACCEPTED, f"gripper: {verb} done, {state.name}", now)
            return
        if state == bm.GraspState.FAILED and (job.progressed or job.start_state != bm.GraspState.FAILED):
            self._finish_job(mav.MavResult.FAILED, f"gripper: {verb} failed: grasp FAILED", now)
            return
        if state != job.last_state:
            job.last_state = state
            self._ack(
                job.requester,
                mav.MAV_CMD_DO_GRIPPER,
                mav.MavResult.IN_PROGRESS,
                int(job.action),
                now,
                "",
                progress=_PROGRESS_PCT.get(state, 0),
            )

    # ---- parameters ----------------------------------------------------------------------------

    def _on_param_request_list(self, now: int) -> None:
        if self._param_count is not None and len(self._params) >= self._param_count:
            queued = set(self._param_tx)
            self._param_tx.extend(
                n for n, _ in sorted(self._params.items(), key=lambda kv: kv[1][0]) if n not in queued
            )
            return
        # Not all parameters mirrored yet: ask the board; its ParamValues are forwarded as they come.
        self._ask_board_for_all(now)

    def _ask_board_for_all(self, now: int) -> None:
        asked = self._param_list_asked_us
        if asked is None or now - asked >= self.config.param_confirm_timeout_us:
            self._param_list_asked_us = now
            self._board(bm.ParamRequest(bm.PARAM_LIST_ALL))

    def _on_param_request_read(self, req: mav.ParamRequestRead) -> None:
        if req.param_index >= 0:
            name = self._param_by_index.get(req.param_index)
            if name is not None:
                self._param_tx.append(name)
            elif self._param_count is None or req.param_index < self._param_count:
                self._board(bm.ParamRequest(req.param_index))
            return
        name = self._param_by_upper.get(req.param_id.upper())
        if name is not None:
            self._param_tx.append(name)
        elif not self._params_complete():
            self._ask_board_for_all(self._clock())

    def _on_param_set(self, req: mav.ParamSet, now: int) -> None:
        name = self._param_by_upper.get(req.param_id.upper())
        if name is None:
            # MAVLink has no negative answer to PARAM_SET (the sender times out); say why.
            self._c["unexpected"] += 1
            self._text(mav.Severity.WARNING, f"param {req.param_id} unknown")
            return
        if not math.isfinite(req.param_value):
            self._param_tx.append(name)  # answer with the value in force
            return
        self._param_pending[name] = _PendingParamSet(name, now + self.config.param_confirm_timeout_us)
        self._board(bm.ParamSet(name, float(req.param_value)))

    def _params_complete(self) -> bool:
        return self._param_count is not None and len(self._params) >= self._param_count

    def _send_params(self) -> None:
        for _ in range(min(_PARAMS_PER_CYCLE, len(self._param_tx))):
            name = self._param_tx.popleft()
            if name in self._param_pending:
                continue  # a set the board has not confirmed yet: its confirmation (or timeout) answers
            self._send_param_value(name)

    def _send_param_value(self, name: str) -> None:
        entry = self._params.get(name)
        if entry is None:
            return
        index, value = entry
        count = self._param_count if self._param_count is not None else len(self._params)
        self._send(mav.ParamValue(name.upper(), value, mav.ParamType.REAL32, count, index))

    # ---- board messages ------------------------------------------------------------------------

    def _drain_board(self) -> None:
        now = self._clock()
        for _ in range(_BOARD_MSGS_PER_CYCLE):
            try:
                msg = self._board_q.get_nowait()
            except queue.Empty:
                return
            if isinstance(msg, bm.Telemetry):
                self._telemetry = msg
                self._telemetry_at_us = now
                self._update_job(msg, now)
            elif isinstance(msg, bm.ParamValue):
                self._on_board_param(msg)
            elif isinstance(msg, bm.Event):
                self._on_board_event(msg)
            elif isinstance(msg, bm.CommandAck):
                self._on_board_ack(msg, now)
            else:
                self._c["board_unexpected"] += 1

    def _on_board_param(self, pv: bm.ParamValue) -> None:
        name = pv.name
        if not name or len(name) > mav.PARAM_ID_MAX:
            self._c["board_unexpected"] += 1
            return
        self._params[name] = (pv.index, float(pv.value))
        self._param_by_index[pv.index] = name
        self._param_by_upper[name.upper()] = name
        self._param_count = pv.count
        self._param_pending.pop(name, None)
        # The board confirms what it took (answer to a request, a set or a change): tell the drone.
        with contextlib.suppress(ValueError):
            self._param_tx.remove(name)
        self._send_param_value(name)

    def _on_board_event(self, ev: bm.Event) -> None:
        kind = ev.kind
        severity = mav.Severity.INFO
        if kind == bm.EventKind.PHASE:
            if ev.code == bm.Phase.ESTOP:
                severity = mav.Severity.EMERGENCY
            elif ev.code in _FAILSAFE_PHASES:
                severity = mav.Severity.CRITICAL
            else:
                severity = mav.Severity.NOTICE
        elif kind == bm.EventKind.FAULT:
            severity = mav.Severity.ERROR
        elif kind == bm.EventKind.GRASP and ev.code == bm.GraspState.FAILED:
            severity = mav.Severity.WARNING
        elif kind == bm.EventKind.MODE:
            severity = mav.Severity.NOTICE
        text = ev.text or f"{_name(bm.EventKind, kind).lower()} {ev.code} {ev.value:g}"
        self._text(severity, text)

    def _on_board_ack(self, ack: bm.CommandAck, now: int) -> None:
        job = self._job
        if job is None or int(ack.command) != int(job.code):
            return
        if ack.result in (bm.AckResult.ACCEPTED, bm.AckResult.IN_PROGRESS):
            return
        why = ack.text or _name(bm.AckResult, ack.result)
        self._finish_job(mav.MavResult.FAILED, f"gripper: {job.action.name.lower()} failed: board {why}", now)

    # ---- periodic ------------------------------------------------------------------------------

    def _heartbeat(self, now: int) -> mav.Heartbeat:
        tel = self._telemetry
        if tel is None:
            return mav.Heartbeat(mav.MAV_TYPE_ARM, mav.MAV_AUTOPILOT_INVALID, 0, 0, mav.MavState.BOOT)
        armed = bool(tel.flags & bm.TelemetryFlags.ARMED)
        base_mode = _MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | (_MAV_MODE_FLAG_SAFETY_ARMED if armed else 0)
        # custom_mode: byte 0 = Mode, byte 1 = Phase, byte 2 = GraspState (see docs/mavlink.md).
        custom_mode = int(tel.mode) | int(tel.phase) << 8 | int(tel.grasp_state) << 16
        if now - self._telemetry_at_us > self.config.board_stale_us:
            status = mav.MavState.CRITICAL
        elif tel.phase == bm.Phase.ESTOP:
            status = mav.MavState.EMERGENCY
        elif tel.phase in _FAILSAFE_PHASES:
            status = mav.MavState.CRITICAL
        elif armed and tel.phase == bm.Phase.OK:
            status = mav.MavState.ACTIVE
        else:
            status = mav.MavState.STANDBY
        return mav.Heartbeat(mav.MAV_TYPE_ARM, mav.MAV_AUTOPILOT_INVALID, base_mode, custom_mode, status)

    def _send_telemetry(self, now: int) -> None:
        tel = self._telemetry
        if tel is None or now - self._telemetry_at_us > self.config.board_stale_us:
            return
        t_ms = (tel.time_us // 1000) & 0xFFFFFFFF
        for i, tension in enumerate(tel.tension_est_n):
            self._send(mav.NamedValueFloat(t_ms, f"ARM_T{i + 1}_N", float(tension)))
        self._send(mav.NamedValueFloat(t_ms, "ARM_MODE", float(tel.mode)))
        self._send(mav.NamedValueFloat(t_ms, "ARM_PHASE", float(tel.phase)))
        self._send(mav.NamedValueFloat(t_ms, "ARM_GRASP", float(tel.grasp_state)))
        amps = tuple(c / 1000.0 for c in tel.motor_current)
        self._send(mav.ActuatorOutputStatus(tel.time_us, len(amps), amps))

    def _check_timeouts(self, now: int) -> None:
        job = self._job
        if job is not None and now >= job.deadline_us:
            self._finish_job(mav.MavResult.FAILED, f"gripper: {job.action.name.lower()} failed: timeout", now)
        if self._param_pending:
            for name, pending in list(self._param_pending.items()):
                if now >= pending.deadline_us:
                    del self._param_pending[name]
                    self._send_param_value(name)  # the value in force
                    self._text(mav.Severity.WARNING, f"param {name.upper()}: board did not confirm")

    def _every_second(self, now: int) -> None:
        self._text_budget = _STATUSTEXT_PER_S
        t0, in0, out0 = self._rate_window
        dt_s = max(now - t0, 1) / _US_PER_S
        self._rx_rate_hz = (self._codec.packets_in - in0) / dt_s
        self._tx_rate_hz = (self._codec.packets_out - out0) / dt_s
        self._rate_window = (now, self._codec.packets_in, self._codec.packets_out)
        for peer in self._peers.values():
            peer.rate_hz = (peer.packets - peer.window_start_packets) / dt_s
            peer.window_start_packets = peer.packets
        if self._tlog is not None:
            with contextlib.suppress(OSError):
                self._tlog.flush()

    # ---- STATUSTEXT ----------------------------------------------------------------------------

    def _drain_texts(self) -> None:
        for _ in range(16):
            try:
                severity, text = self._text_q.get_nowait()
            except queue.Empty:
                return
            self._text(severity, text)

    def _text(self, severity: int, text: str) -> None:
        if self._text_budget <= 0:
            self._c["statustext_dropped"] += 1
            return
        self._text_budget -= 1
        self._text_id = self._text_id % 0xFFFF + 1
        for chunk in mav.statustext_chunks(severity, text, self._text_id)[:8]:
            self._send(chunk)


def _next_deadline(previous_us: int, period_us: int, now_us: int) -> int:
    """The next periodic deadline; missed ones are skipped, never sent in a burst."""
    nxt = previous_us + period_us
    return nxt if nxt > now_us else now_us + period_us


def _gripper_action(value: float) -> mav.GripperAction | None:
    if not math.isfinite(value) or value != int(value):
        return None
    try:
        return mav.GripperAction(int(value))
    except ValueError:
        return None


def _mavutil_connect(cfg: DroneLinkConfig) -> Any:
    # Imported here, after protocol.mavlink has forced MAVLINK20=1 (import order matters, see there).
    from pymavlink import mavutil

    return mavutil.mavlink_connection(
        cfg.url, baud=cfg.baud, source_system=cfg.sysid, source_component=cfg.compid, autoreconnect=True
    )
