"""`spirob-host --record` files in Foxglove's schemas, checked with the schemas the file itself stores."""

from __future__ import annotations

import importlib.metadata
import json
import time
from pathlib import Path

import numpy as np
import pytest

from hil import foxglove_log, recording
from hil.cli.main import main as hil_main
from host.cli import main
from host.drone.tlog import TLOG_LINK_IN, TLOG_LINK_OUT, TlogWriter
from host.link.recording import MAVLINK, MAVLINK_SCHEMA, LinkRecording, read_tlog
from protocol.mavlink import Attitude, Heartbeat, MavCodec
from protocol.messages import SimPoses
from protocol.stream import MessageStream
from tests.support.foxglove_check import Checked, check_recording, poses_array


@pytest.fixture(scope="module")
def host_run(tmp_path_factory: pytest.TempPathFactory) -> tuple[Checked, int, int]:
    path = tmp_path_factory.mktemp("host-rec") / "run.mcap"
    before_ns = time.time_ns()
    argv = ["--headless", "--duration", "3", "--virtual-rc", "manual", "--record", str(path)]
    assert main(argv) == 0
    return check_recording(path), before_ns, time.time_ns()


def test_channels_carry_foxglove_schemas(host_run: tuple[Checked, int, int]) -> None:
    checked, _, _ = host_run
    assert checked.schemas[foxglove_log.TF] == ("foxglove.FrameTransforms", "protobuf", "protobuf")
    assert checked.schemas[foxglove_log.SCENE] == ("foxglove.SceneUpdate", "protobuf", "protobuf")
    assert checked.schemas[foxglove_log.EVENTS] == ("foxglove.Log", "protobuf", "protobuf")
    assert checked.schemas[recording.TELEMETRY] == ("spirob.Telemetry", "jsonschema", "json")
    assert {recording.LINK_TX, recording.LINK_RX} <= set(checked.raw)
    assert len(checked.messages[recording.TELEMETRY]) > 20


def test_telemetry_has_the_same_schema_as_a_hil_recording(
    host_run: tuple[Checked, int, int], tmp_path: Path
) -> None:
    hil_path = tmp_path / "startup-gate.mcap"
    assert hil_main(["run", "startup-gate", "--record", str(hil_path)]) == 0
    hil = check_recording(hil_path)
    host = host_run[0]
    assert host.schemas[recording.TELEMETRY] == hil.schemas[recording.TELEMETRY]
    assert host.json_schemas[recording.TELEMETRY] == hil.json_schemas[recording.TELEMETRY]
    host_keys = {tuple(sorted(obj)) for _, _, obj in host.messages[recording.TELEMETRY]}
    hil_keys = {tuple(sorted(obj)) for _, _, obj in hil.messages[recording.TELEMETRY]}
    assert host_keys == hil_keys and len(host_keys) == 1


def test_log_time_is_unix_and_metadata_describes_the_run(host_run: tuple[Checked, int, int]) -> None:
    checked, before_ns, after_ns = host_run
    for topic in (recording.LINK_TX, recording.TELEMETRY, foxglove_log.TF):
        for log_ns, _, _ in checked.messages.get(topic, []):
            assert before_ns <= log_ns <= after_ns
    # publish_time is log_time, Unix time: Foxglove's publish-time timeline shows today, not 1970.
    day_ns = 86_400 * 10**9
    published = [p for msgs in checked.messages.values() for log_ns, p, _ in msgs if log_ns == p]
    assert len(published) == sum(len(msgs) for msgs in checked.messages.values()) > 20
    published += [p for msgs in checked.raw.values() for p, _ in msgs]
    assert all(abs(p - time.time_ns()) < day_ns for p in published)
    assert all(before_ns <= p <= after_ns for p in published)
    meta = checked.metadata
    assert meta["version"] == importlib.metadata.version("spirob-teleop")
    assert meta["source"] == "spirob-host"
    assert json.loads(meta["design"])["cables"] == 3 and "control_period_us" in json.loads(meta["firmware"])


def test_transforms_reproduce_the_poses_the_board_sent(host_run: tuple[Checked, int, int]) -> None:
    checked, _, _ = host_run
    stream = MessageStream()
    sent = [
        msg
        for _, data in checked.raw[recording.LINK_TX]
        for _, msg in stream.feed(data)
        if isinstance(msg, SimPoses)
    ]
    tfs = checked.messages[foxglove_log.TF]
    assert len(tfs) > 20
    units = len(sent[0].positions_m) - 1
    # Every SimPoses the board sent became one FrameTransforms, in order, with the same numbers (the
    # bytes are tapped before the message reaches the listeners: the last one may miss the closing file).
    assert 0 <= len(sent) - len(tfs) <= 1
    for (_, _, msg), poses in zip(tfs, sent[: len(tfs)], strict=True):
        positions, quats = poses_array(msg, units)
        # Composed down the tree (world -> drone -> arm_base -> unit): the world poses sent.
        np.testing.assert_allclose(
            positions, np.asarray(poses.positions_m, dtype=np.float64), rtol=0, atol=1e-9
        )
        np.testing.assert_allclose(quats, np.asarray(poses.quats_wxyz, dtype=np.float64), rtol=0, atol=1e-9)


def test_link_state_and_board_state_are_events(host_run: tuple[Checked, int, int]) -> None:
    texts = [m.message for _, _, m in host_run[0].messages[foxglove_log.EVENTS]]
    assert "board link connected" in texts
    assert any(t.startswith("mode ") for t in texts), texts


def test_the_tlog_is_copied_to_a_mavlink_channel(tmp_path: Path) -> None:
    tlog_path = tmp_path / "run.tlog"
    ours, autopilot = MavCodec(1, 25), MavCodec(1, 1)
    out_pkt = ours.encode(Heartbeat(mav_type=48))
    in_pkt = autopilot.encode(Attitude(1234, 0.1, -0.2, 1.5))
    t0_us = time.time_ns() // 1000
    tlog = TlogWriter(tlog_path)
    tlog.write(out_pkt, t0_us, TLOG_LINK_OUT)
    tlog.write(in_pkt, t0_us + 20_000, TLOG_LINK_IN)
    tlog.close()
    with open(tlog_path, "ab") as f:
        f.write(b"\x00garbage\x00")  # bytes that start no record: skipped
        f.write((t0_us + 40_000).to_bytes(8, "big") + in_pkt[:-3])  # a cut tail: ignored
    assert len(read_tlog(tlog_path).packets) == 2

    path = tmp_path / "run.mcap"
    rec = LinkRecording(path, {"source": "test"}, tlog=tlog_path)
    rec.close()
    rec.close()
    checked = check_recording(path)  # validated against the schema the file stores
    assert checked.schemas[MAVLINK] == ("spirob.MavlinkPacket", "jsonschema", "json")
    assert checked.json_schemas[MAVLINK] == MAVLINK_SCHEMA
    got = checked.messages[MAVLINK]
    assert [(o["direction"], o["type"], o["src_component"]) for _, _, o in got] == [
        ("out", "HEARTBEAT", 25),
        ("in", "ATTITUDE", 1),
    ]
    assert got[1][2]["fields"]["yaw_rad"] == pytest.approx(1.5)
    assert bytes.fromhex(got[0][2]["raw_hex"]) == out_pkt
    # log_time is the .tlog's own stamp (its two low bits hold the direction), to the µs.
    for (log_ns, _, _), stamp_us in zip(got, (t0_us, t0_us + 20_000), strict=True):
        assert abs(log_ns - (stamp_us & ~3) * 1000) < 1000
