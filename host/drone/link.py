"""The MAVLink drone link: the arm as a gripper component on the drone's MAVLink network.

:class:`DroneLink` owns one pymavlink connection (any ``mavutil.mavlink_connection`` string:
``udpout:127.0.0.1:14550``, ``udpin:...``, ``tcp:...``, a serial device) and runs it in its own thread.
It speaks as component ``compid`` (default 25) of the drone's system ``sysid`` (default 1):

- out: ``HEARTBEAT`` at 1 Hz (``MAV_TYPE_GRIPPER``, ``MAV_AUTOPILOT_INVALID``); ``NAMED_VALUE_FLOAT``
  tensions, mode, failsafe phase and grasp state, and ``ACTUATOR_OUTPUT_STATUS`` motor currents, at
  ``telemetry_rate_hz`` (10 Hz); ``STATUSTEXT`` for board events, refusals and grasp results;
- in: ``COMMAND_LONG`` or ``COMMAND_INT`` ``MAV_CMD_DO_GRIPPER`` (grab / release / hold) with the ACK
  sequence of docs/mavlink.md (``IN_PROGRESS`` then ``ACCEPTED`` / ``FAILED``; ``TEMPORARILY_REJECTED``
  while busy; ``DENIED`` for bad params or when the radio does not allow it; ``UNSUPPORTED`` for other
  commands); ``MAV_CMD_REQUEST_MESSAGE`` / ``REQUEST_PROTOCOL_VERSION`` (``host.drone.requests``);
  the parameter protocol mirroring the firmware's parameters; the drone's ``ATTITUDE`` and
  ``LOCAL_POSITION_NED`` for the panel; optionally the autopilot's gripper output in
  ``SERVO_OUTPUT_RAW`` (``host.drone.servo``), followed with grab / release on the board;
- start-up: until the first board telemetry the heartbeat says ``MAV_STATE_BOOT``; a parameter list
  asked for meanwhile is sent once the board has answered, a ``DO_GRIPPER`` waits for its telemetry
  (``early_command_wait_us``), and the first telemetry announces the arm with an immediate heartbeat;
- optional MAVLink 2 signing (unsigned or wrongly signed packets refused and counted, the signing
  timestamp persisted across restarts) and a ``.tlog`` of every packet in and out.

The board side is decoupled: the host feeds every board message to :meth:`DroneLink.on_board_message`
(thread-safe) and the link sends through ``send_to_board`` (``BoardClient.send``, as ``MAVLink``); a
gripper command's answers come back through its ``on_ack``.

This module is the connection, its thread and the dispatch; the behaviour lives beside it:
``host.drone.gripper`` (DO_GRIPPER; the radio's gate is decided on the board), ``host.drone.params``
(parameter protocol), ``host.drone.telemetry`` (heartbeat, telemetry, event texts),
``host.drone.config``, ``host.drone.state`` (snapshots for observers) and ``host.drone.tlog``.
"""

from __future__ import annotations

import contextlib
import logging
import os
import queue
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path
from types import TracebackType
from typing import Any, Final

from host.drone.config import DroneLinkConfig, DroneLinkError
from host.drone.gripper import AnswerHandler, BoardPort, GripperServer
from host.drone.params import ParamMirror
from host.drone.requests import IDENTITY_COMMANDS, answer_identity
from host.drone.servo import ServoFollower
from host.drone.state import DroneLinkCounters, DroneLinkState, DronePose, PeerInfo
from host.drone.telemetry import event_statustext, heartbeat, send_telemetry
from host.drone.tlog import TLOG_LINK_IN, TLOG_LINK_OUT, TlogWriter
from protocol import mavlink as mav
from protocol import messages as bm

__all__ = ["DroneLink"]

_US_PER_S: Final[int] = 1_000_000
_MAX_PEERS: Final[int] = 64
_BOARD_QUEUE_LEN: Final[int] = 4096
_BOARD_MSGS_PER_CYCLE: Final[int] = 512
_READS_PER_CYCLE: Final[int] = 64
_STATUSTEXT_PER_S: Final[int] = 10
_EARLY_COMMANDS_MAX: Final[int] = 4
_SIGNING_PERSIST_PERIOD_US: Final[int] = 10 * _US_PER_S
_SIGNING_RESTART_MARGIN: Final[int] = 2 * _SIGNING_PERSIST_PERIOD_US // 10
"""Added to a persisted signing timestamp on start (10 µs units): 2 persist periods' worth, far more
than the +1 per packet we can have sent after the last save."""

_log = logging.getLogger(__name__)


@dataclass(frozen=True, slots=True)
class _Answer:
    """A board answer to one of our commands, queued for the link thread."""

    handler: AnswerHandler
    ack: bm.CommandAck | None


def _now_us() -> int:
    return time.monotonic_ns() // 1000


def _wall_us() -> int:
    return time.time_ns() // 1000


@dataclass
class _Peer:
    sysid: int
    compid: int
    mav_type: int | None = None
    autopilot: int | None = None
    packets: int = 0
    window_start_packets: int = 0
    rate_hz: float = 0.0
    last_seen_us: int = 0
    signed: bool = False


class DroneLink:
    """The arm's MAVLink component: one connection, one thread, bounded work per cycle.

    Args:
        config: Link configuration.
        send_to_board: Called (from the link thread) with each ``protocol.messages`` message for the
            board (``Command``, ``ParamRequest``, ``ParamSet``); routes a command's answers to its
            ``on_ack`` (see :class:`BoardPort`). Must not block for long.
        clock_us: Monotonic clock in µs (injectable for tests).
        wall_clock_us: Unix time in µs, for ``.tlog`` stamps and signing timestamps.
        connect: Opens the connection (injectable); default ``mavutil.mavlink_connection``.

    Use as a context manager, or call :meth:`start` and :meth:`close`.
    """

    def __init__(
        self,
        config: DroneLinkConfig,
        send_to_board: BoardPort,
        *,
        clock_us: Callable[[], int] = _now_us,
        wall_clock_us: Callable[[], int] = _wall_us,
        connect: Callable[[DroneLinkConfig], Any] | None = None,
    ) -> None:
        self.config = config
        self._send_to_board = send_to_board
        self._clock = clock_us
        self._wall = wall_clock_us
        self._connect = connect or _mavutil_connect
        self._codec = mav.MavCodec(config.sysid, config.compid)
        self._datagram = config.url.split(":", 1)[0].lower() in {"udp", "udpin", "udpout", "udpbcast"}
        self._conn: Any = None
        self._tlog: TlogWriter | None = None
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        self._lock = threading.RLock()  # RLock: send_to_board may call back into the link
        self._board_q: queue.Queue[bm.Message | _Answer] = queue.Queue(maxsize=_BOARD_QUEUE_LEN)
        self._text_q: queue.Queue[tuple[int, str]] = queue.Queue(maxsize=256)
        self._closed = False
        # --- state below: written by the link thread under self._lock --------------------------
        self._c: dict[str, int] = dict.fromkeys(DroneLinkCounters.__dataclass_fields__, 0)
        self._peers: dict[tuple[int, int], _Peer] = {}
        self._pose = DronePose()
        self._telemetry: bm.Telemetry | None = None
        self._telemetry_at_us = 0
        self._gripper = GripperServer(config, self._send, self._board_command, self._text, self._count)
        self._params = ParamMirror(
            config.param_confirm_timeout_us, self._send, self._board, self._text, self._count, clock_us
        )
        self._follower = ServoFollower(config.servo_follow) if config.servo_follow is not None else None
        self._follow_pending: mav.GripperAction | None = None
        self._early: list[tuple[mav.CommandLong, tuple[int, int], int]] = []  # before any telemetry
        self._announce = False
        self._text_id = 0
        self._text_budget = _STATUSTEXT_PER_S
        self._rx_rate_hz = 0.0
        self._tx_rate_hz = 0.0
        self._rate_window = (0, 0, 0)  # start time, packets_in, packets_out

    # ---- lifecycle -------------------------------------------------------------------------------

    def start(self) -> None:
        """Open the connection (and the ``.tlog``), set up signing and start the link thread.

        Raises:
            DroneLinkError: The connection or the log cannot be opened, or the link was closed.
        """
        if self._closed:
            raise DroneLinkError("DroneLink was closed; create a new one")
        if self._thread is not None:
            return
        cfg = self.config
        if cfg.signing_key is not None:
            self._codec.enable_signing(
                cfg.signing_key, timestamp=self._initial_signing_timestamp(), link_id=cfg.signing_link_id
            )
        try:
            self._conn = self._connect(cfg)
        except Exception as exc:
            raise DroneLinkError(f"cannot open MAVLink connection {cfg.url!r}: {exc}") from exc
        if cfg.tlog_path is not None:
            try:
                self._tlog = TlogWriter(cfg.tlog_path)
            except OSError as exc:
                self._close_conn()
                raise DroneLinkError(f"cannot open tlog {cfg.tlog_path}: {exc}") from exc
        now = self._clock()
        self._rate_window = (now, 0, 0)
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, name="drone-link", daemon=True)
        self._thread.start()

    def close(self) -> None:
        """Stop the thread, persist the signing timestamp, close the log and connection (safe twice)."""
        self._closed = True
        self._stop.set()
        thread, self._thread = self._thread, None
        if thread is not None:
            thread.join(timeout=5.0)
        self._persist_signing_timestamp()
        if self._tlog is not None:
            self._tlog.close()
        self._close_conn()

    def __enter__(self) -> DroneLink:
        self.start()
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    @property
    def running(self) -> bool:
        """True while the link thread runs."""
        t = self._thread
        return t is not None and t.is_alive()

    # ---- inputs from other threads ---------------------------------------------------------------

    def on_board_message(self, msg: bm.Message) -> None:
        """Feed one board message (``Telemetry``, ``Event``, ``ParamValue``, ``CommandAck``, ...).

        Thread-safe and non-blocking; messages are handled by the link thread in order. When the
        queue is full the message is dropped and counted.

        Args:
            msg: A decoded board-link message.
        """
        self._enqueue(msg)

    def _enqueue(self, item: bm.Message | _Answer) -> None:
        try:
            self._board_q.put_nowait(item)
        except queue.Full:
            with self._lock:
                self._c["board_queue_dropped"] += 1

    def send_statustext(self, text: str, severity: int = mav.Severity.INFO) -> None:
        """Queue a ``STATUSTEXT`` (thread-safe; long texts are chunked; rate limited).

        Args:
            text: The message.
            severity: ``MAV_SEVERITY``.
        """
        try:
            self._text_q.put_nowait((int(severity), text))
        except queue.Full:
            with self._lock:
                self._c["statustext_dropped"] += 1

    # ---- observers ----------------------------------------------------------------------------

    def state(self) -> DroneLinkState:
        """A consistent snapshot of the link state for the panel (thread-safe)."""
        with self._lock:
            now = self._clock()
            peers = tuple(
                PeerInfo(
                    p.sysid,
                    p.compid,
                    p.mav_type,
                    p.autopilot,
                    p.packets,
                    p.rate_hz,
                    p.last_seen_us,
                    now - p.last_seen_us <= self.config.peer_timeout_us,
                    p.signed,
                )
                for _, p in sorted(self._peers.items())
            )
            return DroneLinkState(
                running=self.running,
                url=self.config.url,
                sysid=self.config.sysid,
                compid=self.config.compid,
                signing=self._codec.signing_enabled,
                peers=peers,
                drone=self._pose,
                last_command=self._gripper.last_command,
                gripper_busy=self._gripper.busy,
                rx_rate_hz=self._rx_rate_hz,
                tx_rate_hz=self._tx_rate_hz,
                params_known=self._params.known,
                counters=self._counters_locked(),
            )

    @property
    def counters(self) -> DroneLinkCounters:
        """Traffic and error counters (thread-safe snapshot)."""
        with self._lock:
            return self._counters_locked()

    @property
    def signature_refusals(self) -> dict[int, int]:
        """Packets refused by signing, by MAVLink message id (thread-safe copy)."""
        with self._lock:
            return dict(self._codec.refused_by_msg_id)

    @property
    def drone_pose(self) -> DronePose:
        """Latest drone attitude and position."""
        with self._lock:
            return self._pose

    @property
    def params_bytewise(self) -> bool:
        """Integer parameters are encoded bytewise (else by C cast, with an ArduPilot autopilot)."""
        with self._lock:
            return self._params.bytewise

    @property
    def servo_reading(self) -> mav.GripperAction | None:
        """The followed autopilot output's reading (None: no follower, no report yet, or stale)."""
        with self._lock:
            return self._follower.reading if self._follower is not None else None

    @property
    def signing_timestamp(self) -> int:
        """Current outgoing signing timestamp (10 µs units since 2015; 0 without signing)."""
        with self._lock:
            return self._codec.signing_timestamp if self._codec.signing_enabled else 0

    def _counters_locked(self) -> DroneLinkCounters:
        c = dict(self._c)
        codec = self._codec
        c.update(
            packets_in=codec.packets_in,
            packets_out=codec.packets_out,
            bytes_in=codec.bytes_in,
            malformed=codec.malformed,
            unknown_msg_id=codec.unknown_ids,
            signature_refused=codec.signature_refused,
            tlog_records=self._tlog.records if self._tlog is not None else 0,
        )
        return DroneLinkCounters(**c)

    # ---- the thread ----------------------------------------------------------------------------

    def _run(self) -> None:
        cfg = self.config
        now = self._clock()
        next_hb = now
        next_tel = now + cfg.telemetry_period_us
        next_second = now + _US_PER_S
        next_persist = now + _SIGNING_PERSIST_PERIOD_US
        with self._lock:
            if self._params.count is None:
                self._params.ask_board_for_all(now)
        wait_s = cfg.poll_period_us / _US_PER_S
        while not self._stop.is_set():
            # Read outside the lock: a stream transport may block while it reconnects, and the
            # panel's state() must not wait for that.
            chunks, read_errors = self._recv_chunks()
            with self._lock:
                try:
                    self._c["io_errors"] += read_errors
                    self._drain_board()
                    for chunk in chunks:
                        self._on_bytes(chunk)
                    self._drain_texts()
                    now = self._clock()
                    if self._announce:  # the board has answered: tell the drone at once
                        self._announce = False
                        next_hb = now
                    if now >= next_hb:
                        next_hb = _next_deadline(next_hb, cfg.heartbeat_period_us, now)
                        self._send(
                            heartbeat(self._telemetry, now - self._telemetry_at_us, cfg.board_stale_us)
                        )
                    if now >= next_tel:
                        next_tel = _next_deadline(next_tel, cfg.telemetry_period_us, now)
                        self._send_telemetry(now)
                    self._params.send_due()
                    self._check_timeouts(now)
                    if now >= next_second:
                        next_second = _next_deadline(next_second, _US_PER_S, now)
                        self._every_second(now)
                    if now >= next_persist:
                        next_persist = now + _SIGNING_PERSIST_PERIOD_US
                        self._codec.advance_signing_timestamp(
                            mav.signing_timestamp_from_unix_us(self._wall())
                        )
                        self._persist_signing_timestamp()
                except Exception:  # a bug must not silence the drone link: count, log, carry on
                    self._c["internal_errors"] += 1
                    if self._c["internal_errors"] <= 10:
                        _log.exception("drone link cycle failed")
            self._wait(wait_s)

    def _wait(self, timeout_s: float) -> None:
        conn = self._conn
        try:
            if conn is not None and getattr(conn, "fd", None) is not None:
                conn.select(timeout_s)
            else:
                self._stop.wait(timeout_s)
        except (OSError, ValueError):
            self._stop.wait(timeout_s)

    # ---- I/O -----------------------------------------------------------------------------------

    def _recv_chunks(self) -> tuple[list[bytes], int]:
        """Whatever the connection has (at most 64 reads), and how many reads failed."""
        chunks: list[bytes] = []
        conn = self._conn
        if conn is None:
            return chunks, 0
        for _ in range(_READS_PER_CYCLE):
            try:
                data = conn.recv(4096)
            except Exception:  # socket reset, serial unplugged: count, keep the thread alive
                return chunks, 1
            if not data:
                break
            chunks.append(data.encode("latin-1") if isinstance(data, str) else bytes(data))
        return chunks, 0

    def _on_bytes(self, data: bytes) -> None:
        packets = self._codec.feed(data)
        if self._datagram:
            self._codec.discard_partial()
        for pkt in packets:
            self._on_packet(pkt)

    def _send(self, msg: mav.MavMessage) -> None:
        try:
            data = self._codec.encode(msg)
        except (ValueError, TypeError):  # a value we cannot put on the wire: count, never crash the link
            self._c["io_errors"] += 1
            return
        try:
            self._conn.write(data)
        except Exception:
            self._c["io_errors"] += 1
            return
        self._c["bytes_out"] += len(data)
        if self._tlog is not None:
            self._tlog.write(data, self._wall(), TLOG_LINK_OUT)

    def _count(self, name: str) -> None:
        self._c[name] += 1

    def _board(self, msg: bm.Message) -> None:
        try:
            self._send_to_board(msg, origin="MAVLink")
        except Exception:
            self._c["io_errors"] += 1

    def _board_command(self, cmd: bm.Command, on_answer: AnswerHandler) -> bool:
        """Send a command whose answers ``on_answer`` gets on the link thread; False if it did not go."""

        def deliver(ack: bm.CommandAck | None) -> None:  # on the board client's thread: queued, in order
            self._enqueue(_Answer(on_answer, ack))

        try:
            return bool(self._send_to_board(cmd, origin="MAVLink", on_ack=deliver))
        except Exception:
            self._c["io_errors"] += 1
            return False

    def _close_conn(self) -> None:
        conn, self._conn = self._conn, None
        if conn is not None:
            with contextlib.suppress(Exception):
                conn.close()

    # ---- signing persistence -------------------------------------------------------------------

    def _initial_signing_timestamp(self) -> int:
        ts = mav.signing_timestamp_from_unix_us(self._wall())
        path = self.config.signing_timestamp_path
        if path is not None:
            with contextlib.suppress(OSError, ValueError):
                saved = int(Path(path).read_text(encoding="ascii").strip())
                ts = max(ts, saved + _SIGNING_RESTART_MARGIN)
        return ts

    def _persist_signing_timestamp(self) -> None:
        path = self.config.signing_timestamp_path
        if path is None or not self._codec.signing_enabled:
            return
        path = Path(path)
        tmp = path.with_name(path.name + ".tmp")
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            tmp.write_text(f"{self._codec.signing_timestamp}\n", encoding="ascii")
            os.replace(tmp, path)
        except OSError:
            self._c["io_errors"] += 1

    # ---- incoming MAVLink ----------------------------------------------------------------------

    def _on_packet(self, pkt: mav.MavPacket) -> None:
        now = self._clock()
        if self._tlog is not None:
            self._tlog.write(pkt.raw, self._wall(), TLOG_LINK_IN)
        key = (pkt.src_system, pkt.src_component)
        if key == (self.config.sysid, self.config.compid):
            self._c["own_id_conflicts"] += 1
            return
        self._note_peer(key, pkt, now)
        msg = pkt.msg
        if isinstance(msg, mav.CommandInt):
            # COMMAND_INT carries the same commands (x, y as integers): handled as COMMAND_LONG.
            msg = msg.as_long()
        if isinstance(msg, mav.CommandLong):
            if self._for_us(msg.target_system, msg.target_component):
                self._on_command(msg, key, now)
        elif isinstance(msg, mav.ServoOutputRaw) and self._from_autopilot(key):
            self._on_servo_output(msg, now)
        elif isinstance(msg, mav.Heartbeat) and self._from_autopilot(key):
            # Integer parameters are encoded as the drone's autopilot does, the way ground stations
            # decode that system's parameters (C cast for ArduPilot, bytewise otherwise).
            self._params.bytewise = msg.autopilot != mav.MAV_AUTOPILOT_ARDUPILOTMEGA
        elif isinstance(msg, mav.ParamRequestList):
            if self._for_us(msg.target_system, msg.target_component):
                self._params.on_request_list(now)
        elif isinstance(msg, mav.ParamRequestRead):
            if self._for_us(msg.target_system, msg.target_component):
                self._params.on_request_read(msg)
        elif isinstance(msg, mav.ParamSet):
            if self._for_us(msg.target_system, msg.target_component):
                self._params.on_set(msg, now)
        elif isinstance(msg, mav.Attitude) and self._from_autopilot(key):
            self._pose = replace(self._pose, attitude=msg, attitude_time_us=now)
        elif isinstance(msg, mav.LocalPositionNed) and self._from_autopilot(key):
            self._pose = replace(self._pose, position=msg, position_time_us=now)
        elif not isinstance(msg, mav.Heartbeat):
            self._c["unexpected"] += 1

    def _on_command(self, cmd: mav.CommandLong, key: tuple[int, int], now: int) -> None:
        if cmd.command in IDENTITY_COMMANDS:
            hb = heartbeat(self._telemetry, now - self._telemetry_at_us, self.config.board_stale_us)
            result, reply = answer_identity(cmd, hb, bytewise=self._params.bytewise)
            self._send(mav.CommandAck(cmd.command, int(result), 0, 0, key[0], key[1]))
            if reply is not None:
                self._send(reply)
            return
        if cmd.command == mav.MAV_CMD_DO_GRIPPER and self._telemetry is None:
            # The board has not answered yet (start-up): the command waits for its first telemetry.
            self._early = [e for e in self._early if e[1] != key][-(_EARLY_COMMANDS_MAX - 1) :]
            self._early.append((cmd, key, now + self.config.early_command_wait_us))
            return
        self._gripper.on_command(cmd, key, now, self._telemetry, self._telemetry_at_us)

    def _serve_early(self, now: int) -> None:
        """Answer the commands that arrived before the board: served now, or rejected when too old."""
        early, self._early = self._early, []
        for cmd, key, deadline in early:
            if self._telemetry is not None and now <= deadline:
                self._gripper.on_command(cmd, key, now, self._telemetry, self._telemetry_at_us)
            elif now > deadline:
                result = mav.MavResult.TEMPORARILY_REJECTED
                self._send(mav.CommandAck(cmd.command, int(result), 0, 0, key[0], key[1]))
            else:
                self._early.append((cmd, key, deadline))

    def _on_servo_output(self, msg: mav.ServoOutputRaw, now: int) -> None:
        if self._follower is None:
            self._c["unexpected"] += 1
            return
        action = self._follower.on_servo_output(msg, now)
        if action is not None:
            self._follow_pending = action
            self._follow(now)

    def _follow(self, now: int) -> None:
        """Ask the gripper for the follower's latest change; kept only while the gripper is busy."""
        action = self._follow_pending
        if action is None:
            return
        result = self._gripper.request(action, now, self._telemetry, self._telemetry_at_us)
        if result != mav.MavResult.TEMPORARILY_REJECTED:
            # Done, started or refused by the radio: a refusal is never carried out later.
            self._follow_pending = None

    def _note_peer(self, key: tuple[int, int], pkt: mav.MavPacket, now: int) -> None:
        peer = self._peers.get(key)
        if peer is None:
            if len(self._peers) >= _MAX_PEERS:
                return
            peer = self._peers[key] = _Peer(*key)
        peer.packets += 1
        peer.last_seen_us = now
        peer.signed = pkt.signed
        if isinstance(pkt.msg, mav.Heartbeat):
            peer.mav_type = pkt.msg.mav_type
            peer.autopilot = pkt.msg.autopilot

    def _for_us(self, target_system: int, target_component: int) -> bool:
        cfg = self.config
        ok = target_system in (0, cfg.sysid) and target_component in (mav.MAV_COMP_ID_ALL, cfg.compid)
        if not ok:
            self._c["not_for_us"] += 1
        return ok

    def _from_autopilot(self, key: tuple[int, int]) -> bool:
        return key == (self.config.sysid, self.config.autopilot_compid)

    # ---- board messages ------------------------------------------------------------------------

    def _drain_board(self) -> None:
        now = self._clock()
        for _ in range(_BOARD_MSGS_PER_CYCLE):
            try:
                msg = self._board_q.get_nowait()
            except queue.Empty:
                return
            if isinstance(msg, _Answer):
                msg.handler(msg.ack, now)
            elif isinstance(msg, bm.Telemetry):
                if self._telemetry is None:
                    self._announce = True
                self._telemetry = msg
                self._telemetry_at_us = now
                self._gripper.on_telemetry(msg, now)
            elif isinstance(msg, bm.ParamValue):
                self._params.on_board_param(msg)
            elif isinstance(msg, bm.Event):
                self._text(*event_statustext(msg))
            elif not isinstance(msg, bm.CommandAck):  # answers to our commands come as _Answer
                self._c["board_unexpected"] += 1

    # ---- periodic ------------------------------------------------------------------------------

    def _send_telemetry(self, now: int) -> None:
        tel = self._telemetry
        if tel is None or now - self._telemetry_at_us > self.config.board_stale_us:
            return
        send_telemetry(tel, self._send)

    def _check_timeouts(self, now: int) -> None:
        self._gripper.check_timeout(now)
        self._params.check_timeouts(now)
        if self._early and (self._telemetry is not None or now > min(e[2] for e in self._early)):
            self._serve_early(now)
        follower = self._follower
        if follower is not None:
            if follower.check_stale(now):
                self._follow_pending = None
                out = follower.config.output_n
                self._text(mav.Severity.WARNING, f"servo follower: output {out} not reported, no command")
            self._follow(now)

    def _every_second(self, now: int) -> None:
        self._text_budget = _STATUSTEXT_PER_S
        t0, in0, out0 = self._rate_window
        dt_s = max(now - t0, 1) / _US_PER_S
        self._rx_rate_hz = (self._codec.packets_in - in0) / dt_s
        self._tx_rate_hz = (self._codec.packets_out - out0) / dt_s
        self._rate_window = (now, self._codec.packets_in, self._codec.packets_out)
        for peer in self._peers.values():
            peer.rate_hz = (peer.packets - peer.window_start_packets) / dt_s
            peer.window_start_packets = peer.packets
        if self._tlog is not None:
            with contextlib.suppress(OSError):
                self._tlog.flush()

    # ---- STATUSTEXT ----------------------------------------------------------------------------

    def _drain_texts(self) -> None:
        for _ in range(16):
            try:
                severity, text = self._text_q.get_nowait()
            except queue.Empty:
                return
            self._text(severity, text)

    def _text(self, severity: int, text: str) -> None:
        if self._text_budget <= 0:
            self._c["statustext_dropped"] += 1
            return
        self._text_budget -= 1
        self._text_id = self._text_id % 0xFFFF + 1
        for chunk in mav.statustext_chunks(severity, text, self._text_id)[:8]:
            self._send(chunk)


def _next_deadline(previous_us: int, period_us: int, now_us: int) -> int:
    """The next periodic deadline; missed ones are skipped, never sent in a burst."""
    nxt = previous_us + period_us
    return nxt if nxt > now_us else now_us + period_us


def _mavutil_connect(cfg: DroneLinkConfig) -> Any:
    # Imported here, after protocol.mavlink has forced MAVLINK20=1 (import order matters, see there).
    from pymavlink import mavutil

    return mavutil.mavlink_connection(
        cfg.url, baud=cfg.baud, source_system=cfg.sysid, source_component=cfg.compid, autoreconnect=True
    )
