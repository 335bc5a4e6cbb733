"""Timing bounds that hold on a busy machine: the CPU seconds of the code under test alone."""

from __future__ import annotations

import contextlib
import gc
import time


@contextlib.contextmanager
def own_cpu_seconds():
    """Yield a callable giving the CPU seconds this thread has spent inside the block. Neighbour processes
    and the worker's other threads do not count, and neither does collecting the garbage of the tests that
    ran before in this worker: those objects are frozen out of the collector for the block."""
    gc.collect()
    gc.freeze()
    start = time.thread_time()
    spent: list = []
    try:
        yield lambda: spent[0] if spent else time.thread_time() - start
    finally:
        spent.append(time.thread_time() - start)
        gc.unfreeze()
