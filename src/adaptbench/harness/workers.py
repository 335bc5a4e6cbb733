"""A small process pool for rollouts that stops promptly and never leaves orphans.

- Workers ignore SIGINT; the parent turns Ctrl-C and SIGTERM into `Interrupted`, terminates the
  workers (killing any that do not exit within a second) and lets the caller keep what finished.
- On Linux each worker asks the kernel to kill it when its parent dies (PR_SET_PDEATHSIG); elsewhere
  it polls its parent between episodes.
- A worker that dies (out of memory, killed) ends the run with `WorkerDied`; finished work is kept.
"""

from __future__ import annotations

import multiprocessing as mp
import os
import signal
import sys
from contextlib import contextmanager

from ..errors import AdaptError
from .episode import Ticks

POLL_SECONDS = 0.2


class Interrupted(BaseException):
    """The run was stopped by Ctrl-C or SIGTERM (a BaseException, so an episode's `except Exception` cannot
    swallow it)."""

    def __init__(self, signum: int):
        super().__init__(signal.Signals(signum).name)
        self.signum = signum


class WorkerDied(AdaptError, RuntimeError):
    """A worker process ended without being asked to."""


def _die_with_parent(parent: int) -> None:
    if sys.platform.startswith("linux"):
        try:
            import ctypes

            libc = ctypes.CDLL(None, use_errno=True)
            libc.prctl(1, signal.SIGKILL, 0, 0, 0)  # PR_SET_PDEATHSIG
        except (OSError, AttributeError):  # pragma: no cover
            pass
    if os.getppid() != parent:  # the parent died before prctl took effect
        os._exit(1)


@contextmanager
def stop_signals():
    """Turn SIGINT and SIGTERM into `Interrupted` for the duration (main thread only)."""
    def raise_(signum, _frame):
        raise Interrupted(signum)

    try:
        old = {s: signal.signal(s, raise_) for s in (signal.SIGINT, signal.SIGTERM)}
    except ValueError:  # not the main thread: leave signals alone
        yield
        return
    try:
        yield
    finally:
        for s, h in old.items():
            signal.signal(s, h)


def _stream_worker(parent: int, work, jobs, results) -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    _die_with_parent(parent)

    def pulled():
        while True:
            job = jobs.get()
            if job is None or os.getppid() != parent:
                return
            yield job

    for record in work(pulled()):
        results.put(record)


def run_stream_pool(jobs: list, workers: int, work):
    """Yield the records of `work(jobs)` — a function from an iterable of jobs to an iterable of one
    record per job, e.g. batched model rollouts — on `workers` forked processes, each pulling jobs from
    one shared queue as it goes (1: in this process). The children inherit what the parent built
    (a model on the CPU, copy-on-write); they are forked, so the parent must not hold a CUDA context."""
    with stop_signals():
        if workers <= 1 or len(jobs) <= 1:
            yield from work(iter(jobs))
            return
        if _context().get_start_method() != "fork":
            raise ValueError("--workers needs the fork start method (Linux); run with --workers 1")
        yield from _parallel(jobs, min(workers, len(jobs)), _stream_worker, work)


def _context():
    methods = mp.get_all_start_methods()
    return mp.get_context("fork" if "fork" in methods and sys.platform.startswith("linux") else None)


def _parallel(jobs: list, n: int, target, payload):
    ctx = _context()
    job_q, result_q = ctx.Queue(), ctx.SimpleQueue()
    procs = [ctx.Process(target=target, args=(os.getpid(), payload, job_q, result_q), daemon=True) for _ in range(n)]
    for p in procs:
        p.start()
    try:
        for job in jobs:
            job_q.put(job)
        for _ in procs:
            job_q.put(None)
        yield from _collect(len(jobs), procs, result_q)
    finally:
        _stop(procs)
        job_q.cancel_join_thread()
        job_q.close()


def _collect(total: int, procs: list, result_q):
    got = 0
    while got < total:
        if result_q.empty():
            if not any(p.is_alive() for p in procs) and result_q.empty():
                raise WorkerDied(f"every worker ended with {total - got} episode(s) not run")
            dead = [p for p in procs if p.exitcode not in (None, 0)]
            if dead and result_q.empty():
                raise WorkerDied(f"a worker died (exit code {dead[0].exitcode}) with episodes in flight")
            _wait(procs, result_q)
            continue
        item = result_q.get()
        got += not isinstance(item, Ticks)  # progress ticks between the records are not results
        yield item


def _wait(procs: list, result_q) -> None:
    from multiprocessing.connection import wait

    wait([result_q._reader] + [p.sentinel for p in procs if p.is_alive()], timeout=POLL_SECONDS)


def _stop(procs: list) -> None:
    for p in procs:
        if p.is_alive():
            p.terminate()
    for p in procs:
        p.join(timeout=1.0)
        if p.is_alive():  # pragma: no cover - ignored SIGTERM
            p.kill()
            p.join(timeout=1.0)
