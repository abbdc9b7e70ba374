"""Foxglove's schemas in `spirob-hil run --record` files: decoded with the file's own schema definitions."""

from __future__ import annotations

import importlib.metadata
import json
from typing import Any

import jsonschema
import numpy as np
import pytest
from foxglove.messages import LogLevel

from hil import foxglove_log, recording
from hil.cli.main import main
from protocol.messages import GraspState, Mode, Phase, Telemetry
from tests.support.foxglove_check import (
    Checked,
    check_recording,
    frame_parents,
    poses_array,
    protobuf_class,
    transforms_to_poses,
)


@pytest.fixture(scope="module")
def hil_run(tmp_path_factory: pytest.TempPathFactory) -> Checked:
    path = tmp_path_factory.mktemp("fox") / "overcurrent.mcap"
    assert main(["run", "overcurrent", "--seed", "4", "--record", str(path)]) == 0
    return check_recording(path)


def test_channels_carry_foxglove_schemas(hil_run: Checked) -> None:
    checked = hil_run
    assert checked.schemas[foxglove_log.TF] == ("foxglove.FrameTransforms", "protobuf", "protobuf")
    assert checked.schemas[foxglove_log.SCENE] == ("foxglove.SceneUpdate", "protobuf", "protobuf")
    assert checked.schemas[foxglove_log.EVENTS] == ("foxglove.Log", "protobuf", "protobuf")
    assert checked.schemas[recording.TELEMETRY] == ("spirob.Telemetry", "jsonschema", "json")
    assert checked.schemas[recording.BOARD_CONFIG] == ("spirob.BoardConfig", "jsonschema", "json")
    # The raw wires replay needs are still there, schemaless.
    assert set(recording.RAW_TOPICS) <= set(checked.raw)
    assert checked.json_schemas[recording.TELEMETRY] == foxglove_log.TELEMETRY_SCHEMA
    assert len(checked.messages[recording.TELEMETRY]) > 50


def test_metadata_names_the_version_design_and_firmware(hil_run: Checked) -> None:
    meta = hil_run.metadata
    assert meta["version"] == importlib.metadata.version("spirob-teleop")
    assert meta["format"] == str(recording.FORMAT)
    assert json.loads(meta["design"])["cables"] == 3
    assert json.loads(meta["firmware"])["control_period_us"] > 0
    assert meta["scenario"] == "overcurrent" and meta["seed"] == "4"


def test_lockstep_log_time_is_simulated_time_in_the_payload_too(hil_run: Checked) -> None:
    # A lockstep run has no wall clock (and its file is byte-identical for a seed): offset 0.
    checked = hil_run
    assert checked.metadata["clock_offset_ns"] == "0"
    for topic in (foxglove_log.TF, recording.TELEMETRY, foxglove_log.EVENTS):
        for log_ns, publish_ns, _ in checked.messages[topic]:
            assert log_ns == publish_ns
    for _, publish_ns, obj in checked.messages[recording.TELEMETRY]:
        assert publish_ns == obj["time_us"] * 1000
    for log_ns, _, msg in checked.messages[foxglove_log.TF]:
        # The transforms' own stamps are the log time: the 3D panel looks them up at the playback time.
        assert {t.timestamp.seconds * 10**9 + t.timestamp.nanos for t in msg.transforms} == {log_ns}


def test_transforms_reproduce_the_plants_poses(hil_run: Checked) -> None:
    checked = hil_run
    plant = {t: recording.unpack_poses(data) for t, data in checked.raw[recording.POSES]}
    tfs = checked.messages[foxglove_log.TF]
    assert len(tfs) == len(plant) > 10
    units = len(next(iter(plant.values()))[0]) - 1
    moved = 0.0
    first_tip = None
    for _, publish_ns, msg in tfs:
        positions, quats = poses_array(msg, units)
        want_p, want_q = plant[publish_ns]
        # Composed down the tree (world -> drone -> arm_base -> unit), the plant's world poses again.
        np.testing.assert_allclose(positions, want_p, rtol=0, atol=1e-12)
        np.testing.assert_allclose(quats, want_q, rtol=0, atol=1e-12)
        first_tip = positions[-1] if first_tip is None else first_tip
        moved = max(moved, float(np.linalg.norm(positions[-1] - first_tip)))
    assert moved > 0.01, "the arm never moved: the comparison proves little"


def test_frames_form_a_tree_world_drone_arm_base_units(hil_run: Checked) -> None:
    tfs = [m for _, _, m in hil_run.messages[foxglove_log.TF]]
    units = len(tfs[0].transforms) - 2
    assert units > 5
    want = {
        "drone": "world",
        "arm_base": "drone",
        **{foxglove_log.unit_frame(i): "arm_base" for i in range(units)},
    }
    base_in_drone = []
    for msg in tfs:
        assert frame_parents(msg) == want
        # Parents come before their children (a reader that resolves in order never meets an unknown frame).
        seen = {"world"}
        for t in msg.transforms:
            assert t.parent_frame_id in seen
            seen.add(t.child_frame_id)
        by_child = {t.child_frame_id: t for t in msg.transforms}
        b = by_child["arm_base"]
        base_in_drone.append([b.translation.x, b.translation.y, b.translation.z, b.rotation.w, b.rotation.x])
        u0 = by_child[foxglove_log.unit_frame(0)]  # the base unit is the arm's base frame itself
        assert abs(u0.rotation.w) == pytest.approx(1.0, abs=1e-12)
        assert max(abs(u0.translation.x), abs(u0.translation.y), abs(u0.translation.z)) < 1e-12
    # The arm's base is rigid on the drone: one pose in the drone's frame for the whole run (hanging
    # below its origin).
    np.testing.assert_allclose(base_in_drone, [base_in_drone[0]] * len(base_in_drone), rtol=0, atol=1e-9)
    assert base_in_drone[0][2] < 0


def _quat_about(axis: list[float], angle_rad: float) -> np.ndarray[Any, Any]:
    a = np.asarray(axis, dtype=np.float64) / np.linalg.norm(axis)
    return np.array([np.cos(angle_rad / 2), *(np.sin(angle_rad / 2) * a)])


def test_tree_composes_back_to_world_poses_and_follows_the_drone() -> None:
    rng = np.random.default_rng(26)
    n = 6
    positions = rng.normal(size=(n, 3))
    quats = rng.normal(size=(n, 4))
    quats /= np.linalg.norm(quats, axis=1, keepdims=True)
    cls = protobuf_class("foxglove.FrameTransforms", foxglove_log.CHANNELS[foxglove_log.TF].schema_data)
    msg: Any = cls.FromString(foxglove_log.frame_transforms(5, positions, quats))
    got_p, got_q = poses_array(msg, n - 1)
    np.testing.assert_allclose(got_p, positions, rtol=0, atol=1e-12)
    # q and -q are one rotation; composing keeps the sign here, so compare directly.
    np.testing.assert_allclose(got_q, quats, rtol=0, atol=1e-12)
    # Move and turn the drone, carrying the arm with it (a rigid motion of everything): only the
    # world -> drone transform changes, so Foxglove moves the arm when the drone's frame moves.
    turn = _quat_about([0.3, -1.0, 0.2], 0.7)
    shift = np.array([1.5, -2.0, 0.25])
    moved_p = np.array([shift + _rotate(turn, p) for p in positions])
    moved_q = np.array([foxglove_log._quat_mul(turn, q) for q in quats])
    moved: Any = cls.FromString(foxglove_log.frame_transforms(5, moved_p, moved_q))
    before = {t.child_frame_id: t for t in msg.transforms}
    for t in moved.transforms:
        if t.child_frame_id == "drone":
            continue
        b = before[t.child_frame_id]
        got = [t.translation.x, t.translation.y, t.translation.z, t.rotation.w, t.rotation.x, t.rotation.y]
        want = [b.translation.x, b.translation.y, b.translation.z, b.rotation.w, b.rotation.x, b.rotation.y]
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-12)
    world = transforms_to_poses(moved)
    np.testing.assert_allclose(world["unit_04"][0], moved_p[5], rtol=0, atol=1e-12)
    # Only the drone: one transform; no poses at all: none.
    assert [(p, c) for p, c, _, _ in foxglove_log.tree_poses(positions[:1], quats[:1])] == [
        ("world", "drone")
    ]
    assert foxglove_log.tree_poses(np.zeros((0, 3)), np.zeros((0, 4))) == []


def _rotate(q: np.ndarray[Any, Any], v: np.ndarray[Any, Any]) -> np.ndarray[Any, Any]:
    w, u = q[0], q[1:]
    t = 2.0 * np.cross(u, v)
    out: np.ndarray[Any, Any] = v + w * t + np.cross(u, t)
    return out


def test_scene_draws_each_unit_from_its_joint_to_the_next(hil_run: Checked) -> None:
    checked = hil_run
    scenes = checked.messages[foxglove_log.SCENE]
    assert 1 <= len(scenes) <= 3  # the first poses, then once a second of board time
    _, publish_ns, update = scenes[-1]
    tf = next(m for _, t, m in checked.messages[foxglove_log.TF] if t == publish_ns)
    units = len(tf.transforms) - 2  # the drone and the arm's base are frames too
    positions, quats = poses_array(tf, units)
    entities = {e.id: e for e in update.entities}
    assert set(entities) == {"drone", *(foxglove_log.unit_frame(i) for i in range(units))}
    for i in range(units - 1):
        e = entities[foxglove_log.unit_frame(i)]
        assert e.frame_id == foxglove_log.unit_frame(i) and e.frame_locked
        (cyl,) = e.cylinders
        o = cyl.pose.orientation
        q_cyl = np.array([o.w, o.x, o.y, o.z])
        centre = np.array([cyl.pose.position.x, cyl.pose.position.y, cyl.pose.position.z])
        far_end_local = centre + _rotate(q_cyl, np.array([0.0, 0.0, cyl.size.z / 2.0]))
        far_end = positions[1 + i] + _rotate(quats[1 + i], far_end_local)
        # The cone ends at the next joint (the design's chord): within 0.1 mm.
        assert np.linalg.norm(far_end - positions[2 + i]) < 1e-4
        assert cyl.top_scale < cyl.bottom_scale == 1.0  # tapering towards the tip


def test_events_are_foxglove_logs_of_state_changes(hil_run: Checked) -> None:
    checked = hil_run
    logs = [m for _, _, m in checked.messages[foxglove_log.EVENTS]]
    texts = [m.message for m in logs]
    assert any(t.startswith("mode ") for t in texts), texts
    assert all("board t=" in t and m.name == "spirob" for t, m in zip(texts, logs, strict=True))


def test_telemetry_json_validates_and_keeps_every_field() -> None:
    msg = Telemetry(1234, Mode.GRASP, Phase.RC_LOST, GraspState.HOLD, tension_est_n=(1.0, 2.0, 3.5))
    obj = foxglove_log.telemetry_json(msg)
    jsonschema.validate(obj, foxglove_log.TELEMETRY_SCHEMA)
    assert obj["mode"] == 2 and obj["mode_name"] == "GRASP" and obj["tension_est_n"] == [1.0, 2.0, 3.5]
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.validate({**obj, "mode": 99}, foxglove_log.TELEMETRY_SCHEMA)
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.validate({k: v for k, v in obj.items() if k != "time_us"}, foxglove_log.TELEMETRY_SCHEMA)


def test_view_logs_changes_with_their_level() -> None:
    view = foxglove_log.FoxgloveView()
    log_cls = protobuf_class("foxglove.Log", foxglove_log.CHANNELS[foxglove_log.EVENTS].schema_data)
    ok = foxglove_log.telemetry_json(Telemetry(0, Mode.MANUAL, Phase.OK))
    lost = foxglove_log.telemetry_json(Telemetry(500_000, Mode.SAFE, Phase.RC_LOST, motor_offline_events=1))
    first = view.telemetry(10, ok)
    assert [t for t, _ in first] == [foxglove_log.TELEMETRY] + [foxglove_log.EVENTS] * 4
    unchanged = json.dumps(ok, separators=(",", ":")).encode()
    assert view.telemetry(20, ok) == [(foxglove_log.TELEMETRY, unchanged)]
    later = view.telemetry(30, lost)
    logs = [log_cls.FromString(data) for topic, data in later if topic == foxglove_log.EVENTS]
    by_text = {m.message: m.level for m in logs}  # type: ignore[attr-defined]
    assert by_text == {
        "mode MANUAL -> SAFE (board t=0.500 s)": LogLevel.Info.value,
        "phase OK -> RC_LOST (board t=0.500 s)": LogLevel.Warning.value,
        "a motor went offline (board t=0.500 s)": LogLevel.Warning.value,
    }


def test_design_sizes_from_metadata_or_none(hil_run: Checked) -> None:
    sizes = foxglove_log.design_sizes(hil_run.metadata["design"])
    assert sizes is not None
    widths, lengths = sizes
    assert len(widths) == len(lengths) > 5 and all(b > t > 0 for b, t in widths)
    for bad in (None, "", "nonsense", "[1, 2]", '{"a_m": 1}'):
        assert foxglove_log.design_sizes(bad) is None
    # Without sizes, units are drawn from the poses alone: as long as the joint distance.
    positions = [[0.0, 0.0, 1.0], [0.0, 0.0, 0.9], [0.0, 0.0, 0.8], [0.0, 0.0, 0.75]]
    quats = [[1.0, 0.0, 0.0, 0.0]] * 4
    shapes = foxglove_log.unit_shapes(positions, quats)
    assert [round(s.length_m, 9) for s in shapes] == [0.1, 0.05, 0.05]
    assert all(s.axis == pytest.approx((0.0, 0.0, -1.0)) for s in shapes)
    assert shapes[0].base_width_m == pytest.approx(0.08)
