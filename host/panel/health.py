"""The shared Health folder: its builder, a table of checked numbers, and the markdown of its blocks.

The table (:func:`health_checks`) gives each number its threshold and a colour (green ok, orange
watch it, red act), so a first-time pilot can tell which of the numbers below it matter right now.
"""

from __future__ import annotations

import html
from dataclasses import dataclass
from typing import Any

import viser

from host.panel.board_state import BoardState
from protocol.dbus import Lever
from protocol.messages import GraspState, Phase, TelemetryFlags

__all__ = [
    "HealthCheck",
    "HealthHandles",
    "build_health_panel",
    "health_checks",
    "health_html",
    "health_text",
]

_ORDER_HEALTH = 200.0  # folder order in the panel: Control (0), Plots (100), Health (200)


@dataclass
class HealthHandles:
    """The shared Health folder."""

    checks: Any
    summary: Any
    link: Any
    loop: Any


def build_health_panel(server: viser.ViserServer) -> HealthHandles:
    """Build the shared Health folder."""
    with server.gui.add_folder("Health", order=_ORDER_HEALTH):
        checks = server.gui.add_html("")
        summary = server.gui.add_markdown("**Board**: connecting…")
        link = server.gui.add_markdown("")
        loop = server.gui.add_markdown("")
    return HealthHandles(checks, summary, link, loop)


@dataclass(frozen=True, slots=True)
class HealthCheck:
    """One checked number.

    Attributes:
        name: what it is.
        value: its value, formatted with its unit.
        level: ``ok``, ``warn`` or ``bad``.
        rule: the thresholds, in words.
    """

    name: str
    value: str
    level: str
    rule: str


def _grade(value: float, warn: float, bad: float) -> str:
    """``ok`` below ``warn``, ``warn`` below ``bad``, else ``bad`` (higher is worse)."""
    return "ok" if value < warn else "warn" if value < bad else "bad"


def _per_mille(part: int, whole: int) -> float:
    return 1000.0 * part / whole if whole > 0 else 0.0


CONTROL_PERIOD_US = 1000
"""The firmware's control period (1 kHz): execution and lateness are judged against it."""
TELEMETRY_HZ = 100.0
"""The board's telemetry rate."""


def health_checks(board: BoardState, malformed_n: int = 0) -> list[HealthCheck]:
    """The numbers worth watching, each with its thresholds and grade.

    Counters that only grow since boot (late ticks, rejected frames, CRC errors) are judged as a
    share of their totals, so one bad moment an hour ago does not stay red.

    Args:
        board: the board's state.
        malformed_n: panel messages the server could not decode (``host.panel.guard``).
    """
    out: list[HealthCheck] = []
    stats = board.link_stats
    t = board.telemetry
    if stats is not None:
        rate = stats.rx_rate_hz.get("Telemetry", 0.0)
        low = TELEMETRY_HZ - rate
        out.append(
            HealthCheck(
                "Telemetry rate", f"{rate:.0f} Hz", _grade(low, 10.0, 50.0), "ok ≥ 90 Hz, bad < 50 Hz"
            )
        )
        if stats.latency_us is not None:
            ms = stats.latency_us / 1000.0
            out.append(
                HealthCheck(
                    "Link latency", f"{ms:.1f} ms", _grade(ms, 20.0, 100.0), "ok < 20 ms, bad ≥ 100 ms"
                )
            )
        out.append(
            HealthCheck("Link errors", str(stats.errors), _grade(stats.errors, 1, 100), "ok 0, bad ≥ 100")
        )
        out.append(
            HealthCheck(
                "RC frames late (host)", str(stats.rc_late), _grade(stats.rc_late, 1, 50), "ok 0, bad ≥ 50"
            )
        )
        out.append(
            HealthCheck(
                "Sends dropped", str(stats.tx_dropped), _grade(stats.tx_dropped, 1, 10), "ok 0, bad ≥ 10"
            )
        )
    if t is not None:
        online = bin(t.motors_online & 0b111).count("1")
        out.append(HealthCheck("Motors online", f"{online}/3", "ok" if online == 3 else "bad", "ok 3/3"))
        ex = t.control_exec_p99_us
        p = CONTROL_PERIOD_US
        out.append(
            HealthCheck(
                "Control exec p99",
                f"{ex} µs",
                _grade(ex, p // 2, p * 9 // 10),
                f"ok < {p // 2} µs, bad ≥ {p * 9 // 10} µs (period {p} µs)",
            )
        )
        la = t.control_lateness_p99_us
        out.append(
            HealthCheck(
                "Control lateness p99", f"{la} µs", _grade(la, p // 5, p), f"ok < {p // 5} µs, bad ≥ {p} µs"
            )
        )
        ticks = max(1, t.time_us // p)
        late = _per_mille(t.control_late, ticks)
        out.append(
            HealthCheck(
                "Late ticks",
                f"{t.control_late} ({late:.2f} ‰)",
                _grade(late, 1.0, 10.0),
                "ok < 1 ‰ of ticks, bad ≥ 1 %",
            )
        )
        rej = _per_mille(t.rc_rejected, t.rc_frames_ok + t.rc_rejected)
        out.append(
            HealthCheck(
                "RC frames rejected",
                f"{t.rc_rejected} ({rej:.1f} ‰)",
                _grade(rej, 10.0, 100.0),
                "ok < 1 %, bad ≥ 10 %",
            )
        )
        crc = _per_mille(t.link_crc_errors, t.link_frames_ok + t.link_crc_errors)
        out.append(
            HealthCheck(
                "Link CRC errors (board)",
                f"{t.link_crc_errors} ({crc:.1f} ‰)",
                _grade(crc, 1.0, 10.0),
                "ok < 1 ‰, bad ≥ 1 %",
            )
        )
    out.append(
        HealthCheck(
            "Malformed panel messages", str(malformed_n), _grade(malformed_n, 1, 10), "ok 0, bad ≥ 10"
        )
    )
    return out


_LEVEL_STYLE = {"ok": ("#2b8a3e", "ok"), "warn": ("#e8590c", "watch"), "bad": ("#c92a2a", "ACT")}


def health_html(checks: list[HealthCheck]) -> str:
    """The checks as a compact coloured table (value, grade, thresholds on hover and in a column)."""
    rows = []
    for c in checks:
        colour, word = _LEVEL_STYLE[c.level]
        rows.append(
            f'<tr data-level="{c.level}" title="{html.escape(c.rule)}"><td>{html.escape(c.name)}</td>'
            f'<td style="text-align:right">{html.escape(c.value)}</td>'
            f'<td style="color:{colour};font-weight:700">{word}</td>'
            f'<td style="color:#868e96">{html.escape(c.rule)}</td></tr>'
        )
    return (
        '<table data-testid="health-checks" style="font-size:0.75em;border-collapse:collapse;width:100%">'
        + "".join(rows)
        + "</table>"
    )


def _fmt_rate(rates: dict[str, float] | Any, name: str) -> str:
    return f"{rates.get(name, 0.0):.0f}"


def health_text(
    board: BoardState, pose_source: str, mavlink_status: str | None, shadow_status: str | None = None
) -> tuple[str, str, str]:
    """Markdown of the three health blocks (summary, link, loop)."""
    t = board.telemetry
    stats = board.link_stats
    state = board.link_state.value
    if t is None:
        summary = (
            f"**Board** ({board.source_label}): {state} · no telemetry yet  \n**Pose source**: {pose_source}"
        )
    else:
        flags = TelemetryFlags(t.flags)
        count = 3 if board.layout is None else board.layout[0] * board.layout[1]
        motors = " ".join(f"M{i + 1} {'on' if t.motors_online >> i & 1 else '**OFF**'}" for i in range(count))
        rc = "ok" if flags & TelemetryFlags.RC_OK else "**lost**"
        phase = t.phase.name if t.phase == Phase.OK else f"**{t.phase.name}**"
        summary = (
            f"**Board** ({board.source_label}): {state} · **Mode** {t.mode.name} · **Phase** {phase} · "
            f"{'ARMED' if flags & TelemetryFlags.ARMED else 'disarmed'}  \n"
            f"**RC** {rc} (R {Lever(t.right_lever).name if t.right_lever in (1, 2, 3) else '-'}, "
            f"L {Lever(t.left_lever).name if t.left_lever in (1, 2, 3) else '-'}) · {motors}  \n"
            f"**Grasp** {GraspState(t.grasp_state).name} · **Host** "
            f"{'ok' if flags & TelemetryFlags.HOST_OK else 'silent'}"
            f"{' (required)' if flags & TelemetryFlags.HOST_REQUIRED else ''}  \n"
            f"**Pose source**: {pose_source}"
        )
    if board.layout is not None:
        arms, cables = board.layout
        summary += (
            f"  \n**Array**: the board is an array of {arms} arms x {cables} cable(s), "
            f"{arms * cables} motors (ArmsTelemetry); the plots show motors 1-3"
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
        status = board.status
        if status is not None:
            rows = " · ".join(
                f"{s.name} late {s.late}/{s.runs}, p99 {s.exec_p99_us} µs" for s in status.tasks[:6]
            )
            loop += f"  \n**Tasks** ({status.firmware_version}, {status.clock_kind.name}): {rows}"
    return summary, link, loop
