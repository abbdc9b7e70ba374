"""Benchmark of the report pictures (hil.render): what MuJoCo's headless renderer costs; prints its figures.

Films a packed arm pulled by the left stick for 2 s (a frame every 50 ms), then renders (each a render
child of its own, as a report does): one still (the child's start plus one frame), then one still and a
GIF of ``--frames`` frames. Prints wall-clock and CPU time (the child's, from ``getrusage``; wall-clock
figures depend on what else the machine runs, CPU time much less), the cost of one frame, the files'
sizes and the GL back end. With no GL back end it prints the report's one line and exits 0.

Usage: ``.venv/bin/python bench/render.py [--frames 40]``
"""

from __future__ import annotations

import argparse
import os
import resource
import sys
import tempfile
import time
from pathlib import Path

# Run as a script, this file's directory comes first on sys.path, where bench/protocol.py would shadow
# the protocol package; benchmarks import the project only.
_HERE = Path(__file__).resolve().parent
sys.path[:] = [p for p in sys.path if Path(p or ".").resolve() != _HERE]

from hil.board import BoardConfig  # noqa: E402
from hil.environment import Environment, Episode  # noqa: E402
from hil.radio import RadioScript  # noqa: E402
from hil.render import Film, FilmingEpisode, MomentWatcher, Pictures, render_film  # noqa: E402
from protocol.dbus import Lever, RcFrame  # noqa: E402


def _film() -> Film:
    film = Film(period_us=50_000)
    watcher = MomentWatcher(film)
    radio = RadioScript(
        [(0, RcFrame.neutral()), (100_000, RcFrame((0, 0, 0, 500), Lever.MIDDLE, Lever.DOWN))]
    )
    with Environment(
        BoardConfig(start_packed=True), episode=FilmingEpisode(Episode(), watcher), radio=radio
    ) as env:
        env.run(2_000_000)
        watcher.finish(env)
    return film


def _timed(film: Film, out: Path, name: str, frames: int) -> tuple[Pictures, float, float]:
    cpu0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    pics = render_film(film, out, name, video=frames > 1, video_frames_max=max(frames, 2))
    wall = time.perf_counter() - t0
    cpu1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (cpu1.ru_utime - cpu0.ru_utime) + (cpu1.ru_stime - cpu0.ru_stime)
    return pics, wall, cpu


def main() -> int:
    """Run the benchmark and print its figures."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=40, help="GIF frames of the second job (default 40)")
    args = parser.parse_args()
    if not 2 <= args.frames <= 200:
        parser.error("--frames must be 2..200")
    film = _film()
    one = Film(film.period_us)
    one.model, one.unit_names, one.object_names = film.model, film.unit_names, film.object_names
    one.stills, one.frames = film.stills[:1], film.frames
    print(f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} CPUs")
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp)
        pics, wall1, cpu1 = _timed(one, out, "one", 1)
        if pics.note:
            print(pics.note)
            return 0
        size = pics.stills[0].path.stat().st_size
        print(
            f"one 320x240 still ({pics.backend}): {wall1:.2f} s wall, {cpu1:.2f} s CPU "
            "(the child's start + 1 frame)"
        )
        print(f"  its PNG: {size / 1000:.1f} KB")
        one.stills = film.stills[:1]
        pics, wall, cpu = _timed(one, out, "clip", args.frames)
        assert pics.video is not None
        per_wall = (wall - wall1) / args.frames * 1000
        per_cpu = (cpu - cpu1) / args.frames * 1000
        print(
            f"one still + a {args.frames}-frame 240x180 GIF: {wall:.2f} s wall, {cpu:.2f} s CPU; "
            f"per GIF frame {per_wall:.0f} ms wall, {per_cpu:.0f} ms CPU (rendering and GIF encoding)"
        )
        print(f"  the GIF: {pics.video.path.stat().st_size / 1000:.0f} KB")
    return 0


if __name__ == "__main__":
    sys.exit(main())
