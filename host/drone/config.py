"""The drone link's configuration, its error and the signing key loader."""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Final

from host.drone.servo import ServoFollowConfig
from protocol import mavlink as mav

__all__ = ["DroneLinkConfig", "DroneLinkError", "load_signing_key"]

_US_PER_S: Final[int] = 1_000_000


class DroneLinkError(Exception):
    """The drone link could not be opened or configured."""


@dataclass(frozen=True)
class DroneLinkConfig:
    """Configuration of one drone link (validated on creation).

    Attributes:
        url: pymavlink connection string (``udpout:127.0.0.1:14550``, ``udpin:...``, ``tcp:...``,
            ``/dev/ttyUSB0``).
        sysid: Our system id: the drone's (1..255, default 1).
        compid: Our component id (7..255: MAVLink reserves 0..6; default 25).
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
        servo_follow: Follow this autopilot output as the gripper (None = off; ``host.drone.servo``).
        early_command_wait_us: A ``DO_GRIPPER`` that arrives before the first board telemetry waits
            this long for it, then is answered ``TEMPORARILY_REJECTED``.
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
    servo_follow: ServoFollowConfig | None = None
    early_command_wait_us: int = 3_000_000

    def __post_init__(self) -> None:
        if not self.url:
            raise ValueError("url is empty")
        if not 1 <= self.sysid <= 255:
            raise ValueError(f"sysid out of range 1..255: {self.sysid}")
        if not mav.MIN_COMPONENT_ID <= self.compid <= 255:
            raise ValueError(
                f"component id must be {mav.MIN_COMPONENT_ID}..255 (MAVLink reserves 0..6): {self.compid}"
            )
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
            "early_command_wait_us",
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
