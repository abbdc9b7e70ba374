"""Replay: a lockstep recording fed back through the firmware reproduces every output byte."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest
from mcap.writer import Writer

from hil import recording
from hil import replay as replay_module
from hil.errors import HilError
from hil.recording import Recorder, read_metadata, read_records
from hil.replay import replay
from hil.scenarios import run_scenario


@pytest.fixture(scope="module")
def rc_loss_recording(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("rec") / "rc-loss.mcap"
    run_scenario("rc-loss", seed=5, record=path)
    return path


def test_recording_holds_every_wire(rc_loss_recording: Path) -> None:
    topics = {r.topic for r in read_records(rc_loss_recording)}
    assert set(recording.RAW_TOPICS) <= topics
    assert recording.TELEMETRY in topics
    meta = read_metadata(rc_loss_recording)
    assert meta["scenario"] == "rc-loss" and meta["seed"] == "5"


def test_replay_matches_every_output_byte(rc_loss_recording: Path) -> None:
    result = replay(rc_loss_recording)
    assert result.matched, result.first_mismatch
    assert result.ticks == 4000 and result.outputs_compared > 4000


def _rewrite(src: Path, dst: Path, change: dict[str, bytes]) -> None:
    """Copy a recording, replacing the data of the first record of each topic in ``change``."""
    pending = dict(change)
    with Recorder(dst, metadata=read_metadata(src)) as out:
        for rec in read_records(src):
            data = pending.pop(rec.topic, rec.data)
            if rec.topic in (recording.TELEMETRY, "/board/config"):
                out.write_json(rec.topic, rec.time_us, rec.json())
            else:
                out.write_raw(rec.topic, rec.time_us, data)


def test_replay_detects_a_changed_input(rc_loss_recording: Path, tmp_path: Path) -> None:
    # One DBUS chunk with a flipped channel bit: the firmware's outputs must differ from the recording.
    first_dbus = next(r for r in read_records(rc_loss_recording) if r.topic == recording.DBUS_RX)
    corrupted = bytes([first_dbus.data[0] ^ 0x01]) + first_dbus.data[1:]
    changed = tmp_path / "changed.mcap"
    _rewrite(rc_loss_recording, changed, {recording.DBUS_RX: corrupted})
    unchanged = tmp_path / "same.mcap"
    _rewrite(rc_loss_recording, unchanged, {})
    assert replay(unchanged).matched
    result = replay(changed)
    assert not result.matched and result.first_mismatch


def test_replay_refuses_a_foreign_file(tmp_path: Path) -> None:
    other = tmp_path / "other.mcap"
    with Recorder(other, metadata={"something": "else"}) as rec:
        rec.write_raw(recording.LINK_TX, 0, b"x")
    with pytest.raises(HilError, match="not a lockstep board recording"):
        replay(other)
    bare = tmp_path / "bare.mcap"
    with open(bare, "wb") as f:  # an MCAP file without our metadata
        writer = Writer(f)
        writer.start()
        channel = writer.register_channel(recording.LINK_TX, recording.RAW_ENCODING, schema_id=0)
        writer.add_message(channel, log_time=0, data=b"x", publish_time=0)
        writer.finish()
    with pytest.raises(HilError, match="no spirob metadata"):
        replay(bare)
    text = tmp_path / "notes.mcap"
    text.write_text("not a recording\n")
    with pytest.raises(HilError, match="not an MCAP file"):
        replay(text)


def test_replay_streams_the_recording_once(rc_loss_recording: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Linear in the recording's length, counted rather than timed: every record is read once, and each
    tick runs before more than one further tick mark has been read (no copy of what remains, no look
    ahead past the next mark), so the work per tick does not grow with the file."""
    ticks_run = 0
    marks_read = 0
    records_read = 0
    behind_max = 0

    class CountingFirmware(replay_module.Firmware):
        def run_due(self, now_us: int) -> None:
            nonlocal ticks_run
            ticks_run += 1
            super().run_due(now_us)

    def counting_records(path: Path, topics: frozenset[str] | None = None) -> Iterator[recording.Record]:
        nonlocal marks_read, records_read, behind_max
        for rec in read_records(path, topics):
            records_read += 1
            if rec.topic == recording.TICK:
                marks_read += 1
                behind_max = max(behind_max, marks_read - ticks_run)
            yield rec

    monkeypatch.setattr(replay_module, "Firmware", CountingFirmware)
    monkeypatch.setattr(replay_module, "read_records", counting_records)
    result = replay(rc_loss_recording)
    assert result.matched, result.first_mismatch
    wanted = replay_module._INPUTS | replay_module._OUTPUTS | {recording.TICK}
    assert records_read == sum(1 for r in read_records(rc_loss_recording) if r.topic in wanted)
    assert ticks_run == marks_read == result.ticks == 4000
    assert behind_max <= 2  # reading mark k, tick k - 2 has run: one segment held, never the file


def test_a_killed_recording_is_recovered_and_replayed(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """kill -9 of a real `spirob-hil run --record` mid-run: recover, the standard reader, replay."""
    import os
    import signal
    import subprocess
    import sys
    import time

    from mcap.reader import make_reader

    from hil.cli.main import main

    path = tmp_path / "killed.mcap"
    repo = Path(__file__).resolve().parents[2]
    proc = subprocess.Popen(
        [sys.executable, "-m", "hil.cli.main", "run", "rc-loss", "--seed", "5", "--record", str(path)],
        cwd=repo,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    try:
        # Killed once several chunks are on disk, long before the run (and its summary) ends.
        deadline = time.monotonic() + 120.0
        while time.monotonic() < deadline and (not path.exists() or path.stat().st_size < 200_000):
            assert proc.poll() is None, "the run ended before it could be killed"
            time.sleep(0.01)
    finally:
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(timeout=10)
    assert recording.is_truncated(path)
    assert read_metadata(path).get("scenario") == "rc-loss"  # the metadata is on disk at once

    # Replay accepts the truncated tail, says so in one line, and every compared output matches.
    result = replay(path)
    assert result.truncated and result.matched and result.ticks > 1000, result
    assert main(["replay", str(path)]) == 0
    note, verdict = capsys.readouterr().out.splitlines()
    assert "truncated" in note and "every output byte matched" in verdict

    # recover writes a file the mcap library's normal (seeking) reader opens, with every message.
    out = tmp_path / "recovered.mcap"
    assert main(["recover", str(path), "-o", str(out)]) == 0
    assert recording.is_truncated(out)  # complete, but it says its run was cut short
    with open(out, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        assert summary is not None and summary.statistics is not None
        n = summary.statistics.message_count
        assert n == sum(1 for _ in reader.iter_messages())
    assert n == sum(1 for _ in read_records(path)) > 0
    assert read_metadata(out) == {**read_metadata(path), "truncated": "true"}
    again = replay(out)
    assert again.truncated and again.matched and again.ticks == result.ticks


def _downgrade(src: Path, dst: Path, meta: dict[str, str]) -> None:
    """Copy a recording in the layout of format 1: log_time on the board's clock, no format key."""
    with open(dst, "wb") as f:
        writer = Writer(f)
        writer.start(profile=recording.PROFILE, library="spirob-teleop")
        writer.add_metadata(recording.PROFILE, meta)
        channels: dict[str, int] = {}
        for rec in read_records(src):
            if rec.topic not in channels:
                channels[rec.topic] = writer.register_channel(rec.topic, recording.RAW_ENCODING, schema_id=0)
            t_ns = rec.time_us * 1000
            writer.add_message(channels[rec.topic], log_time=t_ns, data=rec.data, publish_time=t_ns)
        writer.finish()


def test_a_format_1_recording_still_replays(rc_loss_recording: Path, tmp_path: Path) -> None:
    meta = {k: v for k, v in read_metadata(rc_loss_recording).items() if k not in ("format", "version")}
    old = tmp_path / "old.mcap"
    _downgrade(rc_loss_recording, old, meta)
    assert recording.recording_format(read_metadata(old)) == 1
    result = replay(old)
    assert result.matched, result.first_mismatch
    assert result.ticks == 4000


def test_a_newer_format_is_refused_in_one_line(rc_loss_recording: Path, tmp_path: Path) -> None:
    meta = {**read_metadata(rc_loss_recording), "format": "7", "version": "9.9.9"}
    newer = tmp_path / "newer.mcap"
    _downgrade(rc_loss_recording, newer, meta)
    with pytest.raises(HilError) as info:
        replay(newer)
    message = str(info.value)
    assert "\n" not in message
    assert "format 7" in message and "9.9.9" in message and f"format {recording.FORMAT}" in message


def test_an_arrays_recording_replays_its_arm_poses_byte_for_byte(tmp_path: Path) -> None:
    """An array's poses (SimPoses + one ArmPoses per further arm) are rebuilt from the recorded bodies."""
    from controller.config import FirmwareConfig
    from hil.board import BoardConfig, VirtualBoard
    from hil.radio import RadioScript
    from hil.sim.spiral import SpiralDesign
    from protocol.dbus import Lever, RcFrame
    from protocol.messages import ArmPoses
    from protocol.stream import MessageStream

    path = tmp_path / "array.mcap"
    cfg = BoardConfig(
        design=SpiralDesign.paper_prototype().with_cables(1), firmware=FirmwareConfig().with_arms(3, 1)
    )
    start = RcFrame.neutral()
    manual = RcFrame((0, 0, 0, 300), Lever.MIDDLE, Lever.DOWN)  # curl every arm
    radio = RadioScript([(0, start), (100_000, manual)])
    with (
        Recorder(path, metadata=cfg.describe()) as rec,
        VirtualBoard(cfg, radio_script=radio, recorder=rec) as board,
    ):
        board.run(300_000)
    stream = MessageStream()
    sent = [m for r in read_records(path, {recording.LINK_TX}) for _, m in stream.feed(r.data)]
    assert sum(isinstance(m, ArmPoses) for m in sent) == 2 * 15  # arms 1 and 2, 50 Hz for 0.3 s
    result = replay(path)
    assert result.matched, result.first_mismatch
    assert result.ticks == 300
