"""host.panel.record: a recording started mid-stream from the panel replays like any other."""

from __future__ import annotations

from pathlib import Path

from host.link.recording import replay_messages
from host.panel.record import RecordingSwitch
from protocol.link import encode_frame
from protocol.messages import Telemetry


def frame(t_us: int, seq: int) -> bytes:
    msg = Telemetry(t_us)
    return encode_frame(msg.CMD_ID, msg.pack(), seq)


def test_start_mid_frame_stop_and_replay(tmp_path: Path) -> None:
    sw = RecordingSwitch(tmp_path / "rec", {"source": "test"})
    sw.tap("rx", frame(1, 0), 1)  # before start: not recorded
    assert not sw.recording and sw.stop() is None
    path = sw.start()
    assert sw.recording and sw.start() == path and path.parent == tmp_path / "rec"
    second = frame(2, 1)
    sw.tap("rx", second[5:], 10)  # the tail of a frame: the reader resynchronises
    sw.tap("rx", frame(3, 2), 20)
    sw.tap("rx", frame(4, 3), 30)
    sw.on_board_message(Telemetry(4))
    assert sw.stop() == path and not sw.recording
    sw.tap("rx", frame(5, 4), 40)  # after stop: not recorded
    got = [msg.time_us for _, msg in replay_messages(path) if isinstance(msg, Telemetry)]
    assert got == [3, 4]
    again = sw.start()  # a second recording goes to a new file
    assert again != path
    sw.stop()


def test_the_hosts_own_messages_go_to_a_recording_only_while_it_runs(tmp_path: Path) -> None:
    from hil import recording
    from hil.identify.motor_data import EXCITATION_TOPIC
    from host.excite import EXCITATION_SCHEMA
    from tests.support.foxglove_check import check_recording

    sw = RecordingSwitch(tmp_path / "rec", {"source": "test"})
    start = {"name": "tiny", "duration_s": 0.5, "rest_n": 2.0, "peak_n": 10.0, "segments": [], "start_us": 7}
    sw.write_json(EXCITATION_TOPIC, start, EXCITATION_SCHEMA)  # not recording: nowhere
    sw.write_event("not recorded")
    path = sw.start()
    sw.on_board_message(Telemetry(4))
    sw.write_json(EXCITATION_TOPIC, start, EXCITATION_SCHEMA)
    sw.write_event("excitation tiny started", warning=False)
    sw.stop()
    checked = check_recording(path)
    assert [m for _, _, m in checked.messages[EXCITATION_TOPIC]] == [start]
    assert checked.schemas[EXCITATION_TOPIC] == ("spirob.Excitation", "jsonschema", "json")
    texts = [m.message for _, _, m in checked.messages["/events"]]
    assert "excitation tiny started" in texts and "not recorded" not in texts
    assert recording.read_metadata(path)["source"] == "test"
