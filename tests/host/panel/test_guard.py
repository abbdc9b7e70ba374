"""The panel's handshake check and malformed messages, with a plain websocket client (no browser).

The browser's side (another origin's page, a browser without the token) is in test_panel.py.
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections.abc import Iterator

import msgspec
import pytest
import viser
import websockets.asyncio.client as ws_client

from host.app import HostApp
from host.options import HostOptions

TOKEN = "t0ken"


@pytest.fixture
def app() -> Iterator[HostApp]:
    with HostApp(HostOptions(port="loop://", ui_port=0, token=TOKEN)) as host:
        host.start()
        yield host


def _open(url: str, origin: str | None, payloads: list[bytes | str]) -> str:
    async def go() -> str:
        try:
            async with ws_client.connect(
                url,
                subprotocols=[f"viser-v{viser.__version__}"],  # type: ignore[list-item]
                origin=origin,  # type: ignore[arg-type]
            ) as conn:
                for p in payloads:
                    await conn.send(p)
                await asyncio.sleep(0.3)
                return "open"
        except Exception as exc:
            return type(exc).__name__

    return asyncio.run(go())


def test_origin_and_token_are_checked_in_the_handshake(app: HostApp) -> None:
    assert app.server is not None and app.guard is not None
    port = app.server.get_port()
    ws, own = f"ws://127.0.0.1:{port}/", f"http://127.0.0.1:{port}"
    assert _open(f"{ws}?token={TOKEN}", own, []) == "open"
    assert _open(f"{ws}?token={TOKEN}", "http://127.0.0.1:1", []) == "InvalidStatus"
    assert _open(f"{ws}?token={TOKEN}", "null", []) == "InvalidStatus"  # a file:// page
    assert _open(f"{ws}?token={TOKEN}", None, []) == "InvalidStatus"
    # A rebound name: Origin and Host agree, but a loopback panel answers only loopback names.
    assert app.guard.check(
        _Conn(), _Req("/", {"Host": f"evil.test:{port}", "Origin": f"http://evil.test:{port}"})
    )
    assert _open(ws, own, []) == "InvalidStatus"
    assert _open(f"{ws}?token=wrong", own, []) == "InvalidStatus"
    assert app.guard.stats.origin_refused_n == 4 and app.guard.stats.token_refused_n == 2


class _Conn:
    def respond(self, status: int, text: str) -> tuple[int, str]:
        return (status, text)


class _Req:
    def __init__(self, path: str, headers: dict[str, str]) -> None:
        self.path = path
        self.headers = _Headers(headers | {"Upgrade": "websocket"})


class _Headers(dict[str, str]):
    def get_all(self, key: str) -> list[str]:
        return [self[key]] if key in self else []


def test_malformed_messages_are_counted_not_traced(app: HostApp, caplog: pytest.LogCaptureFixture) -> None:
    assert app.server is not None and app.guard is not None
    port = app.server.get_port()
    url, own = f"ws://127.0.0.1:{port}/?token={TOKEN}", f"http://127.0.0.1:{port}"
    bad: list[bytes | str] = [
        b"\x00not msgpack",
        "a text frame",
        msgspec.msgpack.encode({"type": "NoSuchMessage"}),
        msgspec.msgpack.encode({"type": "ViewerCameraMessage", "wxyz": "x"}),
    ]
    with caplog.at_level(logging.DEBUG):
        for payload in bad:
            _open(url, own, [payload])
        deadline = time.monotonic() + 10.0
        while app.guard.stats.malformed_messages_n < len(bad) and time.monotonic() < deadline:
            time.sleep(0.05)
    assert app.guard.stats.malformed_messages_n == len(bad)
    assert not [r for r in caplog.records if r.exc_info], "a traceback was logged"
    warnings = [r for r in caplog.records if r.levelno >= logging.WARNING and "malformed" in r.getMessage()]
    assert len(warnings) == 1  # the first one says so; the rest are counted
    # The panel still serves well-formed clients.
    assert _open(url, own, []) == "open"
