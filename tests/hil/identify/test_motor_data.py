"""hil.identify.motor_data: a recording read as the motors' data, and every file it cannot use in one line."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from hil import recording
from hil.identify.motor_data import IdentifyDataError, load_motor_data
from hil.sim.config import MotorConfig


def test_the_board_s_wires_read_as_the_motors_data(preset_recording: Path) -> None:
    d = load_motor_data(preset_recording)
    assert d.source == "can" and d.period_s == pytest.approx(1e-3)
    assert d.profile is not None and d.profile.name == "tiny"
    assert d.profile_start_s == pytest.approx(0.599, abs=2e-3)  # the scenario starts it at 0.6 s board time
    assert d.first_judged() == d.index_at(d.profile_start_s + d.profile.segments[0].end_s)
    assert len(d.sha256) == 64 and d.design is not None and d.design.units == 21
    # The commanded current follows the profile's tension (slewed by the firmware at 50 N/s).
    force_per_amp = MotorConfig().force_per_amp_n
    ramp = d.profile.segments[1]
    peak_at = d.index_at(d.profile_start_s + ramp.start_s + 0.5 * ramp.duration_s)
    assert d.current_cmd_a[peak_at, 0] * force_per_amp == pytest.approx(d.profile.peak_n, abs=0.3)
    # The encoders were unwrapped: cable 0 wound in tens of millimetres during its ramp, smoothly.
    assert d.length_m[:, 0].max() > 0.02
    assert np.abs(np.diff(d.length_m[:, 0])).max() < 1e-3
    # Speed and length agree (speed is the length's derivative, within the rpm resolution).
    v = np.gradient(d.length_m[:, 0], d.t_s)
    assert np.corrcoef(v, d.speed_m_s[:, 0])[0, 1] > 0.95


@pytest.mark.parametrize(
    ("content", "why"),
    [
        (None, "no such file"),
        (b"not an mcap file", "not an MCAP recording"),
    ],
)
def test_unusable_files_are_one_line(tmp_path: Path, content: bytes | None, why: str) -> None:
    path = tmp_path / "x.mcap"
    if content is not None:
        path.write_bytes(content)
    with pytest.raises(IdentifyDataError, match=why) as info:
        load_motor_data(path)
    assert "\n" not in str(info.value)


def test_a_recording_without_motors_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "empty.mcap"
    with recording.Recorder(path, metadata={"source": "test"}) as rec:
        rec.write_raw(recording.DBUS_RX, 1000, b"\x00" * 18)
    with pytest.raises(IdentifyDataError, match="neither the board's CAN frames nor its telemetry"):
        load_motor_data(path)


def test_a_bad_excitation_description_is_one_line(tmp_path: Path, preset_recording: Path) -> None:
    path = tmp_path / "bad.mcap"
    with recording.Recorder(path, metadata={"excitation": '{"name": 3}'}) as rec:
        rec.write_raw(recording.DBUS_RX, 1000, b"")
    with pytest.raises(IdentifyDataError, match="excitation"):
        load_motor_data(path)
    assert math.isfinite(load_motor_data(preset_recording).duration_s)
