"""CSC helpers (compass_sparse.linalg.csc)."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from compass_sparse.linalg.csc import reduced_system


@pytest.mark.parametrize("seed", range(4))
def test_reduced_system_compiled_pass_agrees_with_scipys_slicing(seed):
    """The one-call compiled M_FF (a boolean ``free``) is scipy's M[F][:, F] exactly, and
    its right-hand side -(q + M_FN z_N)_F to rounding (the sums run in another order)."""
    rng = np.random.default_rng(seed)
    n = 80
    M = sp.csc_matrix(sp.random(n, n, density=0.06, random_state=seed) + sp.eye(n))
    free = rng.random(n) < 0.6
    z, q = rng.standard_normal(n), rng.standard_normal(n)
    K, rhs = reduced_system(M, free, z, q)
    K2, rhs2 = _reduced_system_general(M, free, z, q)
    np.testing.assert_allclose(rhs, rhs2, rtol=1e-13, atol=1e-13)  # (another sum order)
    for a in ("indptr", "indices", "data"):
        assert np.array_equal(getattr(K, a), getattr(K2, a))
        assert getattr(K, a).dtype == getattr(K2, a).dtype
    assert K.shape == K2.shape
    none = np.zeros(n, dtype=bool)
    K0, r0 = reduced_system(M, none, z, q)
    assert K0.shape == (0, 0) and r0.size == 0


def _reduced_system_general(M, free, z, q):
    """The reference by scipy's slicing: M_FF and -(q + M_FN z_N)_F."""
    F, N = np.flatnonzero(free), np.flatnonzero(~free)
    K = sp.csc_matrix(M[F][:, F], dtype=float)
    K.sort_indices()
    K.indices = K.indices.astype(np.int32)
    K.indptr = K.indptr.astype(np.int32)
    return K, -(q[F] + M[F][:, N] @ z[N])
