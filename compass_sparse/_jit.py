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
compiles anything.  Python callers that imported a stand-in by name get the dispatcher
too: the first build also rebinds the built stand-ins in the package's loaded modules,
since a forwarded call costs an extra Python frame (~0.4 us) and a small solve makes
hundreds of kernel calls.
A module loaded later keeps its stand-in, which forwards each call to the dispatcher.

Cold start.  Loading numba and its first kernel costs 0.5-0.8 s (its import, then the set-up
of its compiler's contexts, then ~5 ms per kernel from the cache), while the kernels' own
Python bodies, run by the interpreter, solve a small problem in a few milliseconds.  So a
process starts by interpreting.  Whether a solve's kernels are interpreted is decided once,
when the solve starts (:func:`compass_sparse.routes.kernel_route`, recorded in
``Result.routes["kernels"]``), from the process's state and the problem's size, never from
the clock: a solve is interpreted while no kernel has been compiled in the process, its
problem has at most ``INTERPRET_MAX_N`` variables and fewer than ``INTERPRET_SOLVES`` solves
of the process were interpreted; then every kernel call of that solve runs its Python body
(with numpy's floating-point warnings off, as compiled code raises none), whatever the size
of its arrays, and no solve switches in its middle.  Any other solve compiles its kernels
(and, on its first call, loads numba).  Kernels called outside a solve (building a problem,
a generator) are interpreted under the same conditions when their arrays are small (at most
``INTERPRET_MAX_ENTRIES`` entries each).  A one-shot script solving a small model, or a
fresh worker of a batch, answers without loading numba; a process that goes on solving
interprets its first solves only.  An interpreted kernel's numpy scalars are returned as
the Python floats, ints and bools numba returns.  The interpreted and compiled kernels
compute the same formulas in the same order; their last bits may differ where numba's
LAPACK or math functions differ from numpy's and Python's (math.hypot, for one).  The
environment variable ``COMPASS_SPARSE_JIT`` (read at import) changes the rule: ``always``
compiles from the first call (runs that must repeat bit for bit set it); ``interpret``
interprets every solve of a problem of at most ``INTERPRET_MAX_N`` variables, however many
came before (the tests of the interpreted route).

Ctrl-C while numba loads.  An interrupt is raised between any two bytecodes of the main
thread; inside numba's import it leaves a half-imported ``numba`` (later calls fail with
``module 'numba' has no attribute 'core'``), inside LLVM's callbacks (ctypes) it is printed
and lost while numba goes on with a half-built library (``no compiled object yet``), and a
Result built afterwards compiles again in that state.  So numba's import, the building of
the dispatchers and every compilation or load of one of the package's kernels run with
SIGINT held (:class:`interrupts_held`): the signal is recorded, and delivered (the handler
that was in place runs: Python's raises KeyboardInterrupt) at the next point where numba's
state is whole -- the start of a kernel's compilation or of one of its compiler passes, or
the end of the held section.  A solve interrupted there builds its Result without compiling
(:func:`stop_compiling`): a kernel not compiled yet for its arguments runs its Python body.
"""
from __future__ import annotations

import os
import signal
import sys
import threading

import numpy as np

try:
    import fcntl  # (the cache's lock, :func:`_lock_cache`; POSIX only)
except ImportError:  # pragma: no cover - Windows
    fcntl = None

__all__ = [
    "INTERPRET_MAX_ENTRIES",
    "INTERPRET_MAX_N",
    "INTERPRET_SOLVES",
    "NO_INDICES",
    "NO_VALUES",
    "LazyExternal",
    "LazyKernel",
    "cold_start",
    "compilations",
    "end_cold_start",
    "interrupts_held",
    "kernels_interpreted",
    "materialize",
    "may_interpret",
    "njit",
    "quiet_compile_notice",
    "stop_compiling",
]

NO_VALUES = np.zeros(0)
NO_INDICES = np.zeros(0, dtype=np.int32)
"""Empty float and int32 arrays: the arguments of a compiled call (reverse communication)
that its request leaves unused (one object each, so that no call allocates them)."""

INTERPRET_MAX_N = 20
"""Largest problem whose solve may run interpreted: the small-problem engine's work area
(200 n entries) and every dense block then stay within ``INTERPRET_MAX_ENTRIES``, so no
interpreted call of the solve is long (at n = 50 one interpreted path of the engine took
longer than loading numba)."""

INTERPRET_SOLVES = 16
"""Solves a process interprets before it compiles (if no kernel was compiled earlier): a
one-shot script or a fresh batch worker answers without numba, and a process that goes on
solving pays numba's loading once, after a bounded interpreted start.  Measured
(benchmarks/bench_cold_start.py, 16 solves a process, medians of 3): kojshin answers all
16 in 0.38 s from the import against 1.16 s compiling from the first call; a thesis
instance at n = 10 (34 ms an interpreted solve, 3.3 ms compiled) in 0.82 s against 0.88 s.
Interpreting beyond ~25 solves of such a problem would cost more than loading numba."""

INTERPRET_MAX_ENTRIES = 4096
"""Largest array (entries) a kernel called outside a solve takes interpreted (a dense block
of order 64); a call with a larger one loads numba."""


class _ColdStart:
    """The process's cold start: whether it may still interpret, and its solves' modes."""

    def __init__(self):
        mode = os.environ.get("COMPASS_SPARSE_JIT", "auto").strip().lower()
        self.always = mode == "always"
        self.interpret = mode == "interpret"  # no budget, whatever is compiled
        self.built = False  # a kernel was compiled (numba is loaded)
        self.interpreted_solves = 0
        self.local = threading.local()  # .mode, .estimate of this thread's solve, .depth
        self.compiles = 0  # compilations (cache misses) in this process, nested ones too
        self.noticed = False  # the one-time notice of compilation was written (or is off)

    def may_interpret(self) -> bool:
        """Whether a solve starting now may be interpreted (the size aside)."""
        if self.interpret:
            return True
        return (not self.always and not self.built
                and self.interpreted_solves < INTERPRET_SOLVES)


_COLD = _ColdStart()


def cold_start() -> dict:
    """The cold start's state: ``interpreting`` (a small problem's next solve would run its
    kernels interpreted) and ``interpreted_solves`` (solves of this process interpreted)."""
    return {"interpreting": _COLD.may_interpret(),
            "interpreted_solves": _COLD.interpreted_solves}


def end_cold_start():
    """Compile every kernel from its next first call on (benchmarks of warm solves call this
    first, so that they time compiled kernels)."""
    _COLD.always = True


class kernels_interpreted:
    """Context of one solve (:func:`compass_sparse.routes.kernel_route` enters it): every
    kernel called in this thread inside it runs interpreted (``interpreted``) or compiled.
    A solve inside a solve (a hand-over to the general method) keeps the outer one's mode:
    ``interpreted`` is then ignored, and :attr:`interpreted` says which mode holds."""

    def __init__(self, interpreted: bool, compile_estimate: float = 0.0):
        self.interpreted = interpreted
        self.compile_estimate = compile_estimate
        self._outer = None

    def __enter__(self):
        local = _COLD.local
        self._outer = getattr(local, "mode", None)
        if self._outer is None:
            local.mode = "interpreted" if self.interpreted else "compiled"
            local.estimate = self.compile_estimate
            if self.interpreted:
                _COLD.interpreted_solves += 1
        self.interpreted = local.mode == "interpreted"
        return self

    def __exit__(self, *exc):
        _COLD.local.mode = self._outer
        if self._outer is None:
            _COLD.local.estimate = None
            _COLD.local.no_compile = False  # (stop_compiling holds to the solve's end)
        return False


def stop_compiling():
    """Compile nothing more in this thread's solve (its handler of Ctrl-C calls this): a
    kernel without compiled code for its arguments runs its Python body until the solve
    ends, so that the Result of an interrupted solve is built at once, without numba's
    compiler (a minute on a cold cache, and a second Ctrl-C there would be a traceback).
    Outside a solve it does nothing."""
    if getattr(_COLD.local, "mode", None) is not None:
        _COLD.local.no_compile = True


class _Held:
    """SIGINT held while numba loads or compiles (main thread only: Python runs signal
    handlers there and nowhere else)."""

    def __init__(self):
        self.depth = 0  # nested held sections
        self.previous = None  # the handler replaced while held (None: nothing held)
        self.pending = False  # a SIGINT came while held, not delivered yet


_HELD = _Held()


def _record(signum, frame):
    _HELD.pending = True


def _deliver(handler):
    """Run the interrupt handler that was in place for a held SIGINT: Python's default
    raises KeyboardInterrupt, and a solve in progress then compiles nothing more (a
    handler of the user's decides for itself)."""
    if handler is signal.default_int_handler:
        stop_compiling()
        raise KeyboardInterrupt
    handler(signal.SIGINT, None)


def _main_thread() -> bool:
    return threading.current_thread() is threading.main_thread()


class interrupts_held:
    """``with interrupts_held():`` SIGINT is recorded, not raised, inside the block (and
    delivered when the outermost such block ends, or earlier at :func:`interrupt_point`).
    Numba's import, the building of dispatchers and the compilation or load of a kernel run
    inside one: an interrupt there would leave numba half-imported or half-compiled.  Where
    SIGINT is ignored or left to the system (SIG_IGN, SIG_DFL), and in other threads, it
    does nothing."""

    def __enter__(self):
        self._active = _main_thread()
        if self._active:
            if _HELD.depth == 0:
                handler = signal.getsignal(signal.SIGINT)
                if callable(handler):
                    _HELD.previous = handler
                    signal.signal(signal.SIGINT, _record)
            _HELD.depth += 1
        return self

    def __exit__(self, *exc):
        if self._active:
            _HELD.depth -= 1
            if _HELD.depth == 0 and _HELD.previous is not None:
                handler, _HELD.previous = _HELD.previous, None
                signal.signal(signal.SIGINT, handler)
                if _HELD.pending:
                    _HELD.pending = False
                    _deliver(handler)
        return False


def interrupt_point():
    """Deliver a held SIGINT now: called where numba's state is whole, at the start of a
    kernel's compilation and of each of its compiler passes, so that Ctrl-C during a
    minute of compiling is answered within a pass, not at the minute's end."""
    if _HELD.pending and _HELD.previous is not None and _main_thread():
        _HELD.pending = False
        _deliver(_HELD.previous)


def may_interpret() -> bool:
    """Whether a solve starting now in this thread may be interpreted, the problem's size
    aside: no kernel compiled yet, the interpreted solves not used up, and not inside a
    compiled solve (a solve inside an interpreted one is interpreted too)."""
    mode = getattr(_COLD.local, "mode", None)
    if mode is not None:
        return mode == "interpreted"
    return _COLD.may_interpret()


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
            with interrupts_held():  # (numba's import, its compiler's set-up)
                materialize(sys.modules[self.__module__].__dict__)
                if self._dispatcher is None:
                    # not in its module's globals any more (a test's wrapper took its name
                    # there): built alone, its callees built above
                    self._build()
        return self._dispatcher

    def _build(self):
        if self._dispatcher is None:
            with interrupts_held():
                self._dispatcher = self._new_dispatcher()
        return self._dispatcher

    def _new_dispatcher(self):
        import numba  # (lazy: 0.2-0.4 s that a solve which never compiles should not pay)

        if not _COLD.built:
            _listen_to_compilations()
        _COLD.built = True  # numba is loaded: later solves compile
        d = numba.njit(**self.options)(self.py_func)
        d.__class__ = _dispatcher_class(d.__class__)
        _lock_cache(d)
        return d

    def __call__(self, *args):
        mode = getattr(_COLD.local, "mode", None)
        if mode == "interpreted":  # the solve's route: every call, whatever its size
            return _interpret(self.py_func, args)
        d = self._dispatcher
        if d is None:
            if mode is None and _COLD.may_interpret() and _small(args):
                return _interpret(self.py_func, args)  # outside a solve, small arrays
            if getattr(_COLD.local, "no_compile", False):
                return _interpret(self.py_func, args)  # an interrupted solve's Result
            d = self.dispatcher
        return d(*args)

    def __repr__(self):
        state = "built" if self._dispatcher is not None else "not built"
        return f"<LazyKernel {self.__module__}.{self.__qualname__} ({state})>"


def compilations() -> int:
    """Kernels compiled in this process so far (numba's cache misses, each signature of a
    kernel and each callee compiled for it counted once): 0 when every kernel came from the
    on-disk cache."""
    return _COLD.compiles


def quiet_compile_notice():
    """No notice of compilation in this process (the warm-up's workers, whose parent says
    it once; the test suite, whose first test to compile would see it on its stderr)."""
    _COLD.noticed = True


def _listen_to_compilations():
    """Count numba's compilations and announce the first one.  numba signals
    ``numba:compile`` only when it compiles, never when it loads a kernel from its on-disk
    cache, so a warm cache says nothing."""
    from numba.core import event  # (numba is being loaded: a kernel is being built)

    package = __name__.rpartition(".")[0] + "."

    class Listener(event.Listener):
        def on_start(self, ev):
            if not ev.data["dispatcher"].py_func.__module__.startswith(package):
                return  # the user's own numba code, or numba's helpers inside one of ours
            _COLD.compiles += 1
            # Only a solve announces: it knows its route, hence how long it will compile;
            # a kernel called outside a solve (building a large problem) takes a second.
            if not _COLD.noticed and getattr(_COLD.local, "mode", None) is not None:
                _COLD.noticed = True
                _announce(_COLD.local.estimate)

        def on_end(self, ev):
            pass

    class Passes(event.Listener):
        # A compiler pass of one of the package's kernels starts: a held Ctrl-C is
        # delivered here (numba's own helpers compiled inside one are left alone).
        def on_start(self, ev):
            if ev.data["module"].startswith(package):
                interrupt_point()

        def on_end(self, ev):
            pass

    event.register("numba:compile", Listener())
    event.register("numba:run_pass", Passes())


def _announce(estimate):
    """The one-time notice, on stderr.  The one line the library writes itself: a process
    that is about to spend a minute compiling must say so even where no logging is set up
    (the package's logger has only a NullHandler), and it says it once."""
    sys.stderr.write(f"compass_sparse: compiling kernels, one-time: about {estimate:.0f} s "
                     "(cached on disk afterwards; 'compass-sparse warmup' compiles them "
                     "all ahead)\n")
    sys.stderr.flush()


_DISPATCHER_CLASSES = {}


def _dispatcher_class(base):
    """numba's dispatcher class ``base`` with two changes.  Its compilations hold SIGINT
    (:class:`interrupts_held`; in a solve that was interrupted, a call without compiled
    code runs the Python body instead: :func:`stop_compiling`).  And a call from compiled
    code compiles its callee for the arguments' plain types, not their literal values.
    numba types a module constant passed as an argument (``_copy(W, W_CZ, W_TZ)``, a
    reason code, a ``True``) as a literal and compiles the callee once per distinct value:
    17 copies of a three-line kernel, 9 of the crash's exit, 218 compilations in the
    small-problem route where 170 suffice (benchmarks/first_run.md).  No kernel of the
    package asks for a literal; the arithmetic is the same (the constants only stop being
    folded)."""
    cls = _DISPATCHER_CLASSES.get(base)
    if cls is None:
        from numba.core import types  # (numba is loaded: a dispatcher is being built)

        def get_call_template(self, args, kws):
            args = tuple(types.unliteral(a) for a in args)
            kws = {k: types.unliteral(v) for k, v in kws.items()}
            return base.get_call_template(self, args, kws)

        def _compile_for_args(self, *args, **kws):
            # A call from Python found no compiled code for its arguments' types.
            if getattr(_COLD.local, "no_compile", False):
                # (numba calls the callable returned here with the call's arguments)
                return lambda *a: _interpret(self.py_func, a)
            with interrupts_held():
                return base._compile_for_args(self, *args, **kws)

        def compile(self, sig):
            # Compile or load from the cache (a Python call, or a compiled caller being
            # typed): with SIGINT held, one held before delivered now, at its start.
            with interrupts_held():
                interrupt_point()
                return base.compile(self, sig)

        cls = type(base.__name__, (base,), {"get_call_template": get_call_template,
                                            "_compile_for_args": _compile_for_args,
                                            "compile": compile,
                                            "__module__": base.__module__})
        _DISPATCHER_CLASSES[base] = cls
    return cls


def _lock_cache(dispatcher):
    """Make the dispatcher's on-disk cache safe for several processes compiling at once (a
    parallel warm-up, the workers of a batch on a cold cache).  numba writes a function's
    index (signature -> data file) and then the data file, each atomically, but a save reads
    the index first: two processes saving two signatures of one function both pick data
    file 1, and the index of one can end up naming the other's machine code.  Every save
    and load of the package's kernels therefore holds an exclusive lock on one file of the
    cache directory.  Where there is no such lock (no fcntl) or no writable directory, numba
    is left as it is."""
    cache_file = getattr(getattr(dispatcher, "_cache", None), "_cache_file", None)
    path = getattr(cache_file, "_cache_path", None)
    if fcntl is None or path is None:
        return
    lock_path = os.path.join(path, "compass_sparse.lock")
    for name in ("save", "load"):
        setattr(cache_file, name, _locked(getattr(cache_file, name), lock_path))


def _locked(method, lock_path):
    def locked(*args):
        try:
            fd = os.open(lock_path, os.O_RDWR | os.O_CREAT, 0o666)
        except OSError:  # a cache directory we cannot write to: numba's own behaviour
            return method(*args)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX)
            return method(*args)
        finally:
            os.close(fd)  # (releases the lock)
    return locked


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


class LazyExternal:
    """A C function that compiled kernels call (a BLAS routine), bound on first use like
    the kernels: ``factory()`` imports numba and returns its ``ExternalFunction``.  The
    kernels' module holds this stand-in; :func:`materialize` puts the function in its place
    before numba types a caller or loads one from its cache, whose machine code names the
    function's symbol.  Only compiled code calls it."""

    def __init__(self, factory, name: str):
        self.factory = factory
        self.name = name
        self._function = None

    def build(self):
        if self._function is None:
            with interrupts_held():
                self._function = self.factory()
        return self._function

    def __call__(self, *args):
        raise RuntimeError(f"{self.name} is called from compiled kernels only")


def _materialize(namespace: dict):
    for name, obj in list(namespace.items()):
        if isinstance(obj, LazyExternal):
            namespace[name] = obj.build()
        elif isinstance(obj, LazyKernel):
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
