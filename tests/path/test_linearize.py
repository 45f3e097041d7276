"""The linearization of a major iteration (compass_sparse.path.linearize): M = J + eps I on
the pattern of J and the diagonal, q and r, in one compiled pass with the array
formulas' bits."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp


def test_linearizer_pattern_is_jacobian_pattern_union_diagonal():
    from compass_sparse.path.linearize import Linearizer

    rng = np.random.default_rng(5)
    for n in (1, 3, 12, 40):
        J = sp.random(n, n, density=0.3, random_state=rng, format="csc")
        J.sort_indices()
        J.data[: J.nnz // 2] = 0.0  # stored zeros keep their place
        L = Linearizer(J)
        ones = sp.csc_matrix((np.ones(J.nnz), J.indices, J.indptr), shape=J.shape)
        P = (ones + sp.identity(n, format="csc")).tocsc()
        P.sort_indices()
        np.testing.assert_array_equal(L.M.indptr, P.indptr)
        np.testing.assert_array_equal(L.M.indices, P.indices)
        M = L(J, 0.25)
        np.testing.assert_array_equal(M.toarray(), J.toarray() + 0.25 * np.eye(n))
        assert M.nnz == P.nnz


@pytest.mark.parametrize("kind", ["full", "with diagonal", "without diagonal"])
def test_linearizer_on_patterns_that_hold_the_diagonal(kind):
    """A full pattern and a pattern that stores the whole diagonal give M = J + eps I on
    J's own pattern (stored zeros kept); one without it gets the diagonal added."""
    from compass_sparse.linalg.csc import canonical_csc
    from compass_sparse.path.linearize import Linearizer

    rng = np.random.default_rng(8)
    n = 9
    if kind == "full":
        J = canonical_csc(rng.standard_normal((n, n)) * (rng.random((n, n)) < 0.5), n)
    else:
        J = sp.random(n, n, density=0.3, random_state=rng, format="csc")
        if kind == "with diagonal":
            J = (J + sp.diags(rng.standard_normal(n))).tocsc()
            J.data[::3] = 0.0  # stored zeros, some on the diagonal
        else:
            J = J.tolil()
            J.setdiag(0.0)
            J = J.tocsc()
            J.eliminate_zeros()
            J[0, 1] = 1.0
        J.sort_indices()
    L = Linearizer(J)
    if kind == "without diagonal":
        assert L.M.nnz == J.nnz + n
    else:
        np.testing.assert_array_equal(L.M.indptr, J.indptr)
        np.testing.assert_array_equal(L.M.indices, J.indices)
    for eps in (0.0, 0.5):
        M = L(J, eps)
        np.testing.assert_array_equal(M.toarray(), J.toarray() + eps * np.eye(n))


@pytest.mark.parametrize("kind", ["full", "with diagonal", "without diagonal"])
def test_one_pass_linearization_gives_the_array_formulas_bits(kind):
    """Linearizer.linearize: M = J + eps I, q = f - M z and r = f + x - z of a major
    iteration in one compiled pass give the array formulas' bits (M's entries and pattern,
    q with M z summed column by column, r), on J's own pattern and with the diagonal
    added; a vector that is not the solver's float vector takes the array route."""
    from compass_sparse.linalg._csc_kernels import csc_matvec
    from compass_sparse.linalg.csc import canonical_csc
    from compass_sparse.path.linearize import Linearizer

    rng = np.random.default_rng(21)
    n = 11
    if kind == "full":
        J = canonical_csc(rng.standard_normal((n, n)), n)
    else:
        J = sp.random(n, n, density=0.3, random_state=rng, format="csc")
        J = (J + sp.diags(rng.standard_normal(n))).tocsc() if kind == "with diagonal" \
            else J
        J = J.tolil()
        if kind == "without diagonal":
            J.setdiag(0.0)
        J = canonical_csc(J.tocsc(), n)
        J.eliminate_zeros()
    L = Linearizer(J)
    z, f, x = (rng.standard_normal(n) * 10.0 ** rng.integers(-3, 4, n) for _ in range(3))
    for eps in (0.0, 1e-3):
        M, q, r = L.linearize(J, eps, z, f, x)
        ref = L(J, eps)
        Mz = np.empty(n)
        csc_matvec(ref.indptr, ref.indices, ref.data, z, Mz)
        for a in ("indptr", "indices", "data"):
            assert np.array_equal(getattr(M, a), getattr(ref, a)), a
        assert np.array_equal(q, f - Mz) and np.array_equal(r, f + x - z)
        M2, q2, r2 = L.linearize(J, eps, list(z), f, x)  # not a float vector: arrays
        assert np.array_equal(M2.data, ref.data) and np.array_equal(q2, q)
        assert np.array_equal(r2, r)
