"""Camera presets of the teleop panel's 3-D view (``host.panel.scene``): where each one stands and looks.

Every preset follows the yaw of the arm's frame (:func:`host.panel.scene.arm_frame`), so stick forward stays
away from the viewer whatever the drone's heading; the View folder and the keys 1-5 choose them
(``host.panel.controls``).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from host.panel.scene import NOSE_AXIS, DronePose, quat_rotate

__all__ = ["CAMERA_PRESETS", "camera_view"]

CAMERA_PRESETS = ("sticks", "behind", "side", "top", "tip")
"""Camera presets: aligned with the sticks (the default), behind the drone, from the side, from above,
following the arm's tip."""


def camera_view(
    preset: str, centre_m: Sequence[float], drone: DronePose, tip_m: Sequence[float]
) -> tuple[tuple[float, float, float], tuple[float, float, float]]:
    """Camera position and look-at point of a preset.

    Every preset follows the yaw of the arm's frame, whose :data:`NOSE_AXIS` (+y) is stick forward and
    the drone's nose: ``sticks`` looks forward from behind at the arm's height (stick right = screen
    right, stick forward = away), ``behind`` from behind and above the drone, ``side`` from the drone's
    left, ``top`` from above (stick forward = screen up; tilted back a little so the arm is not hidden
    under the drone, and because an orbit camera cannot look along its own up axis), ``tip`` at the tip.

    Args:
        preset: one of :data:`CAMERA_PRESETS`.
        centre_m: the point to look at (the arm's middle).
        drone: the pose of the arm's frame (body 0, see :func:`arm_frame`).
        tip_m: the arm's tip.

    Raises:
        ValueError: an unknown preset.
    """
    c = np.asarray(centre_m, dtype=np.float64)
    q = np.asarray(drone.wxyz, dtype=np.float64)
    nose = quat_rotate(q, np.asarray(NOSE_AXIS, dtype=np.float64))
    nose[2] = 0.0
    length = float(np.linalg.norm(nose))
    nose = nose / length if length > 1e-12 else np.asarray(NOSE_AXIS, dtype=np.float64)  # nose straight down
    left = np.array([-nose[1], nose[0], 0.0])
    up = np.array([0.0, 0.0, 1.0])
    c = c - 0.05 * up  # a little below the arm's middle: the drone above and the arm's sweep below fit
    if preset == "sticks":
        pos, look = c - 1.1 * nose + 0.35 * up, c
    elif preset == "behind":
        pos, look = c - 1.3 * nose + 0.9 * up, c
    elif preset == "side":
        pos, look = c + 1.1 * left + 0.1 * up, c
    elif preset == "top":
        pos, look = c - 0.6 * nose + 1.3 * up, c
    elif preset == "tip":
        t = np.asarray(tip_m, dtype=np.float64)
        pos, look = t - 0.35 * nose + 0.15 * up, t
    else:
        raise ValueError(f"camera preset must be one of {', '.join(CAMERA_PRESETS)}, got {preset!r}")
    return (float(pos[0]), float(pos[1]), float(pos[2])), (float(look[0]), float(look[1]), float(look[2]))
