"""host.virtual_rc: the radio script (``--virtual-rc-script``) read, checked and played against telemetry
in simulated time; the command line's one-line refusals; and the example grasp, end to end."""

from __future__ import annotations

import re
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

import pytest

from host.cli import main
from host.virtual_rc import Condition, Radio, RadioScript, ScriptError, ScriptRun, ScriptState
from protocol.dbus import Lever
from protocol.messages import GraspState, Mode, Phase, Telemetry
from tests.support.realtime_guard import retry_void

ROOT = Path(__file__).resolve().parents[2]
EXAMPLE = ROOT / "examples" / "06_scripted_grasp.toml"


def one_error_line(err: str) -> str:
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1, f"expected one line, got {lines!r}"
    assert "Traceback" not in err
    return lines[0]


IDLE = Radio()
"""The radio at start: sticks centred, both levers DOWN."""


def tel(
    time_s: float,
    radio: Radio = IDLE,
    mode: Mode = Mode.SAFE,
    phase: Phase = Phase.OK,
    grasp: GraspState = GraspState.IDLE,
) -> Telemetry:
    """Telemetry at board time ``time_s`` reporting ``radio`` as the board's last accepted frame."""
    return Telemetry(
        time_us=round(time_s * 1e6),
        mode=mode,
        phase=phase,
        grasp_state=grasp,
        rc_channels=radio.sticks,
        right_lever=int(radio.right),
        left_lever=int(radio.left),
    )


GRASP = RadioScript.parse(
    {
        "step": [
            {"right": "DOWN", "until": {"phase": "OK"}},
            {"right": "UP", "until": {"mode": "GRASP"}},
            {"for_s": 3.0, "keep": {"mode": "GRASP"}},
            {"left": "up", "sticks": {"right_x": -200}, "until": {"grasp": "HOLD"}, "timeout_s": 40},
        ]
    }
)


# ---------------------------------------------------------------------- reading a script


def test_the_example_script_reads() -> None:
    script = RadioScript.load(EXAMPLE)
    assert len(script.steps) == 5
    assert script.steps[3].left == Lever.UP and script.steps[3].until == Condition(grasp=GraspState.HOLD)
    assert script.steps[2].keep == Condition(mode=Mode.GRASP, phase=Phase.OK)


def test_steps_change_only_what_they_name() -> None:
    radio = Radio()
    for step in GRASP.steps:
        radio = step.apply(radio)
    assert radio == Radio((-200, 0, 0, 0), Lever.UP, Lever.UP)
    assert GRASP.steps[3].timeout_s == 40.0 and GRASP.steps[0].timeout_s == 30.0
    assert GRASP.steps[2].timeout_s == 33.0  # for_s + 30 unless told


@pytest.mark.parametrize(
    ("text", "needle"),
    [
        ("", "no [[step]] tables"),
        ("title = 'x'\n[[step]]\nright = 'UP'\n", "unknown top-level key 'title'"),
        ("[[step]]\nright = 'UPP'\n", "step 1: right: 'UPP' is not a lever position (UP, MIDDLE or DOWN)"),
        ("[[step]]\nright = 'UP'\n[[step]]\nrigth = 'UP'\n", "step 2: unknown key 'rigth'"),
        (
            "[[step]]\nsticks = { left_y = 700 }\n",
            "step 1: sticks: left_y = 700 is not a whole number of counts",
        ),
        ("[[step]]\nsticks = { left_y = 1.5 }\n", "step 1: sticks: left_y = 1.5 is not a whole number"),
        ("[[step]]\nsticks = { ch9 = 1 }\n", "step 1: sticks: unknown stick 'ch9'"),
        ("[[step]]\nfor_s = -1\n", "step 1: for_s: -1 s is out of range"),
        ("[[step]]\nfor_s = 'long'\n", "step 1: for_s: 'long' is not a number of seconds"),
        ("[[step]]\nfor_s = 5\ntimeout_s = 2\n", "step 1: timeout_s (2 s) must be longer than for_s (5 s)"),
        ("[[step]]\nuntil = { grasp = 'HELD' }\n", "step 1: until: grasp = 'HELD' is not one of IDLE, REACH"),
        ("[[step]]\nuntil = { speed = 'fast' }\n", "step 1: until: unknown key 'speed'"),
        ("[[step]]\nsay = 'nothing'\n", "step 1: does nothing"),
        ("[[step]\n", "not TOML: "),
    ],
)
def test_a_bad_script_is_one_line_and_exit_2(
    tmp_path: Path, text: str, needle: str, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(ScriptError, match=None):
        RadioScript.load(path)
    assert main(["--headless", "--virtual-rc-script", str(path)]) == 2
    line = one_error_line(capsys.readouterr().err)
    assert line.startswith(f"spirob-host: error: --virtual-rc-script {path}: ") and needle in line, line


@pytest.mark.parametrize(
    ("argv", "needle"),
    [
        (["--virtual-rc-script", "nowhere.toml"], "--virtual-rc-script nowhere.toml: no such file"),
        (["--virtual-rc-script", str(EXAMPLE), "--virtual-rc", "manual"], "and --virtual-rc cannot be"),
        (["--virtual-rc-script", str(EXAMPLE), "--excite", "quick"], "and --excite cannot be combined"),
        (["--virtual-rc-script", str(EXAMPLE), "--replay", str(EXAMPLE)], "needs a board"),
    ],
)
def test_refused_combinations(argv: list[str], needle: str, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["--headless", *argv]) == 2
    assert needle in one_error_line(capsys.readouterr().err)


# ---------------------------------------------------------------------- playing it (simulated time)


def test_a_script_runs_its_steps_in_order_on_the_boards_reports() -> None:
    run = ScriptRun(GRASP)
    assert run.start(0.0) == Radio()
    run.on_telemetry(tel(1.0), 0.1)  # gate passed, radio echoed: step 2
    assert run.index == 1 and run.radio == Radio((0, 0, 0, 0), Lever.UP, Lever.DOWN)
    # Telemetry from before the board took the new radio cannot end a step, even if it says GRASP.
    run.on_telemetry(tel(1.01, mode=Mode.GRASP), 0.11)
    assert run.index == 1
    up = run.radio
    run.on_telemetry(tel(1.02, up, Mode.GRASP), 0.12)
    assert run.index == 2
    # for_s counts board time from the first telemetry showing the step's radio.
    run.on_telemetry(tel(1.03, up, Mode.GRASP), 0.13)
    run.on_telemetry(tel(4.02, up, Mode.GRASP), 0.14)  # 2.99 s: not yet
    assert run.index == 2
    run.on_telemetry(tel(4.03, up, Mode.GRASP), 0.15)
    assert run.index == 3 and run.radio == Radio((-200, 0, 0, 0), Lever.UP, Lever.UP)
    grasp = run.radio
    for i, state in enumerate((GraspState.REACH, GraspState.WRAP)):
        run.on_telemetry(tel(5.0 + i, grasp, Mode.GRASP, grasp=state), 1.0 + i)
    assert run.step is not None and run.step.number == 4
    run.on_telemetry(tel(7.0, grasp, Mode.GRASP, grasp=GraspState.HOLD), 3.0)
    assert run.state is ScriptState.DONE and run.step is None
    assert run.reason == "all 4 steps done in 6.0 s of board time"


@pytest.mark.parametrize(
    ("feed", "needle"),
    [
        # A failsafe ends the script at once (its until asked for something else).
        (lambda r: tel(2.0, r, phase=Phase.RC_LOST), "step 1: the board entered RC_LOST"),
        (lambda r: tel(2.0, r, grasp=GraspState.FAILED), "step 1: the board entered grasp FAILED"),
    ],
)
def test_a_failsafe_or_a_failed_grasp_ends_the_script(
    feed: Callable[[Radio], Telemetry], needle: str
) -> None:
    run = ScriptRun(RadioScript.parse({"step": [{"right": "UP", "until": {"grasp": "HOLD"}}]}))
    run.start(0.0)
    run.on_telemetry(feed(run.radio), 0.5)
    assert run.state is ScriptState.FAILED and run.reason.startswith(needle), run.reason


def test_a_step_may_ask_for_a_failsafe() -> None:
    run = ScriptRun(RadioScript.parse({"step": [{"for_s": 1.0, "until": {"phase": "ESTOP"}}]}))
    run.start(0.0)
    run.on_telemetry(tel(0.0, phase=Phase.ESTOP), 0.1)
    run.on_telemetry(tel(1.0, phase=Phase.ESTOP), 0.2)
    assert run.state is ScriptState.DONE


def test_keep_must_hold_throughout() -> None:
    run = ScriptRun(RadioScript.parse({"step": [{"say": "hold", "for_s": 2.0, "keep": {"grasp": "HOLD"}}]}))
    run.start(0.0)
    run.on_telemetry(tel(0.0, grasp=GraspState.HOLD), 0.1)
    run.on_telemetry(tel(1.0, grasp=GraspState.RELEASE), 0.2)
    assert run.state is ScriptState.FAILED
    assert run.reason == (
        "step 1 (hold): grasp HOLD did not hold (the board: mode SAFE, phase OK, grasp RELEASE)"
    )


def test_a_step_times_out_on_host_time_stretched_by_the_load() -> None:
    script = RadioScript.parse({"step": [{"right": "UP", "until": {"mode": "GRASP"}, "timeout_s": 5}]})
    run = ScriptRun(script, timeout_scale=2.0)
    run.start(100.0)
    run.poll(109.0)
    assert run.step is not None  # 5 s x 2: still running
    run.poll(110.5)
    assert run.state is ScriptState.FAILED
    assert "did not report this step's radio within 10 s (the board: no telemetry)" in run.reason
    run2 = ScriptRun(script)
    run2.start(0.0)
    run2.on_telemetry(tel(0.0, run2.radio), 1.0)
    run2.poll(6.0)
    assert "mode GRASP not reached within 5 s" in run2.reason


# ---------------------------------------------------------------------- end to end (the real virtual board)


def _grasp_run(tmp_path: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, str(ROOT / "examples" / "06_scripted_grasp.py")],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=240,
    )


def _starved(proc: subprocess.CompletedProcess[str]) -> str | None:
    """A run in which the link sent two RC frames more than 30 ms apart was starved by the machine (the
    board rightly latched RC_LOST): void, not a result."""
    m = re.search(r"RC gaps over 30 ms: [1-9]\d*.*", proc.stdout)
    return None if m is None else f"the link's RC frames were late: {m.group(0)}"


@pytest.mark.realtime
def test_the_example_grasps_the_pole_records_it_and_the_board_refuses_to_replay_it(tmp_path: Path) -> None:
    proc = retry_void(lambda: _grasp_run(tmp_path), _starved)
    out = proc.stdout + proc.stderr
    assert proc.returncode == 0, out
    assert "--virtual-rc-script step 4/5: grasp: left lever UP (until grasp HOLD)" in proc.stdout, out
    assert "all 5 steps done" in proc.stdout and "RC_LOST" not in out, out
    assert "holds the grasp states" in proc.stdout and "-> HOLD" in proc.stdout, out
    recording = tmp_path / "runs" / "06_scripted_grasp.mcap"
    assert recording.stat().st_size > 10_000
    # A real spirob-host recording: the board cannot replay it, one line, exit 2.
    replay = subprocess.run(
        [sys.executable, "-m", "hil.cli.main", "replay", str(recording)],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert replay.returncode == 2, replay.stdout + replay.stderr
    line = one_error_line(replay.stderr)
    assert "a spirob-host recording" in line and "the board cannot replay it" in line, line
    assert "differ" not in replay.stdout


@pytest.mark.realtime
def test_a_script_that_cannot_reach_hold_exits_1_with_one_line(tmp_path: Path) -> None:
    """A step the board cannot reach in its time-out (HOLD within 0.3 s of the lever's edge, with no pole
    in the scene: a grasp takes seconds): the run fails, naming the step, in one line, exit 1.

    Not "wait for the FAILED grasp": with no object the firmware's grasp usually ends FAILED about 4 s
    after the edge, but one real-time run of this machine's suite declared HOLD on nothing (issue 24,
    item 4: HOLD only on evidence); the runner's FAILED path is unit-tested above."""
    script = tmp_path / "grasp.toml"
    script.write_text(EXAMPLE.read_text().replace("timeout_s = 40.0", "timeout_s = 0.3"))
    argv = [sys.executable, "-m", "host.cli", "--headless", "--no-object", "--virtual-rc-script", str(script)]
    proc = retry_void(lambda: subprocess.run(argv, capture_output=True, text=True, timeout=240), _starved)
    assert proc.returncode == 1, proc.stdout + proc.stderr
    line = one_error_line(proc.stderr)
    assert line.startswith("spirob-host: error: --virtual-rc-script: step 4 (grasp): "), line
    assert re.search(r"grasp HOLD not reached within [\d.]+ s \(the board: mode GRASP", line), line
    assert "all 5 steps done" not in proc.stdout
