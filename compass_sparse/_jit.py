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
"""
from __future__ import annotations

import sys

__all__ = ["LazyKernel", "materialize", "njit"]


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
        return self._dispatcher

    def _build(self):
        if self._dispatcher is None:
            import numba

            self._dispatcher = numba.njit(**self.options)(self.py_func)
        return self._dispatcher

    def __call__(self, *args):
        d = self._dispatcher
        if d is None:
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
