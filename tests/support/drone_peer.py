"""A pymavlink ground station (or autopilot) peer and a drone-link test rig with a fake board.

The peer listens on ``udpin:127.0.0.1:PORT``; the link connects with ``udpout``. Every wait is
bounded; nothing asserts how long anything took.
"""

from __future__ import annotations

import socket
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from pymavlink import mavutil

from host.drone.config import DroneLinkConfig
from host.drone.link import DroneLink
from protocol import mavlink as mav
from tests.support.fake_board import FakeBoard

R = mav.MavResult
WAIT_S = 5.0


def free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


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

    def ready(self) -> None:
        """The peer has heard the link, and the link has fresh board telemetry."""
        self.peer.recv_type("HEARTBEAT", lambda m: m.get_srcComponent() == 25)
        self.peer.recv_type("NAMED_VALUE_FLOAT")


def rig_factory(tmp_path: Path) -> Iterator[Callable[..., Rig]]:
    """The body of a ``make_rig`` fixture: ``make(**DroneLinkConfig fields)`` builds a started rig.

    ``board_params`` sets parameter values (wire names) on the fake board before the link first asks.
    """
    made: list[Rig] = []

    def make(
        *,
        start_board: bool = True,
        peer_key: bytes | None = None,
        board_params: dict[str, float] | None = None,
        **cfg: Any,
    ) -> Rig:
        port = free_udp_port()
        peer = Peer(f"udpin:127.0.0.1:{port}", key=peer_key)
        board = FakeBoard()
        board.params.update(board_params or {})
        cfg.setdefault("tlog_path", tmp_path / f"link{len(made)}.tlog")
        link = DroneLink(DroneLinkConfig(url=f"udpout:127.0.0.1:{port}", **cfg), board)
        board.attach(link.on_board_message)
        rig = Rig(link, board, peer)
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
