"""`spirob-host --foxglove [PORT]`: the recording's Foxglove channels served live on 127.0.0.1.

A :class:`FoxgloveLive` is one more listener of the board link: what it is handed goes through the same
:class:`hil.foxglove_log.FoxgloveView` a recording uses, so the live server and a ``--record`` file carry
the same topics, schemas and encodings (``/tf``, ``/arm/scene``, ``/events``, ``/telemetry``). The server
is the ``foxglove-sdk`` package's WebSocket server (Foxglove's ``foxglove.websocket.v1`` protocol), in its
own SDK context so nothing else in the process logs to it; the Foxglove app connects to
``ws://127.0.0.1:PORT``. Who may connect is decided by :class:`host.foxglove_gate.FoxgloveGate`, which
holds that port: no ``Origin`` (Foxglove's desktop app) or an origin the user named (``--foxglove-origin``),
other origins refused and counted; the SDK's server itself listens on another loopback port, TLS only,
under this run's own certificate, which only the gate trusts.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Mapping
from typing import Any, Final

import foxglove
from foxglove.messages import LogLevel

from host.errors import HostError
from host.foxglove_gate import FoxgloveGate, self_signed_tls
from host.link.source import LinkState
from protocol.messages import Message, SimPoses, Telemetry

__all__ = ["LIVE_HOST", "FoxgloveLive"]

LIVE_HOST: Final = "127.0.0.1"


class FoxgloveLive:
    """Serves the board's state to Foxglove while the host runs; a listener. :meth:`close` is safe twice.

    Args:
        port: TCP port on 127.0.0.1 (0 = any free port; :attr:`port` says which).
        metadata: the run's description; its ``design`` (JSON) sizes the arm's drawing.
        origins: browser origins let through besides none (``--foxglove-origin``).
    """

    def __init__(
        self, port: int, metadata: Mapping[str, str] | None = None, origins: tuple[str, ...] = ()
    ) -> None:
        from hil import foxglove_log

        self._fl = foxglove_log
        self._view = foxglove_log.FoxgloveView(foxglove_log.design_sizes((metadata or {}).get("design")))
        self._context = foxglove.Context()
        self._channels: dict[str, foxglove.Channel] = {}
        for topic, spec in foxglove_log.CHANNELS.items():
            schema = foxglove.Schema(
                name=spec.schema_name, encoding=spec.schema_encoding, data=spec.schema_data
            )
            self._channels[topic] = foxglove.Channel(
                topic, schema=schema, message_encoding=spec.message_encoding, context=self._context
            )
        self._lock = threading.Lock()
        self._server: Any = None
        self._requested_port = port
        self._origins = origins
        self.port = 0
        self.backend_port = 0
        """The SDK server's own port (TLS, this run's certificate): only the gate connects there."""
        self.gate: FoxgloveGate | None = None
        self.messages_logged = 0

    def start(self) -> int:
        """Start serving; returns the port.

        Raises:
            HostError: the port cannot be bound (one line).
        """
        cert, key, der = self_signed_tls()
        try:
            self._server = foxglove.start_server(
                name="spirob-host", host=LIVE_HOST, port=0, context=self._context, tls_cert=cert, tls_key=key
            )
        except Exception as exc:  # the SDK raises its own error types for a bind failure
            raise HostError(f"--foxglove: cannot start the Foxglove server on {LIVE_HOST}: {exc}") from exc
        self.backend_port = int(self._server.port)
        try:
            self.gate = FoxgloveGate(LIVE_HOST, self._requested_port, self.backend_port, der, self._origins)
        except HostError:
            self._server.stop()
            self._server = None
            raise
        self.port = self.gate.port
        return self.port

    @property
    def url(self) -> str:
        """The address the Foxglove app connects to."""
        return f"ws://{LIVE_HOST}:{self.port}"

    def _log(self, messages: list[tuple[str, bytes]], stamp_ns: int) -> None:
        for topic, data in messages:
            self._channels[topic].log(data, log_time=stamp_ns)
            self.messages_logged += 1

    def on_board_message(self, msg: Message) -> None:
        """Listener: telemetry (and the events it shows) and the simulated poses."""
        if self._server is None:
            return
        stamp_ns = time.time_ns()
        with self._lock:
            if isinstance(msg, Telemetry):
                self._log(self._view.telemetry(stamp_ns, self._fl.telemetry_json(msg)), stamp_ns)
            elif isinstance(msg, SimPoses) and msg.positions_m:
                now_us = time.monotonic_ns() // 1000
                self._log(self._view.poses(stamp_ns, now_us, msg.positions_m, msg.quats_wxyz), stamp_ns)

    def on_link_state(self, state: LinkState) -> None:
        """State listener: each change of the link's state is an event."""
        if self._server is None:
            return
        stamp_ns = time.time_ns()
        level = LogLevel.Warning if state is LinkState.DISCONNECTED else LogLevel.Info
        with self._lock:
            message = self._fl.log_message(stamp_ns, level, f"board link {state.value}")
            self._log([(self._fl.EVENTS, message)], stamp_ns)

    def close(self) -> None:
        """Stop the server and close the channels (safe twice)."""
        if self.gate is not None:
            self.gate.close()
        with self._lock:
            server, self._server = self._server, None
            if server is not None:
                server.stop()
            for channel in self._channels.values():
                channel.close()
            self._channels.clear()
