"""Where the scenarios of a batch run: in this process, in a local process pool, or on a
Dask cluster.

Every executor offers the same four operations to :func:`compass_sparse.batch.solve_batch`
— ``share`` (ship the pickled model once), ``submit``, ``wait_any`` and ``close`` — so the
batch has one code path and the executors differ only in transport.  Workers are prepared
once by :func:`prepare_worker`: one BLAS thread (the batch is parallel over scenarios, and
BLAS threads on top of worker processes oversubscribe the cores) and the compiled kernels
loaded (numba's on-disk cache), so the first scenario of a worker does not pay for either.
"""
from __future__ import annotations

import concurrent.futures as cf
import functools
import multiprocessing
import os
import signal
import sys
import threading
import time

import numpy as np
from threadpoolctl import threadpool_limits

from ..lcp import solve_lcp

__all__ = [
    "DaskExecutor",
    "InProcessExecutor",
    "LocalPoolExecutor",
    "make_executor",
    "prepare_worker",
]


def prepare_worker() -> int:
    """Limit BLAS to one thread and load the compiled kernels (returns the pid)."""
    threadpool_limits(limits=1)
    # A 3 x 3 LCP touches the crash, the path and its numba kernels.
    solve_lcp(np.array([[2.0, 1, 0], [1, 2, 1], [0, 1, 2]]), np.array([-1.0, 1, -1]))
    return os.getpid()


PARENT_POLL = 0.5
"""Seconds between a local pool worker's checks that the batch's process is alive."""


def _pool_worker(parent: int):
    """A local pool's worker: prepared (:func:`prepare_worker`), and ended when the batch's
    process ``parent`` is gone.  A batch that is killed (SIGKILL, a crash) cannot shut its
    pool down, and its workers waited for tasks forever, holding their memory and the
    killed batch's output pipes (a caller reading its output hung)."""
    prepare_worker()
    threading.Thread(target=_watch_parent, args=(parent,), daemon=True,
                     name="compass-sparse-batch-parent").start()


def _watch_parent(parent: int):
    while os.getppid() == parent:
        time.sleep(PARENT_POLL)
    # the batch is gone, and nobody waits for this worker's results (a signal: a thread
    # cannot end its process by an exception)
    os.kill(os.getpid(), signal.SIGKILL)


class InProcessExecutor:
    """Runs each task at submission, in this process (``workers=0``): for debugging and
    small batches; the same code path as the pools."""

    workers = 1
    name = "in-process"

    def share(self, blob):
        return blob

    def submit(self, fn, *args):
        fut = cf.Future()
        try:
            fut.set_result(fn(*args))
        except BaseException as exc:  # a task failure is reported through the future
            fut.set_exception(exc)
        return fut

    @staticmethod
    def wait_any(futures):
        return cf.wait(futures, return_when=cf.FIRST_COMPLETED)[0]

    def close(self, cancel=False):
        pass


class LocalPoolExecutor(InProcessExecutor):
    """A process pool over ``workers`` processes (default: every core); a worker ends
    itself when the batch's process is gone (killed).

    Workers are forked on Linux when the caller runs a single thread (they inherit the
    compiled kernels and need no ``if __name__ == "__main__"`` guard in scripts), spawned
    otherwise.  A pool broken by a dying worker is replaced (at most ``MAX_RESTARTS``
    times): the tasks it held come back as failures, which the batch retries once, alone."""

    name = "local process pool"
    MAX_RESTARTS = 100

    def __init__(self, workers: int | None = None, pool: cf.Executor | None = None):
        self._own = pool is None
        self._restarts = 0
        self.workers = int(getattr(pool, "_max_workers", 1)) if pool is not None \
            else int(workers or os.cpu_count() or 1)
        # Decided once: a replacement pool forks too (the broken pool's own management
        # thread may still be alive then, and is no reason to switch to spawn).
        self._method = "fork" if sys.platform == "linux" and threading.active_count() == 1 \
            else "spawn"
        self.pool = pool if pool is not None else self._new_pool()

    def _new_pool(self):
        return cf.ProcessPoolExecutor(max_workers=self.workers,
                                      mp_context=multiprocessing.get_context(self._method),
                                      initializer=functools.partial(_pool_worker, os.getpid()))

    def submit(self, fn, *args):
        try:
            return self.pool.submit(fn, *args)
        except cf.process.BrokenProcessPool:
            if not self._own or self._restarts >= self.MAX_RESTARTS:
                raise
            self._restarts += 1
            self.pool.shutdown(wait=False, cancel_futures=True)
            self.pool = self._new_pool()
            return self.pool.submit(fn, *args)

    def close(self, cancel=False):
        if self._own:
            self.pool.shutdown(wait=not cancel, cancel_futures=cancel)


class DaskExecutor:
    """A ``dask.distributed.Client``: the model is scattered to every worker once and each
    task is a plain function call on data."""

    name = "dask"

    def __init__(self, client):
        from distributed import wait  # (dask: an optional extra, the batch one)

        self.client = client
        self._wait = wait
        client.run(prepare_worker)
        self.workers = max(1, sum(int(w.get("nthreads", 1)) for w in
                                  client.scheduler_info()["workers"].values()))

    def share(self, blob):
        return self.client.scatter(blob, broadcast=True, hash=False)

    def submit(self, fn, *args):
        return self.client.submit(fn, *args, pure=False)

    def wait_any(self, futures):
        return set(self._wait(list(futures), return_when="FIRST_COMPLETED").done)

    def close(self, cancel=False):
        pass


def make_executor(executor=None, workers: int | None = None):
    """The executor adapter for ``solve_batch``'s ``executor``/``workers`` arguments:
    a ``dask.distributed.Client`` -> Dask; a ``concurrent.futures.Executor`` -> used as the
    pool; None -> a new local pool (``workers=0``: in this process)."""
    if executor is None:
        if workers == 0:
            return InProcessExecutor()
        return LocalPoolExecutor(workers)
    if isinstance(executor, cf.Executor):
        return LocalPoolExecutor(pool=executor)
    if type(executor).__module__.startswith("distributed"):
        return DaskExecutor(executor)
    raise TypeError("executor must be None, a concurrent.futures.Executor or a "
                    f"dask.distributed.Client, not {type(executor).__name__}")
