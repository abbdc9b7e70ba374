"""What observers see of the drone link: immutable snapshots taken under the link's lock."""

from __future__ import annotations

from dataclasses import dataclass

from protocol import mavlink as mav

__all__ = ["DroneLinkCounters", "DroneLinkState", "DronePose", "GripperCommand", "PeerInfo"]


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

    def describe(self) -> str:
        """One line for the panel's health area (markdown)."""
        alive = sum(1 for p in self.peers if p.alive)
        last = ""
        if self.last_command is not None:
            last = f" · last command {self.last_command.command} → result {self.last_command.result}"
        return (
            f"`{self.url}` {'running' if self.running else '**stopped**'} · sys {self.sysid} comp "
            f"{self.compid} · peers {alive}/{len(self.peers)} · rx {self.rx_rate_hz:.0f}/s tx "
            f"{self.tx_rate_hz:.0f}/s · signing {'on' if self.signing else 'off'}{last}"
        )
