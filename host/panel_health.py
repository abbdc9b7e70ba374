"""The shared Health folder: its builder and the markdown of its three blocks."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import viser

from host.model import UiModel
from protocol.dbus import Lever
from protocol.messages import GraspState, Phase, TelemetryFlags

__all__ = ["HealthHandles", "build_health_panel", "health_text"]

_ORDER_HEALTH = 200.0  # folder order in the panel: Control (0), Plots (100), Health (200)


@dataclass
class HealthHandles:
    """The shared Health folder."""

    summary: Any
    link: Any
    loop: Any


def build_health_panel(server: viser.ViserServer) -> HealthHandles:
    """Build the shared Health folder."""
    with server.gui.add_folder("Health", order=_ORDER_HEALTH):
        summary = server.gui.add_markdown("**Board**: connecting…")
        link = server.gui.add_markdown("")
        loop = server.gui.add_markdown("")
    return HealthHandles(summary, link, loop)


def _fmt_rate(rates: dict[str, float] | Any, name: str) -> str:
    return f"{rates.get(name, 0.0):.0f}"


def health_text(
    model: UiModel, pose_source: str, mavlink_status: str | None, shadow_status: str | None = None
) -> tuple[str, str, str]:
    """Markdown of the three health blocks (summary, link, loop)."""
    t = model.telemetry
    stats = model.link_stats
    state = model.link_state.value
    if t is None:
        summary = (
            f"**Board** ({model.source_label}): {state} · no telemetry yet  \n**Pose source**: {pose_source}"
        )
    else:
        flags = TelemetryFlags(t.flags)
        motors = " ".join(f"M{i + 1} {'on' if t.motors_online >> i & 1 else '**OFF**'}" for i in range(3))
        rc = "ok" if flags & TelemetryFlags.RC_OK else "**lost**"
        phase = t.phase.name if t.phase == Phase.OK else f"**{t.phase.name}**"
        summary = (
            f"**Board** ({model.source_label}): {state} · **Mode** {t.mode.name} · **Phase** {phase} · "
            f"{'ARMED' if flags & TelemetryFlags.ARMED else 'disarmed'}  \n"
            f"**RC** {rc} (R {Lever(t.right_lever).name if t.right_lever in (1, 2, 3) else '-'}, "
            f"L {Lever(t.left_lever).name if t.left_lever in (1, 2, 3) else '-'}) · {motors}  \n"
            f"**Grasp** {GraspState(t.grasp_state).name} · **Host** "
            f"{'ok' if flags & TelemetryFlags.HOST_OK else 'silent'}"
            f"{' (required)' if flags & TelemetryFlags.HOST_REQUIRED else ''}  \n"
            f"**Pose source**: {pose_source}"
        )
    if shadow_status is not None:
        summary += f"  \n**Shadow**: {shadow_status}"
    if mavlink_status is not None:
        summary += f"  \n**MAVLink**: {mavlink_status}"
    if stats is None:
        link = "**Link**: no statistics"
    else:
        lat = "-" if stats.latency_us is None else f"{stats.latency_us / 1000:.1f} ms"
        link = (
            f"**Link** `{stats.url}`: telemetry {_fmt_rate(stats.rx_rate_hz, 'Telemetry')} Hz · poses "
            f"{_fmt_rate(stats.rx_rate_hz, 'SimPoses')} Hz · errors {stats.errors} · "
            f"skipped {stats.parser.get('bytes_skipped', 0)} B · reconnects {stats.reconnects} · "
            f"link process restarts {stats.process_restarts} · "
            f"latency {lat} · RC late {stats.rc_late} · tx dropped {stats.tx_dropped}"
        )
    if t is None:
        loop = ""
    else:
        loop = (
            f"**Loop**: late {t.control_late} · exec p99 {t.control_exec_p99_us} µs · "
            f"max {t.control_exec_max_us} µs · lateness p99 {t.control_lateness_p99_us} µs · "
            f"max {t.control_lateness_max_us} µs  \n"
            f"**Counters**: RC ok {t.rc_frames_ok} · RC rejected {t.rc_rejected} · DBUS dropped "
            f"{t.dbus_bytes_dropped} B · link CRC {t.link_crc_errors} · motor offline "
            f"{t.motor_offline_events} · CAN errors {t.can_errors}"
        )
        status = model.status
        if status is not None:
            rows = " · ".join(
                f"{s.name} late {s.late}/{s.runs}, p99 {s.exec_p99_us} µs" for s in status.tasks[:6]
            )
            loop += f"  \n**Tasks** ({status.firmware_version}, {status.clock_kind.name}): {rows}"
    return summary, link, loop
