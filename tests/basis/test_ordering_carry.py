"""Orderings carried over between principal submatrices of one matrix whose index sets
differ by a few indices (the crash's reduced Jacobians)."""

import numpy as np
import pytest
import scipy.sparse as sp
from scipy.sparse.linalg import splu

from compass_sparse.basis import ordering as ordmod
from compass_sparse.basis.backends import _permute, solve_sparse

pytestmark = pytest.mark.usefixtures("lu_choice")


def _grid_with_shuffled_rows(k, seed):
    """A 2-D grid Laplacian-like matrix (nested dissection pays) with some rows swapped
    so that the matching is not the identity."""
    rng = np.random.default_rng(seed)
    T = sp.diags([-1.0, 4.0, -1.3], [-1, 0, 1], shape=(k, k))
    A = sp.csc_matrix(sp.kron(sp.eye(k), T) + sp.kron(sp.diags([-1.0, -0.7], [-1, 1],
                                                              shape=(k, k)), sp.eye(k)))
    A.data *= rng.uniform(0.5, 1.5, A.nnz)
    p = np.arange(A.shape[0])
    for i in range(0, A.shape[0] - 1, 7):     # swaps: rows i, i+1 exchanged
        p[i], p[i + 1] = p[i + 1], p[i]
    return sp.csc_matrix(A[p, :])


def _fill(K, o):
    lu = splu(_permute(K, o.rows, o.cols), permc_spec="NATURAL", diag_pivot_thresh=0.1,
              options=dict(SymmetricMode=True))
    return lu.L.nnz + lu.U.nnz


@pytest.mark.parametrize("change", [[5], [0, 300], [17, 18, 19]])
@pytest.mark.parametrize("method", ["amd", "metis"])
def test_carried_ordering_is_valid_and_fills_like_a_fresh_one(change, method):
    J = _grid_with_shuffled_rows(24, 1)
    n = J.shape[0]
    old_labels = np.setdiff1d(np.arange(n), [100])           # the crash's last set
    Kold = sp.csc_matrix(J[old_labels][:, old_labels])
    old = ordmod.compute_ordering(Kold, method)
    assert old.method == method
    labels = np.setxor1d(old_labels, change)                   # a few indices moved
    K = sp.csc_matrix(J[labels][:, labels])
    c = ordmod.carry_ordering(K, labels, old_labels, old)
    assert c is not None and c.method == method
    m = labels.size
    assert np.array_equal(np.sort(c.rows), np.arange(m))
    assert np.array_equal(np.sort(c.cols), np.arange(m))
    assert np.all(K.toarray()[c.rows, c.cols] != 0.0)         # zero-free diagonal
    fresh = ordmod.compute_ordering(K, method)
    assert _fill(K, c) <= 1.15 * _fill(K, fresh)


def test_carry_refused_when_the_block_has_no_zero_free_diagonal():
    J = _grid_with_shuffled_rows(10, 2)
    n = J.shape[0]
    old_labels = np.arange(n - 1)
    old = ordmod.compute_ordering(sp.csc_matrix(J[old_labels][:, old_labels]), "amd")
    K = sp.lil_matrix(J)
    K[:, 7] = 0.0                                               # structurally singular
    assert ordmod.carry_ordering(sp.csc_matrix(K), np.arange(n), old_labels, old) is None


def test_solve_sparse_with_labels_carries_the_ordering_and_solves(lu_choice):
    ordmod._SHARED.clear()
    del ordmod._NEAR[:]
    J = _grid_with_shuffled_rows(30, 3)            # n = 900 >= the AMD threshold
    n = J.shape[0]
    rng = np.random.default_rng(0)
    for drop in ([4], [4, 500], [500]):
        labels = np.setdiff1d(np.arange(n), drop)
        K = sp.csc_matrix(J[labels][:, labels])
        b = rng.standard_normal(labels.size)
        x = solve_sparse(K, b, labels=labels)
        assert np.abs(K @ x - b).max() <= 1e-10 * (1 + np.abs(b).max())
    if lu_choice in ("superlu:colamd", "umfpack"):
        assert not ordmod._NEAR            # no symmetric ordering to carry
        return
    # the first set was ordered afresh, the two neighbours carried it over
    assert len(ordmod._NEAR) == 3
    assert sum(o.time < 0.5 and o.nnz_lu == ordmod._NEAR[0][2].nnz_lu
               for _, _, o in ordmod._NEAR) == 3


def test_labels_that_do_not_fit_the_block_are_ignored():
    J = _grid_with_shuffled_rows(8, 4)
    cache = ordmod.OrderingCache("amd")
    ordmod._SHARED.clear()
    o = cache.get(J, labels=np.arange(J.shape[0])[::-1])      # not increasing: ignored
    assert o.method == "amd" and cache.computed == 1 and cache.carried == 0
