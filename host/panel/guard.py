"""Who may open the panel: the Origin and token check in viser's websocket handshake.

viser 1.1.1 serves its page and its websocket on one port through ``websockets.asyncio.server.serve``,
with a ``process_request`` hook (``viser.infra._infra.WebsockServer._background_worker``) that serves
the page and lets every websocket upgrade through: no authentication, no Origin check. Any web page
the operator has open could therefore drive the arm. :func:`start_guarded_server` wraps that hook
while the server starts, so every request passes :meth:`PanelGuard.check` first:

- **Origin**: a websocket upgrade must come from the panel's own page, ``Origin`` equal to
  ``http://`` + the request's ``Host``. A page from another origin (another port, ``file://``, whose
  Origin is ``null``) is refused with 403, whatever it carries. On a loopback bind ``Host`` must also
  name the loopback (``127.0.0.1``, ``localhost``, ``[::1]``): a DNS-rebound name passes the Origin
  comparison but not this one.
- **Token** (unless ``--no-token``): the page and the websocket need it, from the ``token`` query
  parameter (the URL printed at start, ``http://HOST:PORT/?token=T``) or from the cookie the page
  request with a valid token sets (``HttpOnly``, ``SameSite=Strict``): viser's client drops the page's
  query from its websocket URL, and the cookie carries it there, as Jupyter does. Compared in
  constant time.

- **Well-formed headers**: a request with more than one ``Host`` or ``Origin`` header, or one that is not
  a host name (or IP literal) with an optional port, or an ``Origin`` that is not ``null`` or
  ``scheme://host[:port]``, is answered 400 before anything reads them (a duplicate used to raise inside
  the check: HTTP 500 and a traceback per request).

Refusals are counted (:class:`GuardStats`) and logged at info level, one line each.

The page it lets through is viser's ``index.html`` with its ``<title>`` set to :data:`PAGE_TITLE`
(viser's client never sets ``document.title``: every tab was titled "Viser").

A message on an open websocket that viser cannot decode (not msgpack, a text frame, an unknown type,
missing fields) ends that connection inside viser's handler, which ``websockets`` logs with a
traceback; a decoded one whose handler raises ends as an asyncio task error, traced too. Both are
counted instead (``GuardStats.malformed_messages_n``), the first one logged as a warning line and the
rest at debug level (:meth:`PanelGuard.attach`).
"""

from __future__ import annotations

import asyncio
import dataclasses
import gzip
import hmac
import http
import http.cookies
import logging
import threading
import urllib.parse
import warnings
from dataclasses import dataclass
from typing import Any

from controller.transport import is_loopback_host
from host.errors import HostError
from host.http_headers import header_problem

__all__ = ["PAGE_TITLE", "GuardStats", "PanelGuard", "request_token", "retitle_page", "start_guarded_server"]

_log = logging.getLogger(__name__)

COOKIE_PREFIX = "spirob_token_"
"""Cookie name prefix; the panel's port follows, so two hosts on one machine keep their own tokens."""

PAGE_TITLE = "SpiRob Teleop"
"""The browser tab's title."""
_VISER_TITLE = b"<title>Viser</title>"

_START_LOCK = threading.Lock()
"""Serialises the window in which ``websockets.asyncio.server.serve`` is wrapped (see below)."""


@dataclass(slots=True)
class GuardStats:
    """What the guard refused since start.

    Attributes:
        origin_refused_n: websocket upgrades refused for their Origin (or, on loopback, their Host).
        token_refused_n: requests refused for a missing or wrong token.
        malformed_messages_n: panel messages viser could not decode or handle (each one closes the
            connection that sent it, or is dropped).
        bad_headers_n: requests answered 400 for a duplicate or malformed ``Host`` or ``Origin``.
    """

    origin_refused_n: int = 0
    token_refused_n: int = 0
    malformed_messages_n: int = 0
    bad_headers_n: int = 0


def _host_name(host_header: str) -> str | None:
    """The host part of a ``Host`` header (``127.0.0.1:8080``, ``[::1]:8080``), lower-case."""
    try:
        return urllib.parse.urlsplit("//" + host_header).hostname
    except ValueError:
        return None


def _host_port(host_header: str) -> int | None:
    try:
        return urllib.parse.urlsplit("//" + host_header).port
    except ValueError:
        return None


def retitle_page(response: Any, cache: dict[bytes, bytes] | None = None) -> Any:
    """``response`` with viser's page title replaced by :data:`PAGE_TITLE` (other responses unchanged).

    Args:
        response: a ``websockets`` HTTP response (``status_code``, ``reason_phrase``, ``headers``,
            ``body``), its body plain or gzip-encoded.
        cache: original body -> rewritten body (viser serves the same bytes every time).
    """
    if response is None or not str(response.headers.get("Content-Type", "")).startswith("text/html"):
        return response
    body: bytes = response.body
    new = cache.get(body) if cache is not None else None
    if new is None:
        zipped = response.headers.get("Content-Encoding") == "gzip"
        try:
            page = gzip.decompress(body) if zipped else body
        except (OSError, EOFError):
            return response
        if _VISER_TITLE not in page:
            return response
        page = page.replace(_VISER_TITLE, f"<title>{PAGE_TITLE}</title>".encode(), 1)
        new = gzip.compress(page) if zipped else page
        if cache is not None:
            cache[body] = new
    if "Content-Length" in response.headers:  # ``Headers`` holds several values per name: replace, not add
        del response.headers["Content-Length"]
    response.headers["Content-Length"] = str(len(new))
    return dataclasses.replace(response, body=new)


def request_token(path: str, headers: Any) -> str | None:
    """The token a request carries: its ``token`` query parameter, else the panel's cookie.

    Args:
        path: the request path with its query.
        headers: the request headers (``websockets.datastructures.Headers``).
    """
    values = urllib.parse.parse_qs(urllib.parse.urlsplit(path).query).get("token")
    if values:
        return values[0]
    port = _host_port(str(headers.get("Host", "")))
    name = f"{COOKIE_PREFIX}{port}"
    for raw in headers.get_all("Cookie"):
        jar = http.cookies.SimpleCookie()
        try:
            jar.load(raw)
        except http.cookies.CookieError:
            continue
        if name in jar:
            return jar[name].value
    return None


class PanelGuard:
    """The handshake check of the panel's server.

    Args:
        token: the access token; None (``--no-token``) lets any same-origin page in.
        loopback: the panel binds a loopback address (then ``Host`` must name the loopback too).
    """

    def __init__(self, token: str | None, *, loopback: bool) -> None:
        self.token = token
        self.loopback = loopback
        self.stats = GuardStats()
        self.port: int | None = None
        """The server's port, once it listens (:meth:`attach`)."""
        self._lock = threading.Lock()
        self._ws_filter: logging.Filter | None = None
        self._pages: dict[bytes, bytes] = {}

    def _malformed(self, what: object) -> None:
        with self._lock:
            self.stats.malformed_messages_n += 1
            n = self.stats.malformed_messages_n
        level = logging.WARNING if n == 1 else logging.DEBUG
        _log.log(level, "malformed panel message #%d dropped: %s", n, what)

    def attach(self, server: Any) -> None:
        """Count, instead of tracing, what viser fails on in ``server``'s messages.

        ``websockets`` logs a failed connection handler on ``websockets.server`` with the connection in
        the record (``record.websocket``); the filter takes the records of this server's port only.
        Handler tasks' errors reach the server loop's exception handler (viser's private
        ``_websock_server._background_event_loop``; without it only the log filter is installed).
        """
        self.port = int(server.get_port())
        guard = self

        class _Malformed(logging.Filter):
            def filter(self, record: logging.LogRecord) -> bool:
                if record.getMessage() != "connection handler failed":
                    return True
                try:
                    port = record.websocket.local_address[1]  # type: ignore[attr-defined]
                except (AttributeError, IndexError, TypeError):
                    return True
                if port != guard.port:
                    return True
                exc = record.exc_info[1] if record.exc_info else None
                guard._malformed(f"{type(exc).__name__}: {exc}" if exc is not None else record.getMessage())
                return False

        self._ws_filter = _Malformed()
        logging.getLogger("websockets.server").addFilter(self._ws_filter)
        # viser warns (UserWarning, once per location) when a field does not match its annotation.
        warnings.filterwarnings("ignore", message=r"\[viser\] .* does not match annotation")
        loop = getattr(getattr(server, "_websock_server", None), "_background_event_loop", None)
        if isinstance(loop, asyncio.AbstractEventLoop):

            def on_error(_loop: asyncio.AbstractEventLoop, context: dict[str, Any]) -> None:
                exc = context.get("exception")
                self._malformed(f"{type(exc).__name__}: {exc}" if exc is not None else context.get("message"))

            loop.call_soon_threadsafe(loop.set_exception_handler, on_error)

    def detach(self) -> None:
        """Remove the log filter (the server is stopped); safe twice."""
        if self._ws_filter is not None:
            logging.getLogger("websockets.server").removeFilter(self._ws_filter)
            self._ws_filter = None

    def _token_ok(self, path: str, headers: Any) -> bool:
        if self.token is None:
            return True
        given = request_token(path, headers)
        return given is not None and hmac.compare_digest(given.encode(), self.token.encode())

    def _origin_ok(self, headers: Any) -> bool:
        host = str(headers.get("Host", ""))
        origin = str(headers.get("Origin", ""))
        if not host or origin.lower() != f"http://{host}".lower():
            return False
        if self.loopback:
            name = _host_name(host)
            return name is not None and is_loopback_host(name)
        return True

    def check(self, connection: Any, request: Any) -> Any:
        """Refuse (an HTTP 400 or 403 response) or let through (None) one request.

        Args:
            connection: the ``websockets`` ``ServerConnection``.
            request: its ``Request`` (path and headers).
        """
        headers = request.headers
        problem = header_problem(headers)
        if problem is not None:
            with self._lock:
                self.stats.bad_headers_n += 1
            _log.info("panel request refused (400): %s", problem)
            return connection.respond(http.HTTPStatus.BAD_REQUEST, f"bad request: {problem}\n")
        if str(headers.get("Upgrade", "")).lower() == "websocket":
            if not self._origin_ok(headers):
                with self._lock:
                    self.stats.origin_refused_n += 1
                _log.info(
                    "panel websocket refused: Origin %r is not the panel's (Host %r)",
                    headers.get("Origin"),
                    headers.get("Host"),
                )
                return connection.respond(http.HTTPStatus.FORBIDDEN, "Origin refused\n")
            if not self._token_ok(request.path, headers):
                with self._lock:
                    self.stats.token_refused_n += 1
                _log.info("panel websocket refused: no valid token")
                return connection.respond(http.HTTPStatus.FORBIDDEN, "token required\n")
            return None
        if not self._token_ok(request.path, headers):
            with self._lock:
                self.stats.token_refused_n += 1
            return connection.respond(
                http.HTTPStatus.FORBIDDEN,
                "spirob-host: open the panel with the URL printed at start (it carries ?token=...)\n",
            )
        return None

    def wrap(self, inner: Any) -> Any:
        """``process_request`` that runs :meth:`check` first, then viser's own (page files)."""

        def process_request(connection: Any, request: Any) -> Any:
            refused = self.check(connection, request)
            if refused is not None:
                return refused
            response = retitle_page(inner(connection, request) if inner is not None else None, self._pages)
            given = urllib.parse.parse_qs(urllib.parse.urlsplit(request.path).query).get("token")
            if response is not None and self.token is not None and given:
                # The page came with a valid token: the cookie takes it to the websocket, whose URL
                # viser's client builds without the page's query.
                port = _host_port(str(request.headers.get("Host", "")))
                response.headers["Set-Cookie"] = (
                    f"{COOKIE_PREFIX}{port}={self.token}; Path=/; HttpOnly; SameSite=Strict"
                )
            return response

        return process_request


def start_guarded_server(guard: PanelGuard, **viser_kwargs: Any) -> Any:
    """Start a ``viser.ViserServer`` whose every HTTP and websocket request passes ``guard`` first.

    viser hands its ``process_request`` straight to ``websockets.asyncio.server.serve`` in its server
    thread, and ``ViserServer()`` returns only once that server listens. So ``serve`` is wrapped for
    exactly that window (one server start at a time), and the guard is checked to be in place before
    anything is served: if viser ever starts its server another way, the panel fails closed.

    Args:
        guard: the handshake check.
        **viser_kwargs: ``viser.ViserServer`` arguments (host, port, label, verbose).

    Returns:
        The running ``viser.ViserServer``.

    Raises:
        HostError: the check could not be installed (then no server is left running), or viser's
            message buffer is not the one :mod:`host.panel.wakeups` repairs.
    """
    import viser
    import websockets.asyncio.server as ws_server

    from host.panel import wakeups

    wakeups.install()  # before the server's buffers exist: a sender woken from our threads never freezes
    installed: list[bool] = []
    original = ws_server.serve

    def guarded_serve(*args: Any, **kwargs: Any) -> Any:
        kwargs["process_request"] = guard.wrap(kwargs.get("process_request"))
        installed.append(True)
        return original(*args, **kwargs)

    with _START_LOCK:
        ws_server.serve = guarded_serve  # type: ignore[misc,assignment]
        try:
            server = viser.ViserServer(**viser_kwargs)
        finally:
            ws_server.serve = original  # type: ignore[misc]
    if not installed:
        server.stop()
        raise HostError("the panel's access check could not be installed in this viser version")
    guard.attach(server)
    return server
