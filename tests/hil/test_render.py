"""hil.render: the run's own states filmed, rendered headless by MuJoCo, listed in the report; no GL gives
one line and the 2-D figures."""

from __future__ import annotations

import math
from pathlib import Path

import mujoco
import numpy as np
import pytest
from PIL import Image

from hil.board import BoardConfig
from hil.campaign.runner import run_one
from hil.campaign.spec import load_campaign
from hil.campaign.summary import campaign_pictures
from hil.cli.main import main
from hil.environment import Environment, Episode
from hil.faults import Fault, FaultKind
from hil.radio import RadioScript
from hil.render import (
    NO_GL,
    Film,
    FilmingEpisode,
    MomentWatcher,
    Pictures,
    render_film,
    render_moments,
    same_measurements,
)
from hil.report import write_index
from protocol.dbus import Lever, RcFrame
from protocol.messages import Phase


def _arm_pixels(path: Path) -> int:
    """Pixels of the arm's TPU orange (material rgba 0.95 0.55 0.15, lit): red high, green between,
    blue low."""
    rgb = np.asarray(Image.open(path).convert("RGB"), dtype=np.int32)
    r, g, b = rgb[..., 0], rgb[..., 1], rgb[..., 2]
    return int(np.count_nonzero((r > 120) & (r - b > 70) & (g > 0.3 * r) & (g < 0.8 * r)))


@pytest.fixture(scope="module")
def filmed() -> tuple[Film, int]:
    """A packed arm pulled by the left stick for 0.4 s, then the radio cut at 0.3 s (RC_LOST)."""
    film = Film(period_us=50_000)
    watcher = MomentWatcher(film)
    pull = RcFrame((0, 0, 0, 500), Lever.MIDDLE, Lever.DOWN)
    radio = RadioScript([(0, RcFrame.neutral()), (100_000, pull)])
    config = BoardConfig(start_packed=True)
    with Environment(
        config,
        episode=FilmingEpisode(Episode(), watcher),
        radio=radio,
        faults=[Fault(FaultKind.RC_SILENCE, 300_000, None)],
    ) as env:
        env.run(400_000)
        watcher.finish(env)
        phase = int(env.board.firmware.phase)
    return film, phase


def _rendered(pictures: Pictures) -> Pictures:
    if pictures.note == NO_GL:
        pytest.skip("no OpenGL back end on this machine (EGL and OSMesa both failed)")
    assert not pictures.note, pictures.note
    return pictures


def test_the_film_keeps_the_runs_moments(filmed: tuple[Film, int]) -> None:
    film, phase = filmed
    assert phase == Phase.RC_LOST
    labels = [label for _, label, _ in film.stills]
    assert labels == ["start", "failsafe RC_LOST", "end"]
    times = [t for t, _, _ in film.stills]
    assert 300_000 < times[1] <= 300_000 + 32_000  # RC lost 30 ms after the last frame, on a 1 ms tick
    assert times[-1] == 400_000
    assert [t for t, _ in film.frames] == list(range(1000, 400_000, 50_000))


def test_stills_and_gif_show_the_arm(filmed: tuple[Film, int], tmp_path: Path) -> None:
    film, _ = filmed
    pictures = _rendered(render_film(film, tmp_path, "run", video=True, video_frames_max=3))
    assert [p.caption for p in pictures.stills] == ["start", "failsafe RC_LOST", "end"]
    for p in pictures.stills:
        assert p.path.name.startswith("run-") and p.path.suffix == ".png"
        with Image.open(p.path) as im:
            assert im.size == (320, 240)
        assert _arm_pixels(p.path) > 300, f"{p.path.name}: no arm in the picture"
        assert p.path.stat().st_size < 150_000
    assert pictures.video is not None
    with Image.open(pictures.video.path) as gif:
        assert gif.n_frames == 3 and gif.size == (240, 180)
        gif.seek(1)
        frame = tmp_path / "frame.png"
        gif.convert("RGB").save(frame)
    assert _arm_pixels(frame) > 100
    # the report's index lists every picture with its time, and says what rendered it from what
    index = write_index(tmp_path, "run", "a run", [], [("", pictures)])
    text = index.read_text()
    for p in pictures.stills:
        assert f"]({p.path.name})" in text and f"t = {p.t_s:.3f} s: {p.caption}" in text
    assert "](run.gif)" in text and "from the run's own states (no re-simulation)" in text


def test_render_moments_picks_the_nearest_states(filmed: tuple[Film, int], tmp_path: Path) -> None:
    film, _ = filmed
    paths = render_moments(film, [0.1, 0.26], tmp_path, "tune")
    if not paths:
        pytest.skip("no OpenGL back end on this machine")
    assert [p.name for p in paths] == ["tune-01-t-0-101-s.png", "tune-02-t-0-251-s.png"]
    assert all(_arm_pixels(p) > 300 for p in paths)
    a = np.asarray(Image.open(paths[0]).convert("RGB"), dtype=np.int32)
    b = np.asarray(Image.open(paths[1]).convert("RGB"), dtype=np.int32)
    assert np.abs(a - b).sum() > 0  # the arm moved between them: two states, not one picture twice


def test_no_gl_gives_one_line_and_no_files(
    filmed: tuple[Film, int], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    film, _ = filmed
    # EGL with no vendor library: the back end fails to start, as on a machine without GL
    monkeypatch.setenv("__EGL_VENDOR_LIBRARY_FILENAMES", "/nonexistent/vendor.json")
    pictures = render_film(film, tmp_path / "a", "run", backends=("egl",))
    assert pictures.note == NO_GL and pictures.paths == [] and pictures.lines() == [NO_GL]
    assert not list((tmp_path / "a").glob("*.png"))
    monkeypatch.setenv("MUJOCO_GL", "disable")  # the user's switch: no back end tried at all
    assert render_film(film, tmp_path / "b", "run").note == NO_GL


def test_scenario_report_lists_its_pictures(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["run", "rc-loss", "--report", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    index = (tmp_path / "rc-loss.md").read_text()
    assert "![rc-loss](rc-loss.png)" in index  # the 2-D figure, as before
    if NO_GL in index:
        pytest.skip("no OpenGL back end on this machine")
    stills = sorted(tmp_path.glob("rc-loss-*.png"))
    assert len(stills) >= 3
    for still in stills:
        assert f"]({still.name})" in index and f"rc-loss: {still.name}: t = " in out
        assert _arm_pixels(still) > 300
    assert "failsafe RC_LOST" in index
    assert f"rc-loss: report {tmp_path / 'rc-loss.md'}" in out


def test_scenario_report_without_gl_is_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("MUJOCO_GL", "disable")
    assert main(["run", "startup-gate", "--report", str(tmp_path)]) == 0
    captured = capsys.readouterr()
    assert captured.out.count(NO_GL) == 1 and "Traceback" not in captured.out + captured.err
    index = (tmp_path / "startup-gate.md").read_text()
    assert index.count(NO_GL) == 1 and "![startup-gate](startup-gate.png)" in index
    assert (tmp_path / "startup-gate.png").stat().st_size > 10_000
    assert not list(tmp_path.glob("startup-gate-*.png")) and not list(tmp_path.glob("*.gif"))


def test_a_long_film_thins_itself(filmed: tuple[Film, int]) -> None:
    film, _ = filmed
    plant_film = Film(period_us=1000, max_frames=4)

    class _Plant:  # the film reads these four
        mj_model, mj_data = film.model, None
        unit_names, object_names = film.unit_names, film.object_names

    fake = _Plant()
    fake.mj_data = mujoco.MjData(film.model)
    for t_us in range(0, 10_000, 1000):
        plant_film.capture(fake, t_us)  # type: ignore[arg-type]
    assert [t for t, _ in plant_film.frames] == [0, 4000, 8000]
    assert plant_film.period_us == 4000 and len(plant_film.frames) <= 4


def test_an_empty_film_says_so(tmp_path: Path) -> None:
    assert render_film(Film(), tmp_path, "x").note == "nothing filmed: no pictures"
    with pytest.raises(ValueError, match="empty"):
        Film().nearest(0)
    with pytest.raises(ValueError, match="positive"):
        Film(period_us=0)


def test_same_measurements_compares_as_a_results_file_keeps_them() -> None:
    recorded = {"state": "HOLD", "t_hold_s": None, "extremes": {"tension_n": 1.5}, "setup": {"x_m": 1}}
    rerun = {"state": "HOLD", "t_hold_s": math.nan, "extremes": {"tension_n": 1.5}, "setup": {"x_m": 2}}
    assert same_measurements(recorded, rerun) == []  # NaN is JSON's null; the setup is the input
    rerun["extremes"] = {"tension_n": 1.5000000001}
    rerun["units_after"] = 3
    assert same_measurements(recorded, rerun) == ["extremes", "units_after"]


def test_a_scenario_campaign_pictures_its_runs_only_if_the_rerun_matches(tmp_path: Path) -> None:
    campaign = load_campaign(
        None, ["kind=scenario", "scenario.name=startup-gate", "scenario.faults=[[], ['rc-silence@0']]"]
    )
    rows = [run_one(r) for r in campaign.runs()]
    assert [r["outcome"] for r in rows] == ["success", "failure"]
    pictures, notes = campaign_pictures(rows, tmp_path)
    assert pictures == []  # a scenario's pictures are in its own report, linked from the notes
    text = "\n".join(notes)
    for label in ("success", "failure"):
        assert f"### a {label}: scenario startup-gate" in text
        assert f"its report: [run-{label}/startup-gate.md](run-{label}/startup-gate.md)" in text
        assert (tmp_path / f"run-{label}" / "startup-gate.png").exists()
    assert "re-run differs" not in text
    # a row the re-run does not reproduce: its pictures are not kept
    rows[1]["measured"]["duration_s"] = 99.0
    _, notes = campaign_pictures(rows, tmp_path / "tampered")
    text = "\n".join(notes)
    assert "re-run differs from the recorded run (duration_s): pictures skipped" in text
    assert not (tmp_path / "tampered" / "run-failure").exists()
    assert (tmp_path / "tampered" / "run-success" / "startup-gate.md").exists()
