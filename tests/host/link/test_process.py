"""The board link's own process (host.link.process) driven directly over ``loop://``: the lease gates it."""

from __future__ import annotations

import contextlib
import dataclasses
import multiprocessing as mp
import queue
import time
from collections.abc import Iterator
from typing import Any

import pytest

from host.link.client import BoardClientConfig, load_scaled_s
from host.link.process import BoardLinkError, LinkShared, link_main, now_us, open_port
from protocol.dbus import Lever, RcFrame
from protocol.messages import Heartbeat, Message, VirtualRc
from protocol.stream import MessageStream

SAFE = RcFrame.neutral().pack()


class Link:
    """A link process on ``loop://`` and the host's ends of its pipe, queue and shared memory."""

    def __init__(self) -> None:
        ctx = mp.get_context("spawn")
        self.shared = LinkShared(ctx)
        child, self.conn = ctx.Pipe(duplex=False)
        self.events: Any = ctx.Queue()
        cfg = BoardClientConfig(rt_priority=None, safe_frames_on_connect=2)
        self.proc = ctx.Process(
            target=link_main, args=("loop://", cfg, self.shared, child, self.events, False), daemon=True
        )
        self.proc.start()
        child.close()

    def collect(self, duration_s: float) -> list[tuple[Any, ...]]:
        """Events posted during ``duration_s``."""
        items: list[tuple[Any, ...]] = []
        deadline = time.monotonic() + duration_s
        while (left := deadline - time.monotonic()) > 0:
            with contextlib.suppress(queue.Empty):
                items.append(self.events.get(timeout=left))
        return items

    def until_connected(self) -> list[tuple[Any, ...]]:
        """Events up to the first ``state`` (a fresh interpreter under load takes a while to start)."""
        items: list[tuple[Any, ...]] = []
        deadline = time.monotonic() + load_scaled_s(20.0)
        while not any(i[0] == "state" for i in items) and time.monotonic() < deadline:
            with contextlib.suppress(queue.Empty):
                items.append(self.events.get(timeout=0.1))
        return items

    def stop(self) -> None:
        self.conn.send(("stop",))
        deadline = time.monotonic() + 5.0
        while self.proc.is_alive() and time.monotonic() < deadline:
            with contextlib.suppress(queue.Empty):
                while True:
                    self.events.get_nowait()
            self.proc.join(timeout=0.05)
        assert not self.proc.is_alive()
        self.conn.close()


@pytest.fixture
def link() -> Iterator[Link]:
    running = Link()
    try:
        yield running
    finally:
        if running.proc.is_alive():
            running.stop()


def sent(items: list[tuple[Any, ...]]) -> list[Message]:
    """The messages of every ``tx`` event, in order."""
    stream = MessageStream()
    return [r.msg for item in items if item[0] == "tx" for r in stream.feed(item[1])]


def test_open_port_refuses_a_missing_device_in_one_line() -> None:
    with pytest.raises(BoardLinkError, match="no such device: /dev/no-such-board"):
        open_port("/dev/no-such-board", timeout_s=0)


def test_the_lease_gates_heartbeat_and_rc_and_frames_stay_safe_until_the_host_acknowledges(
    link: Link,
) -> None:
    sh = link.shared
    first = link.until_connected()
    assert ("state", "connected", "", 1) in [i for i in first if i[0] == "state"]
    # Right after opening: the SAFE frames only; the lease was never renewed, so no heartbeat.
    assert sent(first) == [VirtualRc(SAFE)] * 2

    # A renewed lease and the host's frame, pushed once, but this connection not yet acknowledged:
    # heartbeats and SAFE frames.
    host_frame = dataclasses.replace(RcFrame.neutral(), right_lever=Lever.MIDDLE)
    link.conn.send(("rc", host_frame.pack()))
    sh.lease_until_us.value = now_us() + 10_000_000
    unacked = sent(link.collect(0.3))
    assert any(isinstance(m, Heartbeat) for m in unacked)
    assert {m.data for m in unacked if isinstance(m, VirtualRc)} == {SAFE}

    # Acknowledged: the host's frame goes out, in every slot, without being sent again.
    link.conn.send(("rc_gen", 1))
    acked = sent(link.collect(0.3))
    assert [m.data for m in acked if isinstance(m, VirtualRc)][-3:] == [host_frame.pack()] * 3

    # The lease runs out: RC and heartbeat stop, and the expiry is counted (once).
    expiry_us = now_us()
    sh.lease_until_us.value = expiry_us
    # Judged by write time, not arrival: a pass decided just before expiry may still be in the queue.
    late = [i for i in link.collect(0.5) if i[0] == "tx" and i[2] > expiry_us + 100_000]
    assert sent(late) == []
    assert sh.lease_expired.value == 1
    # The lease is liveness only: renewed, the host's frame goes on (it was never resent).
    sh.lease_until_us.value = now_us() + 10_000_000
    back = sent(link.collect(0.3))
    assert host_frame.pack() in {m.data for m in back if isinstance(m, VirtualRc)}
    assert sh.lease_expired.value == 1

    # None: no RC at all (the heartbeat goes on).
    link.conn.send(("rc", None))
    time.sleep(0.1)
    stopped_us = now_us()
    quiet = sent([i for i in link.collect(0.3) if i[0] == "tx" and i[2] > stopped_us])
    assert not any(isinstance(m, VirtualRc) for m in quiet) and any(isinstance(m, Heartbeat) for m in quiet)
    link.stop()
