"""``python -m controller``: argument handling, python-can's CAN options and configuration, one-line
errors with exit 2, ``--version``, a short real run."""

from __future__ import annotations

import importlib.metadata
import os
import select
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import can
import pytest

from controller.cli import can_bus_config, main, parse_args
from controller.fake_c610 import FakeC610Set
from controller.transport import SerialTransport
from protocol.messages import Heartbeat, encode
from tests.support.c610_rigs import C610SetServer
from tests.support.terminal import ctrl_c, start_in_own_group

ROOT = Path(__file__).resolve().parents[2]


def test_parse_args() -> None:
    args = parse_args(
        [
            "--can-interface",
            "slcan",
            "--can-channel",
            "/dev/ttyACM0",
            "--rc",
            "/dev/ttyUSB0",
            "--require-host",
        ]
    )
    assert (
        args.can_interface,
        args.can_channel,
        args.can_bitrate,
        args.rc,
        args.link,
        args.require_host,
    ) == (
        "slcan",
        "/dev/ttyACM0",
        None,
        "/dev/ttyUSB0",
        None,
        True,
    )
    with pytest.raises(SystemExit) as exc:
        parse_args(["--can-interface", "fake"])  # no RC source at all
    assert exc.value.code == 2


def test_missing_port_is_one_line_and_exit_2(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["--can-interface", "fake", "--rc", "/dev/ttyDOESNOTEXIST"]) == 2
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
        assert main(["--can-interface", "fake", "--link", pty_path]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and err.count("\n") == 1


def test_bad_config_is_exit_2(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    cfg = tmp_path / "fw.json"
    cfg.write_text('{"current_limit_a": 42}')
    assert main(["--can-interface", "fake", "--link", "loop://", "--config", str(cfg)]) == 2
    assert "current_limit_a" in capsys.readouterr().err


@pytest.mark.parametrize(
    ("argv", "needle"),
    [
        (
            ["--can-interface", "fake", "--link", "loop://", "--duration", "nan"],
            "--duration: must be a finite number > 0",
        ),
        (
            ["--can-interface", "fake", "--link", "loop://", "--duration", "inf"],
            "--duration: must be a finite number > 0",
        ),
        (
            ["--can-interface", "fake", "--link", "loop://", "--duration", "1e303"],
            "--duration: must be at most",
        ),
        (["--can-interface", "fake", "--link", "loop://", "--duration", "x"], "--duration: not a number"),
        (["--can-interface", "fake"], "give --rc (DBUS UART) or --link"),
        (
            ["--can", "slcan:///dev/ttyACM0", "--link", "loop://"],
            "--can is gone: use --can-interface and --can-channel",
        ),
        (
            ["--can-interface", "fake", "--link", "loop://", "--can-bitrate", "1M"],
            "--can-bitrate: must be a whole",
        ),
        (
            ["--can-interface", "fake", "--link", "loop://", "--can-bitrate", "0"],
            "--can-bitrate: must be > 0",
        ),
        (["--can-interface", "fake", "--link", "loop://", "--bogus"], "unrecognized arguments: --bogus"),
        (
            ["--can-interface", "fake", "--listen", "socket://0.0.0.0:5760"],
            "is reachable from other machines (anyone there can drive the arm): use a loopback address",
        ),
        (
            ["--can-interface", "fake", "--listen", "tcp://127.0.0.1:5760"],
            "--listen takes socket://HOST:PORT",
        ),
        (["--can-interface", "fake", "--link", "loop://", "--listen-any"], "--listen-any needs --listen"),
        (["--can-interface", "fake", "--link", "loop://", "--arms", "9"], "--arms: must be 1..8"),
        (["--can-interface", "fake", "--link", "loop://", "--arms", "two"], "--arms: must be a whole number"),
        (
            ["--can-interface", "fake", "--link", "loop://", "--cables-per-arm", "4"],
            "--cables-per-arm: must be",
        ),
        (
            ["--can-interface", "fake", "--link", "loop://", "--listen", "socket://127.0.0.1:1"],
            "not allowed with argument",
        ),
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
    assert main(["--can-interface", "fake", "--link", pty_path, "--duration", "0.2", "--no-fifo"]) == 0
    assert "stopped: phase GATE" in capsys.readouterr().err


def test_module_entry_no_traceback() -> None:
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "controller",
            "--can-interface",
            "slcan",
            "--can-channel",
            "/dev/ttyDOESNOTEXIST",
            "--link",
            "loop://",
        ],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    assert proc.returncode == 2
    assert proc.stderr.startswith("error: cannot open CAN") and "Traceback" not in proc.stderr
    assert proc.stderr.count("\n") == 1


def test_version_prints_prog_and_the_installed_version(capsys: pytest.CaptureFixture[str]) -> None:
    for prog in ("python -m controller", "spirob-firmware"):
        with pytest.raises(SystemExit) as exc:
            main(["--version"], prog=prog)
        assert exc.value.code == 0
        assert capsys.readouterr().out == f"{prog} {importlib.metadata.version('spirob-teleop')}\n"


@pytest.fixture
def no_can_config(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> Path:
    """No python-can configuration from this machine: an empty home, no CAN_* variables."""
    for name in ("CAN_INTERFACE", "CAN_CHANNEL", "CAN_BITRATE", "CAN_CONFIG"):
        monkeypatch.delenv(name, raising=False)
    home = tmp_path / "home"
    home.mkdir()
    monkeypatch.setenv("HOME", str(home))
    return home


def test_can_options_default_to_1_mbit_on_every_interface(no_can_config: Path) -> None:
    for interface in ("gs_usb", "socketcan", "pcan", "virtual"):
        args = parse_args(["--can-interface", interface, "--can-channel", "0", "--link", "loop://"])
        config = can_bus_config(args)
        assert (config["interface"], config["channel"], config["bitrate"]) == (interface, 0, 1_000_000)
    args = parse_args(
        ["--can-interface", "gs_usb", "--can-channel", "0", "--can-bitrate", "500000", "--link", "x"]
    )
    assert can_bus_config(args)["bitrate"] == 500_000


def test_can_config_file_environment_and_flags(
    no_can_config: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    conf = tmp_path / "can.ini"
    conf.write_text("[default]\ninterface = socketcan\nchannel = can1\nreceive_own_messages = False\n")
    args = parse_args(["--can-config", str(conf), "--link", "loop://"])
    config = can_bus_config(args)
    assert config["interface"] == "socketcan" and config["channel"] == "can1"
    assert config["bitrate"] == 1_000_000 and config["receive_own_messages"] is False
    # the flags win over the file
    args = parse_args(["--can-config", str(conf), "--can-channel", "can0", "--link", "loop://"])
    assert can_bus_config(args)["channel"] == "can0"
    # python-can's own sources when no file is named: ~/.canrc, then the environment above it
    (no_can_config / ".canrc").write_text(
        "[default]\ninterface = slcan\nchannel = /dev/ttyACM0\nbitrate = 250000\n"
    )
    config = can_bus_config(parse_args(["--link", "loop://"]))
    assert (config["interface"], config["channel"], config["bitrate"]) == ("slcan", "/dev/ttyACM0", 250_000)
    monkeypatch.setenv("CAN_CHANNEL", "/dev/ttyACM1")
    assert can_bus_config(parse_args(["--link", "loop://"]))["channel"] == "/dev/ttyACM1"


@pytest.mark.parametrize(
    ("argv", "needle"),
    [
        (["--link", "loop://"], "error: no CAN interface: give --can-interface"),
        (["--can-interface", "socketcan", "--link", "loop://"], "error: no CAN channel for socketcan"),
        (["--can-interface", "nosuchcan", "--can-channel", "0", "--link", "loop://"], "Unknown interface"),
        (["--can-config", "/nonexistent/can.ini", "--link", "loop://"], "cannot read CAN config"),
        (
            ["--can-interface", "fake", "--can-log", "x.log", "--link", "loop://"],
            "--can-log needs a python-can",
        ),
        (
            [
                "--can-interface",
                "virtual",
                "--can-channel",
                "c",
                "--can-log",
                "/nonexistent/x.log",
                "--link",
                "loop://",
            ],
            "cannot log CAN frames to /nonexistent/x.log",
        ),
        (
            [
                "--can-interface",
                "virtual",
                "--can-channel",
                "c",
                "--can-log",
                "frames.nosuch",
                "--link",
                "loop://",
            ],
            "cannot log CAN frames to frames.nosuch",
        ),
    ],
)
def test_can_mistakes_are_one_line_and_exit_2(
    argv: list[str], needle: str, no_can_config: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and needle in err, err


def test_can_log_of_a_firmware_run_on_python_cans_virtual_bus(
    tmp_path: Path, no_can_config: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The hardware path end to end: flags -> python-can bus -> a candump log that python-can reads back."""
    channel = f"test-cli-canlog-{os.getpid()}"
    log = tmp_path / "run.log"
    argv = ["--can-interface", "virtual", "--can-channel", channel, "--can-log", str(log)]
    with C610SetServer(can.Bus(interface="virtual", channel=channel)) as server:
        assert main([*argv, "--link", "loop://", "--duration", "0.3", "--no-fifo"]) == 0
    assert server.error is None and "stopped:" in capsys.readouterr().err
    frames = list(can.LogReader(log))
    ids = {m.arbitration_id for m in frames}
    assert ids == {0x200, 0x201, 0x202, 0x203}
    commands = [m for m in frames if m.arbitration_id == 0x200]
    assert len(commands) > 50 and all(not m.is_rx for m in commands)
    assert all(m.is_rx and m.channel == channel for m in frames if m.arbitration_id != 0x200)


def test_an_array_that_does_not_fit_a_board_is_one_line_and_exit_2(
    capsys: pytest.CaptureFixture[str],
) -> None:
    assert main(["--can-interface", "fake", "--link", "loop://", "--arms", "3"]) == 2  # 3 x 3 cables
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "3 arm(s) of 3 cable(s) need 9 motors" in err, err


def test_an_eight_arm_array_on_python_cans_virtual_bus(
    tmp_path: Path, no_can_config: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``--arms 8 --cables-per-arm 1``: eight C610s, commands on 0x200 and 0x1FF, feedback 0x201-0x208."""
    channel = f"test-cli-arms-{os.getpid()}"
    log = tmp_path / "run.log"
    argv = ["--can-interface", "virtual", "--can-channel", channel, "--can-log", str(log)]
    with C610SetServer(can.Bus(interface="virtual", channel=channel), FakeC610Set.of(8)) as server:
        assert (
            main(
                [
                    *argv,
                    "--arms",
                    "8",
                    "--cables-per-arm",
                    "1",
                    "--link",
                    "loop://",
                    "--duration",
                    "0.3",
                    "--no-fifo",
                ]
            )
            == 0
        )
    assert server.error is None and "stopped:" in capsys.readouterr().err
    frames = list(can.LogReader(log))
    assert {m.arbitration_id for m in frames} == {0x1FF, *range(0x200, 0x209)}
    low = [m for m in frames if m.arbitration_id == 0x200]
    high = [m for m in frames if m.arbitration_id == 0x1FF]
    assert len(low) > 50 and len(high) == len(low)
    assert [m.arbitration_id for m in frames if not m.is_rx][:4] == [0x200, 0x1FF, 0x200, 0x1FF]


def test_spy_url_logs_the_firmwares_board_link(tmp_path: Path) -> None:
    """``--link spy://PTY?file=LOG``: pyserial's spy handler logs what the firmware sends and receives."""
    log = tmp_path / "link.txt"
    master, slave = os.openpty()
    proc = start_in_own_group(
        "controller",
        *("--can-interface", "fake", "--no-fifo", "--duration", "1.5"),
        *("--link", f"spy://{os.ttyname(slave)}?file={log}"),
    )
    heartbeat = encode(Heartbeat(host_time_us=1, counter=1), seq=0)
    received = b""
    try:
        deadline = time.monotonic() + 60.0
        sent = False
        while proc.poll() is None and time.monotonic() < deadline:
            ready, _, _ = select.select([master], [], [], 0.05)
            if ready:
                received += os.read(master, 65536)
            if received and not sent:  # the port is open and raw: the host speaks
                os.write(master, heartbeat)
                sent = True
        _, err = ctrl_c(proc) if proc.poll() is None else proc.communicate(timeout=60)
    finally:
        os.close(slave)
        os.close(master)
    assert proc.returncode == 0, err
    assert sent and received.startswith(b"\xa5")
    # pyserial's hex dump: "000001.234 TX   0010  A5 0C ... (16 bytes in two groups)  ASCII"
    lines = log.read_text().splitlines()
    tx = b"".join(bytes.fromhex(line[22:71]) for line in lines if line[11:13] == "TX")
    rx = b"".join(bytes.fromhex(line[22:71]) for line in lines if line[11:13] == "RX")
    assert tx.startswith(received[:64]) and rx == heartbeat


def test_the_host_link_over_tcp_serves_one_host_at_a_time() -> None:
    """``--listen socket://127.0.0.1:PORT``: the firmware is the TCP end a host connects to (``spirob-host
    --port socket://...``), as ``spirob-hil board --listen`` is; a second host is refused while one is
    live."""
    import socket

    from protocol.link import LinkParser
    from protocol.messages import Telemetry

    with socket.socket() as s:  # a free port: take one, then free it
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    proc = start_in_own_group(
        "controller",
        *("--can-interface", "fake", "--no-fifo", "--duration", "4"),
        *("--listen", f"socket://127.0.0.1:{port}"),
    )
    telemetry: list[Telemetry] = []
    second = b"-"
    try:
        deadline = time.monotonic() + 60.0
        host: socket.socket | None = None
        while host is None and proc.poll() is None and time.monotonic() < deadline:
            try:
                host = socket.create_connection(("127.0.0.1", port), timeout=1.0)
            except OSError:
                time.sleep(0.05)
        assert host is not None, "the firmware never listened"
        with host:
            host.settimeout(0.2)
            host.sendall(encode(Heartbeat(host_time_us=1, counter=1), seq=0))
            parser = LinkParser()
            while len(telemetry) < 20 and proc.poll() is None and time.monotonic() < deadline:
                try:
                    data = host.recv(65536)
                except TimeoutError:
                    continue
                telemetry += [
                    Telemetry.unpack(f.payload) for f in parser.feed(data) if f.cmd_id == Telemetry.CMD_ID
                ]
            with socket.create_connection(("127.0.0.1", port), timeout=5.0) as other:
                other.settimeout(5.0)
                second = other.recv(1)  # accepted and closed at once: end-of-file
        _, err = ctrl_c(proc) if proc.poll() is None else proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(timeout=10)
    assert f"host link: listening on socket://127.0.0.1:{port}" in err, err
    assert len(telemetry) >= 20 and telemetry[-1].time_us > telemetry[0].time_us
    assert all(t.commanded_current == (0, 0, 0) for t in telemetry)  # no RC: the gate stays shut
    assert second == b""
