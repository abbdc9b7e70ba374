"""host.panel.wakeups: viser's senders are woken on their own loop, whatever thread sends.

The race it repairs (an ``asyncio.Event`` set from another thread while the loop parks a waiter) is
timing-dependent; these tests check the mechanism deterministically and then hammer the real buffer the
way viser's ``push`` does, with a bound on every wait."""

from __future__ import annotations

import asyncio
import sys
import threading
import time

from viser.infra._async_message_buffer import AsyncMessageBuffer

from host.panel import wakeups
from host.panel.wakeups import LoopSafeEvent


class _LoopThread:
    """An event loop running in a thread of its own, as viser's server runs it."""

    def __init__(self) -> None:
        self.loop = asyncio.new_event_loop()
        self.thread = threading.Thread(target=self.loop.run_forever, daemon=True)

    def __enter__(self) -> _LoopThread:
        self.thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.loop.call_soon_threadsafe(self.loop.stop)
        self.thread.join(timeout=5)
        self.loop.close()


def test_a_set_from_another_thread_runs_on_the_loop() -> None:
    with _LoopThread() as lt:
        event = asyncio.run_coroutine_threadsafe(_make(lt.loop), lt.loop).result(timeout=5)
        woke = asyncio.run_coroutine_threadsafe(asyncio.wait_for(event.wait(), 5), lt.loop)
        time.sleep(0.05)  # the waiter is parked
        event.set()  # from this thread: handed to the loop, never touching its waiters here
        assert woke.result(timeout=5) is True
        assert event.is_set()


async def _make(loop: asyncio.AbstractEventLoop) -> LoopSafeEvent:
    return LoopSafeEvent(loop)


def test_a_closed_loop_is_not_an_error() -> None:
    loop = asyncio.new_event_loop()
    event = LoopSafeEvent(loop)
    loop.close()
    event.set()  # nothing left to wake
    assert not event.is_set()


def test_viser_buffers_get_the_loop_safe_event_and_no_sender_sleeps_through_a_message() -> None:
    """viser's ``push`` sets the event from the sending thread, then through the loop; its sender waits
    and clears. 20 000 sends from a thread, with the interpreter switching threads every microsecond: the
    sender must see the last one, every time. With a plain ``asyncio.Event`` in its place the sender slept
    through a message in 1 of 5 such runs on the project's VM."""
    wakeups.install()
    wakeups.install()  # once per process, whoever asks
    interval = sys.getswitchinterval()
    sys.setswitchinterval(1e-6)
    try:
        for _ in range(3):
            _hammer(20_000)
    finally:
        sys.setswitchinterval(interval)


def _hammer(sends: int) -> None:
    with _LoopThread() as lt:
        buffer = AsyncMessageBuffer(lt.loop, persistent_messages=False)
        assert isinstance(buffer.message_event, LoopSafeEvent)
        sent = [0]
        seen = [0]

        async def sender() -> None:
            deadline = time.monotonic() + 30
            while seen[0] < sends and time.monotonic() < deadline:
                try:
                    await asyncio.wait_for(buffer.message_event.wait(), timeout=2.0)
                except TimeoutError:
                    return  # slept through a message: the race
                buffer.message_event.clear()
                seen[0] = sent[0]

        task = asyncio.run_coroutine_threadsafe(sender(), lt.loop)
        for _ in range(sends):
            sent[0] += 1
            buffer.message_event.set()  # as push does, from its caller's thread
            lt.loop.call_soon_threadsafe(buffer.message_event.set)
        task.result(timeout=40)
        assert seen[0] == sends, (seen[0], sends)
