"""``python -m controller``: argument handling, one-line errors with exit 2, a short real run."""

from __future__ import annotations

import os
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

from controller.cli import main, parse_args
from controller.transport import SerialTransport

ROOT = Path(__file__).resolve().parents[2]


def test_parse_args() -> None:
    args = parse_args(["--can", "slcan:///dev/ttyACM0", "--rc", "/dev/ttyUSB0", "--require-host"])
    assert (args.can, args.rc, args.link, args.require_host) == (
        "slcan:///dev/ttyACM0",
        "/dev/ttyUSB0",
        None,
        True,
    )
    with pytest.raises(SystemExit) as exc:
        parse_args(["--can", "fake"])  # no RC source at all
    assert exc.value.code == 2
    with pytest.raises(SystemExit):
        parse_args(["--rc", "/dev/ttyUSB0"])  # --can is required


def test_missing_port_is_one_line_and_exit_2(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["--can", "fake", "--rc", "/dev/ttyDOESNOTEXIST"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and err.count("\n") == 1 and "ttyDOESNOTEXIST" in err


@pytest.fixture
def pty_path() -> Iterator[str]:
    master, slave = os.openpty()
    try:
        yield os.ttyname(slave)
    finally:
        os.close(slave)
        os.close(master)


def test_busy_port_is_one_line_and_exit_2(pty_path: str, capsys: pytest.CaptureFixture[str]) -> None:
    with SerialTransport(pty_path):
        assert main(["--can", "fake", "--link", pty_path]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and err.count("\n") == 1


def test_bad_config_is_exit_2(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    cfg = tmp_path / "fw.json"
    cfg.write_text('{"current_limit_a": 42}')
    assert main(["--can", "fake", "--link", "loop://", "--config", str(cfg)]) == 2
    assert "current_limit_a" in capsys.readouterr().err


@pytest.mark.parametrize(
    ("argv", "needle"),
    [
        (
            ["--can", "fake", "--link", "loop://", "--duration", "nan"],
            "--duration: must be a finite number > 0",
        ),
        (
            ["--can", "fake", "--link", "loop://", "--duration", "inf"],
            "--duration: must be a finite number > 0",
        ),
        (["--can", "fake", "--link", "loop://", "--duration", "1e303"], "--duration: must be at most"),
        (["--can", "fake", "--link", "loop://", "--duration", "x"], "--duration: not a number"),
        (["--can", "fake"], "give --rc (DBUS UART) or --link"),
        ([], "required: --can"),
        (["--can"], "--can: expected one argument"),
        (["--can", "fake", "--link", "loop://", "--bogus"], "unrecognized arguments: --bogus"),
    ],
)
def test_usage_errors_are_one_line_and_exit_2(
    argv: list[str], needle: str, capsys: pytest.CaptureFixture[str]
) -> None:
    with pytest.raises(SystemExit) as exc:
        main(argv)
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("python -m controller: error: ") and needle in err, err


def test_short_run_with_the_fake_bus(pty_path: str, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["--can", "fake", "--link", pty_path, "--duration", "0.2", "--no-fifo"]) == 0
    assert "stopped: phase GATE" in capsys.readouterr().err


def test_module_entry_no_traceback() -> None:
    proc = subprocess.run(
        [sys.executable, "-m", "controller", "--can", "slcan:///dev/ttyDOESNOTEXIST", "--link", "loop://"],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    assert proc.returncode == 2
    assert proc.stderr.startswith("error: cannot open CAN") and "Traceback" not in proc.stderr
    assert proc.stderr.count("\n") == 1
