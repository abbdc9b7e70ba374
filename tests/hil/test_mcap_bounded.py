"""The bounded MCAP reader (hil.mcap_bounded): crafted hostile files, each with its one-line outcome in
every command that opens a recording (``spirob-hil replay``, ``spirob-hil recover``,
``spirob-host --replay``), memory bounded in a real process, and replays that stream."""

from __future__ import annotations

import io
import subprocess
import sys
import threading
from pathlib import Path

import pytest

from hil import recording
from hil.cli.main import main as hil_main
from hil.mcap_bounded import MAGIC, MAX_RECORD_BYTES, RecordingError, iter_records
from host.cli import main as host_main
from host.link.replay import ReplaySource
from tests.support.hostile_mcap import (
    CRAFTED,
    LINK_TX_CHANNEL,
    MIB,
    Crafted,
    channel,
    header,
    preamble,
    small_messages,
    zstd_chunk,
)

REPO = Path(__file__).resolve().parents[2]
RSS_GOAL_KB = 300 * 1024


@pytest.fixture(scope="module")
def crafted_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    directory = tmp_path_factory.mktemp("crafted")
    for c in CRAFTED:
        c.write(directory)
    return directory


def _ids(c: Crafted) -> str:
    return c.name


def _one_line(err: str, prog: str) -> str:
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1, f"expected one line, got {lines!r}"
    assert "Traceback" not in err
    assert lines[0].startswith(f"{prog}: error: ") or lines[0].startswith(f"{prog} "), lines[0]
    return lines[0]


@pytest.mark.parametrize("crafted", CRAFTED, ids=_ids)
def test_the_reader_refuses_or_stops_quietly(crafted: Crafted, crafted_dir: Path) -> None:
    with open(crafted_dir / f"{crafted.name}.mcap", "rb") as f:
        if crafted.refusal is None:
            assert sum(1 for _ in iter_records(f)) > 3
        else:
            with pytest.raises(RecordingError, match=None) as info:
                for _ in iter_records(f):
                    pass
            assert crafted.refusal in str(info.value)
            assert "\n" not in str(info.value)


@pytest.mark.parametrize("crafted", CRAFTED, ids=_ids)
def test_spirob_hil_replay(crafted: Crafted, crafted_dir: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = crafted_dir / f"{crafted.name}.mcap"
    assert hil_main(["replay", str(path)]) == crafted.exits[0]
    out, err = capsys.readouterr()
    if crafted.refusal is not None:
        assert crafted.refusal in _one_line(err, "spirob-hil replay")
    elif crafted.exits[0] == 2:  # read quietly up to its cut, but the board's outputs precede any tick
        assert "not a lockstep recording" in _one_line(err, "spirob-hil replay")
    else:
        assert err == "" and "truncated" in out


@pytest.mark.parametrize("crafted", CRAFTED, ids=_ids)
def test_spirob_hil_recover(
    crafted: Crafted, crafted_dir: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out_path = tmp_path / "out.mcap"
    assert (
        hil_main(["recover", str(crafted_dir / f"{crafted.name}.mcap"), "-o", str(out_path)])
        == crafted.exits[1]
    )
    out, err = capsys.readouterr()
    if crafted.refusal is None:
        assert err == "" and "100 messages" in out  # the first chunk, the cut one dropped
        assert sum(1 for _ in recording.read_records(out_path)) == 100
    else:
        line = _one_line(err, "spirob-hil recover")
        assert crafted.refusal in line and "nothing recovered" in line
        assert not out_path.exists()  # no half copy left behind


@pytest.mark.parametrize("crafted", CRAFTED, ids=_ids)
def test_spirob_host_replay(crafted: Crafted, crafted_dir: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = crafted_dir / f"{crafted.name}.mcap"
    argv = ["--replay", str(path), "--headless", "--duration", "30", "--replay-speed", "100"]
    assert host_main(argv) == crafted.exits[2]
    _, err = capsys.readouterr()
    if crafted.refusal is not None:
        assert crafted.refusal in _one_line(err, "spirob-host")
    else:
        assert "error" not in err


def test_the_cap_is_inclusive() -> None:
    """A chunk that inflates to exactly the cap is read; one message more is refused before inflating;
    a top-level record of exactly the cap is read, one byte more refused."""
    start = MAGIC + header() + channel(LINK_TX_CHANNEL, "/board/link_tx")  # records far under the cap
    whole = small_messages(10)
    cap = len(whole)
    at_cap = start + zstd_chunk(whole)
    assert sum(1 for _ in iter_records(io.BytesIO(at_cap), max_record_bytes=cap)) == 2 + 10
    over = start + zstd_chunk(small_messages(11))
    with pytest.raises(RecordingError, match=f"over the {cap} bytes cap"):
        list(iter_records(io.BytesIO(over), max_record_bytes=cap))
    one = small_messages(1)
    body = len(one) - 9  # the message record's length field
    assert sum(1 for _ in iter_records(io.BytesIO(start + one), max_record_bytes=body)) == 3
    with pytest.raises(RecordingError, match=f"message record at byte \\d+ announces {body} bytes"):
        list(iter_records(io.BytesIO(start + one), max_record_bytes=body - 1))


def test_our_recordings_read_the_same(tmp_path: Path) -> None:
    """The recorder's own files (zstd chunks, metadata, summary) read through the bounded reader."""
    path = tmp_path / "ok.mcap"
    with recording.Recorder(path, metadata={"scenario": "x"}, flush_every=50) as rec:
        for t in range(500):
            rec.write_raw(recording.LINK_TX, t, bytes([t % 256]) * 40)
    assert [r.time_us for r in recording.read_records(path)] == list(range(500))
    assert recording.read_metadata(path)["scenario"] == "x"
    assert not recording.is_truncated(path)


_MEASURE = (
    "import os, subprocess, sys\n"
    "p = subprocess.Popen(sys.argv[1:], stdout=subprocess.DEVNULL)\n"
    "_, status, usage = os.wait4(p.pid, 0)\n"
    "print(usage.ru_maxrss)\n"
    "sys.exit(os.waitstatus_to_exitcode(status))\n"
)
"""Starts the command from a small process: Linux counts in a child's ``ru_maxrss`` the resident set of
the process it was forked from (a pytest worker that has loaded MuJoCo: 340 MB), so the command is forked
from this one instead and its own peak is read here."""


def _peak_rss_kb(argv: list[str]) -> tuple[int, int, str]:
    proc = subprocess.run(
        [sys.executable, "-c", _MEASURE, *argv], cwd=REPO, capture_output=True, text=True, timeout=120
    )
    return proc.returncode, int(proc.stdout.strip().splitlines()[-1]), proc.stderr


@pytest.mark.parametrize("name", ["zstd-bomb", "lz4-liar"])
def test_a_bomb_stays_under_the_memory_goal_in_a_real_process(name: str, crafted_dir: Path) -> None:
    """The 1 GiB zstd bomb (2.2 GB before) and the unlimited lz4 chunk, in a real ``spirob-hil recover``."""
    path = crafted_dir / f"{name}.mcap"
    status, rss_kb, err = _peak_rss_kb(
        [sys.executable, "-m", "hil.cli.main", "recover", str(path), "-o", str(crafted_dir / "x.mcap")]
    )
    assert status == 2 and len(err.strip().splitlines()) == 1, err
    assert rss_kb < RSS_GOAL_KB, f"peak RSS {rss_kb / 1024:.0f} MB"


def test_a_large_legitimate_chunk_reads() -> None:
    """A legitimate 8 MiB chunk (32 times our recorder's) reads under the 32 MiB cap."""
    assert MAX_RECORD_BYTES == 32 * MIB
    size = len(small_messages(1))
    inner = small_messages(8 * MIB // size)
    data = preamble() + zstd_chunk(inner)
    n = sum(1 for _ in iter_records(io.BytesIO(data)))
    assert n == 3 + len(inner) // size


def test_host_replay_streams_from_the_first_chunk(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The first message is fanned out before the file is read further than its first chunks: a file of
    300,000 records starts at once (it was decoded whole first: 1 GB and 67 s)."""
    path = tmp_path / "many.mcap"
    path.write_bytes(preamble() + b"".join(zstd_chunk(small_messages(1000, k * 10**9)) for k in range(60)))
    read = [0]
    original = recording.read_records

    def counting(p: Path, topics: frozenset[str] | set[str] | None = None) -> object:
        for rec in original(p, topics):
            read[0] += 1
            yield rec

    monkeypatch.setattr(recording, "read_records", counting)
    source = ReplaySource(path, speed=1.0)
    first = threading.Event()
    read_at_first: list[int] = []

    def listener(msg: object) -> None:
        if not first.is_set():
            read_at_first.append(read[0])
            first.set()

    source.add_listener(listener)  # type: ignore[arg-type]
    source.start()
    try:
        assert first.wait(10.0)
        assert read_at_first[0] <= 1000  # within the first chunk
        assert not source.done.is_set()  # 60 s of recording at speed 1: still playing
    finally:
        source.stop()
    assert read[0] < 60_000


def test_host_replay_duration_holds_on_a_long_file(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``--duration`` ends a replay of a long file in time: nothing is decoded before it starts."""
    import time

    path = tmp_path / "long.mcap"
    path.write_bytes(
        preamble() + b"".join(zstd_chunk(small_messages(2000, k * 2 * 10**9)) for k in range(100))
    )
    t0 = time.monotonic()
    assert host_main(["--replay", str(path), "--headless", "--duration", "1"]) == 0
    assert time.monotonic() - t0 < 10.0
    assert "error" not in capsys.readouterr().err


def test_hil_replay_holds_a_bounded_segment(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Records between two tick marks are held until the next mark: a file without marks is refused
    once it passes the bound, in one line, instead of growing without limit. (Inputs only: a board
    output before any mark is refused at once, see the ``truncated`` file.)"""
    from hil.replay import MAX_SEGMENT_RECORDS

    path = tmp_path / "no-ticks.mcap"
    n = MAX_SEGMENT_RECORDS + 1000
    path.write_bytes(
        preamble("/board/link_rx")
        + b"".join(zstd_chunk(small_messages(1000, k * 10**9)) for k in range(n // 1000))
    )
    assert hil_main(["replay", str(path)]) == 2
    line = _one_line(capsys.readouterr().err, "spirob-hil replay")
    assert f"more than {MAX_SEGMENT_RECORDS} records" in line and "not a lockstep recording" in line
