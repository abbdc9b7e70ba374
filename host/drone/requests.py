"""The identity commands of the drone link: ``MAV_CMD_REQUEST_MESSAGE`` and ``REQUEST_PROTOCOL_VERSION``.

A ground station asks a component what it is and what it speaks: ``REQUEST_MESSAGE`` for
``HEARTBEAT``, ``PROTOCOL_VERSION`` or ``AUTOPILOT_VERSION`` (its capabilities: MAVLink 2,
``COMMAND_INT`` and how integer parameters are encoded), and the older
``REQUEST_PROTOCOL_VERSION``. Both are answered ``ACCEPTED`` followed by the message; another
message id is ``UNSUPPORTED``. Pure functions; the link sends what they return.
"""

from __future__ import annotations

import math
from typing import Final

from protocol import mavlink as mav

__all__ = ["IDENTITY_COMMANDS", "answer_identity", "capabilities"]

IDENTITY_COMMANDS: Final = frozenset({mav.MAV_CMD_REQUEST_MESSAGE, mav.MAV_CMD_REQUEST_PROTOCOL_VERSION})
"""The commands :func:`answer_identity` answers."""

_MAVLINK_MIN_VERSION_X100: Final[int] = 100


def capabilities(*, bytewise: bool) -> int:
    """``AUTOPILOT_VERSION.capabilities`` of the arm.

    Args:
        bytewise: Integer parameters encoded bytewise (else by C cast).

    Returns:
        The ``MAV_PROTOCOL_CAPABILITY`` bits.
    """
    encoding = (
        mav.MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE
        if bytewise
        else mav.MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_C_CAST
    )
    return mav.MAV_PROTOCOL_CAPABILITY_MAVLINK2 | mav.MAV_PROTOCOL_CAPABILITY_COMMAND_INT | encoding


def answer_identity(
    cmd: mav.CommandLong, heartbeat: mav.Heartbeat, *, bytewise: bool
) -> tuple[mav.MavResult, mav.MavMessage | None]:
    """The ACK result and the message (if any) that answer an identity command.

    Args:
        cmd: ``MAV_CMD_REQUEST_MESSAGE`` (param1 = message id) or ``MAV_CMD_REQUEST_PROTOCOL_VERSION``.
        heartbeat: The arm's current heartbeat (sent for a ``HEARTBEAT`` request).
        bytewise: Integer parameters encoded bytewise (else by C cast).

    Returns:
        ``(ACCEPTED, message)``, or ``(UNSUPPORTED, None)`` for a message we do not send and
        ``(DENIED, None)`` for a malformed id.
    """
    protocol = mav.ProtocolVersion(
        mav.MAVLINK_VERSION_X100, _MAVLINK_MIN_VERSION_X100, mav.MAVLINK_VERSION_X100
    )
    if cmd.command == mav.MAV_CMD_REQUEST_PROTOCOL_VERSION:
        return mav.MavResult.ACCEPTED, protocol
    msg_id_f = cmd.params[0]
    if not math.isfinite(msg_id_f) or msg_id_f != int(msg_id_f) or msg_id_f < 0:
        return mav.MavResult.DENIED, None
    msg_id = int(msg_id_f)
    if msg_id == mav.MSG_ID_HEARTBEAT:
        return mav.MavResult.ACCEPTED, heartbeat
    if msg_id == mav.MSG_ID_PROTOCOL_VERSION:
        return mav.MavResult.ACCEPTED, protocol
    if msg_id == mav.MSG_ID_AUTOPILOT_VERSION:
        return mav.MavResult.ACCEPTED, mav.AutopilotVersion(capabilities(bytewise=bytewise))
    return mav.MavResult.UNSUPPORTED, None
