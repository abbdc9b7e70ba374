"""The render child of :mod:`hil.render`: ``python -m hil.render_child JOB`` renders a job's stills and GIF
with ``MUJOCO_GL`` set by its parent. It imports MuJoCo, NumPy and Pillow only, so it starts fast."""

from __future__ import annotations

import pickle
import sys
from pathlib import Path
from typing import Any, Final

import mujoco
import numpy as np
import numpy.typing as npt

NO_GL_EXIT: Final = 3
"""The child's exit status when its GL back end cannot start."""


def _child(job_path: str) -> int:
    """Render a job written by :func:`hil.render.render_film` (``MUJOCO_GL`` is set by the parent)."""
    from PIL import Image, ImageDraw

    job = pickle.loads(Path(job_path).read_bytes())  # our own file, in our own temporary directory
    m = job["model"]
    m.vis.quality.offsamples = 0
    m.vis.headlight.ambient[:] = 0.45
    m.vis.headlight.diffuse[:] = 0.6
    m.vis.map.znear = 0.005
    d = mujoco.MjData(m)
    cam = mujoco.MjvCamera()
    (cam.lookat[0], cam.lookat[1], cam.lookat[2]), cam.distance, cam.azimuth, cam.elevation = job["camera"]

    def renderer(size: tuple[int, int]) -> Any:
        try:
            r = mujoco.Renderer(m, size[1], size[0])
        except Exception as exc:  # the back end is missing: the parent tries the next one
            print(f"no GL: {type(exc).__name__}: {exc}", file=sys.stderr)
            raise SystemExit(NO_GL_EXIT) from exc
        for flag in (mujoco.mjtRndFlag.mjRND_SHADOW, mujoco.mjtRndFlag.mjRND_REFLECTION):
            r.scene.flags[flag] = 0
        r.scene.flags[mujoco.mjtRndFlag.mjRND_SKYBOX] = 0
        return r

    def frame(r: Any, state: npt.NDArray[np.float64], caption: str = "") -> Any:
        mujoco.mj_setState(m, d, state, job["spec"])
        mujoco.mj_forward(m, d)  # the cables' paths and the sites come from the positions
        r.update_scene(d, cam)
        image = Image.fromarray(r.render())
        ImageDraw.Draw(image).text((4, 4), f"t = {d.time:.2f} s  {caption}", fill=(230, 230, 230))
        return image

    r = renderer(job["still_size"])
    try:
        for path, caption, state in job["stills"]:
            frame(r, state, caption).save(path, optimize=True)
    finally:
        r.close()
    if job["video"] is not None:
        path, states, frame_ms, size = job["video"]
        r = renderer(size)
        try:
            images = [frame(r, s) for s in states]
        finally:
            r.close()
        images[0].save(
            path, save_all=True, append_images=images[1:], duration=frame_ms, loop=0, optimize=True
        )
    return 0


if __name__ == "__main__":
    sys.exit(_child(sys.argv[1]))
