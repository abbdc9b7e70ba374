"""A motion-capture tracker of the simulated arm's tip: the pose channel a lab's tracker adds to a recording.

A lab that tracks the arm's tip (a marker cluster on the last unit, seen by a motion-capture system) records
it beside the board's frames as ``foxglove.PoseInFrame`` in the drone's frame, which is what
:mod:`hil.identify.motor_data` reads (a topic ending in ``/tip``). :class:`TipTracker` plays that tracker
on the virtual board: every ``1 / rate_hz`` of board time it writes the plant's true tip, relative to the
drone, plus white noise of ``noise_m`` per axis (its own random stream: the rest of the recording is the
same with or without it). Commercial optical trackers resolve a marker to a few tenths of a millimetre.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Final

import numpy as np

from hil.foxglove_log import DRONE_FRAME, in_parent

if TYPE_CHECKING:
    from hil.environment import Environment

__all__ = ["POSE_IN_FRAME_SCHEMA", "TIP_TOPIC", "TipTracker", "pose_in_frame"]

TIP_TOPIC: Final = "/mocap/tip"
"""Where the tracker's samples go (any topic ending in ``/tip`` is read as the tip)."""

_VEC3: Final = {
    "type": "object",
    "properties": {"x": {"type": "number"}, "y": {"type": "number"}, "z": {"type": "number"}},
}
POSE_IN_FRAME_SCHEMA: Final[dict[str, Any]] = {
    "$schema": "https://json-schema.org/draft/2020-12/schema",
    "title": "foxglove.PoseInFrame",
    "description": "a timestamped pose in a named frame (Foxglove's schema, JSON encoding)",
    "type": "object",
    "properties": {
        "timestamp": {
            "type": "object",
            "properties": {"sec": {"type": "integer"}, "nsec": {"type": "integer"}},
        },
        "frame_id": {"type": "string"},
        "pose": {
            "type": "object",
            "properties": {
                "position": _VEC3,
                "orientation": {
                    "type": "object",
                    "properties": {k: {"type": "number"} for k in ("x", "y", "z", "w")},
                },
            },
        },
    },
}


def pose_in_frame(unix_ns: int, frame_id: str, pos_m: np.ndarray, quat_wxyz: np.ndarray) -> dict[str, Any]:
    """A ``foxglove.PoseInFrame`` as JSON (position in metres, quaternion w, x, y, z)."""
    return {
        "timestamp": {"sec": unix_ns // 1_000_000_000, "nsec": unix_ns % 1_000_000_000},
        "frame_id": frame_id,
        "pose": {
            "position": {"x": float(pos_m[0]), "y": float(pos_m[1]), "z": float(pos_m[2])},
            "orientation": {
                "x": float(quat_wxyz[1]),
                "y": float(quat_wxyz[2]),
                "z": float(quat_wxyz[3]),
                "w": float(quat_wxyz[0]),
            },
        },
    }


@dataclass
class TipTracker:
    """The tip in the drone's frame, every ``1 / rate_hz`` of board time, to the run's recording.

    Raises:
        ValueError: a negative or non-finite noise, or a rate outside (0, 1000] Hz.
    """

    noise_m: float = 3e-4
    rate_hz: float = 100.0
    seed: int = 0
    samples: int = field(default=0, init=False)
    """Samples written so far."""

    def __post_init__(self) -> None:
        if not (math.isfinite(self.noise_m) and self.noise_m >= 0.0):
            raise ValueError(f"tracker noise {self.noise_m} m: must be finite and >= 0")
        if not (math.isfinite(self.rate_hz) and 0.0 < self.rate_hz <= 1000.0):
            raise ValueError(f"tracker rate {self.rate_hz} Hz: must be in (0, 1000]")
        self._period_us = round(1e6 / self.rate_hz)
        self._next_us = 0
        self._rng = np.random.default_rng(self.seed)

    def after_tick(self, env: Environment) -> None:
        """Write a sample when one is due (nothing without a recording)."""
        rec = env.recorder
        now = env.now_us
        if rec is None or now < self._next_us:
            return
        self._next_us = (now // self._period_us + 1) * self._period_us
        plant = env.board.plant
        drone, tip = plant.drone_pose(), plant.tip_pose()
        rel, quat = in_parent(drone.pos_m, drone.quat_wxyz, tip.pos_m[None], tip.quat_wxyz[None])
        pos = rel[0] + (self._rng.normal(0.0, self.noise_m, 3) if self.noise_m > 0.0 else 0.0)
        rec.write_json(
            TIP_TOPIC,
            now,
            pose_in_frame(rec.unix_ns(now), DRONE_FRAME, pos, quat[0]),
            schema=POSE_IN_FRAME_SCHEMA,
        )
        self.samples += 1
