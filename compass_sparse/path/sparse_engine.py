"""The sparse engine: the whole pivotal path in compiled code on a sparse LU.

Above the dense engine's order the basis of a path is large and sparse: unit columns for
the slacks, columns of M for the basic z, the covering vector.  The Python loop over the
sparse basis manager (``PivotalPath._pivot_loop``, the reference route) spends most of a
pivot in Python: 280-400 us per pivot at n = 912 and 620-760 us at n = 2452 on the traffic
model, against ~10-30 us of arithmetic.  :class:`SparsePathEngine` runs the loop of
:mod:`compass_sparse.path._path_kernels` -- the one the dense engine runs -- on the sparse
factors of :mod:`compass_sparse.path._sparse_lu`: a compiled left-looking LU with
threshold partial pivoting and the thesis' rank repair, hypersparse in its triangular
solves (each column's elimination costs its flops), and Forrest-Tomlin updates with the
manager's safeguards.  No Python runs per pivot, nor per refactorization: the path calls
its factorization from compiled code (see the LU module's docstring for why this, and not
a backend called back from Python, was chosen).

The LU's elimination order is computed at every factorization from the basis itself
(:mod:`compass_sparse.path._sparse_order`): the unit columns first, then the basic z
columns, each matched to a row where it has a large entry and ordered by minimum degree
on the pattern of the matched block, then r.  Measured on the bases a traffic solve
factorizes (one process, before / after; the same pivots): n = 2452, 64 / 53
factorizations, L + U 56.5e3 / 19.6e3 entries on average, 9.8 / 4.0 ms each; n = 912,
7.6e3 / 4.7e3 entries, 0.78 ms each both (the order's own cost eats the gain there).
The order before this one, COLAMD's order of M's columns computed once per pattern with
partial pivoting, cannot see that a saddle-point block paired with its large entries is
as cheap to factor as a symmetric one (see the ordering module).
The factors' storage is preallocated from M's entries; a factorization that does not fit
returns to Python, which doubles the storage and runs the path again from its start (it
is deterministic: the same pivots).

Tolerances (the basis manager's defaults, :class:`compass_sparse.basis.types.BasisOptions`):
``rank_tolerance`` 1e-11 relative to the column's inf-norm (a dependent column is repaired
by an artificial), ``pivot_tolerance`` 1e-11 (a replacement refused), ``stability_tolerance``
1e-8 (|d1 - d2| / |d1|), ``fill_factor`` 2 and ``growth_limit`` ``GROWTH_LIMIT``.
The route (:func:`compass_sparse.routes.path_route`) gives the engine the problems above
the dense engine's order whose Jacobian has at most ``SPARSE_ENGINE_MAX_DENSITY`` entries
per column on average; denser ones (the CGE models, the thesis families' dense
Jacobians) start on the basis manager and come here after a long path (the route "sparse
basis to engine", :func:`compass_sparse.routes.hand_over_pivots`); option ``path_basis =
"sparse engine"`` sends every problem here.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from . import _path_kernels as K
from . import _sparse_lu as SL
from .engine import PIVOT_CHUNK, PathEngine
from ._dense_lu import N_PERM
from ..basis.backends import MEMORY_SHARE, FactorBudget
from ..exceptions import FactorBudgetError
from ..linalg._csc_kernels import csc_is_canonical
from ..linalg.blas import single_threaded_blas

__all__ = ["AUTO_UPDATE_LIMIT", "ORDERING", "SPARSE_ENGINE_MAX_DENSITY", "SparsePathEngine"]

_I = np.int64

SPARSE_ENGINE_MAX_DENSITY = 8.0
"""Average entries per column of the Jacobian above which a problem's paths start on the
basis manager (``routes.path_route``: the route "sparse basis to engine", which hands
them to this engine after a long path).  On such Jacobians (the CGE models, 9.6 entries
a column; the thesis families' dense ones) a basis that fills factors faster in the
manager's supernodal LU, and the manager reuses factors from one major iteration to the
next: a solve that pivots little is faster there (a 50% output tax on the static CGE
model at n = 2024, 36 pivots: 0.36-0.43 s against 0.54-0.85 s here), one that pivots
much is faster here since its dense tails are factored by BLAS (the endowment shock,
3348 pivots: 2.3-2.9 s against 5.5-8.4 s; benchmarks/pivots.md).  Traffic (5.2 entries a
column) was 3.5x faster here at n = 912."""

GROWTH_LIMIT = 1e8
"""The Forrest-Tomlin growth limit of the sparse factors: an update whose row-eta
multiplier ``|c_i| = |u_pp y_i|`` exceeds it is declined (the dense engine's limit is
100).  Measured on the traffic model (n = 912, 586 pivots, same path for every limit):
a limit of 100 declined 315 updates (339 factorizations against the Python loop's 35),
1e6 declined 57, 1e8 and above 4 (38 factorizations).  Multipliers of 1e4-1e6 are common
on these bases (variables of different units: flows and potentials) and harmless: the
d1 / d2 stability test and the final residual check guard the accuracy, as in the basis
manager, which has no growth test."""

AUTO_UPDATE_LIMIT = 250
"""The engine's update limit when ``factorization_update_limit`` is None (automatic): a
hard maximum above its own rule (:func:`compass_sparse.path._sparse_lu.refactor_pays`),
which refactorizes when that costs less per pivot than further updates.  The storage of
the updates does not grow with it (see :func:`compass_sparse.path._sparse_lu.allocate`)."""

ORDERING = "matching, minimum degree"
"""The engine's ordering as ``Result.lu`` reports it (see the module docstring)."""

CHUNK_WORK = 2_000_000
"""Pivots per compiled call are at most CHUNK_WORK / n (and PIVOT_CHUNK): a pivot costs
O(n) at least, so the time limit is checked about every few milliseconds."""

_DENSE_PLACEHOLDERS = (np.zeros((2, 2), order="F"), np.zeros((2, 2), order="F"),
                       np.zeros((2, 2)))


class SparsePathEngine(PathEngine):
    """Runs pivotal paths of a linear MCP with the sparse matrix M (n x n) in compiled
    code on sparse factors; takes the place of the basis manager (``set_matrix``,
    ``set_dense_column``, ``stats``, :meth:`run_path`)."""

    kind = K.FAC_SPARSE
    automatic_update_limit = AUTO_UPDATE_LIMIT

    def __init__(self, M, options=None, *, update_limit: int | None = None,
                 pivot_tolerance: float = 1e-11, rank_tolerance: float = 1e-11,
                 stability_tolerance: float = 1e-8, growth_limit: float | None = None,
                 fill_factor: float = 2.0):
        if growth_limit is None:
            growth_limit = GROWTH_LIMIT
        self.n = M.shape[0]
        self.set_matrix(M)
        self.init_common(update_limit, options, pivot_tolerance, rank_tolerance,
                         stability_tolerance, growth_limit, fill_factor)
        self.chunk = int(max(16, min(PIVOT_CHUNK, CHUNK_WORK // max(self.n, 1))))
        self.pivot_threshold = SL.PIVOT_THRESHOLD
        self._S = None
        self._D = None

    def set_matrix(self, M):
        """Take M (scipy sparse; canonical CSC float64 is used as it is, else a copy)."""
        if not (sp.issparse(M) and M.format == "csc" and M.dtype == np.float64
                and M.indices.dtype == M.indptr.dtype
                and csc_is_canonical(M.indptr, M.indices, M.shape[0], M.nnz)):
            M = sp.csc_matrix(M, dtype=np.float64, copy=True)
            M.sum_duplicates()
            M.sort_indices()
        self.n = M.shape[0]
        self._M = M
        self._Mp = M.indptr.astype(_I, copy=False)
        self._Mi = M.indices.astype(_I, copy=False)
        self._Mx = M.data
        # (the order of the columns left unmatched by the factorization's matching)
        self.colkey = np.arange(self.n, dtype=_I)

    def run_path(self, path, z, w, v, slack_basis):
        """As :meth:`PathEngine.run_path`, with BLAS on one thread: the factorizations'
        dense tails of 256 columns and more are updated by BLAS (see
        :mod:`compass_sparse.path._sparse_steps`), and a second thread waiting for work
        between those calls doubled the CPU time of the CGE endowment shock at n = 2024
        (4.4 s against 2.3 s) and lengthened its wall time (2.45 against 2.28 s)."""
        with single_threaded_blas():
            return super().run_path(path, z, w, v, slack_basis)

    def _allocate(self, nnz_guess=None):
        n = self.n
        if nnz_guess is None:
            nnz_guess = 2 * int(self._Mp[-1]) + 8 * n
        self._S = self._within_budget(n, self.update_limit, nnz_guess)
        perm = np.zeros((N_PERM, max(n, 2)), dtype=_I)  # (its repair rows serve the LU)
        self._D = (*_DENSE_PLACEHOLDERS, perm, np.zeros((3, 2)))
        self.stats.backend, self.stats.ordering = "sparse engine", ORDERING

    def _grow(self):
        size = SL.grown_size(self._S)
        self._S = None  # (the old storage is released before the new is taken)
        self._S = self._within_budget(*size)

    def _within_budget(self, n, update_limit, nnz_guess):
        """The factors' storage, unless it would exceed ``MEMORY_SHARE`` of the memory the
        system reports available (the manager's budget for its factors): then
        FactorBudgetError, which the solve reports as MEMORY_LIMIT."""
        need = SL.storage_bytes(n, update_limit, nnz_guess)
        avail = FactorBudget.available_memory()
        if avail is not None and need > MEMORY_SHARE * avail:
            raise FactorBudgetError(
                "memory", f"the sparse engine's factors of a {n} x {n} basis would need "
                f"{need / 2**30:.1f} GiB ({nnz_guess:.3g} entries of L and U, "
                f"{update_limit} updates); {MEMORY_SHARE * avail / 2**30:.1f} GiB allowed")
        return SL.allocate(n, update_limit, nnz_guess)

    def _account(self, istate):
        super()._account(istate)
        h = self._S[0]
        self.stats.max_nnz_lu = max(self.stats.max_nnz_lu, int(h[SL.H_BASE]))
        self.stats.pivot_lu_entries += int(istate[K.I_LUSUM])

    def prepare(self, q, lb, ub):
        if self._S is None:
            self._allocate()
        r = self.r
        rI = np.flatnonzero(r).astype(_I)
        prob = (self._D[0], self._Mp, self._Mi, self._Mx, q, r, rI, r[rI], lb, ub,
                self.colkey)
        return prob, self._D, self._S
