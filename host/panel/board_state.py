"""The board as the panel sees it: the latest telemetry, poses and status, the plots' history, link health.

An array board (issue 27) says its layout in ``ArmsTelemetry`` (:attr:`BoardState.layout`) and sends
the poses of its arms after arm 0 in ``ArmPoses`` (:attr:`BoardState.arm_poses`); :meth:`BoardState.bodies`
joins them to ``SimPoses`` (the drone and arm 0) as the plant gives its body poses.

:class:`BoardState` is a listener and a state listener of a board source (the live link or a replay)
and only keeps what arrives; the panel reads it at its own rates (``host.panel.teleop``). Who may act
is the control arbiter's business (``host.panel.arbiter``), what to tell people the notices'
(``host.panel.notices``).
"""

from __future__ import annotations

import enum
import threading
from collections.abc import Callable

import numpy as np
import numpy.typing as npt

from host.link.client import LinkStats
from host.link.source import LinkState
from host.panel.history import PLOT_COLUMNS, RingBuffer
from protocol.c610 import RAW_PER_AMP
from protocol.messages import ArmPoses, ArmsTelemetry, BoardStatus, CommandAck, Message, SimPoses, Telemetry

__all__ = ["BoardState", "PoseSource"]


class PoseSource(enum.Enum):
    """Where the arm's drawn shape comes from (the value is what the panel says)."""

    NONE = "no pose source"
    SIMULATION = "simulation (SimPoses)"
    """The plant of a virtual board, over the board link."""
    SHADOW = "shadow plant (measured currents)"
    """A local plant driven by a real board's measured motor currents (``host.shadow``)."""


class BoardState:
    """Latest board messages, plot history and link health; thread-safe.

    Args:
        source_label: what the board is (``virtual board``, ``board /dev/ttyACM0``, ``replay x.mcap``).
        link_stats: gives a fresh link-statistics snapshot (``BoardClient.stats``); None in a replay.
        history_s: seconds of telemetry kept for the plots.
        telemetry_hz: expected telemetry rate (sizes the history).
    """

    def __init__(
        self,
        source_label: str = "board",
        link_stats: Callable[[], LinkStats] | None = None,
        *,
        history_s: float = 20.0,
        telemetry_hz: float = 100.0,
    ) -> None:
        self.source_label = source_label
        self._link_stats_fn = link_stats
        self._lock = threading.Lock()
        self.history_s = history_s
        """Seconds of telemetry kept for the plots."""
        self.history = RingBuffer(max(10, int(history_s * telemetry_hz)), len(PLOT_COLUMNS))
        self.telemetry: Telemetry | None = None
        self.telemetry_count = 0
        self.poses: SimPoses | None = None
        self.poses_count = 0
        self.poses_event = threading.Event()
        """Set whenever new poses arrive (the panel waits on it)."""
        self.pose_source = PoseSource.NONE
        """Where :attr:`poses` came from."""
        self.sim_poses_count = 0
        """``SimPoses`` received from the board (after the first, shadow poses are ignored)."""
        self.arm_poses: dict[int, ArmPoses] = {}
        """The latest ``ArmPoses`` of each arm after arm 0 of an array (empty for one arm)."""
        self.layout: tuple[int, int] | None = None
        """An array's (arms, cables per arm) from ``ArmsTelemetry``; None for a board that sends none (one
        arm of up to three cables, or a host-side replay of such a board)."""
        self.status: BoardStatus | None = None
        self.last_ack: CommandAck | None = None
        self.link_state = LinkState.CONNECTING
        self.link_stats: LinkStats | None = None

    def on_board_message(self, msg: Message) -> None:
        """Listener: keep the latest of each message and extend the history."""
        if isinstance(msg, Telemetry):
            self._on_telemetry(msg)
        elif isinstance(msg, SimPoses):
            with self._lock:
                self.poses = msg
                self.poses_count += 1
                self.sim_poses_count += 1
                self.pose_source = PoseSource.SIMULATION
            self.poses_event.set()
        elif isinstance(msg, ArmPoses):
            with self._lock:
                if any(m.arms != msg.arms for m in self.arm_poses.values()):
                    self.arm_poses.clear()  # another plant (the board restarted): forget the old arms
                self.arm_poses[msg.arm] = msg
                self.poses_count += 1
            self.poses_event.set()
        elif isinstance(msg, ArmsTelemetry):
            self.layout = (msg.arms, msg.cables_per_arm)
        elif isinstance(msg, BoardStatus):
            self.status = msg
        elif isinstance(msg, CommandAck):
            self.last_ack = msg

    def _on_telemetry(self, t: Telemetry) -> None:
        row = (
            *t.tension_target_n,
            *t.tension_est_n,
            *(c / RAW_PER_AMP for c in t.commanded_current),
            *(c / RAW_PER_AMP for c in t.motor_current),
            *(x * 1000.0 for x in t.cable_length_m),
        )
        with self._lock:
            prev = self.telemetry
            if prev is not None and t.time_us < prev.time_us:
                self.history.clear()  # the board restarted, perhaps with another layout: it says it again
                self.layout = None
                self.arm_poses.clear()
            self.telemetry = t
            self.telemetry_count += 1
            self.history.append(t.time_us / 1e6, row)

    @property
    def arms(self) -> int:
        """Arms of the board: from its layout (``ArmsTelemetry``), else from its ``ArmPoses``, else 1."""
        if self.layout is not None:
            return self.layout[0]
        with self._lock:
            return max((m.arms for m in self.arm_poses.values()), default=1)

    def bodies(self) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64], int] | None:
        """The poses to draw, as the plant gives them: the drone, then each arm's units, arm after arm.

        ``SimPoses`` gives the drone and arm 0; each further arm comes from its latest ``ArmPoses`` if it
        has as many units as arm 0 (an arm not heard from yet is left out, not drawn at a guessed place).

        Returns:
            positions (1 + k n, 3), quaternions (1 + k n, 4) and k, the arms in them; None without poses.
        """
        with self._lock:
            poses = self.poses
            if poses is None or len(poses.positions_m) < 2:
                return None
            units = len(poses.positions_m) - 1
            others = [
                m
                for _, m in sorted(self.arm_poses.items())
                if m.arm > 0 and len(m.positions_m) == units and self.pose_source is PoseSource.SIMULATION
            ]
        positions = [poses.positions_m, *(m.positions_m for m in others)]
        quats = [poses.quats_wxyz, *(m.quats_wxyz for m in others)]
        return (
            np.concatenate([np.asarray(p, dtype=np.float64).reshape(-1, 3) for p in positions]),
            np.concatenate([np.asarray(q, dtype=np.float64).reshape(-1, 4) for q in quats]),
            1 + len(others),
        )

    def on_shadow_poses(self, poses: SimPoses) -> bool:
        """Poses of the shadow plant (``host.shadow``); ignored once the board itself sent ``SimPoses``.

        Returns:
            True if they became the poses shown.
        """
        with self._lock:
            if self.sim_poses_count:
                return False
            self.poses = poses
            self.poses_count += 1
            self.pose_source = PoseSource.SHADOW
        self.poses_event.set()
        return True

    def on_link_state(self, state: LinkState) -> None:
        """State listener: the link's state as the panel shows it."""
        self.link_state = state

    def refresh_link_stats(self) -> LinkStats | None:
        """Pull a fresh snapshot from the board client (the panel calls this at its own rate)."""
        fn = self._link_stats_fn
        if fn is not None:
            stats = fn()
            with self._lock:
                self.link_stats = stats
        return self.link_stats
