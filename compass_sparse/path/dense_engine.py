"""The small-problem engine: the whole pivotal path in compiled code on a dense LU.

For small n the cost of a path is not arithmetic but the Python work around each pivot
and each factorization (slot tables, column specs, manager calls: 50-200 us per pivot and
~1 ms per path, measured on 4-variable problems).  :class:`DensePathEngine` stands where a
basis manager stands (the solve's basis factory hands it out for n <=
``compass_sparse.routes.DENSE_ENGINE_MAX_N``) and runs the path's loop of
:mod:`compass_sparse.path._path_kernels` on its dense factors (the loop and its Python
side are shared with the sparse engine: :mod:`compass_sparse.path.engine`).

The factorization is a dense LU with partial pivoting; column replacements are
Forrest-Tomlin updates of its U (row etas, no explicit inverse), refreshed every
``factorization_update_limit`` pivots (see :mod:`compass_sparse.path._dense_lu`).  All
work arrays (L, U, row etas, the best point) are allocated once per engine and reused by
every path of a solve.

Tolerances: a column whose eliminated pivot is at most ``rank_tolerance`` (1e-9, the dense
reference basis' repair threshold) times
max(1, its inf-norm) is dependent and repaired by an artificial; a replacement with
``|d_s| <= pivot_tolerance * max(1, ||d||_inf)`` (1e-11) is refused and the basis
refactorized (the sparse manager's tests, same defaults).  An update whose two computations
of the new diagonal of U differ by more than ``stability_tolerance`` (1e-8, relative) or
whose row eta has a multiplier above ``growth_limit`` (100) is replaced by a
refactorization.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from . import _path_kernels as K
from . import _sparse_lu as SL
from ._dense_lu import allocate_factors
from .engine import PIVOT_CHUNK, PathEngine
from ..linalg._csc_kernels import csc_to_dense

__all__ = ["DensePathEngine", "PIVOT_CHUNK"]

_I = np.int64
_NO_CSC = (np.zeros(1, _I), np.zeros(0, _I), np.zeros(0))  # the sparse kind's M: unused


class DensePathEngine(PathEngine):
    """Runs pivotal paths of a linear MCP with matrix M (n x n) in compiled code on dense
    factors.

    Takes the place of the basis manager: ``set_matrix`` / ``set_dense_column`` / ``stats``
    as the managers, and :meth:`run_path` called by :meth:`PivotalPath.run`."""

    kind = K.FAC_DENSE

    def __init__(self, M, options=None, *, update_limit: int | None = None,
                 pivot_tolerance: float = 1e-11, rank_tolerance: float = 1e-9,
                 stability_tolerance: float = 1e-8, growth_limit: float = 100.0):
        self._dense = None
        self.set_matrix(M)
        self.init_common(update_limit, options, pivot_tolerance, rank_tolerance,
                         stability_tolerance, growth_limit)
        self.L = None  # the factors: allocated by the first path (see _allocate)
        self._S = None

    def _allocate(self):
        """The factors' work areas, once per engine: a solve whose paths all end by the
        direct step (direct_step.py) never needs them."""
        self.L, self.U, self.R, self.perm, self.fwork = allocate_factors(self.n,
                                                                         self.update_limit)
        self._S = SL.empty()

    def set_matrix(self, M):
        """Take M (sparse or dense); its dense column-major copy is made when a path
        first needs it (a path ended by the direct step never does)."""
        self.n = M.shape[0]
        self._pending = M

    @property
    def M(self):
        """The dense column-major copy of M, allocated once per order and refilled for
        every later linearization."""
        M = self._pending
        if M is not None:
            n = M.shape[0]
            A = self._dense
            if A is None or A.shape != (n, n):
                A = self._dense = np.zeros((n, n), order="F")
            if sp.issparse(M) and M.format == "csc":
                csc_to_dense(M.indptr, M.indices, M.data, A)
            else:
                A[...] = M.toarray() if sp.issparse(M) else np.asarray(M, dtype=float)
            self._pending = None
        return self._dense

    def prepare(self, q, lb, ub):
        if self.L is None:
            self._allocate()
        prob = (self.M, *_NO_CSC, q, self.r, _NO_CSC[1], _NO_CSC[2], lb, ub, _NO_CSC[1])
        return prob, (self.L, self.U, self.R, self.perm, self.fwork), self._S
