"""Independent runs over worker processes: a map that reports progress and leaves Ctrl-C to the parent."""

from __future__ import annotations

import multiprocessing
import signal
from collections.abc import Callable, Sequence
from typing import TypeVar

from hil.experiments.common import Progress

T = TypeVar("T")
R = TypeVar("R")


def parallel_map(
    fn: Callable[[T], R],
    items: Sequence[T],
    jobs: int,
    progress: Progress | None,
    done0: int = 0,
    total: int = 0,
) -> list[R]:
    """``[fn(x) for x in items]``, over ``jobs`` processes when > 1, reporting one unit per item."""
    total = total or done0 + len(items)
    out: list[R] = []
    if jobs <= 1 or len(items) <= 1:
        for i, item in enumerate(items):
            out.append(fn(item))
            if progress is not None:
                progress(done0 + i + 1, total)
        return out
    # multiprocessing's pool, not concurrent.futures': on Ctrl-C or a failed item it can *terminate* the
    # workers, where an executor's shutdown leaves running items to finish (minutes for a long drive)
    # before the interpreter may exit.
    # SIGINT is blocked while the workers start, so none can take a Ctrl-C before it ignores it: a worker
    # interrupted while it holds the task queue's lock would hang the pool's terminate() below. A Ctrl-C
    # in that window stays pending and reaches the parent once the pool exists.
    mask = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        pool = multiprocessing.Pool(processes=jobs, initializer=_ignore_ctrl_c)
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, mask)
    try:
        for i, r in enumerate(pool.imap(fn, items)):
            out.append(r)
            if progress is not None:
                progress(done0 + i + 1, total)
    except BaseException:
        pool.terminate()
        pool.join()
        raise
    pool.close()
    pool.join()
    return out


def _ignore_ctrl_c() -> None:
    """Pool workers leave Ctrl-C to the parent (a terminal sends it to the whole process group); they
    start with SIGINT blocked (:func:`parallel_map`) and unblock it once it is ignored."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})
