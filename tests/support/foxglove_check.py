"""Checking recordings against Foxglove's schemas with the schemas' own definitions.

Protobuf channels are decoded with the ``FileDescriptorSet`` stored in the file (no generated code of
ours), JSON channels validated with their stored JSON schema; a message that does not decode, carries
fields its schema lacks, or fails validation fails the test.
"""

from __future__ import annotations

import json
from collections import defaultdict
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import jsonschema
import numpy as np
import numpy.typing as npt
from google.protobuf import descriptor_pb2, descriptor_pool, message_factory
from google.protobuf.message import Message as PbMessage
from mcap.reader import make_reader


def protobuf_class(schema_name: str, schema_data: bytes) -> type[PbMessage]:
    """The message class a ``FileDescriptorSet`` schema defines (its dependencies included)."""
    fds = descriptor_pb2.FileDescriptorSet.FromString(schema_data)
    pool = descriptor_pool.DescriptorPool()
    pending = list(fds.file)
    # The set lists each file once; add a file after the files it imports.
    for _ in range(len(pending) + 1):
        if not pending:
            break
        fd = pending.pop(0)
        try:
            pool.Add(fd)
        except TypeError:
            pending.append(fd)
    assert not pending, f"unresolvable descriptor set for {schema_name}"
    cls: type[PbMessage] = message_factory.GetMessageClass(pool.FindMessageTypeByName(schema_name))
    return cls


def decode_protobuf(cls: type[PbMessage], data: bytes) -> PbMessage:
    """Decode ``data``; it must re-encode to the same bytes (no field the schema does not define)."""
    msg = cls.FromString(data)
    assert msg.SerializeToString(deterministic=True) == data, f"{cls.DESCRIPTOR.full_name}: unknown fields"
    return msg


@dataclass
class Checked:
    """What a recording holds on its non-raw channels, decoded and validated.

    Attributes:
        schemas: topic -> (schema name, schema encoding, message encoding).
        json_schemas: topic -> the stored JSON schema.
        messages: topic -> [(log_time_ns, publish_time_ns, decoded)]: protobuf messages or JSON objects.
        raw: topic -> [(publish_time_ns, bytes)] of the schemaless channels.
        metadata: the ``spirob`` metadata record.
    """

    schemas: dict[str, tuple[str, str, str]] = field(default_factory=dict)
    json_schemas: dict[str, Any] = field(default_factory=dict)
    messages: dict[str, list[tuple[int, int, Any]]] = field(default_factory=lambda: defaultdict(list))
    raw: dict[str, list[tuple[int, bytes]]] = field(default_factory=lambda: defaultdict(list))
    metadata: dict[str, str] = field(default_factory=dict)


def check_recording(path: Path) -> Checked:
    """Open ``path`` with the mcap library's (indexed) reader and check every message, and that every
    declared channel holds messages."""
    out = Checked()
    classes: dict[int, type[PbMessage]] = {}
    validators: dict[int, Any] = {}
    with open(path, "rb") as f:
        reader = make_reader(f)
        for meta in reader.iter_metadata():
            if meta.name == "spirob":
                out.metadata = dict(meta.metadata)
        for schema, channel, message in reader.iter_messages():
            if schema is None or schema.id == 0:
                out.raw[channel.topic].append((message.publish_time, bytes(message.data)))
                continue
            out.schemas[channel.topic] = (schema.name, schema.encoding, channel.message_encoding)
            if schema.encoding == "protobuf":
                assert channel.message_encoding == "protobuf"
                if schema.id not in classes:
                    classes[schema.id] = protobuf_class(schema.name, schema.data)
                decoded: Any = decode_protobuf(classes[schema.id], message.data)
            else:
                assert (schema.encoding, channel.message_encoding) == ("jsonschema", "json")
                if schema.id not in validators:
                    doc = json.loads(schema.data)
                    jsonschema.Draft202012Validator.check_schema(doc)
                    out.json_schemas[channel.topic] = doc
                    validators[schema.id] = jsonschema.Draft202012Validator(doc)
                decoded = json.loads(message.data)
                validators[schema.id].validate(decoded)
            out.messages[channel.topic].append((message.log_time, message.publish_time, decoded))
        summary = reader.get_summary()
    assert summary is not None
    declared = {c.topic for c in summary.channels.values()}
    # A file declares no channel it does not hold.
    assert declared == set(out.messages) | set(out.raw), declared ^ (set(out.messages) | set(out.raw))
    return out


def _quat_mul(a: npt.NDArray[np.float64], b: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    aw, av = a[0], a[1:]
    bw, bv = b[0], b[1:]
    return np.array([aw * bw - av @ bv, *(aw * bv + bw * av + np.cross(av, bv))])


def _rotate(q: npt.NDArray[np.float64], v: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    conj = q * np.array([1.0, -1.0, -1.0, -1.0])
    return _quat_mul(_quat_mul(q, np.array([0.0, *v])), conj)[1:]


def frame_parents(msg: Any) -> dict[str, str]:
    """child frame -> parent frame of a decoded ``foxglove.FrameTransforms``; each child once."""
    parents: dict[str, str] = {}
    for t in msg.transforms:
        assert t.child_frame_id not in parents, f"{t.child_frame_id} has two parents"
        parents[t.child_frame_id] = t.parent_frame_id
    return parents


def transforms_to_poses(msg: Any) -> dict[str, tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]]:
    """child frame -> world (position, quaternion w x y z) of a decoded ``foxglove.FrameTransforms``:
    each transform composed with its parent's up to ``world`` (computed here, independently of the
    code that wrote them), as Foxglove's 3D panel does. Every frame must reach ``world``."""
    local = {}
    for t in msg.transforms:
        p = np.array([t.translation.x, t.translation.y, t.translation.z])
        q = np.array([t.rotation.w, t.rotation.x, t.rotation.y, t.rotation.z])
        local[t.child_frame_id] = (t.parent_frame_id, p, q)
    assert len(local) == len(msg.transforms), "a frame with two parents"
    out: dict[str, tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]] = {}

    def world(frame: str, depth: int = 0) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
        if frame == "world":
            return np.zeros(3), np.array([1.0, 0.0, 0.0, 0.0])
        assert depth <= len(local), f"a cycle through {frame}"
        assert frame in local, f"frame {frame} does not reach world"
        if frame not in out:
            parent, p, q = local[frame]
            pp, pq = world(parent, depth + 1)
            out[frame] = (pp + _rotate(pq, p), _quat_mul(pq, q))
        return out[frame]

    for frame in local:
        world(frame)
    return out


def poses_array(msg: Any, units: int) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """Drone then units base to tip, as (n, 3) world positions and (n, 4) quaternions, from ``/tf``
    (the tree composed by :func:`transforms_to_poses`)."""
    frames = transforms_to_poses(msg)
    names = ["drone", *(f"unit_{i:02d}" for i in range(units))]
    assert set(frames) == {*names, "arm_base"}, sorted(frames)
    return np.array([frames[n][0] for n in names]), np.array([frames[n][1] for n in names])
