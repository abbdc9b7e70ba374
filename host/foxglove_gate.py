"""Who may read the live Foxglove view: an Origin check in front of foxglove-sdk's WebSocket server.

A browser lets any page open a websocket to 127.0.0.1, and the SDK's server (``foxglove.start_server``,
foxglove-sdk 0.30) serves anyone: it has no hook on the handshake (no Origin check, no verify callback;
its ``ServerListener`` hears subscriptions, with no way to refuse the client). An ``Origin:
http://evil.example`` socket got 453 messages in 3 s. So the port the user names is served by
:class:`FoxgloveGate`, which reads each connection's HTTP upgrade request and decides:

- no ``Origin`` header (Foxglove's desktop app, scripts): let through;
- an ``Origin`` the user named (``--foxglove-origin https://app.foxglove.dev``, Foxglove's web app): let
  through;
- any other ``Origin`` (another site, another port, ``null`` from ``file://``): 403, counted
  (:attr:`GateStats.origin_refused_n`), one info line;
- two ``Host`` or ``Origin`` headers or a malformed one (``host.http_headers.header_problem``): 400,
  counted, one line; a request head over 16 KiB or not complete within 5 s: closed.

A connection let through is relayed byte for byte to the SDK's server, which listens on another loopback
port with TLS only, under a certificate made for this run (:func:`self_signed_tls`) that the gate pins: a
page that finds that port cannot complete a TLS handshake its browser does not trust, and a plain
``ws://`` there fails. The Foxglove protocol itself is untouched (the SDK speaks it to the app).
"""

from __future__ import annotations

import asyncio
import contextlib
import datetime
import http
import logging
import socket
import ssl
import threading
from dataclasses import dataclass
from typing import Final

from host.errors import HostError
from host.http_headers import header_problem, normalise_origin

__all__ = ["FoxgloveGate", "GateStats", "self_signed_tls"]

_log = logging.getLogger(__name__)

MAX_HEAD_BYTES: Final = 16 * 1024
"""The largest HTTP request head the gate reads."""
HEAD_TIMEOUT_S: Final = 5.0
"""How long a connection may take to send its request head."""
_CHUNK = 65536


def self_signed_tls() -> tuple[bytes, bytes, bytes]:
    """A key and a self-signed certificate for this run's backend: (certificate PEM, PKCS#8 key PEM,
    certificate DER, which the gate pins). EC P-256, valid from five minutes ago for two days.

    Raises:
        HostError: the ``cryptography`` package is missing.
    """
    try:
        from cryptography import x509
        from cryptography.hazmat.primitives import hashes, serialization
        from cryptography.hazmat.primitives.asymmetric import ec
        from cryptography.x509.oid import NameOID
    except ImportError as exc:  # an environment set up before the dependency: one line, not a traceback
        raise HostError("--foxglove needs the cryptography package (pip install -e . installs it)") from exc

    key = ec.generate_private_key(ec.SECP256R1())
    name = x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, "spirob-host Foxglove backend")])
    now = datetime.datetime.now(datetime.UTC)
    cert = (
        x509.CertificateBuilder()
        .subject_name(name)
        .issuer_name(name)
        .public_key(key.public_key())
        .serial_number(x509.random_serial_number())
        .not_valid_before(now - datetime.timedelta(minutes=5))
        .not_valid_after(now + datetime.timedelta(days=2))
        .sign(key, hashes.SHA256())
    )
    pem = cert.public_bytes(serialization.Encoding.PEM)
    key_pem = key.private_bytes(
        serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8, serialization.NoEncryption()
    )
    return pem, key_pem, cert.public_bytes(serialization.Encoding.DER)


class _Headers:
    """Request headers as ``header_problem`` reads them (``get_all``, case-insensitive)."""

    def __init__(self, pairs: list[tuple[str, str]]) -> None:
        self._pairs = pairs

    def get_all(self, name: str) -> list[str]:
        key = name.lower()
        return [v for k, v in self._pairs if k.lower() == key]


def _parse_head(head: bytes) -> _Headers | None:
    """The headers of an HTTP request head (None: not one)."""
    lines = head.decode("latin-1").split("\r\n")  # HTTP's header bytes: latin-1 decodes every one
    if len(lines[0].split(" ")) != 3:
        return None
    pairs: list[tuple[str, str]] = []
    for line in lines[1:]:
        if not line:
            continue
        name, sep, value = line.partition(":")
        if not sep or not name or name != name.strip():
            return None
        pairs.append((name, value.strip()))
    return _Headers(pairs)


@dataclass(slots=True)
class GateStats:
    """What the gate did since start.

    Attributes:
        accepted_n: connections relayed to the server.
        origin_refused_n: connections refused for their ``Origin`` (403).
        bad_headers_n: requests refused for duplicate or malformed ``Host`` / ``Origin``, or no HTTP
            request head at all (400).
    """

    accepted_n: int = 0
    origin_refused_n: int = 0
    bad_headers_n: int = 0


class FoxgloveGate:
    """Listens on ``host:port``, checks each handshake, relays what it lets through to the backend.

    Runs its own asyncio loop in a thread (TLS to the backend needs one thread per SSL object, which
    asyncio gives). :meth:`close` is safe twice.

    Args:
        host: the address to listen on (loopback).
        port: the port (0: any free one; :attr:`port` says which).
        backend_port: the SDK server's port on ``host`` (TLS).
        backend_der: the backend's certificate (DER), pinned.
        origins: the origins let through besides none (``host.http_headers.normalise_origin`` forms).

    Raises:
        HostError: the port cannot be bound (one line).
    """

    def __init__(
        self, host: str, port: int, backend_port: int, backend_der: bytes, origins: tuple[str, ...] = ()
    ) -> None:
        self.host = host
        self.origins = frozenset(normalise_origin(o) for o in origins)
        self.stats = GateStats()
        self._backend_port = backend_port
        self._der = backend_der
        self._tls = ssl.SSLContext(ssl.PROTOCOL_TLS_CLIENT)
        self._tls.check_hostname = False
        self._tls.verify_mode = ssl.CERT_NONE  # pinned instead: the certificate is this run's own
        self._lock = threading.Lock()
        self._writers: set[asyncio.StreamWriter] = set()
        try:
            self._listener = socket.create_server((host, port))
        except OSError as exc:
            raise HostError(f"--foxglove: cannot serve on {host}:{port}: {exc.strerror or exc}") from exc
        self.port = int(self._listener.getsockname()[1])
        self._loop = asyncio.new_event_loop()
        self._server: asyncio.Server | None = None
        started = threading.Event()
        self._thread = threading.Thread(target=self._run, args=(started,), name="foxglove-gate", daemon=True)
        self._thread.start()
        started.wait(5.0)

    def _run(self, started: threading.Event) -> None:
        asyncio.set_event_loop(self._loop)

        async def serve() -> None:
            self._server = await asyncio.start_server(self._serve, sock=self._listener, limit=MAX_HEAD_BYTES)
            started.set()

        self._loop.run_until_complete(serve())
        self._loop.run_forever()
        self._loop.close()

    # ---------------------------------------------------------------- decisions

    def decide(self, head: bytes) -> tuple[http.HTTPStatus, str] | None:
        """The answer to a request head: a refusal (status, reason) or None (let through); counted."""
        headers = _parse_head(head)
        problem = "not an HTTP request" if headers is None else header_problem(headers)
        if problem is not None or headers is None:
            with self._lock:
                self.stats.bad_headers_n += 1
            _log.info("Foxglove live: refused (400): %s", problem)
            return http.HTTPStatus.BAD_REQUEST, f"bad request: {problem}"
        origins = headers.get_all("Origin")
        if origins and origins[0].rstrip("/").lower() not in self.origins:
            with self._lock:
                self.stats.origin_refused_n += 1
            _log.info(
                "Foxglove live: refused a connection from Origin %r (name it with --foxglove-origin)",
                origins[0][:120],
            )
            return http.HTTPStatus.FORBIDDEN, "Origin refused"
        with self._lock:
            self.stats.accepted_n += 1
        return None

    # ---------------------------------------------------------------- connections

    async def _serve(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        self._writers.add(writer)
        backend: asyncio.StreamWriter | None = None
        try:
            try:
                head = await asyncio.wait_for(reader.readuntil(b"\r\n\r\n"), HEAD_TIMEOUT_S)
            except asyncio.LimitOverrunError:
                with self._lock:
                    self.stats.bad_headers_n += 1
                _log.info("Foxglove live: refused (400): a request head over %d bytes", MAX_HEAD_BYTES)
                return
            except (TimeoutError, asyncio.IncompleteReadError):
                return
            refusal = self.decide(head[:-4])
            if refusal is not None:
                status, reason = refusal
                body = f"{reason}\n".encode()
                writer.write(
                    f"HTTP/1.1 {status.value} {status.phrase}\r\nContent-Type: text/plain\r\n"
                    f"Content-Length: {len(body)}\r\nConnection: close\r\n\r\n".encode()
                    + body
                )
                await writer.drain()
                return
            b_reader, backend = await asyncio.open_connection(
                self.host, self._backend_port, ssl=self._tls, server_hostname=self.host
            )
            self._writers.add(backend)
            tls = backend.get_extra_info("ssl_object")
            if tls is None or tls.getpeercert(binary_form=True) != self._der:
                _log.warning("Foxglove live: the backend's certificate is not this run's: dropped")
                return
            backend.write(head)
            await asyncio.gather(_pump(reader, backend), _pump(b_reader, writer))
        except (OSError, ssl.SSLError):
            pass  # a client or the server went away
        finally:
            for w in (writer, backend):
                if w is not None:
                    self._writers.discard(w)
                    w.close()

    def close(self) -> None:
        """Stop listening and drop every relayed connection; safe twice."""
        if self._loop.is_closed() or not self._thread.is_alive():
            return

        async def shut() -> None:
            if self._server is not None:
                self._server.close()
            for w in list(self._writers):
                w.close()
            self._writers.clear()
            self._loop.stop()

        with contextlib.suppress(RuntimeError):
            self._loop.call_soon_threadsafe(lambda: self._loop.create_task(shut()))
        self._thread.join(timeout=5.0)


async def _pump(src: asyncio.StreamReader, dst: asyncio.StreamWriter) -> None:
    """Copy ``src`` to ``dst`` until ``src`` ends, then close ``dst``."""
    try:
        while data := await src.read(_CHUNK):
            dst.write(data)
            await dst.drain()
    except (OSError, ssl.SSLError):
        pass
    finally:
        dst.close()
