"""One BLAS thread for the dense kernels that need it.

A multithreaded BLAS on a loaded machine spends its time spinning threads on small and
medium dense kernels (measured here: a 200 x 200 inverse took 0.2 s against 2 ms on one
thread, a dense least-squares solve of order 1000 25 s against 0.8 s).  threadpoolctl's
``threadpool_limits`` scans the loaded libraries (/proc/self/maps) on every call, 1.7 ms,
more than a whole small solve should take, so the process keeps one controller and sets
the limit through it (~10 us).
"""
from __future__ import annotations

import contextlib

_CONTROLLER = []
"""The one threadpoolctl controller of the process (empty until first needed)."""


def single_threaded_blas():
    """A context manager limiting BLAS to one thread (a no-op without threadpoolctl)."""
    if not _CONTROLLER:
        try:
            from threadpoolctl import ThreadpoolController
        except ImportError:  # pragma: no cover - a declared dependency
            return contextlib.nullcontext()
        _CONTROLLER.append(ThreadpoolController())
    return _CONTROLLER[0].limit(limits=1, user_api="blas")
