"""controller.cli_kit: one-line usage errors, exit statuses, argument types and signal handling."""

from __future__ import annotations

import argparse
import os
import signal
import threading
from pathlib import Path

import pytest

from controller.cli_kit import (
    EXIT_INTERRUPTED,
    EXIT_OK,
    EXIT_USAGE,
    Parser,
    UsageError,
    error_line,
    finite_float,
    parse_or_exit,
    port_number,
    positive_duration,
    run_command,
    seed,
    stop_on_signals,
    writable_dir,
    writable_file,
)


def test_parser_errors_raise_usage_error_naming_the_subcommand() -> None:
    p = Parser(prog="tool")
    sub = p.add_subparsers(dest="cmd", required=True, parser_class=Parser)
    sub.add_parser("go").add_argument("--n", type=int)
    with pytest.raises(UsageError) as info:
        p.parse_args(["go", "--n", "x"])
    assert info.value.prog == "tool go" and "--n" in str(info.value)


def test_parse_or_exit_prints_one_line_and_exits_2(capsys: pytest.CaptureFixture[str]) -> None:
    p = Parser(prog="tool")
    p.add_argument("--port", type=port_number)
    with pytest.raises(SystemExit) as info:
        parse_or_exit(p, ["--port", "70000"], hint=" (see --help)")
    assert info.value.code == EXIT_USAGE
    err = capsys.readouterr().err
    assert err == "tool: error: argument --port: port must be 0..65535: '70000' (see --help)\n"
    assert parse_or_exit(p, ["--port", "0"]).port == 0


def test_error_line_is_one_line(capsys: pytest.CaptureFixture[str]) -> None:
    error_line("tool", "cannot open\n  /dev/x:   busy\n")
    error_line(None, "")
    assert capsys.readouterr().err == "tool: error: cannot open /dev/x: busy\nerror: invalid input\n"


def test_run_command_maps_what_escapes_to_a_status(capsys: pytest.CaptureFixture[str]) -> None:
    def raises(exc: BaseException) -> int:
        raise exc

    assert run_command("tool", lambda: EXIT_OK) == EXIT_OK
    assert run_command("tool", lambda: raises(UsageError("bad", "tool sub"))) == EXIT_USAGE
    assert run_command("tool", lambda: raises(ValueError("worse"))) == EXIT_USAGE
    assert run_command("tool", lambda: raises(KeyboardInterrupt())) == EXIT_INTERRUPTED
    assert run_command("tool", lambda: raises(PermissionError(13, "Permission denied", "/x"))) == EXIT_USAGE
    assert capsys.readouterr().err.splitlines() == [
        "tool sub: error: bad",
        "tool: error: worse",
        "tool: error: interrupted",
        "tool: error: /x: Permission denied",
    ]


@pytest.mark.parametrize(
    ("kind", "text", "value"),
    [
        (positive_duration, "0.5", 0.5),
        (positive_duration, "1e9", 1e9),
        (finite_float, "-2.5", -2.5),
        (seed, "0", 0),
        (port_number, "65535", 65535),
    ],
)
def test_argument_types_accept(kind: object, text: str, value: float) -> None:
    assert callable(kind) and kind(text) == value


@pytest.mark.parametrize(
    ("kind", "text"),
    [
        (positive_duration, "0"),
        (positive_duration, "-1"),
        (positive_duration, "nan"),
        (positive_duration, "inf"),
        (positive_duration, "x"),
        (positive_duration, "1e300"),
        (finite_float, "nan"),
        (finite_float, "-inf"),
        (finite_float, "x"),
        (seed, "-1"),
        (seed, "1.5"),
        (port_number, "-1"),
        (port_number, "http"),
    ],
)
def test_argument_types_refuse(kind: object, text: str) -> None:
    assert callable(kind)
    with pytest.raises(argparse.ArgumentTypeError):
        kind(text)


def test_writable_dir_creates_it_and_refuses_files_and_pseudo_file_systems(tmp_path: Path) -> None:
    assert writable_dir(tmp_path / "a" / "b", "write plots into").is_dir()
    afile = tmp_path / "afile"
    afile.write_text("")
    with pytest.raises(UsageError, match=r"cannot write plots into .*afile: not a directory"):
        writable_dir(afile, "write plots into")
    with pytest.raises(UsageError, match="cannot write plots into /proc/spirob"):
        writable_dir(Path("/proc/spirob"), "write plots into")  # refused even to root


def test_writable_file_checks_without_writing(tmp_path: Path) -> None:
    target = tmp_path / "x.mcap"
    assert writable_file(target, "record to") == target and not target.exists()
    assert list(tmp_path.iterdir()) == []  # the probe leaves nothing behind
    with pytest.raises(UsageError, match="it is a directory"):
        writable_file(tmp_path, "record to")
    with pytest.raises(UsageError, match="no such directory"):
        writable_file(tmp_path / "missing" / "x.mcap", "record to")
    with pytest.raises(UsageError, match=r"cannot record to /proc/x\.mcap"):
        writable_file(Path("/proc/x.mcap"), "record to")


def test_stop_on_signals_sets_the_event_and_restores_the_handlers() -> None:
    before = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    with stop_on_signals() as stop:
        assert not stop.is_set()
        os.kill(os.getpid(), signal.SIGTERM)
        assert stop.wait(5.0)
    with stop_on_signals() as stop:
        os.kill(os.getpid(), signal.SIGINT)  # Ctrl-C: no KeyboardInterrupt inside the block
        assert stop.wait(5.0)
    assert {s: signal.getsignal(s) for s in before} == before


def test_stop_on_signals_off_the_main_thread_installs_nothing() -> None:
    before = signal.getsignal(signal.SIGTERM)
    seen: list[bool] = []

    def worker() -> None:
        given = threading.Event()
        with stop_on_signals(given) as stop:
            seen.append(stop is given and signal.getsignal(signal.SIGTERM) is before)

    t = threading.Thread(target=worker)
    t.start()
    t.join()
    assert seen == [True]
