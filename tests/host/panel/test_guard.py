"""The panel's handshake check and malformed messages, with a plain websocket client (no browser).

The browser's side (another origin's page, a browser without the token) is in test_panel.py.
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections.abc import Iterator
from http import HTTPStatus

import msgspec
import pytest
import viser
import websockets.asyncio.client as ws_client
from websockets.exceptions import InvalidStatus

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
        except InvalidStatus as exc:  # the handshake answered with an HTTP status: which one
            return f"HTTP {exc.response.status_code}"
        except Exception as exc:
            return type(exc).__name__

    return asyncio.run(go())


def test_origin_and_token_are_checked_in_the_handshake(app: HostApp) -> None:
    assert app.server is not None and app.guard is not None
    port = app.server.get_port()
    ws, own = f"ws://127.0.0.1:{port}/", f"http://127.0.0.1:{port}"
    assert _open(f"{ws}?token={TOKEN}", own, []) == "open"
    assert _open(f"{ws}?token={TOKEN}", "http://127.0.0.1:1", []) == "HTTP 403"
    assert _open(f"{ws}?token={TOKEN}", "null", []) == "HTTP 403"  # a file:// page
    assert _open(f"{ws}?token={TOKEN}", None, []) == "HTTP 403"
    # A rebound name: Origin and Host agree, but a loopback panel answers only loopback names.
    rebound = {"Host": f"evil.test:{port}", "Origin": f"http://evil.test:{port}"}
    assert app.guard.check(_Conn(), _Req(f"/?token={TOKEN}", rebound)) == (
        HTTPStatus.FORBIDDEN,
        "Origin refused\n",
    )
    assert _open(ws, own, []) == "HTTP 403"
    assert _open(f"{ws}?token=wrong", own, []) == "HTTP 403"
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


def _raw_upgrade(port: int, header_lines: list[str]) -> str:
    """A websocket upgrade written by hand (a client library will not send two Host headers): the
    status line of the answer."""
    import base64
    import os
    import socket

    key = base64.b64encode(os.urandom(16)).decode()
    lines = [
        f"GET /?token={TOKEN} HTTP/1.1",
        *header_lines,
        "Upgrade: websocket",
        "Connection: Upgrade",
        f"Sec-WebSocket-Key: {key}",
        "Sec-WebSocket-Version: 13",
    ]
    with socket.create_connection(("127.0.0.1", port), timeout=5) as s:
        s.sendall(("\r\n".join(lines) + "\r\n\r\n").encode())
        return s.recv(4096).decode(errors="replace").split("\r\n", 1)[0]


_HOST, _ORIGIN = "Host: 127.0.0.1:{port}", "Origin: http://127.0.0.1:{port}"


@pytest.mark.parametrize(
    ("headers", "problem"),
    [
        (
            ["Host: 127.0.0.1:{port}", "Host: 127.0.0.1:{port}", "Origin: http://127.0.0.1:{port}"],
            "2 Host headers",
        ),
        (
            ["Host: 127.0.0.1:{port}", "Origin: http://127.0.0.1:{port}", "Origin: http://evil.example"],
            "2 Origin",
        ),
        (["Host: 127.0.0.1:{port}/x y", "Origin: http://127.0.0.1:{port}"], "malformed Host header"),
        (["Host: 127.0.0.1:99999", "Origin: http://127.0.0.1:99999"], "malformed Host header"),
        (["Host: 127.0.0.1:{port}", "Origin: http://127.0.0.1:{port}/path"], "malformed Origin header"),
    ],
)
def test_duplicate_or_malformed_host_and_origin_get_400_counted_in_one_line(
    app: HostApp, caplog: pytest.LogCaptureFixture, headers: list[str], problem: str
) -> None:
    assert app.server is not None and app.guard is not None
    port = app.server.get_port()
    with caplog.at_level(logging.DEBUG):
        status = _raw_upgrade(port, [h.format(port=port) for h in headers])
        time.sleep(0.2)  # the server's log line
    assert status.startswith("HTTP/1.1 400"), status
    assert app.guard.stats.bad_headers_n == 1
    assert app.guard.stats.origin_refused_n == 0 and app.guard.stats.token_refused_n == 0
    assert not [r for r in caplog.records if r.exc_info], "a traceback was logged"
    ours = [r.getMessage() for r in caplog.records if "refused (400)" in r.getMessage()]
    assert len(ours) == 1 and problem in ours[0], ours
    # the same request with one well-formed Host and Origin opens
    own = f"http://127.0.0.1:{port}"
    assert _raw_upgrade(port, [f"Host: 127.0.0.1:{port}", f"Origin: {own}"]).startswith("HTTP/1.1 101")
    assert app.guard.stats.bad_headers_n == 1


def test_page_title_is_the_products() -> None:
    """viser's page says "Viser"; the guard serves it as SpiRob Teleop, gzip or not, other files untouched."""
    import dataclasses
    import gzip

    from websockets.datastructures import Headers
    from websockets.http11 import Response

    from host.panel.guard import PAGE_TITLE, retitle_page

    page = b"<html><head><title>Viser</title></head><body></body></html>"
    want = f"<title>{PAGE_TITLE}</title>".encode()
    cache: dict[bytes, bytes] = {}
    for enc, body in (("identity", page), ("gzip", gzip.compress(page))):
        headers = Headers(**{"Content-Type": "text/html; charset=utf-8", "Content-Length": str(len(body))})
        headers["Content-Encoding"] = enc
        out = retitle_page(Response(200, "OK", headers, body), cache)
        text = gzip.decompress(out.body) if enc == "gzip" else out.body
        assert want in text and b"Viser" not in text
        assert out.headers.get_all("Content-Length") == [str(len(out.body))]
    assert PAGE_TITLE == "SpiRob Teleop" and len(cache) == 2
    js = Response(200, "OK", Headers(**{"Content-Type": "application/javascript"}), b"<title>Viser</title>")
    assert retitle_page(js, cache) is js
    assert retitle_page(None) is None
    broken = Response(200, "OK", Headers(**{"Content-Type": "text/html", "Content-Encoding": "gzip"}), b"x")
    assert dataclasses.asdict(retitle_page(broken)) == dataclasses.asdict(broken)
