"""The linear MCP of a major iteration (thesis §3.2, §3.4).

At z_k = pi(x_k) with F(z_k) = f and the proximal perturbation eps (Billups),

    M = J(z_k) + eps I,   q = f - M z_k,   r = f + x_k - z_k,

r being the normal map of the linearization at x_k (the covering vector of the path).
M's pattern is pattern(J) united with the diagonal whatever the values, so it is the same
in every major iteration and every solve of a problem: :class:`Linearizer` keeps its index
arrays and the positions of J's entries and of the diagonal in it, and fills M's values in
place (one compiled pass with q and r for the solver's float vectors).
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from ..box import solver_vectors
from ..linalg._csc_kernels import csc_matvec
from ..linalg.csc import trusted_csc
from ._kernels import newton_linearization

__all__ = ["Linearizer", "linearizer_for"]


class Linearizer:
    """M = J + eps I on the fixed pattern pattern(J) U diag, filled in place."""

    def __init__(self, J: sp.csc_matrix):
        n = J.shape[0]
        self.n = n
        self.nnz_J = J.nnz
        key_D = np.arange(n, dtype=np.int64) * (n + 1)
        if J.nnz == n * n:
            # A full pattern (a dense Jacobian) holds the diagonal: M has J's pattern.
            self._same_pattern(J, key_D)
            return
        # Structural union of pattern(J) and the diagonal, as sorted keys col * n + row
        # (values of J could cancel against the identity and vanish); built with array
        # operations, no sparse arithmetic: small problems build one per solve.
        col = np.repeat(np.arange(n, dtype=np.int64), np.diff(J.indptr))
        key_J = col * n + J.indices
        pos_D = np.searchsorted(key_J, key_D)
        if key_J.size and (pos_D < key_J.size).all() and (key_J[pos_D] == key_D).all():
            self._same_pattern(J, key_D, pos_D)  # the diagonal is stored already
            return
        # (a sort and a mask: numpy 2's hashing np.union1d took 0.6 s at n = 3e4, this 30 ms)
        keys = np.sort(np.concatenate((key_J, key_D)))
        keys = keys[np.concatenate(([True], keys[1:] != keys[:-1]))]
        indices = (keys % n).astype(np.int32)
        indptr = np.searchsorted(keys, np.arange(n + 1, dtype=np.int64) * n).astype(np.int32)
        self.M = trusted_csc(np.zeros(keys.size), indices, indptr, (n, n))
        # position of each J entry and each diagonal entry inside M's pattern
        self.pos_J = np.searchsorted(keys, key_J)
        self.pos_D = np.searchsorted(keys, key_D)

    def _same_pattern(self, J, key_D, pos_D=None):
        """M on J's own (canonical) pattern; ``pos_D``: the diagonal's positions in it
        (on a full pattern the diagonal of column j is entry j * (n + 1))."""
        n = self.n
        self.M = trusted_csc(np.zeros(J.nnz), J.indices.astype(np.int32),
                             J.indptr.astype(np.int32), (n, n))
        self.pos_J = None  # J's entries are M's, in the same order
        self.pos_D = key_D if pos_D is None else pos_D

    def linearize(self, J, eps: float, z, f, x):
        """(M, q, r) of the major iteration at z (F = f) from x: M = J + eps I, q = f - M z
        and r = f + x - z (the normal map of the linearization at x), in one compiled pass
        for the solver's float vectors (five array steps cost a small problem ~10 us per
        major iteration); the same bits either way."""
        n = self.n
        if (J.data.dtype == np.float64 and J.data.shape[0] == J.nnz
                and solver_vectors(z, f, x, x) and z.shape[0] == n):
            data = np.empty(self.M.data.shape[0])
            q, r = np.empty(n), np.empty(n)
            scatter = self.pos_J is not None
            newton_linearization(J.data, self.pos_J if scatter else self.pos_D, scatter,
                                 self.pos_D, float(eps), self.M.indptr, self.M.indices,
                                 z, f, x, data, q, r)
            return trusted_csc(data, self.M.indices, self.M.indptr, self.M.shape), q, r
        z, f, x = (np.asarray(a, dtype=float) for a in (z, f, x))
        M = self(J, eps)
        Mz = np.empty(n)
        csc_matvec(M.indptr, M.indices, M.data, z, Mz)  # M @ z without scipy's dispatch
        return M, f - Mz, f + x - z

    def __call__(self, J, eps: float) -> sp.csc_matrix:
        if self.pos_J is None:
            data = J.data.copy()
        else:
            data = np.zeros_like(self.M.data)
            data[self.pos_J] = J.data  # canonical pattern: positions are distinct
        if eps:
            data[self.pos_D] += eps
        return trusted_csc(data, self.M.indices, self.M.indptr, self.M.shape)


def linearizer_for(J, P):
    """A Linearizer of J when J is stored on the pattern P (None otherwise: not kept)."""
    if P is None or not (J.nnz == P.nnz and J.indptr.shape == P.indptr.shape
                         and np.array_equal(J.indptr, P.indptr)
                         and np.array_equal(J.indices, P.indices)):
        return None
    return Linearizer(J)
