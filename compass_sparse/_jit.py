"""Compiled kernels without paying for numba at import time.

``import numba`` costs 0.2-0.4 s, more than the rest of ``import compass_sparse``; a user
script pays it once, but every fresh worker process of a batch pays it again, and a solve
that never reaches a compiled kernel should not pay it at all.  :func:`njit` here has the
signature of ``numba.njit`` but returns a :class:`LazyKernel`: a stand-in that imports
numba and builds the real dispatcher on its first call (compiled code is still loaded from
numba's on-disk cache with ``cache=True``).

Kernels call each other inside compiled code, where numba resolves a callee through the
caller's module globals at compile time and must find a dispatcher there, not a stand-in.
So the first call of any kernel replaces EVERY stand-in found in its module's globals
(its own and those imported from other kernel modules) by its dispatcher before numba
compiles anything.  Python callers that imported a stand-in by name get the dispatcher too: the first build
also rebinds the built stand-ins in the package's loaded modules, since a forwarded call
costs an extra Python frame (~0.4 us) and a small solve makes hundreds of kernel calls.
A module loaded later keeps its stand-in, which forwards each call to the dispatcher.

Cold start.  Loading numba and its first kernel costs 0.5-0.8 s (its import, then the set-up
of its compiler's contexts, then ~5 ms per kernel from the cache), while the kernels' own
Python bodies, run by the interpreter, solve a small problem in a few milliseconds.  So a
process starts by interpreting: a stand-in whose kernel is not built runs its Python body
(with numpy's floating-point warnings off, as compiled code raises none) as long as the
call's arrays are small (at most ``INTERPRET_MAX_ENTRIES`` entries each) and less than
``INTERPRET_WINDOW`` seconds have passed since the process first interpreted a kernel; the
first call past either limit loads numba, and from then on every kernel is compiled.  A
one-shot script solving a small model, or a fresh worker of a batch, answers without
loading numba; a process that goes on solving interprets for the window only and then
compiles.  An interpreted kernel's numpy scalars are returned as the Python floats, ints
and bools numba returns.
The window is wall time, not kernel time: it bounds what the interpreted start can cost
such a process whatever the share of the kernels (measured on 200 solves of one small
problem: see benchmarks/bench_cold_start.py and small.md, round 12).  The interpreted and
compiled kernels compute the same formulas in the same order; their last bits may differ
where numba's LAPACK or math functions differ from numpy's and Python's (math.hypot, for
one), and since the switch comes after a time, which solves of a long run are interpreted
depends on the machine's speed.  The environment variable ``COMPASS_SPARSE_JIT=always``
(read at import) compiles from the first call: runs that must repeat bit for bit set it.
"""
from __future__ import annotations

import os
import sys
import threading
import time

import numpy as np

__all__ = ["INTERPRET_MAX_ENTRIES", "INTERPRET_WINDOW", "LazyKernel", "NO_INDICES",
           "NO_VALUES", "cold_start", "end_cold_start", "materialize", "njit"]

NO_VALUES = np.zeros(0)
NO_INDICES = np.zeros(0, dtype=np.int32)
"""Empty float and int32 arrays: the arguments of a compiled call (reverse communication)
that its request leaves unused (one object each, so that no call allocates them)."""

INTERPRET_WINDOW = 0.2
"""Seconds of wall time, from a process's first interpreted kernel call, during which
kernels are interpreted: the first solve of the small problems of the benchmarks takes
3-120 ms interpreted (thesis family 2 n = 10 seed 1 the longest, with the package's own
first imports), and a process that goes on solving loses at most about this much."""

INTERPRET_MAX_ENTRIES = 4096
"""Largest array (entries) an interpreted kernel call takes (a dense block of order 64); a
call with a larger one loads numba.  It also bounds a single interpreted call, which the
window is only checked before: the small-problem engine's work area has 200 n entries, so
its paths run interpreted up to n = 20 only, and the longest interpreted calls left (a
dense direct step or crash step of order 64) take tens of milliseconds."""


class _ColdStart:
    """The process's cold start: whether stand-ins still interpret, and since when."""

    def __init__(self):
        self.on = os.environ.get("COMPASS_SPARSE_JIT", "auto").strip().lower() != "always"
        self.since = None  # perf_counter() of the first interpreted call
        self.local = threading.local()  # .depth: interpreted kernels running in this thread

    def open(self) -> bool:
        """Whether the window is still open (it opens at the first interpreted call)."""
        now = time.perf_counter()
        if self.since is None:
            self.since = now
        elif now - self.since > INTERPRET_WINDOW:
            self.on = False
        return self.on


_COLD = _ColdStart()


def cold_start() -> dict:
    """The cold start's state: ``interpreting`` (stand-ins still run their Python bodies)
    and ``seconds`` since the first interpreted kernel call (None before one)."""
    since = _COLD.since
    return {"interpreting": _COLD.on,
            "seconds": None if since is None else time.perf_counter() - since}


def end_cold_start():
    """Compile every kernel from its next first call on (benchmarks of warm solves call this
    first, so that they time compiled kernels)."""
    _COLD.on = False


def _small(args) -> bool:
    for a in args:
        if a.__class__ is np.ndarray and a.size > INTERPRET_MAX_ENTRIES:
            return False
    return True


def _as_returned(value):
    """A kernel's value as compiled code returns it: numpy scalars (what an interpreted
    body reads out of arrays) become Python floats, ints and bools, in tuples too.  The
    callers then see the types they see from numba, and their arithmetic on them runs at
    Python's speed, not numpy scalars' (a few times slower)."""
    if isinstance(value, np.generic):
        return value.item()
    if value.__class__ is tuple:
        return tuple(v.item() if isinstance(v, np.generic) else v for v in value)
    return value


def _interpret(fn, args):
    """fn(*args) by the interpreter (the kernels it calls run interpreted inside it)."""
    local = _COLD.local
    if getattr(local, "depth", 0):
        return _as_returned(fn(*args))
    local.depth = 1
    try:
        with np.errstate(all="ignore"):
            return _as_returned(fn(*args))
    finally:
        local.depth = 0


class LazyKernel:
    """A numba kernel built on first use (see the module docstring)."""

    def __init__(self, py_func, options):
        self.py_func = py_func
        self.options = options
        self._dispatcher = None
        self.__name__ = py_func.__name__
        self.__qualname__ = py_func.__qualname__
        self.__module__ = py_func.__module__
        self.__doc__ = py_func.__doc__
        self.__wrapped__ = py_func

    @property
    def dispatcher(self):
        """The numba dispatcher (built, with its module's other kernels, on first access)."""
        if self._dispatcher is None:
            materialize(sys.modules[self.__module__].__dict__)
            if self._dispatcher is None:
                # not in its module's globals any more (a test's wrapper took its name
                # there): built alone, its callees built above
                self._build()
        return self._dispatcher

    def _build(self):
        if self._dispatcher is None:
            import numba

            _COLD.on = False  # numba is loaded: every kernel compiles from now on
            self._dispatcher = numba.njit(**self.options)(self.py_func)
        return self._dispatcher

    def __call__(self, *args):
        d = self._dispatcher
        if d is None:
            if _COLD.on and _small(args) and _COLD.open():
                return _interpret(self.py_func, args)
            d = self.dispatcher
        return d(*args)

    def __repr__(self):
        state = "built" if self._dispatcher is not None else "not built"
        return f"<LazyKernel {self.__module__}.{self.__qualname__} ({state})>"


def materialize(namespace: dict):
    """Replace every :class:`LazyKernel` in ``namespace`` (a module's globals) by its
    dispatcher, so that compiled callers find dispatchers when numba types them; then
    rebind built stand-ins in the package's other loaded modules (Python callers)."""
    _materialize(namespace)
    package = __name__.rpartition(".")[0]
    for mod_name, mod in list(sys.modules.items()):
        if mod is None or not (mod_name == package or mod_name.startswith(package + ".")):
            continue
        ns = mod.__dict__
        for name, obj in list(ns.items()):
            if isinstance(obj, LazyKernel) and obj._dispatcher is not None:
                ns[name] = obj._dispatcher


def _materialize(namespace: dict):
    for name, obj in list(namespace.items()):
        if isinstance(obj, LazyKernel):
            namespace[name] = obj._build()
            # A kernel defined elsewhere has callees in its own module too.
            home = sys.modules.get(obj.__module__)
            if home is not None and home.__dict__ is not namespace:
                _materialize(home.__dict__)


def njit(*args, **options):
    """``numba.njit`` built lazily: ``@njit``, ``@njit(cache=True, ...)``."""
    if args and callable(args[0]) and len(args) == 1 and not options:
        return LazyKernel(args[0], {})
    if args:
        raise TypeError("njit takes keyword options only (signatures are not supported)")

    def wrap(fn):
        return LazyKernel(fn, options)

    return wrap
