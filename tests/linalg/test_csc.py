"""CSC helpers (compass_sparse.linalg.csc)."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from compass_sparse.linalg._csc_kernels import csc_rmatvec
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


@pytest.mark.parametrize("n,density", [(1, 1.0), (7, 0.5), (60, 0.1)])
def test_csc_rmatvec_is_transpose_product(n, density):
    rng = np.random.default_rng(n)
    A = sp.random(n, n, density=density, format="csc", random_state=n)
    u = rng.standard_normal(n)
    out = np.empty(n)
    csc_rmatvec(A.indptr, A.indices, A.data, u, out)
    assert np.allclose(out, A.T @ u, rtol=1e-14, atol=1e-14)


def test_dense_jacobian_gets_canonical_full_pattern_each_call():
    from compass_sparse.linalg.csc import canonical_csc as _canonical_csc

    A = np.arange(9.0).reshape(3, 3)
    C1 = _canonical_csc(A, 3)
    C1.indices[:] = 0  # a caller mutating its matrix must not touch the next one
    C2 = _canonical_csc(A, 3)
    assert np.array_equal(C2.toarray(), A) and C2.has_canonical_format
    assert C2.nnz == 9


# ---------------------------------------------------------------- fixed per-solve cost
def _valid_csc_arrays(rng, n, density, sort=True):
    cols = [np.flatnonzero(rng.random(n) < density) for _ in range(n)]
    if not sort:
        cols = [rng.permutation(c) for c in cols]
    indptr = np.concatenate([[0], np.cumsum([c.size for c in cols])]).astype(np.int32)
    indices = (np.concatenate(cols) if cols else np.zeros(0)).astype(np.int32)
    return rng.standard_normal(indices.size), indices, indptr


@pytest.mark.parametrize("sort", [True, False])
def test_trusted_csc_equals_the_checked_constructor(sort):
    from compass_sparse.linalg.csc import trusted_csc

    rng = np.random.default_rng(3)
    for n in (1, 2, 7, 30):
        data, indices, indptr = _valid_csc_arrays(rng, n, 0.4, sort=sort)
        T = trusted_csc(data, indices, indptr, (n, n))
        C = sp.csc_matrix((data, indices, indptr), shape=(n, n))
        assert type(T) is type(C) and T.shape == C.shape
        # the flags are computed from the arrays, not assumed
        assert T.has_sorted_indices == C.has_sorted_indices
        assert T.has_canonical_format == C.has_canonical_format
        x = rng.standard_normal(n)
        np.testing.assert_array_equal(T @ x, C @ x)
        np.testing.assert_array_equal(T.toarray(), C.toarray())
        np.testing.assert_array_equal((T + T).toarray(), (C + C).toarray())
        np.testing.assert_array_equal(T.tocsr().toarray(), C.toarray())


def test_trusted_csc_with_int64_indices_falls_back_to_the_checked_constructor():
    from compass_sparse.linalg.csc import trusted_csc

    T = trusted_csc(np.ones(2), np.array([0, 1]), np.array([0, 1, 2]), (2, 2))
    np.testing.assert_array_equal(T.toarray(), np.eye(2))


@pytest.mark.parametrize("n,density", [(1, 1.0), (5, 0.6), (40, 0.1)])
def test_csc_abs_maxima_matches_array_formulas(n, density):
    """Row and column max-norms and the diagonal of a canonical CSC in one compiled pass
    agree with numpy's (a NaN entry poisons its row and column, as np.maximum does)."""
    from compass_sparse.linalg._csc_kernels import csc_abs_maxima

    A = sp.random(n, n, density=density, format="csc", random_state=n) - 0.5 * sp.random(
        n, n, density=density, format="csc", random_state=n + 1)
    A = sp.csc_matrix(A)
    A.sum_duplicates()
    if A.nnz and n > 1:
        A.data[A.nnz // 2] = np.nan
    rows, cols, diag = np.zeros(n), np.empty(n), np.empty(n)
    csc_abs_maxima(A.indptr, A.indices, A.data, rows, cols, diag)
    dense = np.abs(A.toarray())  # absent entries are 0, below every |stored| but NaN
    with np.errstate(invalid="ignore"):
        assert np.array_equal(rows, np.max(dense, axis=1), equal_nan=True)
        assert np.array_equal(cols, np.max(dense, axis=0), equal_nan=True)
    assert np.array_equal(diag, A.diagonal(), equal_nan=True)


@pytest.mark.parametrize("n,density", [(1, 1.0), (7, 0.5), (60, 0.1)])
def test_csc_matvec_is_scipy_product_bitwise(n, density):
    """The linearization's M z in compiled code, bit for bit scipy's CSC product (same
    order of the sums), entries over 40 orders of magnitude."""
    from compass_sparse.linalg._csc_kernels import csc_matvec

    rng = np.random.default_rng(n)
    A = sp.random(n, n, density=density, format="csc", random_state=n)
    A.data *= 10.0 ** rng.uniform(-20, 20, A.nnz)
    x = rng.standard_normal(n) * 10.0 ** rng.uniform(-20, 20, n)
    out = np.full(n, np.nan)
    csc_matvec(A.indptr, A.indices, A.data, x, out)
    assert np.array_equal(out, A @ x)


def test_csc_same_pattern_compares_pointers_and_the_stored_indices():
    """The pattern test of the evaluator, the preprocessor and the KLU cache: equal when
    the pointers and the first nnz row indices agree (room beyond nnz is ignored), and
    against numpy's comparison of the arrays on random patterns, equal and not."""
    from compass_sparse.linalg._csc_kernels import csc_same_pattern

    rng = np.random.default_rng(9)
    seen = set()
    for trial in range(200):
        n = int(rng.integers(1, 12))
        A = sp.csc_matrix(sp.random(n, n, density=0.4, random_state=rng))
        B = A.copy()
        if trial % 3 == 1 and B.nnz:
            B.indices[int(rng.integers(B.nnz))] = (B.indices[0] + 1) % n  # a row moved
        elif trial % 3 == 2:
            B = sp.csc_matrix(sp.random(n, n, density=0.4, random_state=rng))
        ref = (np.array_equal(A.indptr, B.indptr)
               and np.array_equal(A.indices[:A.nnz], B.indices[:B.nnz]))
        assert csc_same_pattern(B.indptr, B.indices, A.indptr, A.indices[:A.nnz]) == ref
        seen.add(ref)
    assert seen == {True, False}
    P = sp.csc_matrix(np.eye(3))
    longer = np.concatenate([P.indices, np.array([7, 7], np.int32)])
    assert csc_same_pattern(P.indptr, longer, P.indptr, P.indices)
    assert not csc_same_pattern(P.indptr[:-1], P.indices, P.indptr, P.indices)

