"""Routes: which implementation of each pass runs, chosen once per solve.

Several pieces of the method have two implementations that compute the same thing: a
compiled loop and its Python reference (the stabilized Newton method's bookkeeping, the
crash, the homotopy's path tracker), and the bases a pivotal path can run on (the compiled
dense engine, the dense reference basis, the sparse basis manager).  Which one runs is
decided here and only here, from the problem's size and the options -- never from the
log level and never from the clock -- and recorded in ``Result.routes``:

``kernels``   "compiled", or "interpreted" for the first small solves of a process before
              numba is loaded (the cold start: :func:`kernel_route`, decided when the solve
              starts and held to its end);
``path``      "dense engine" (n <= ``DENSE_ENGINE_MAX_N``, option ``path_basis = "auto"``),
              "sparse engine" (above it, ``path_basis = "auto"``, ``engine = "auto"``, the
              sparse LU left to the solver -- ``lu_backend`` and ``lu_ordering`` "auto" and
              no ``COMPASS_SPARSE_LU`` in the environment: a chosen LU is the manager's --
              and a Jacobian of at most ``SPARSE_ENGINE_MAX_DENSITY`` entries per column;
              or ``path_basis = "sparse engine"``, at every order and density),
              "sparse basis to engine" (the same conditions but a denser Jacobian, n at
              most ``HAND_OVER_MAX_N``: the paths start on the basis manager, and a path
              that makes :func:`hand_over_pivots` pivots hands them to the sparse engine:
              the linear MCP is solved again there, and every later path runs there),
              "dense basis" (``path_basis = "dense"``, n <= ``DENSE_BASIS_MAX_N``) or
              "sparse basis" (the Python loop over the basis manager: every other case);
``nms``       "compiled" (``engine = "auto"``, compiled kernels, the problem left unscaled
              by the scaling pass, n <= ``COMPILED_NMS_MAX_N``) or "python";
``crash``     "compiled" (``engine = "auto"``, every block dense: n <= ``DENSE_SOLVE_MAX_N``)
              or "python";
``homotopy``  "compiled" (``engine = "auto"``, compiled kernels, n <= ``HOMOTOPY_DENSE_MAX_N``,
              and numba binds LAPACK's getrf) or "python".

``engine = "reference"`` also has a small problem's path (n < ``DIRECT_MIN_N``, on the
dense engine) compute its start and its dense direct step in Python, where the automatic
route makes them in one compiled call with the linearization
(:meth:`compass_sparse.nms.newton.NewtonStep.dense_lane`).

The compiled loops and their Python references give the same points bit for bit (the
tests hold them against each other in tests/routes/); the three bases take the same
pivots up to rounding.  Verbosity only decides what is written
to the log: the compiled engines report their pivots and major iterations to it from
record buffers they fill (see :mod:`compass_sparse.path.dense_engine` and
:mod:`compass_sparse.nms`), so a solve logs what a silent solve computes.

To add a route: give the pass both implementations behind one entry point that takes the
choice as an argument, add the field and its rule to :class:`Routes` and
:func:`choose_routes`, and a test that runs both on the same problems.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass

from . import _jit
from .basis.backends import DENSE_SOLVE_MAX_N
from .basis.dense import DenseBasis
from .basis.manager import BasisManager
from .basis.types import BasisOptions
from .homotopy.tracker import compiled_tracker_available
from .linalg.direct import automatic_lu
from .options import HOMOTOPY_DENSE_MAX_N, Options
from .path.dense_engine import DensePathEngine
from .path.engine import DEFAULT_UPDATE_LIMIT, UPDATE_LIMIT_FLOOR, resolve_update_limit
from .path.sparse_engine import SPARSE_ENGINE_MAX_DENSITY, SparsePathEngine

__all__ = ["COMPILED_NMS_MAX_N", "COMPILE_SECONDS_DENSE", "COMPILE_SECONDS_MEDIUM",
           "COMPILE_SECONDS_SPARSE",
           "DENSE_BASIS_MAX_N", "DENSE_ENGINE_MAX_N", "UPDATE_LIMIT_FLOOR", "Routes",
           "DEFAULT_UPDATE_LIMIT", "HAND_OVER_MAX_N", "HAND_OVER_MIN_PIVOTS",
           "HAND_OVER_SHARE", "basis_factory", "choose_routes", "compile_estimate",
           "hand_over_pivots", "kernel_route"]

DENSE_ENGINE_MAX_N = 500
"""Largest n whose paths run on the compiled dense engine (above: the sparse manager)."""

DENSE_BASIS_MAX_N = 300
"""Largest n whose paths run on the dense reference basis with ``path_basis = "dense"``."""

COMPILED_NMS_MAX_N = 5000
"""Largest order whose major iterations run in compiled calls.  Their work area holds 28
vectors of length n (224 MB at n = 1e6), and above a few thousand variables the ~50 us of
Python a major iteration saves is a vanishing share of its factorizations."""


@dataclass(frozen=True)
class Routes:
    """The routes of one solve (see the module docstring for each field's values)."""

    kernels: str = "compiled"
    path: str = "dense engine"
    nms: str = "compiled"
    crash: str = "compiled"
    homotopy: str = "compiled"

    def as_dict(self) -> dict:
        return asdict(self)


COMPILE_SECONDS_DENSE = 140.0
"""Seconds a solve of a small problem (n <= ``DENSE_ENGINE_MAX_N``: the compiled crash,
major iterations, dense engine and homotopy) spends compiling when numba's cache is empty:
the estimate of the one-time notice, CPU seconds measured on a 2-core machine
(``benchmarks/bench_compile_estimate.py``, ``results/compile_estimate.json``; a partly
warm cache compiles less).  The thesis demo: 138 s (97 s at 81ac55b)."""

COMPILE_SECONDS_MEDIUM = 120.0
"""The same up to ``COMPILED_NMS_MAX_N`` (the compiled major iterations and the sparse
engine, or the basis manager; the preprocessor of a model of that size).  The traffic
model at n = 912: 107-130 s.  (It was 45 s, from before the sparse engine's route.)"""

COMPILE_SECONDS_SPARSE = 110.0
"""The same for larger problems (the sparse engine, the Python major iterations).  The
structured demo at n = 1e5: 99-113 s.  (It was 25 s.)"""


def compile_estimate(n: int) -> float:
    """Seconds a solve of order n would spend compiling its kernels with an empty cache."""
    if n <= DENSE_ENGINE_MAX_N:
        return COMPILE_SECONDS_DENSE
    return COMPILE_SECONDS_MEDIUM if n <= COMPILED_NMS_MAX_N else COMPILE_SECONDS_SPARSE


class kernel_route:
    """The solve's kernel route (:mod:`compass_sparse._jit`, "Cold start"), entered when a
    solve starts and left when it ends: ``with kernel_route(n) as kernels`` gives
    "interpreted" or "compiled".  A solve inside a solve keeps the outer one's route.  A
    compiled solve that finds a kernel missing from numba's cache says once, on stderr,
    that it compiles and about how long that takes (:func:`compile_estimate`)."""

    def __init__(self, n: int):
        self._mode = _jit.kernels_interpreted(
            n <= _jit.INTERPRET_MAX_N and _jit.may_interpret(), compile_estimate(n))

    def __enter__(self) -> str:
        return "interpreted" if self._mode.__enter__().interpreted else "compiled"

    def __exit__(self, *exc):
        return self._mode.__exit__(*exc)


def path_route(n: int, options: Options, nnz: int | None = None) -> str:
    """The basis of the pivotal paths of a problem of order n whose Jacobian has ``nnz``
    entries (None: unknown, taken as sparse)."""
    if options.path_basis == "sparse engine":
        return "sparse engine"
    if options.path_basis == "auto" and n <= DENSE_ENGINE_MAX_N:
        return "dense engine"
    if (options.path_basis == "auto" and options.engine == "auto"
            and automatic_lu(options.lu_backend, options.lu_ordering)):
        if nnz is None or nnz <= SPARSE_ENGINE_MAX_DENSITY * n:
            return "sparse engine"
        if n <= HAND_OVER_MAX_N:
            return "sparse basis to engine"
    if options.path_basis == "dense" and n <= DENSE_BASIS_MAX_N:
        return "dense basis"
    return "sparse basis"


def choose_routes(n: int, options: Options, *, kernels: str = "compiled",
                  scaled: bool = False, nnz: int | None = None) -> Routes:
    """The routes of a solve of a problem of order n (after the preprocessor) whose
    Jacobian has ``nnz`` entries; ``scaled``: the scaling pass scaled it (the compiled
    major iterations judge points unscaled)."""
    compiled = options.engine == "auto"
    running = compiled and kernels == "compiled"
    return Routes(
        kernels=kernels,
        path=path_route(n, options, nnz),
        nms="compiled" if running and not scaled and 0 < n <= COMPILED_NMS_MAX_N else "python",
        crash="compiled" if compiled and 0 < n <= DENSE_SOLVE_MAX_N else "python",
        homotopy="compiled" if (running and n <= HOMOTOPY_DENSE_MAX_N
                                and compiled_tracker_available()) else "python")


HAND_OVER_MIN_PIVOTS = 100
HAND_OVER_SHARE = 10
"""On the route "sparse basis to engine" a path on the basis manager that makes
max(HAND_OVER_MIN_PIVOTS, n / HAND_OVER_SHARE) pivots hands the solve's paths to the
compiled sparse engine.  Why: the manager's supernodal LU and its reused factors make it
the faster basis for solves that pivot little on dense-ish Jacobians (the CGE models,
9.6 entries a column: a 50% output tax at n = 2024, 36 pivots, 0.36-0.43 s against
0.54-0.85 s on the engine), the engine for those that pivot much (the endowment shock,
3348 pivots: 5.5-8.4 s on the manager against 2.3-2.9 s; the thesis families at
n = 600: 5.4 against 5.3 s, and 2.5 against 1.3 s); a path's pivots tell which kind a solve is,
where its density does not.  The pivots made before the hand-over are spent (counted
in the Result): at most ~0.4 s at n = 2024 (~2 ms a pivot on the manager)."""


HAND_OVER_MAX_N = 5000
"""Above this order a denser Jacobian's paths stay on the manager ("sparse basis"): the
hand-over is measured up to n = 2024, and a large CGE model's bases, whose Schur
complement is dense, would give the engine a dense tail of thousands of columns where the
manager's supernodal LU and METIS order serve (benchmarks/cge.md).  The engine does not
estimate a factorization's time before it starts (the manager does; the engine checks its
storage against the memory budget): at n = 5000 a wholly dense tail is a block of 2.5e7
entries (200 MB) and ~3 s of panels at 0.08 ns a multiply-add."""


def hand_over_pivots(n: int) -> int:
    """The pivots of a manager's path after which the route "sparse basis to engine"
    hands the paths to the engine."""
    return max(HAND_OVER_MIN_PIVOTS, n // HAND_OVER_SHARE)


def basis_factory(route: str, options: Options, deadline=None):
    """``make(M)``: the basis of the pivotal paths of a linear MCP with matrix M on the path
    route ``route``; the sparse manager gets the solve's deadline, so that a factorization
    that cannot finish in time is not started (TIME_LIMIT).  On the route "sparse basis to
    engine", ``make.hand_over`` is ``(pivots, make_engine)``: the pivots of
    :func:`hand_over_pivots` as a function of n, and the engine's factory (else None)."""
    def make(M):
        # (the engines resolve factorization_update_limit themselves, the managers here:
        # path.engine.resolve_update_limit either way)
        if route == "dense engine":
            return DensePathEngine(M, options)
        if route == "sparse engine":
            return SparsePathEngine(M, options)
        if route == "dense basis":
            return DenseBasis(M)
        limit = resolve_update_limit(options.factorization_update_limit,
                                     DEFAULT_UPDATE_LIMIT, M.shape[0])
        return BasisManager(M, options=BasisOptions(update_limit=limit, deadline=deadline,
                                                    backend=options.lu_backend,
                                                    ordering=options.lu_ordering,
                                                    reuse_factors=options.factor_reuse))

    make.hand_over = ((hand_over_pivots, basis_factory("sparse engine", options))
                      if route == "sparse basis to engine" else None)
    return make
