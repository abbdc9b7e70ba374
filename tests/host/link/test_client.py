"""host.link.client over real ptys and TCP sockets against a scripted fake board
(tests/support/link_peer.py)."""

from __future__ import annotations

import os
import time
from collections.abc import Callable, Iterator

import pytest

from host.link.client import BoardClient, BoardClientConfig
from host.link.process import BoardLinkError, open_port
from host.link.source import LinkState
from protocol.dbus import Lever, RcFrame
from protocol.messages import (
    Command,
    CommandAck,
    CommandCode,
    Heartbeat,
    Message,
    SimPoses,
    Telemetry,
    VirtualRc,
)
from tests.support.link_peer import LinkPeer
from tests.support.realtime_guard import wait_for


@pytest.fixture(params=["pty", "socket"])
def peer(request: pytest.FixtureRequest) -> Iterator[LinkPeer]:
    with LinkPeer(request.param) as p:
        yield p


def test_receives_and_fans_out_messages(peer: LinkPeer) -> None:
    got: list[Message] = []
    with BoardClient(peer.url) as client:
        client.add_listener(got.append)
        client.start()
        assert _wait(lambda: any(isinstance(m, SimPoses) for m in got))
        assert _wait(lambda: sum(isinstance(m, Telemetry) for m in got) >= 20)
        stats = client.stats()
        assert stats.state is LinkState.CONNECTED
        assert stats.rx_counts["Telemetry"] >= 20
        assert stats.rx_rate_hz["Telemetry"] > 0
        assert stats.errors == 0
        assert stats.latency_us is not None
    assert client.state is LinkState.STOPPED


def test_heartbeat_and_virtual_rc_only_while_a_frame_is_set(peer: LinkPeer) -> None:
    with BoardClient(peer.url) as client:
        client.start()
        assert _wait(lambda: len(peer.messages(Heartbeat)) >= 2)
        # On connect: neutral frames with the right lever DOWN, then nothing while no frame is set.
        first = [m.frame for m in peer.messages(VirtualRc)]  # type: ignore[attr-defined]
        assert first and all(f.right_lever == Lever.DOWN and f.channels == (0, 0, 0, 0) for f in first)
        n0 = len(first)
        time.sleep(0.1)
        assert len(peer.messages(VirtualRc)) == n0
        # Set once: the link process sends it in every 14 ms slot from then on (the only clock).
        client.set_rc(RcFrame((0, 0, 0, 300), Lever.MIDDLE, Lever.DOWN))
        assert _wait(lambda: len(peer.messages(VirtualRc)) >= n0 + 5)
        last = peer.messages(VirtualRc)[-1].frame  # type: ignore[attr-defined]
        assert last.channels[3] == 300 and last.right_lever == Lever.MIDDLE
        counters = [m.counter for m in peer.messages(Heartbeat)]  # type: ignore[attr-defined]
        assert counters == sorted(counters)
        # None: no RC at all (the board falls to zero current after its RC timeout).
        client.set_rc(None)
        time.sleep(0.1)
        n1 = len(peer.messages(VirtualRc))
        time.sleep(0.2)
        assert len(peer.messages(VirtualRc)) == n1
        with pytest.raises(ValueError):
            client.set_rc(RcFrame((0, 0, 0, 5000), Lever.MIDDLE, Lever.DOWN))  # out of range: refused
        assert client.stats().tx_counts["VirtualRc"] >= n0 + 5


def test_command_round_trip_gives_rtt(peer: LinkPeer) -> None:
    acks: list[Message] = []
    with BoardClient(peer.url) as client:
        client.add_listener(lambda m: acks.append(m) if isinstance(m, CommandAck) else None)
        client.start()
        assert client.send(Command(CommandCode.ESTOP))
        assert _wait(lambda: bool(acks))
        assert client.stats().rtt_us is not None
        assert any(isinstance(m, Command) and m.code == CommandCode.ESTOP for m in peer.received)


def test_each_commands_answers_go_to_its_sender_and_sends_are_told(peer: LinkPeer) -> None:
    answers: dict[str, list[CommandAck | None]] = {"a": [], "b": []}
    sent: list[tuple[Message, str]] = []
    with BoardClient(peer.url) as client:
        client.add_sent_listener(lambda msg, origin: sent.append((msg, origin)))
        client.start()
        assert client.send(Command(CommandCode.ARM), origin="Tab 1", on_ack=answers["a"].append)
        assert client.send(Command(CommandCode.DISARM), origin="MAVLink", on_ack=answers["b"].append)
        assert client.send(Command(CommandCode.ARM))  # nobody awaits this one's answer
        assert _wait(lambda: bool(answers["a"]) and bool(answers["b"]))
        time.sleep(0.2)
        # Each handler got exactly its own command's answer (the fake board acks every one, same seq).
        (a,) = answers["a"]
        (b,) = answers["b"]
        assert a is not None and a.command == CommandCode.ARM
        assert b is not None and b.command == CommandCode.DISARM and b.request_seq != a.request_seq
        assert [(type(m).__name__, o) for m, o in sent] == [
            ("Command", "Tab 1"),
            ("Command", "MAVLink"),
            ("Command", "host"),
        ]
        assert client.stats().tx_counts["Command"] == 3


def test_a_command_awaiting_answers_gets_none_when_the_link_goes_down() -> None:
    import socket

    got: list[CommandAck | None] = []
    with socket.socket() as server:  # a board that reads and never answers
        server.bind(("127.0.0.1", 0))
        server.listen(1)
        url = f"socket://127.0.0.1:{server.getsockname()[1]}"
        with BoardClient(url, BoardClientConfig(reconnect_period_us=50_000)) as client:
            client.start()
            conn, _ = server.accept()
            with conn:
                assert client.send(Command(CommandCode.GRASP), on_ack=got.append)
                assert _wait(lambda: client.stats().tx_counts.get("Command") == 1)
                time.sleep(0.1)
                assert got == []  # written, not answered yet
                server.close()  # and no board to reconnect to
            # The board goes away: the command can have no answer any more.
            assert _wait(lambda: got == [None])
            assert not client.send(Command(CommandCode.GRASP), on_ack=got.append)  # down: refused
            time.sleep(0.1)
            assert got == [None]


def test_listener_errors_are_counted_not_fatal(peer: LinkPeer) -> None:
    seen: list[Message] = []

    def bad(_msg: Message) -> None:
        raise RuntimeError("boom")

    with BoardClient(peer.url) as client:
        client.add_listener(bad)
        client.add_listener(seen.append)
        client.start()
        assert _wait(lambda: len(seen) >= 10)
        assert client.stats().listener_errors >= 10


def test_garbage_is_counted_and_good_frames_still_arrive(peer: LinkPeer) -> None:
    seen: list[Message] = []
    with BoardClient(peer.url) as client:
        client.add_listener(seen.append)
        client.start()
        assert _wait(lambda: len(seen) >= 5)
        peer.inject(b"\xa5\x10\x00\x01\x00garbage\xa5\xff" * 20)
        n = len(seen)
        assert _wait(lambda: len(seen) >= n + 20)
        assert client.stats().parser["bytes_skipped"] > 0


def test_reconnects_after_the_device_vanishes_and_starts_safe() -> None:
    states: list[LinkState] = []
    cfg = BoardClientConfig(reconnect_period_us=50_000)
    with LinkPeer("socket") as peer, BoardClient(peer.url, cfg) as client:
        client.add_state_listener(states.append)
        client.start()
        client.set_rc(RcFrame.neutral(Lever.MIDDLE))
        assert _wait(lambda: len(peer.messages(VirtualRc)) > 5)
        peer.drop_connection()
        assert _wait(lambda: LinkState.DISCONNECTED in states)
        assert not client.send(Heartbeat(0, 0))  # link down: refused, counted
        assert client.stats().tx_dropped >= 1
        with peer.lock:
            peer.received.clear()
        peer.resume()
        assert _wait(lambda: client.stats().reconnects == 1 and states[-1] is LinkState.CONNECTED)
        assert _wait(lambda: len(peer.messages(VirtualRc)) >= 3)
        # The first frames after the reconnect are SAFE (right lever DOWN), whatever frame was set.
        first = peer.messages(VirtualRc)[0].frame  # type: ignore[attr-defined]
        assert first.right_lever == Lever.DOWN
    assert states[-1] is LinkState.STOPPED


def test_stop_is_safe_twice(peer: LinkPeer) -> None:
    client = BoardClient(peer.url)
    client.start()
    client.stop()
    client.stop()
    assert client.state is LinkState.STOPPED


def test_open_errors_are_one_line(tmp_path: os.PathLike[str]) -> None:
    with pytest.raises(BoardLinkError, match="no such device"):
        open_port(os.path.join(tmp_path, "ttyACM9"), timeout_s=0.01)
    with pytest.raises(BoardLinkError, match=r"cannot open socket://127\.0\.0\.1:1"):
        open_port("socket://127.0.0.1:1", timeout_s=0.01)
    with pytest.raises(BoardLinkError):
        BoardClient("not-a-scheme://x").start()


def test_busy_device_is_reported() -> None:
    with LinkPeer("pty") as peer:
        first = open_port(peer.url, timeout_s=0.01)
        try:
            with pytest.raises(BoardLinkError, match="busy"):
                open_port(peer.url, timeout_s=0.01)
        finally:
            first.close()


def test_config_validation() -> None:
    with pytest.raises(ValueError):
        BoardClientConfig(rc_period_us=0)
    with pytest.raises(ValueError):
        BoardClientConfig(lease_us=0)
    with pytest.raises(ValueError):
        BoardClientConfig(rt_priority=100)


def test_a_stalled_host_stops_rc_and_heartbeat() -> None:
    # The lease is renewed by the dispatcher thread; block it inside a listener and the link process
    # must stop sending RC (the board then times out to zero current) instead of repeating stale sticks;
    # it carries no data, so the frame set once goes on when the host is back.
    import threading

    release = threading.Event()
    stalled = threading.Event()

    def stall(msg: Message) -> None:
        if isinstance(msg, Telemetry) and not stalled.is_set():
            stalled.set()
            release.wait(2.0)

    cfg = BoardClientConfig(lease_us=100_000)
    with LinkPeer("socket") as peer, BoardClient(peer.url, cfg) as client:
        client.start()
        client.set_rc(RcFrame.neutral(Lever.MIDDLE))
        assert _wait(lambda: len(peer.messages(VirtualRc)) > 5)
        client.add_listener(stall)
        assert _wait(stalled.is_set)
        time.sleep(0.5)
        n_rc = len(peer.messages(VirtualRc))
        n_hb = len(peer.messages(Heartbeat))
        time.sleep(0.5)
        assert len(peer.messages(VirtualRc)) == n_rc
        assert len(peer.messages(Heartbeat)) == n_hb
        release.set()
        assert _wait(lambda: len(peer.messages(VirtualRc)) > n_rc + 5)
        assert client.stats().lease_expired >= 1


def _wait(cond: Callable[[], bool], timeout_s: float = 5.0) -> bool:
    return wait_for(cond, timeout_s, 0.01)
