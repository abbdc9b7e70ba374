"""`spirob-host --foxglove`: a Foxglove WebSocket client subscribes and decodes a transform."""

from __future__ import annotations

import base64
import json
import socket
import struct
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import jsonschema
import numpy as np
import pytest
from websockets.sync.client import ClientConnection, connect

from hil import foxglove_log
from host.app import HostApp
from host.cli import main
from host.options import HostOptions
from protocol.messages import Message, SimPoses
from tests.support.foxglove_check import decode_protobuf, poses_array, protobuf_class
from tests.support.link_peer import LinkPeer

SUBPROTOCOL = "foxglove.sdk.v1"
"""Foxglove's WebSocket protocol as the SDK's server (0.30) names it: the wire format of
``foxglove.websocket.v1`` under a new name; the old name is refused at the handshake."""
MESSAGE_DATA = 0x01
"""Binary opcode of a message on a subscription (Foxglove WebSocket protocol v1)."""


@pytest.fixture
def peer() -> Iterator[LinkPeer]:
    with LinkPeer("pty") as p:
        yield p


def _json_until(ws: ClientConnection, op: str, deadline: float) -> dict[str, Any]:
    while time.monotonic() < deadline:
        frame = ws.recv(timeout=max(0.05, deadline - time.monotonic()))
        if isinstance(frame, str):
            obj: dict[str, Any] = json.loads(frame)
            if obj.get("op") == op:
                return obj
    raise AssertionError(f"no {op!r} from the server")


def _binary_until(ws: ClientConnection, sub_id: int, deadline: float) -> tuple[int, bytes]:
    while time.monotonic() < deadline:
        frame = ws.recv(timeout=max(0.05, deadline - time.monotonic()))
        if isinstance(frame, bytes) and frame[0] == MESSAGE_DATA:
            got_id, stamp_ns = struct.unpack_from("<IQ", frame, 1)
            if got_id == sub_id:
                return stamp_ns, frame[13:]
    raise AssertionError("no message on the subscription")


def test_a_client_subscribes_and_decodes_the_arms_transforms(peer: LinkPeer) -> None:
    received: list[SimPoses] = []
    lock = threading.Lock()

    def collect(msg: Message) -> None:
        if isinstance(msg, SimPoses):
            with lock:
                received.append(msg)

    with HostApp(HostOptions(port=peer.url, ui=False, foxglove_port=0)) as app:
        app.start()
        assert app.foxglove is not None and app.client is not None
        app.client.add_listener(collect)
        url = app.foxglove.url
        assert url.startswith("ws://127.0.0.1:") and app.foxglove.port > 0
        deadline = time.monotonic() + 20.0
        before_ns = time.time_ns()
        with connect(url, subprotocols=[SUBPROTOCOL], open_timeout=10) as ws:
            assert ws.subprotocol == SUBPROTOCOL
            _json_until(ws, "serverInfo", deadline)
            channels = {c["topic"]: c for c in _json_until(ws, "advertise", deadline)["channels"]}
            assert set(channels) == set(foxglove_log.CHANNELS)
            tf = channels[foxglove_log.TF]
            assert (tf["encoding"], tf["schemaName"], tf["schemaEncoding"]) == (
                "protobuf",
                "foxglove.FrameTransforms",
                "protobuf",
            )
            ws.send(json.dumps({"op": "subscribe", "subscriptions": [{"id": 7, "channelId": tf["id"]}]}))
            stamp_ns, payload = _binary_until(ws, 7, deadline)
        # Decoded with the schema the server advertised (base64 FileDescriptorSet), nothing of ours.
        cls = protobuf_class("foxglove.FrameTransforms", base64.b64decode(tf["schema"]))
        msg: Any = decode_protobuf(cls, payload)
        assert before_ns - 10**9 <= stamp_ns <= time.time_ns()
        with lock:
            sent = list(received)
    units = len(sent[0].positions_m) - 1
    positions, quats = poses_array(msg, units)
    # The transforms, composed down the tree, are the poses of one SimPoses the board sent.
    assert any(
        np.allclose(positions, np.asarray(p.positions_m, dtype=np.float64), rtol=0, atol=1e-9)
        and np.allclose(quats, np.asarray(p.quats_wxyz, dtype=np.float64), rtol=0, atol=1e-9)
        for p in sent
    )


def test_a_taken_port_is_one_error_line(peer: LinkPeer, capsys: pytest.CaptureFixture[str]) -> None:
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    s.listen(1)
    try:
        port = s.getsockname()[1]
        assert main(["--port", peer.url, "--headless", "--duration", "1", "--foxglove", str(port)]) == 2
    finally:
        s.close()
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--foxglove" in err[0] and str(port) in err[0], err
    assert "Traceback" not in err[0]


def test_flag_default_is_foxglove_port() -> None:
    from host.options import build_parser

    opts = HostOptions.from_args(build_parser().parse_args(["--foxglove"]))
    assert opts.foxglove_port == 8765
    assert HostOptions.from_args(build_parser().parse_args([])).foxglove_port is None
    assert HostOptions.from_args(build_parser().parse_args(["--foxglove", "9001"])).foxglove_port == 9001


def test_a_replay_is_served_live_too(peer: LinkPeer, tmp_path: Path) -> None:
    path = tmp_path / "run.mcap"
    assert main(["--port", peer.url, "--headless", "--duration", "1", "--record", str(path)]) == 0
    with HostApp(HostOptions(replay=path, ui=False, foxglove_port=0, replay_speed=0.5)) as app:
        app.start()
        assert app.foxglove is not None
        deadline = time.monotonic() + 20.0
        with connect(app.foxglove.url, subprotocols=[SUBPROTOCOL], open_timeout=10) as ws:
            channels = {c["topic"]: c for c in _json_until(ws, "advertise", deadline)["channels"]}
            tel = channels[foxglove_log.TELEMETRY]
            assert (tel["encoding"], tel["schemaEncoding"]) == ("json", "jsonschema")
            ws.send(json.dumps({"op": "subscribe", "subscriptions": [{"id": 3, "channelId": tel["id"]}]}))
            _, payload = _binary_until(ws, 3, deadline)
    obj = json.loads(payload)
    jsonschema.validate(obj, json.loads(tel["schema"]))  # the schema the server advertised
    assert obj["time_us"] > 0


# ---------------------------------------------------------------------- who may connect (issue 26)

WEB_APP = "https://app.foxglove.dev"


def _subscribe_telemetry(ws: ClientConnection, deadline: float) -> dict[str, Any]:
    channels = {c["topic"]: c for c in _json_until(ws, "advertise", deadline)["channels"]}
    tel = channels[foxglove_log.TELEMETRY]
    ws.send(json.dumps({"op": "subscribe", "subscriptions": [{"id": 5, "channelId": tel["id"]}]}))
    _, payload = _binary_until(ws, 5, deadline)
    obj: dict[str, Any] = json.loads(payload)
    return obj


def test_other_origins_are_refused_and_counted_named_ones_and_the_desktop_app_read(peer: LinkPeer) -> None:
    """A real cross-origin websocket client on 127.0.0.1: 403 and nothing served (it got 453 messages in
    3 s before); no Origin (Foxglove's desktop app) and a named origin subscribe and read telemetry."""
    from websockets.exceptions import InvalidStatus

    opts = HostOptions(port=peer.url, ui=False, foxglove_port=0, foxglove_origins=(WEB_APP,))
    with HostApp(opts) as app:
        app.start()
        assert app.foxglove is not None and app.foxglove.gate is not None
        url, stats = app.foxglove.url, app.foxglove.gate.stats
        for origin in (
            "http://evil.example",
            "null",
            f"http://127.0.0.1:{app.foxglove.port}",
            WEB_APP + ".evil",
        ):
            with pytest.raises(InvalidStatus) as info:
                connect(url, subprotocols=[SUBPROTOCOL], origin=origin, open_timeout=10)  # type: ignore[arg-type]
            assert info.value.response.status_code == 403, origin
        assert stats.origin_refused_n == 4 and stats.accepted_n == 0
        deadline = time.monotonic() + 20.0
        for origin in (None, WEB_APP):  # the desktop app sends none
            with connect(url, subprotocols=[SUBPROTOCOL], origin=origin, open_timeout=10) as ws:  # type: ignore[arg-type]
                assert ws.subprotocol == SUBPROTOCOL
                assert _subscribe_telemetry(ws, deadline)["time_us"] > 0
        assert stats.accepted_n == 2 and stats.origin_refused_n == 4


def test_the_sdk_server_behind_the_gate_takes_no_browser(peer: LinkPeer) -> None:
    """The SDK's own port speaks TLS under this run's certificate: a plain ws:// fails, and a wss:// that
    checks certificates (as every browser does) fails; only the gate, which pins it, gets through."""
    import ssl

    from websockets.exceptions import InvalidMessage

    with HostApp(HostOptions(port=peer.url, ui=False, foxglove_port=0)) as app:
        app.start()
        assert app.foxglove is not None and app.foxglove.backend_port not in (0, app.foxglove.port)
        backend = app.foxglove.backend_port
        with pytest.raises((InvalidMessage, OSError, EOFError)):
            connect(f"ws://127.0.0.1:{backend}", subprotocols=[SUBPROTOCOL], open_timeout=5)  # type: ignore[list-item]
        with pytest.raises(ssl.SSLCertVerificationError):
            connect(f"wss://127.0.0.1:{backend}", subprotocols=[SUBPROTOCOL], open_timeout=5)  # type: ignore[list-item]


def test_duplicate_or_malformed_origin_gets_400(peer: LinkPeer) -> None:
    with HostApp(HostOptions(port=peer.url, ui=False, foxglove_port=0)) as app:
        app.start()
        assert app.foxglove is not None and app.foxglove.gate is not None
        port = app.foxglove.port
        for headers in (
            ["Origin: http://evil.example", "Origin: https://app.foxglove.dev"],
            ["Origin: http://evil.example/path"],
            ["Host: a b"],
        ):
            host = ["Host: 127.0.0.1"] if "Host" not in headers[0] else []
            lines = ["GET / HTTP/1.1", *host, *headers, "Upgrade: websocket", "Connection: Upgrade"]
            with socket.create_connection(("127.0.0.1", port), timeout=5) as s:
                s.sendall(("\r\n".join(lines) + "\r\n\r\n").encode())
                assert s.recv(1024).startswith(b"HTTP/1.1 400"), headers
        assert app.foxglove.gate.stats.bad_headers_n == 3 and app.foxglove.gate.stats.accepted_n == 0


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--foxglove-origin", WEB_APP], "--foxglove-origin needs --foxglove"),
        (["--foxglove", "0", "--foxglove-origin", "app.foxglove.dev"], "--foxglove-origin: not an origin"),
        (["--foxglove", "0", "--foxglove-origin", f"{WEB_APP}/studio"], "--foxglove-origin: not an origin"),
    ],
)
def test_bad_origin_flags_are_one_line(
    peer: LinkPeer, capsys: pytest.CaptureFixture[str], argv: list[str], message: str
) -> None:
    assert main(["--port", peer.url, "--headless", "--duration", "1", *argv]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0] and "Traceback" not in err[0], err


def test_origin_flags_are_normalised() -> None:
    from host.options import build_parser

    ns = build_parser().parse_args(["--foxglove", "--foxglove-origin", "HTTPS://App.Foxglove.dev/"])
    ns2 = ["--foxglove-origin", "https://app.foxglove.dev", "--foxglove-origin", "http://localhost:8080"]
    assert HostOptions.from_args(ns).foxglove_origins == (WEB_APP,)
    both = HostOptions.from_args(build_parser().parse_args(["--foxglove", *ns2]))
    assert both.foxglove_origins == (WEB_APP, "http://localhost:8080")
