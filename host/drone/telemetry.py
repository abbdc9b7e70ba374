"""How the board's state looks on MAVLink: the arm's ``HEARTBEAT``, its telemetry and its event texts.

Pure functions of the latest board messages; :class:`host.drone.link.DroneLink` decides when to send.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, Final

from protocol import mavlink as mav
from protocol import messages as bm

__all__ = ["FAILSAFE_PHASES", "enum_name", "event_statustext", "heartbeat", "send_telemetry"]

FAILSAFE_PHASES: Final = frozenset({bm.Phase.RC_LOST, bm.Phase.MOTOR_FAULT, bm.Phase.HOST_LOST})
"""Failsafe phases reported as ``CRITICAL`` (E-stop is ``EMERGENCY``; the start-up gate is not a failsafe)."""


def enum_name(enum_cls: Any, value: int) -> str:
    """The member name of ``value`` in ``enum_cls``, or the number itself when it is not a member.

    Args:
        enum_cls: An ``IntEnum`` class.
        value: A wire value.

    Returns:
        The name, or ``str(value)``.
    """
    try:
        return str(enum_cls(value).name)
    except ValueError:
        return str(value)


def heartbeat(telemetry: bm.Telemetry | None, age_us: int, stale_us: int) -> mav.Heartbeat:
    """The arm's ``HEARTBEAT`` for the latest board telemetry.

    Args:
        telemetry: Latest board telemetry (None before any: ``BOOT``).
        age_us: How old it is.
        stale_us: Older than this, the board counts as lost (``CRITICAL``).

    Returns:
        The heartbeat to send.
    """
    tel = telemetry
    if tel is None:
        return mav.Heartbeat(mav.MAV_TYPE_ARM, mav.MAV_AUTOPILOT_INVALID, 0, 0, mav.MavState.BOOT)
    armed = bool(tel.flags & bm.TelemetryFlags.ARMED)
    base_mode = mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | (mav.MAV_MODE_FLAG_SAFETY_ARMED if armed else 0)
    # custom_mode: byte 0 = Mode, byte 1 = Phase, byte 2 = GraspState (see docs/mavlink.md).
    custom_mode = int(tel.mode) | int(tel.phase) << 8 | int(tel.grasp_state) << 16
    if age_us > stale_us:
        status = mav.MavState.CRITICAL
    elif tel.phase == bm.Phase.ESTOP:
        status = mav.MavState.EMERGENCY
    elif tel.phase in FAILSAFE_PHASES:
        status = mav.MavState.CRITICAL
    elif armed and tel.phase == bm.Phase.OK:
        status = mav.MavState.ACTIVE
    else:
        status = mav.MavState.STANDBY
    return mav.Heartbeat(mav.MAV_TYPE_ARM, mav.MAV_AUTOPILOT_INVALID, base_mode, custom_mode, status)


def send_telemetry(telemetry: bm.Telemetry, send: Callable[[mav.MavMessage], None]) -> None:
    """Send one round of telemetry: ``NAMED_VALUE_FLOAT`` tensions, mode, phase, grasp state, then
    ``ACTUATOR_OUTPUT_STATUS`` motor currents in A.

    Args:
        telemetry: The board telemetry to publish.
        send: Sends one message.
    """
    tel = telemetry
    t_ms = (tel.time_us // 1000) & 0xFFFFFFFF
    for i, tension in enumerate(tel.tension_est_n):
        send(mav.NamedValueFloat(t_ms, f"ARM_T{i + 1}_N", float(tension)))
    send(mav.NamedValueFloat(t_ms, "ARM_MODE", float(tel.mode)))
    send(mav.NamedValueFloat(t_ms, "ARM_PHASE", float(tel.phase)))
    send(mav.NamedValueFloat(t_ms, "ARM_GRASP", float(tel.grasp_state)))
    amps = tuple(c / 1000.0 for c in tel.motor_current)
    send(mav.ActuatorOutputStatus(tel.time_us, len(amps), amps))


def event_statustext(event: bm.Event) -> tuple[int, str]:
    """The ``STATUSTEXT`` severity and text of a board event.

    Args:
        event: A board event.

    Returns:
        ``(MAV_SEVERITY, text)``.
    """
    ev = event
    kind = ev.kind
    severity = mav.Severity.INFO
    if kind == bm.EventKind.PHASE:
        if ev.code == bm.Phase.ESTOP:
            severity = mav.Severity.EMERGENCY
        elif ev.code in FAILSAFE_PHASES:
            severity = mav.Severity.CRITICAL
        else:
            severity = mav.Severity.NOTICE
    elif kind == bm.EventKind.FAULT:
        severity = mav.Severity.ERROR
    elif kind == bm.EventKind.GRASP and ev.code == bm.GraspState.FAILED:
        severity = mav.Severity.WARNING
    elif kind == bm.EventKind.MODE:
        severity = mav.Severity.NOTICE
    text = ev.text or f"{enum_name(bm.EventKind, kind).lower()} {ev.code} {ev.value:g}"
    return severity, text
