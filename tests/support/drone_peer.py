"""A pymavlink ground station (or autopilot) peer and a drone-link test rig with a fake board.

The peer listens on ``udpin:127.0.0.1:PORT``; the link connects with ``udpout``. Every wait is
bounded; nothing asserts how long anything took. :class:`GripperBoard` puts the fake board behind what
the drone link sends to (``BoardClient.send``): each grasp command's answers routed back to its sender
as the firmware gives them (``IN_PROGRESS``, then the final one).
"""

from __future__ import annotations

import socket
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from pymavlink import mavutil

from controller.grasp import grasp_refusal
from host.drone.config import DroneLinkConfig
from host.drone.link import DroneLink
from protocol import mavlink as mav
from protocol import messages as bm
from tests.support.fake_board import FakeBoard

R = mav.MavResult
WAIT_S = 5.0


def free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


AckHandler = Callable[[bm.CommandAck | None], None]
_GRASP_CODES = (bm.CommandCode.GRASP, bm.CommandCode.RELEASE, bm.CommandCode.HOLD)


class GripperBoard:
    """A :class:`FakeBoard` as the drone link's ``send_to_board``, answering grasp commands like the
    firmware's command server does (``controller.commands``: the radio's rule ``grasp_refusal``,
    ``IN_PROGRESS`` and the final ``GraspAcks``), each answer to the command's ``on_ack``.

    Only the fake's public face is used: its state fields, its own command handling and telemetry.
    """

    def __init__(self, board: FakeBoard) -> None:
        self.board = board
        self.origins: list[str] = []
        self._lock = threading.Lock()
        self._owed: dict[bm.CommandCode, AckHandler] = {}
        self._sink: Callable[[bm.Message], None] | None = None
        self.up = threading.Event()
        """Set: commands reach the board (clear it for a board that is not there yet)."""
        self.up.set()

    def attach(self, sink: Callable[[bm.Message], None]) -> None:
        """Where board -> host messages go (``DroneLink.on_board_message``)."""
        self._sink = sink
        self.board.attach(self._from_board)

    def __call__(self, msg: bm.Message, *, origin: str = "host", on_ack: AckHandler | None = None) -> bool:
        self.origins.append(origin)
        if not self.up.is_set():
            return True  # lost on the way (a board that is not up yet)
        b = self.board
        if not (isinstance(msg, bm.Command) and msg.code in _GRASP_CODES):
            b(msg)
            return True
        code = bm.CommandCode(msg.code)
        why = grasp_refusal(b.phase, b.armed, b.mode)
        before = b.grasp_state
        b(msg)  # the fake's own grasp state machine
        after = b.grasp_state
        if why is not None:
            answer = bm.CommandAck(code, bm.AckResult.REJECTED, 0, why)
        elif code == bm.CommandCode.HOLD:
            ok = after == bm.GraspState.HOLD
            text = "holding" if ok else f"cannot hold in {before.name}"
            answer = bm.CommandAck(code, bm.AckResult.ACCEPTED if ok else bm.AckResult.REJECTED, 0, text)
        elif code == bm.CommandCode.RELEASE and before == bm.GraspState.IDLE:
            answer = bm.CommandAck(code, bm.AckResult.ACCEPTED, 0, "idle")
        elif after == before or (code == bm.CommandCode.GRASP and before == bm.GraspState.HOLD):
            answer = bm.CommandAck(code, bm.AckResult.REJECTED, 0, "grasp already running")
        else:
            answer = bm.CommandAck(code, bm.AckResult.IN_PROGRESS, 0, "")
            if on_ack is not None:
                with self._lock:
                    self._owed[code] = on_ack
        if on_ack is not None:
            on_ack(answer)
        return True

    def _from_board(self, msg: bm.Message) -> None:
        if isinstance(msg, bm.Telemetry):
            for handler, ack in self._finals(msg):
                handler(ack)
        if self._sink is not None:
            self._sink(msg)

    def _finals(self, t: bm.Telemetry) -> list[tuple[AckHandler, bm.CommandAck]]:
        """The final answers this telemetry settles (the firmware's ``GraspAcks``)."""
        out: list[tuple[AckHandler, bm.CommandAck]] = []
        why = grasp_refusal(t.phase, bool(t.flags & bm.TelemetryFlags.ARMED), t.mode)
        state = bm.GraspState(t.grasp_state)
        with self._lock:
            for code, handler in list(self._owed.items()):
                if why is not None:
                    result, text = bm.AckResult.FAILED, why
                elif code == bm.CommandCode.GRASP and state == bm.GraspState.HOLD:
                    result, text = bm.AckResult.ACCEPTED, "holding"
                elif code == bm.CommandCode.GRASP and state in (bm.GraspState.FAILED, bm.GraspState.RELEASE):
                    result, text = bm.AckResult.FAILED, f"grasp {state.name}"
                elif code == bm.CommandCode.RELEASE and state == bm.GraspState.IDLE:
                    result, text = bm.AckResult.ACCEPTED, "released"
                else:
                    continue
                del self._owed[code]
                out.append((handler, bm.CommandAck(code, result, 0, text)))
        return out


class Peer:
    """A ground station on udpin (pymavlink), with bounded waits."""

    def __init__(self, url: str, sysid: int = 255, compid: int = 190, key: bytes | None = None) -> None:
        self.conn = mavutil.mavlink_connection(url, source_system=sysid, source_component=compid)
        if key is not None:
            self.conn.setup_signing(key, sign_outgoing=True, link_id=2)
        self.seen: list[Any] = []

    def recv(self, pred: Callable[[Any], bool], timeout: float = WAIT_S) -> Any:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            m = self.conn.recv_match(blocking=True, timeout=0.05)
            if m is None or m.get_type() == "BAD_DATA":
                continue
            self.seen.append(m)
            if pred(m):
                return m
        types = sorted({m.get_type() for m in self.seen[-50:]})
        raise AssertionError(f"peer timed out; recent types: {types}")

    def recv_type(self, mtype: str, pred: Callable[[Any], bool] = lambda m: True) -> Any:
        return self.recv(lambda m: m.get_type() == mtype and pred(m))

    def command(
        self, command: int, p1: float = 0.0, p2: float = 0.0, *, comp: int = 25, sys_: int = 1, conf: int = 0
    ) -> None:
        self.conn.mav.command_long_send(sys_, comp, command, conf, p1, p2, 0, 0, 0, 0, 0)

    def gripper(self, action: float, *, instance: float = 25.0, comp: int = 25, conf: int = 0) -> None:
        self.command(mav.MAV_CMD_DO_GRIPPER, instance, action, comp=comp, conf=conf)

    def acks_until_final(self) -> list[Any]:
        acks = [self.recv_type("COMMAND_ACK")]
        while acks[-1].result == R.IN_PROGRESS:
            acks.append(self.recv_type("COMMAND_ACK"))
        return acks

    def statustext(self, contains: str) -> Any:
        return self.recv_type("STATUSTEXT", lambda m: contains in m.text)

    def send_raw(self, data: bytes) -> None:
        self.conn.write(data)

    def close(self) -> None:
        self.conn.close()


@dataclass
class Rig:
    link: DroneLink
    board: FakeBoard
    peer: Peer
    port: GripperBoard

    def ready(self) -> None:
        """The peer has heard the link, and the link has fresh board telemetry."""
        self.peer.recv_type("HEARTBEAT", lambda m: m.get_srcComponent() == 25)
        self.peer.recv_type("NAMED_VALUE_FLOAT")


def rig_factory(tmp_path: Path) -> Iterator[Callable[..., Rig]]:
    """The body of a ``make_rig`` fixture: ``make(**DroneLinkConfig fields)`` builds a started rig.

    ``board_params`` sets parameter values (wire names) on the fake board before the link first asks;
    ``board_state`` sets its other attributes then (``answer_param_list=False``: a board slow to list).
    """
    made: list[Rig] = []

    def make(
        *,
        start_board: bool = True,
        peer_key: bytes | None = None,
        board_params: dict[str, float] | None = None,
        board_state: dict[str, object] | None = None,
        **cfg: Any,
    ) -> Rig:
        port = free_udp_port()
        peer = Peer(f"udpin:127.0.0.1:{port}", key=peer_key)
        board = FakeBoard()
        board.params.update(board_params or {})
        board.set(**(board_state or {}))
        cfg.setdefault("tlog_path", tmp_path / f"link{len(made)}.tlog")
        to_board = GripperBoard(board)
        link = DroneLink(DroneLinkConfig(url=f"udpout:127.0.0.1:{port}", **cfg), to_board)
        to_board.attach(link.on_board_message)
        rig = Rig(link, board, peer, to_board)
        made.append(rig)
        if start_board:
            board.start()
        link.start()
        return rig

    yield make
    for rig in made:
        rig.link.close()
        rig.board.stop()
        rig.peer.close()
    assert [r.link.counters.internal_errors for r in made] == [0] * len(made)
