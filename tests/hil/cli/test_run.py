"""`spirob-hil list | run | replay | board` from the command line (argv in, exit status and output out)."""

from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from hil.cli.main import main
from hil.identify.motor_data import load_motor_data
from hil.scenarios import SCENARIOS
from tests.support.realtime_guard import scaled_s, timed_out
from tests.support.terminal import children, ctrl_c, start_in_own_group


def test_list_names_every_scenario(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["list"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert [line.split()[0] for line in lines] == list(SCENARIOS)
    assert main(["list", "--json"]) == 0
    listed = json.loads(capsys.readouterr().out)
    assert [item["name"] for item in listed] == list(SCENARIOS)


def test_run_json_record_report_and_replay(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    rec = tmp_path / "runs"
    plots = tmp_path / "plots"
    status = main(
        [
            "run",
            "startup-gate",
            "overcurrent",
            "--json",
            "--seed",
            "2",
            "--record",
            str(rec),
            "--report",
            str(plots),
        ]
    )
    out = capsys.readouterr().out.splitlines()
    assert status == 0
    objs = [json.loads(line) for line in out]
    assert [o["name"] for o in objs] == ["startup-gate", "overcurrent"]
    assert all(o["passed"] and o["checks"] for o in objs)
    check = objs[0]["checks"][0]
    assert {"name", "value", "bound", "passed"} <= set(check)
    assert (plots / "startup-gate.png").stat().st_size > 10_000
    assert main(["replay", str(rec / "overcurrent.mcap"), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["matched"] is True


def test_an_excitation_with_a_tracked_tip_is_read_with_its_tip(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / "excite.mcap"
    argv = ["run", "excitation", "--excite", "tiny", "--tracked-tip", "0.3", "--record", str(path)]
    assert main(argv) == 0, capsys.readouterr()
    data = load_motor_data(path)
    assert data.tip_m is not None and np.isfinite(data.tip_m).all()
    assert -0.25 < data.tip_m[0, 2] < -0.2  # the prototype's tip hangs about 22 cm below the drone


def test_run_fails_with_nonzero_status_when_a_check_fails(capsys: pytest.CaptureFixture[str]) -> None:
    # The radio dies at 0 s for good: the gate never opens, so "current once armed" fails.
    assert main(["run", "startup-gate", "--fault", "rc-silence@0"]) == 1
    assert "FAIL" in capsys.readouterr().out


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["run"], "name at least one scenario"),
        (["run", "no-such"], "unknown scenario 'no-such'"),
        (["run", "rc-loss", "--fault", "rc-silence@x"], "expected KIND@START"),
        (["replay", "/no/such/file.mcap"], "no such recording"),
        (["board", "--listen", "tcp://1.2.3.4:5"], "socket://HOST:PORT"),
        (["board", "--listen", "socket://0.0.0.0:5760"], "add --listen-any"),
        (["board", "--listen", "socket://example.org:5760"], "add --listen-any"),
        (["run", "rc-loss", "--record", "/no/such/dir/x.mcap"], "cannot record"),
        (["run", "rc-loss", "--seed", "-1"], "--seed: must be a whole number >= 0"),
        # issue 18: every path the user gives is checked before the first run, one line
        (
            ["run", "rc-loss", "--report", "/etc/passwd"],
            "cannot write plots into /etc/passwd: not a directory",
        ),
        (["run", "rc-loss", "--report", "/proc/spirob"], "cannot write plots into /proc/spirob"),
        (["run", "rc-loss", "--record", "/proc/x.mcap"], "cannot record to /proc/x.mcap"),
        (["run", "rc-loss", "host-loss", "--record", "/etc/passwd"], "cannot record into /etc/passwd"),
        (["board", "--duration", "nan"], "--duration: must be a finite number > 0"),
        (["board", "--duration", "1e300"], "--duration: must be at most"),
        (["experiment", "packing", "--seed", "x"], "--seed: must be a whole number >= 0"),
        (["run", "rc-loss", "--tracked-tip", "0.3"], "--tracked-tip is the excitation scenario's option"),
        (["run", "excitation", "--tracked-tip", "0.3"], "give --record FILE.mcap"),
        (["run", "excitation", "--tracked-tip", "-1", "--record", "x.mcap"], "a noise in mm from 0 to 100"),
        (["run", "excitation", "--tracked-tip", "nan", "--record", "x.mcap"], "a noise in mm from 0 to 100"),
        (
            ["run", "excitation", "--tracked-tip", "0.3", "--port", "/dev/ttyACM9", "--record", "x.mcap"],
            "a real arm's comes from its own bridge",
        ),
    ],
)
def test_user_mistakes_are_one_line_and_status_2(
    argv: list[str], message: str, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0], err


def test_board_command_serves_and_stops(tmp_path: Path) -> None:
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "hil.cli.main",
            "board",
            "--listen",
            "socket://127.0.0.1:0",
            "--duration",
            "1",
            "--no-fifo",
        ],
        capture_output=True,
        text=True,
        timeout=120,
        cwd=Path(__file__).resolve().parents[3],
    )
    assert proc.returncode == 0, proc.stderr
    assert "board link on socket://127.0.0.1:" in proc.stdout
    assert "zero current sent" in proc.stdout


def _working(proc: subprocess.Popen[str], argv: list[str]) -> None:
    """Wait (bounded, scaled with the load) until ``proc`` is past its start-up and into the work: the
    scenario suite has reported a scenario; the experiment has started its worker processes."""
    deadline = time.monotonic() + scaled_s(60.0)
    if argv[0] == "run":
        assert proc.stderr is not None
        while time.monotonic() < deadline:
            line = proc.stderr.readline()
            assert line, "the scenario suite ended before reporting a scenario"
            if line.rstrip().endswith(": passed"):
                return
    else:
        while time.monotonic() < deadline:
            if len(children(proc)) >= 2:
                time.sleep(0.5)  # the workers are in their first runs
                return
            assert proc.poll() is None
            time.sleep(0.05)
    timed_out(f"{argv[0]} to start its work")


@pytest.mark.parametrize(
    "argv",
    [["run", "--all"], ["experiment", "workspace", "--jobs", "2"]],
    ids=["scenarios", "experiment-with-workers"],
)
def test_ctrl_c_stops_with_one_line_and_no_traceback(argv: list[str]) -> None:
    """A terminal's Ctrl-C reaches the whole process group (the CLI and any pool workers), in the middle
    of the work (the scenario suite's first report comes with a dozen scenarios still to run)."""
    proc = start_in_own_group("hil.cli.main", *argv)
    _working(proc, argv)
    assert proc.poll() is None
    _, err = ctrl_c(proc)
    assert proc.returncode == 130
    assert err.strip().splitlines()[-1] == "spirob-hil: error: interrupted"
    assert "Traceback" not in err and "KeyboardInterrupt" not in err, err
