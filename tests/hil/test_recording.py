"""MCAP recordings: round trip, metadata, and a file left by a killed process."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from mcap.reader import make_reader
from mcap.writer import Writer

from hil import recording
from hil.mcap_bounded import RecordingError
from hil.recording import Recorder, read_metadata, read_records


def test_round_trip_raw_and_json(tmp_path: Path) -> None:
    path = tmp_path / "run.mcap"
    with Recorder(path, metadata={"scenario": "rc-loss", "seed": "3"}) as rec:
        rec.write_raw(recording.DBUS_RX, 10, b"\x00" * 18)
        rec.write_raw(recording.CAN_TX, 1000, recording.pack_can(0x200, bytes(8)))
        rec.write_json(recording.TELEMETRY, 2000, {"mode": 1, "tension_n": [1.0, 2.0, 3.0]})
    records = list(read_records(path))
    # The first telemetry also writes the event of its mode (none before it: "-").
    assert [r.topic for r in records] == [recording.DBUS_RX, recording.CAN_TX, recording.TELEMETRY, "/events"]
    assert [r.time_us for r in records] == [10, 1000, 2000, 2000]
    assert recording.unpack_can(records[1].data) == (0x200, bytes(8))
    assert records[2].json() == {"mode": 1, "tension_n": [1.0, 2.0, 3.0]}
    meta = read_metadata(path)
    assert (meta["scenario"], meta["seed"], meta["format"]) == ("rc-loss", "3", str(recording.FORMAT))
    only_can = list(read_records(path, topics={recording.CAN_TX}))
    assert len(only_can) == 1


def test_a_port_recording_logs_unix_time(tmp_path: Path) -> None:
    # A run against a port is on the host's monotonic clock: log_time becomes Unix time.
    path = tmp_path / "port.mcap"
    before_ns = time.time_ns()
    mono_us = time.monotonic_ns() // 1000
    with Recorder(path, metadata={"kind": recording.KIND_PORT}) as rec:
        rec.write_raw(recording.LINK_TX, mono_us, b"x")
    after_ns = time.time_ns()
    (record,) = read_records(path)
    assert record.time_us == mono_us
    assert before_ns - 1000 <= record.log_time_ns <= after_ns
    assert read_metadata(path)["clock_offset_ns"] == str(record.log_time_ns - mono_us * 1000)
    # publish_time is the same Unix time (format 3): within a day of now, not 1970.
    with open(path, "rb") as f:
        ((_, _, message),) = make_reader(f).iter_messages()
    assert message.publish_time == message.log_time == record.log_time_ns
    assert abs(message.publish_time - time.time_ns()) < 86_400 * 10**9


def _write(path: Path, meta: dict[str, str], times_ns: list[tuple[int, int]]) -> None:
    with open(path, "wb") as f:
        writer = Writer(f)
        writer.start(profile=recording.PROFILE, library="test")
        writer.add_metadata(recording.PROFILE, meta)
        channel = writer.register_channel(recording.LINK_TX, recording.RAW_ENCODING, schema_id=0)
        for log_ns, publish_ns in times_ns:
            writer.add_message(channel, log_time=log_ns, data=b"x", publish_time=publish_ns)
        writer.finish()


def test_board_time_reads_the_same_in_every_format(tmp_path: Path) -> None:
    offset = 1_790_000_000 * 10**9
    # Format 2 kept the board's clock in publish_time; format 3 has publish_time = log_time.
    _write(tmp_path / "f2.mcap", {"format": "2", "clock_offset_ns": str(offset)}, [(offset + 5000, 5000)])
    _write(tmp_path / "f3.mcap", {"format": "3", "clock_offset_ns": str(offset)}, [(offset + 5000,) * 2])
    _write(tmp_path / "f1.mcap", {}, [(5000, 5000)])
    for name in ("f1", "f2", "f3"):
        (record,) = read_records(tmp_path / f"{name}.mcap")
        assert record.time_us == 5, name
    _write(tmp_path / "bad.mcap", {"format": "3", "clock_offset_ns": "soon"}, [(5000, 5000)])
    with pytest.raises(RecordingError, match="clock_offset_ns 'soon' is not an integer"):
        list(read_records(tmp_path / "bad.mcap"))


def test_close_twice_and_write_after_close(tmp_path: Path) -> None:
    rec = Recorder(tmp_path / "x.mcap")
    rec.close()
    rec.close()
    with pytest.raises(ValueError, match="closed"):
        rec.write_raw(recording.LINK_TX, 0, b"x")


def test_bad_flush_interval(tmp_path: Path) -> None:
    with pytest.raises(ValueError):
        Recorder(tmp_path / "x.mcap", flush_every=0)


_WRITER = """
import sys, time
from hil.recording import Recorder, LINK_TX
rec = Recorder(sys.argv[1], flush_every=100)
for i in range(1000):
    rec.write_raw(LINK_TX, i, i.to_bytes(4, "little"))
print("ready", flush=True)
time.sleep(30)
"""


def test_file_of_a_killed_process_stays_readable(tmp_path: Path) -> None:
    path = tmp_path / "killed.mcap"
    proc = subprocess.Popen(
        [sys.executable, "-c", _WRITER, str(path)],
        stdout=subprocess.PIPE,
        cwd=Path(__file__).resolve().parents[2],
    )
    try:
        assert proc.stdout is not None
        assert proc.stdout.readline().strip() == b"ready"
    finally:
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(timeout=10)
    times = [r.time_us for r in read_records(path)]
    # Everything up to the last flush (every 100 messages) survives, in order.
    assert times == list(range(1000))


def test_truncated_file_reads_up_to_the_cut(tmp_path: Path) -> None:
    path = tmp_path / "cut.mcap"
    with Recorder(path, flush_every=50) as rec:
        for i in range(500):
            rec.write_raw(recording.LINK_RX, i, b"abc")
    data = path.read_bytes()
    cut = tmp_path / "cut2.mcap"
    cut.write_bytes(data[: len(data) // 2])
    times = [r.time_us for r in read_records(cut)]
    assert 0 < len(times) < 500
    assert times == list(range(len(times)))
