"""Pictures of runs: MuJoCo's own renderer, headless, at the moments that matter, and a short animated GIF.

A report shows the run itself, never a re-run that could differ: a :class:`Film` keeps the plant's state
(``mj_getState``: time, joint positions and the mocap bodies, that is the drone and the objects' supports)
while the run runs, every :attr:`Film.period_us` of simulated time for the video and at once at the moments
a :class:`MomentWatcher` marks:

- the first time the grasp state machine enters WRAP (contact), HOLD, RELEASE or FAILED;
- the first time the failsafe enters each phase other than OK (``RC_LOST``, ``MOTOR_LOST`` ...);
- an object's support removed, and :data:`AFTER_SUPPORT_S` later (does the grasp hold?);
- the start and the end of the run.

Rendering runs in a child process (:mod:`hil.render_child`): MuJoCo picks its GL back end from
``MUJOCO_GL`` when it is first imported, so a process that already simulated cannot switch, and a GL driver
that crashes ends the child, never the run. EGL is tried first, then OSMesa (``MUJOCO_GL`` set to one of
them tries only that one; ``MUJOCO_GL=disable`` skips pictures). With no back end the report carries
:data:`NO_GL` (one line) and its 2-D figures as before.

Cost (``bench/render.py`` on this project's 2-core machine, Mesa's llvmpipe through EGL): the child's
start and one 320x240 still take 0.86 s of CPU, each 240x180 GIF frame 53 ms with its encoding (shadows,
reflections and multisampling off); a scenario's report (up to :data:`MAX_STILLS` stills and a GIF of up
to :data:`VIDEO_FRAMES_MAX` frames) about 4 s of CPU. Every report states its own cost.
"""

from __future__ import annotations

import math
import os
import pickle
import re
import subprocess
import sys
import tempfile
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Final

import mujoco
import numpy as np
import numpy.typing as npt

from hil.environment import Environment, Episode
from hil.render_child import NO_GL_EXIT
from protocol.messages import GraspState, Phase

if TYPE_CHECKING:
    from hil.sim.plant import Plant
    from hil.sim.spiral import SpiralDesign
    from hil.trial.grasp import GraspSetup

__all__ = [
    "AFTER_SUPPORT_S",
    "MAX_STILLS",
    "NO_GL",
    "OWN_STATES",
    "RERUN",
    "Film",
    "FilmingEpisode",
    "MomentWatcher",
    "Picture",
    "Pictures",
    "film_grasp_trial",
    "gl_backends",
    "render_film",
    "render_moments",
    "same_measurements",
]

NO_GL: Final = "no OpenGL: pictures skipped, 2-D figures only"
"""The report's one line when no GL back end works (and its 2-D figures stay as they were)."""
AFTER_SUPPORT_S: Final = 2.0
"""A still this long after an object's support went: is the object still held?"""
MAX_STILLS: Final = 8
"""The most stills one run keeps (the start and the end among them): a report stays short."""
VIDEO_FRAMES_MAX: Final = 60
"""The most frames of a run's GIF (the film is thinned evenly to fit)."""
MOTION_MM: Final = 5.0
"""A GIF is made when the tip's path over the run spans more than this (a still arm needs no video)."""
STILL_SIZE: Final = (320, 240)
VIDEO_SIZE: Final = (240, 180)
OWN_STATES: Final = "the run's own states (no re-simulation)"
RERUN: Final = "a re-run of the recorded trial that measured exactly what it recorded"
CHILD_TIMEOUT_S: Final = 300.0
"""A render child that takes longer is killed and its pictures skipped (one line)."""
_STATE_SPEC: Final = int(
    mujoco.mjtState.mjSTATE_TIME
    | mujoco.mjtState.mjSTATE_QPOS
    | mujoco.mjtState.mjSTATE_MOCAP_POS
    | mujoco.mjtState.mjSTATE_MOCAP_QUAT
)
_DISABLED: Final = ("disable", "disabled", "off", "false", "0")

FloatArray = npt.NDArray[np.float64]


# --- the film: the run's own states -------------------------------------------------------------------


class Film:
    """The plant's states over one run: frames every ``period_us`` and stills at marked moments.

    Args:
        period_us: simulated time between two video frames.
        max_frames: the most frames kept (then the film thins itself: see :meth:`capture`).

    A film holds one model: if the plant rebuilds its model mid-run (an object added), what was filmed
    before is dropped, since those states do not fit the new model.
    """

    def __init__(self, period_us: int = 100_000, max_frames: int = 600) -> None:
        if period_us <= 0 or max_frames <= 0:
            raise ValueError("period_us and max_frames must be positive")
        self.period_us = period_us
        self.max_frames = max_frames
        self.model: Any = None
        self.unit_names: tuple[str, ...] = ()
        self.object_names: tuple[str, ...] = ()
        self.frames: list[tuple[int, FloatArray]] = []
        self.stills: list[tuple[int, str, FloatArray]] = []
        self._next_us = 0

    def _state(self, plant: Plant) -> FloatArray:
        m = plant.mj_model
        if m is not self.model:
            self.model = m
            self.unit_names = plant.unit_names
            self.object_names = plant.object_names
            self.frames.clear()
            self.stills.clear()
        out = np.empty(mujoco.mj_stateSize(m, _STATE_SPEC))
        mujoco.mj_getState(m, plant.mj_data, out, _STATE_SPEC)
        return out

    def capture(self, plant: Plant, t_us: int) -> None:
        """Keep a frame if one is due at ``t_us`` (the run's time); when ``max_frames`` are kept, every
        other one is dropped and the period doubled, so a long run stays whole in bounded memory."""
        if t_us < self._next_us:
            return
        if len(self.frames) >= self.max_frames:
            del self.frames[1::2]
            self.period_us *= 2
        self.frames.append((t_us, self._state(plant)))
        self._next_us = t_us + self.period_us

    def mark(self, plant: Plant, t_us: int, label: str) -> bool:
        """Keep a still of this moment (False when :data:`MAX_STILLS` are kept already; ``end`` always
        fits: it replaces the last other still)."""
        state = self._state(plant)  # first: a rebuilt model clears what was kept
        if self.stills and self.stills[-1][0] == t_us:  # the same tick: one picture, both captions
            self.stills[-1] = (t_us, f"{self.stills[-1][1]}; {label}", state)
            return True
        if len(self.stills) >= MAX_STILLS:
            if label != "end":
                return False
            self.stills.pop()
        self.stills.append((t_us, label, state))
        return True

    def nearest(self, t_us: float) -> tuple[int, FloatArray]:
        """The frame or still closest to ``t_us``.

        Raises:
            ValueError: the film is empty.
        """
        pool = [*self.frames, *((t, s) for t, _, s in self.stills)]
        if not pool:
            raise ValueError("the film is empty")
        return min(pool, key=lambda f: abs(f[0] - t_us))


class MomentWatcher:
    """Marks a run's moments on a :class:`Film` (see the module's docstring), and films it.

    Call it after every tick (``watcher(env)``) and :meth:`finish` once the run is over.
    """

    def __init__(self, film: Film, after_support_s: float = AFTER_SUPPORT_S) -> None:
        self.film = film
        self._after_support_us = round(after_support_s * 1e6)
        self._seen_states: set[int] = set()
        self._seen_phases: set[int] = set()
        self._held: dict[str, bool] = {}
        self._due: list[tuple[int, str]] = []
        self._started = False
        self._env: Environment | None = None

    def __call__(self, env: Environment) -> None:
        self._env = env
        plant, fw, now = env.board.plant, env.board.firmware, env.now_us
        film = self.film
        film.capture(plant, now)
        if not self._started:
            self._started = True
            film.mark(plant, now, "start")
        state = int(fw.grasp_state)
        if state not in self._seen_states:
            self._seen_states.add(state)
            if state in (GraspState.WRAP, GraspState.HOLD, GraspState.RELEASE, GraspState.FAILED):
                label = "contact (WRAP)" if state == GraspState.WRAP else GraspState(state).name
                film.mark(plant, now, f"grasp {label}")
        phase = int(fw.phase)
        if phase not in self._seen_phases:
            self._seen_phases.add(phase)
            if phase not in (Phase.OK, Phase.GATE):  # GATE: every run starts there
                film.mark(plant, now, f"failsafe {Phase(phase).name}")
        for name in plant.object_names:
            held = plant.object_held(name)
            if self._held.get(name, held) and not held:
                film.mark(plant, now, f"{name}'s support removed")
                after = f"{self._after_support_us / 1e6:g} s after {name}'s support went"
                self._due.append((now + self._after_support_us, after))
            self._held[name] = held
        while self._due and self._due[0][0] <= now:
            film.mark(plant, now, self._due.pop(0)[1])

    def finish(self, env: Environment | None = None) -> None:
        """Mark the end of the run (of ``env``, or of the environment it last watched)."""
        env = env if env is not None else self._env
        if env is not None:
            self.film.mark(env.board.plant, env.now_us, "end")


class FilmingEpisode(Episode):
    """An episode that runs another one and films the run with a :class:`MomentWatcher`.

    Args:
        inner: the episode (a scenario) whose hooks run unchanged.
        watcher: called after the inner episode's ``after_tick``.
    """

    def __init__(self, inner: Episode, watcher: MomentWatcher) -> None:
        self.inner = inner
        self.watcher = watcher

    def initialize(self, env: Environment) -> None:
        self.inner.initialize(env)

    def before_tick(self, env: Environment) -> None:
        self.inner.before_tick(env)

    def after_tick(self, env: Environment) -> None:
        self.inner.after_tick(env)
        self.watcher(env)


# --- re-running a recorded trial, filmed ---------------------------------------------------------------


def _normal(value: Any) -> Any:
    """A measured value as JSON sees it (NaN as None, tuples as lists): the form a results file keeps."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: _normal(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_normal(v) for v in value]
    if isinstance(value, np.generic):
        return _normal(value.item())
    return value


def same_measurements(recorded: Mapping[str, Any], rerun: Mapping[str, Any]) -> list[str]:
    """The keys whose values differ between a recorded trial's measurements and a re-run's (``setup``,
    the inputs, is not compared; floats must be equal to the bit, as a deterministic re-run gives them)."""
    keys = (set(recorded) | set(rerun)) - {"setup"}
    return sorted(k for k in keys if _normal(recorded.get(k)) != _normal(rerun.get(k)))


def film_grasp_trial(
    setup: GraspSetup, design: SpiralDesign, recorded: Mapping[str, Any], film: Film | None = None
) -> tuple[Film | None, str]:
    """Run a recorded grasp trial again, filmed, and check that it is the same trial.

    A trial is a pure function of its setup and design (MuJoCo is deterministic on one machine), so the
    re-run must measure exactly what was recorded (every field of
    :class:`~hil.trial.grasp.GraspOutcome`: its state, times, contacts, drop, extremes ...). If any
    differs, the film is discarded: a picture never shows a run that is not the recorded one.

    Returns:
        ``(film, "")``, or ``(None, one line naming what differed)``.
    """
    from hil.trial.grasp import grasp_trial  # the trial's rig: only when a report asks for it

    film = film if film is not None else Film()
    watcher = MomentWatcher(film)
    outcome = grasp_trial(setup, design, on_tick=watcher)
    watcher.finish()
    differ = same_measurements(recorded, outcome.as_dict())
    if differ:
        return None, f"re-run differs from the recorded trial ({', '.join(differ[:3])}): pictures skipped"
    return film, ""


# --- what a report gets back -------------------------------------------------------------------------


@dataclass(frozen=True)
class Picture:
    """One image written: its file, the run's time it shows, and what it shows."""

    path: Path
    t_s: float
    caption: str


@dataclass(frozen=True)
class Pictures:
    """What :func:`render_film` wrote.

    Attributes:
        stills: one PNG per moment.
        video: the animated GIF (None: the arm barely moved, or no GL).
        note: empty, or one line saying why there are no pictures (:data:`NO_GL`, a timeout ...).
        backend: the GL back end that rendered (``egl``, ``osmesa``; empty if none).
        render_s: wall-clock cost of the rendering (the child process included).
        frames_n: frames rendered.
        source: where the states came from (:data:`OWN_STATES` or :data:`RERUN`).
    """

    stills: tuple[Picture, ...] = ()
    video: Picture | None = None
    note: str = ""
    backend: str = ""
    render_s: float = 0.0
    frames_n: int = 0
    source: str = OWN_STATES

    @property
    def paths(self) -> list[Path]:
        """Every file written (stills, then the video)."""
        return [p.path for p in self.stills] + ([self.video.path] if self.video is not None else [])

    def lines(self) -> list[str]:
        """The report's lines: the note, or one line per picture and the cost."""
        if self.note:
            return [self.note]
        out = [f"{p.path.name}: t = {p.t_s:.3f} s, {p.caption}" for p in self.stills]
        if self.video is not None:
            out.append(f"{self.video.path.name}: {self.video.caption}")
        out.append(
            f"rendered by MuJoCo ({self.backend}) from {self.source}: "
            f"{self.frames_n} frames in {self.render_s:.1f} s"
        )
        return out


# --- rendering ------------------------------------------------------------------------------------------


def gl_backends() -> tuple[str, ...]:
    """The GL back ends to try: ``MUJOCO_GL``'s if it names egl or osmesa, none if it disables GL, else
    EGL then OSMesa."""
    chosen = os.environ.get("MUJOCO_GL", "").strip().lower()
    if chosen in _DISABLED:
        return ()
    if chosen in ("egl", "osmesa"):
        return (chosen,)
    return ("egl", "osmesa")


def _slug(label: str) -> str:
    return re.sub(r"[^a-z0-9]+", "-", label.lower()).strip("-")


def _camera(film: Film) -> tuple[tuple[float, float, float], float, float, float]:
    """One camera for the whole film: looking along +y at the x-z plane the arm bends in (cable 0 is on
    +x), framing the arm over every frame and the objects near it (an object waiting out of reach stays
    out of the picture)."""
    m = film.model
    d = mujoco.MjData(m)
    units = [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, n) for n in film.unit_names]
    objects = [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, n) for n in film.object_names]
    points: list[FloatArray] = []
    reach = 0.0
    states = [s for _, s in film.frames] + [s for _, _, s in film.stills]
    arm_at: list[tuple[FloatArray, FloatArray]] = []
    for s in states:
        mujoco.mj_setState(m, d, s, _STATE_SPEC)
        mujoco.mj_kinematics(m, d)
        arm = d.xpos[units].copy()
        arm_at.append((arm, d.xpos[objects].copy()))
        reach = max(reach, float(np.linalg.norm(arm[-1] - arm[0])))
    for arm, objs in arm_at:
        points.append(arm)
        base = arm[0]
        near = [o for o in objs if np.linalg.norm(o - base) < 1.5 * reach + 0.05]
        if near:
            points.append(np.asarray(near))
    pts = np.vstack(points)
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    centre = (lo + hi) / 2
    span = max(float(hi[0] - lo[0]), float(hi[2] - lo[2]), 0.06) + 0.04
    fovy = math.radians(float(m.vis.global_.fovy))
    distance = span / 2 / math.tan(fovy / 2) + float(hi[1] - lo[1]) / 2
    return (float(centre[0]), float(centre[1]), float(centre[2])), distance, 90.0, -10.0


def _tip_span_mm(film: Film) -> float:
    m = film.model
    d = mujoco.MjData(m)
    tip = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, film.unit_names[-1])
    path = []
    for _, s in film.frames:
        mujoco.mj_setState(m, d, s, _STATE_SPEC)
        mujoco.mj_kinematics(m, d)
        path.append(d.xpos[tip].copy())
    if len(path) < 2:
        return 0.0
    arr = np.asarray(path)
    return float(np.linalg.norm(arr.max(axis=0) - arr.min(axis=0))) * 1000


def render_film(
    film: Film,
    out_dir: str | Path,
    name: str,
    *,
    video: bool | None = None,
    backends: Sequence[str] | None = None,
    still_size: tuple[int, int] = STILL_SIZE,
    video_size: tuple[int, int] = VIDEO_SIZE,
    video_frames_max: int = VIDEO_FRAMES_MAX,
    timeout_s: float = CHILD_TIMEOUT_S,
    source: str = OWN_STATES,
) -> Pictures:
    """Render a film's stills (``NAME-01-grasp-hold.png`` ...) and, where the arm moves, a GIF
    (``NAME.gif``) into ``out_dir``.

    Args:
        film: the run's states.
        out_dir: where the images go (created).
        name: the files' prefix.
        video: make the GIF (None: when the tip's path spans more than :data:`MOTION_MM`).
        backends: GL back ends to try, in order (default :func:`gl_backends`).
        still_size, video_size: (width, height) in pixels.
        video_frames_max: the most GIF frames.
        timeout_s: the render child's bound.
        source: where the film's states come from, for the report (:data:`OWN_STATES`, :data:`RERUN`).

    Returns:
        The pictures, or a :class:`Pictures` whose ``note`` says in one line why there are none.
    """
    t0 = time.perf_counter()
    if film.model is None or not (film.stills or film.frames):
        return Pictures(note="nothing filmed: no pictures")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    stills = [
        Picture(out / f"{name}-{i:02d}-{_slug(label)}.png", t_us / 1e6, label)
        for i, (t_us, label, _) in enumerate(film.stills, start=1)
    ]
    if video is None:
        video = _tip_span_mm(film) > MOTION_MM
    frames = film.frames
    if video and len(frames) > video_frames_max:
        picks = np.linspace(0, len(frames) - 1, video_frames_max).round().astype(int)
        frames = [frames[i] for i in picks]
    clip: Picture | None = None
    frame_ms = 100
    if video and len(frames) >= 2:
        span_s = (frames[-1][0] - frames[0][0]) / 1e6
        frame_ms = max(40, round(1000 * span_s / (len(frames) - 1)))
        speed = 1000 * span_s / (frame_ms * (len(frames) - 1))
        pace = "in real time" if abs(speed - 1) < 0.05 else f"at {speed:.2g}x real time"
        clip = Picture(
            out / f"{name}.gif",
            frames[0][0] / 1e6,
            f"animated GIF, {len(frames)} frames from {frames[0][0] / 1e6:.1f} s to "
            f"{frames[-1][0] / 1e6:.1f} s, {pace}",
        )
    job = {
        "model": film.model,
        "spec": _STATE_SPEC,
        "camera": _camera(film),
        "stills": [(str(p.path), p.caption, s) for p, (_, _, s) in zip(stills, film.stills, strict=True)],
        "still_size": still_size,
        "video": None if clip is None else (str(clip.path), [s for _, s in frames], frame_ms, video_size),
    }
    frames_n = len(stills) + (len(frames) if clip is not None else 0)
    tried = tuple(gl_backends() if backends is None else backends)
    with tempfile.TemporaryDirectory(prefix="spirob-render-") as tmp:
        job_path = Path(tmp) / "job.pickle"
        job_path.write_bytes(pickle.dumps(job))
        for backend in tried:
            env = {**os.environ, "MUJOCO_GL": backend, "PYOPENGL_PLATFORM": backend}
            try:
                done = subprocess.run(
                    [sys.executable, "-m", "hil.render_child", str(job_path)],
                    env=env,
                    capture_output=True,
                    text=True,
                    timeout=timeout_s,
                    check=False,
                )
            except subprocess.TimeoutExpired:
                return Pictures(note=f"pictures skipped: the renderer took over {timeout_s:g} s")
            if done.returncode == 0:
                return Pictures(tuple(stills), clip, "", backend, time.perf_counter() - t0, frames_n, source)
            if done.returncode == NO_GL_EXIT or done.returncode < 0:
                continue  # this back end cannot start (or its driver crashed): the next one
            last = (done.stderr.strip().splitlines() or ["no message"])[-1]
            return Pictures(note=f"pictures failed ({backend}): {last}")
    return Pictures(note=NO_GL)


def render_moments(
    film: Film, times_s: Sequence[float], out_dir: str | Path, name: str = "moment"
) -> list[Path]:
    """Stills of a film at given times (the nearest state kept), for callers that choose their own
    moments (a tuning run). Returns the files written; none when no GL back end works.

    Raises:
        ValueError: the film is empty.
    """
    picked = Film(film.period_us)
    picked.model, picked.unit_names, picked.object_names = film.model, film.unit_names, film.object_names
    for t in times_s:
        t_us, state = film.nearest(t * 1e6)
        picked.stills.append((t_us, f"t = {t_us / 1e6:.3f} s", state))
    picked.frames = list(film.frames)  # framing only: no video
    return render_film(picked, out_dir, name, video=False).paths
