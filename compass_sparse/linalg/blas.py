"""One BLAS thread for the dense kernels that need it, and BLAS for compiled kernels.

A multithreaded BLAS on a loaded machine spends its time spinning threads on small and
medium dense kernels (measured here: a 200 x 200 inverse took 0.2 s against 2 ms on one
thread, a dense least-squares solve of order 1000 25 s against 0.8 s).  threadpoolctl's
``threadpool_limits`` scans the loaded libraries (/proc/self/maps) on every call, 1.7 ms,
more than a whole small solve should take, so the process keeps one controller, and its
BLAS libraries, found once, are set to one thread and back directly (~2 us; the
controller's own ``limit`` re-reads every library's state, ~15 us).
"""
from __future__ import annotations

import contextlib

BLAS_LIMIT_MIN_N = 16
"""Below this dimension the BLAS thread count is left alone: the dense kernels of such a
problem have at most 256 entries, and OpenBLAS runs every LU or matrix-vector product of
fewer than 10^4 entries on one thread by itself (setting and restoring the count cost
~10 us, a few percent of a whole solve of a 2-variable problem; the crash's block around
its dense solves, set and restored at every crash, was 2% of the solver's time over the
problems of n <= 10, sampled)."""

_CONTROLLER = []
"""The one threadpoolctl controller of the process (empty until first needed)."""


def single_threaded_blas():
    """A context manager limiting BLAS to one thread (a no-op without threadpoolctl)."""
    if not _CONTROLLER:
        try:
            # (lazy: ~15 ms of import, for the BLAS limit only)
            from threadpoolctl import ThreadpoolController
        except ImportError:  # pragma: no cover - a declared dependency
            return contextlib.nullcontext()
        _CONTROLLER.append(ThreadpoolController())
        libs = _CONTROLLER[0].select(user_api="blas").lib_controllers
        ok = all(hasattr(c, "get_num_threads") and hasattr(c, "set_num_threads")
                 for c in libs)
        _BLAS_LIBS.append(list(libs) if ok else None)
    if _BLAS_LIBS[0] is None:  # pragma: no cover - an older threadpoolctl
        return _CONTROLLER[0].limit(limits=1, user_api="blas")
    return _OneThread(_BLAS_LIBS[0])


_BLAS_LIBS = []
"""[the BLAS library controllers of _CONTROLLER, or None to use its ``limit``]."""


_DEPTH = [0]
"""How many single-threaded blocks are open: a block inside another one (a dense solve
inside the crash's loop) has nothing to set or restore (the crash of a 4 x 4 problem opened
eleven, each setting and restoring two libraries, ~15 us apiece)."""


class _OneThread:
    """One BLAS thread inside the block, each library's own count restored after."""

    __slots__ = ("libs", "saved")

    def __init__(self, libs):
        self.libs = libs
        self.saved = []

    def __enter__(self):
        if _DEPTH[0] == 0:
            for c in self.libs:
                k = c.get_num_threads()
                if k != 1:
                    c.set_num_threads(1)
                    self.saved.append((c, k))
        _DEPTH[0] += 1
        return self

    def __exit__(self, *exc):
        _DEPTH[0] -= 1
        for c, k in self.saved:
            c.set_num_threads(k)
        self.saved.clear()
        return False


def blas_external(name: str, nargs: int):
    """SciPy's BLAS routine ``name`` (Fortran calling convention: every one of its
    ``nargs`` arguments a pointer, integers 32-bit) as a function that compiled kernels
    call (:class:`compass_sparse._jit.LazyExternal` builds it on first use).  Its address
    is registered under a symbol of its own, so that a kernel loaded from numba's cache
    finds it in a new process."""
    # (lazy: numba, for the compiled kernels only)
    import llvmlite.binding as llvm
    from numba import types
    from numba.extending import get_cython_function_address

    symbol = f"compass_sparse_blas_{name}"
    llvm.add_symbol(symbol, get_cython_function_address("scipy.linalg.cython_blas", name))
    return types.ExternalFunction(symbol, types.void(*([types.voidptr] * nargs)))
