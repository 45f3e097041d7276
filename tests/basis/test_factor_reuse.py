"""Solves on reused factors (BasisOptions.reuse_factors): GMRES preconditioned by the LU
of an older basis of the same slot table agrees with a fresh factorization, and every
doubt ends in a fresh factorization."""

import numpy as np
import pytest
import scipy.linalg
import scipy.sparse as sp

from basis_helpers import dense_B, dominant_dense_column, dominant_matrix, family_start, rel_err
from compass_sparse.basis import (KIND_DENSE, KIND_M, BasisManager, BasisOptions, FactorReuseFailed,
                                  UpdateStatus)
from compass_sparse.basis.krylov import preconditioned_gmres

pytestmark = pytest.mark.usefixtures("lu_choice")


def _moved(M, rng, size):
    """M with every stored value moved by a relative amount up to ``size`` (same pattern)."""
    M2 = M.copy()
    M2.data = M2.data * (1.0 + size * rng.uniform(-1.0, 1.0, M2.nnz))
    return M2


def _setup(n=80, seed=0, **opts):
    rng = np.random.default_rng(seed)
    M = dominant_matrix(n, 0.06, rng)
    r = dominant_dense_column(M, 0, rng)
    bm = BasisManager(M, BasisOptions(reuse_factors=True, reuse_min_nnz=0, **opts))
    bm.set_dense_column(r)
    table = family_start(n, rng)
    bm.factor(*table)
    return bm, M, r, table, rng


def _backward_error(B, x, b):
    return np.abs(B @ x - b).max() / (np.abs(b).max() + np.abs(B).sum(axis=1).max()
                                      * np.abs(x).max())


def test_gmres_with_nearby_preconditioner_reaches_the_solution():
    rng = np.random.default_rng(3)
    n = 60
    A = np.eye(n) * 4 + rng.uniform(-1, 1, (n, n)) / n
    P = A + rng.uniform(-1, 1, (n, n)) * 0.05 / n     # an older, nearby matrix
    lu = scipy.linalg.lu_factor(P)
    b = rng.standard_normal(n)
    x, steps, res = preconditioned_gmres(lambda v: A @ v, lambda v: scipy.linalg.lu_solve(lu, v),
                                         b, 1e-13, 20)
    assert rel_err(x, np.linalg.solve(A, b)) < 1e-12
    assert 1 <= steps <= 8 and res <= 1e-13
    # a poor preconditioner and two steps: the estimate says it did not converge
    _, steps, res = preconditioned_gmres(lambda v: A @ v, lambda v: v / 100.0, b, 1e-13, 2)
    assert steps == 2 and res > 1e-13


def test_reuse_agrees_with_fresh_factorization():
    bm, M, r, table, rng = _setup()
    M2 = _moved(M, rng, 1e-3)
    bm.set_matrix(M2)
    bm.factor(*table)
    assert bm.reusing and bm.stats.factorizations == 1 and bm.stats.reuses == 1
    B = dense_B(bm.kinds, bm.indices, bm.signs, M2, r)
    b = rng.standard_normal(B.shape[0])
    x = bm.ftran(b)
    assert rel_err(x, np.linalg.solve(B, b)) < 1e-10
    assert _backward_error(B, x, b) <= 1e-12
    # the covering vector was solved in lockstep with b: its FTRAN costs no more GMRES
    assert bm.stats.reuse_solves == 2
    dr = bm.ftran_column(KIND_DENSE, 0, -1.0)
    assert bm.stats.reuse_solves == 2
    assert rel_err(dr, np.linalg.solve(B, -r)) < 1e-10
    s = int(np.flatnonzero(np.asarray(bm.kinds) == KIND_M)[0])
    j = int(bm.indices[s])
    d = bm.ftran_column(KIND_M, j, 1.0)
    e = np.zeros(B.shape[0])
    e[s] = 1.0
    assert rel_err(d, e) < 1e-10            # B^{-1} (column s of B) = e_s
    assert bm.stats.factorizations == 1 and bm.stats.reuse_solves == 3
    # the fresh solve of the same system agrees
    fresh = BasisManager(M2, BasisOptions())
    fresh.set_dense_column(r)
    fresh.factor(*table)
    assert rel_err(x, fresh.ftran(b)) < 1e-10


def test_reuse_falls_back_when_old_factors_are_a_bad_preconditioner():
    bm, M, r, table, rng = _setup(seed=1)
    M2 = M.copy()
    M2.data = rng.uniform(-1, 1, M2.nnz) * 10.0       # same pattern, unrelated values
    M2 = M2 + sp.diags(np.full(M2.shape[0], 0.0))     # (keeps the pattern: diagonal stored)
    M2 = sp.csc_matrix(M2)
    assert np.array_equal(M2.indices, sp.csc_matrix(M).indices)
    bm.set_matrix(M2)
    bm.factor(*table)
    assert bm.reusing
    B = dense_B(bm.kinds, bm.indices, bm.signs, M2, r)
    b = rng.standard_normal(B.shape[0])
    if abs(np.linalg.det(B)) == 0.0:  # pragma: no cover - the seed gives a regular B
        pytest.skip("singular draw")
    try:
        x = bm.ftran(b)
    except FactorReuseFailed:   # the unrelated values made B singular: also a fallback
        assert bm.stats.reuse_fallbacks == 1
        return
    assert bm.stats.reuse_fallbacks == 1 and bm.stats.factorizations == 2
    assert not bm.reusing
    assert _backward_error(B, x, b) <= 1e-12


def test_reused_singular_basis_raises_and_factor_starts_afresh():
    bm, M, r, table, rng = _setup(seed=2)
    kinds, indices, _ = table
    j = int(indices[np.flatnonzero(kinds == KIND_M)[0]])
    M2 = M.copy()
    M2.data[M2.indptr[j]:M2.indptr[j + 1]] = 0.0      # stored zeros: the pattern stays
    bm.set_matrix(M2)
    bm.factor(*table)
    assert bm.reusing
    with pytest.raises(FactorReuseFailed):
        bm.ftran(np.ones(M.shape[0]))
    rep = bm.factor(*table)                            # afresh now, with its repair
    assert not bm.reusing and rep.rank_deficiency == 1


def test_replace_and_btran_on_reused_factors_factor_afresh_first():
    bm, M, r, table, rng = _setup(seed=4)
    M2 = _moved(M, rng, 1e-4)
    bm.set_matrix(M2)
    bm.factor(*table)
    c = rng.standard_normal(M.shape[0])
    y = bm.btran(c)
    assert bm.stats.factorizations == 2 and not bm.reusing
    B = dense_B(bm.kinds, bm.indices, bm.signs, M2, r)
    assert rel_err(y, np.linalg.solve(B.T, c)) < 1e-10
    bm.set_matrix(_moved(M2, rng, 1e-4))
    bm.factor(*table)
    assert bm.reusing
    s = int(np.flatnonzero(np.asarray(bm.kinds) == KIND_M)[0])
    j = int(bm.indices[s])
    st = bm.replace(s, 1, j, -1.0)                     # M_j -> -e_j
    assert st in (UpdateStatus.OK, UpdateStatus.REFACTORED)
    assert bm.stats.factorizations == 3 and not bm.reusing


def test_no_reuse_after_pattern_change_or_other_slot_table():
    bm, M, r, table, rng = _setup(seed=5)
    M2 = sp.csc_matrix(M + sp.eye(M.shape[0], k=3) * 1e-3)   # a new pattern
    bm.set_matrix(M2)
    bm.factor(*table)
    assert not bm.reusing and bm.stats.factorizations == 2
    bm.set_matrix(_moved(M2, rng, 1e-4))
    kinds, indices, signs = table
    bm.factor(kinds, indices, -signs)                       # another slot table
    assert not bm.reusing and bm.stats.factorizations == 3


@pytest.mark.parametrize("tol", [1e-16, 1e-14, 1e-12, 1e-9, 1e-6])
@pytest.mark.parametrize("iters", [1, 3, 12, 40])
def test_reuse_tolerances_stress(tol, iters):
    """Every (tolerance, step limit) pair answers within its tolerance: accepted solves
    meet it, the others fall back to a fresh factorization."""
    bm, M, r, table, rng = _setup(seed=6, reuse_tolerance=tol, reuse_iterations=iters)
    M2 = _moved(M, rng, 1e-2)
    bm.set_matrix(M2)
    bm.factor(*table)
    B = dense_B(bm.kinds, bm.indices, bm.signs, M2, r)
    b = rng.standard_normal(B.shape[0])
    x = bm.ftran(b)
    err = _backward_error(B, x, b)
    if bm.stats.reuse_fallbacks:
        assert bm.stats.factorizations == 2 and err <= 1e-13
    else:
        assert err <= tol
    assert rel_err(x, np.linalg.solve(B, b)) <= max(1e4 * tol, 1e-10)
    if iters == 1 and tol <= 1e-9:   # one step cannot bring a 1% move that far
        assert bm.stats.reuse_fallbacks == 1


def test_reuse_option_validation():
    from compass_sparse.exceptions import OptionError

    with pytest.raises(OptionError):
        BasisOptions(reuse_tolerance=0.0)
    with pytest.raises(OptionError):
        BasisOptions(reuse_tolerance=1e-3)
    with pytest.raises(OptionError):
        BasisOptions(reuse_iterations=0)
    with pytest.raises(OptionError):
        BasisOptions(reuse_min_nnz=-1)


def _offer_setup(seed, move):
    """A basis whose M columns are the labels L and whose unit columns cover the other rows,
    and the SuperLU factors of M_LL moved by ``move`` (as the crash leaves them)."""
    from compass_sparse.basis import KIND_UNIT
    from compass_sparse.basis.backends import SuperLUBackend

    rng = np.random.default_rng(seed)
    n = 90
    M = dominant_matrix(n, 0.06, rng)
    labels = np.sort(rng.choice(n, 60, replace=False))
    kinds = np.full(n, KIND_UNIT)
    kinds[labels] = KIND_M
    indices = np.arange(n)
    signs = np.where(rng.random(n) < 0.5, -1.0, 1.0)
    perm = rng.permutation(n)                       # slots in any order
    table = (kinds[perm], indices[perm], signs[perm])
    Mold = _moved(M, rng, move)
    K = sp.csc_matrix(Mold[labels][:, labels])
    _, held = SuperLUBackend().solve(K, np.ones(labels.size), keep=True)
    return M, labels, held, table, rng


@pytest.mark.parametrize("move", [1e-3, 3e-2])
def test_offered_crash_factors_solve_the_first_basis_like_a_fresh_factorization(move):
    M, labels, held, table, rng = _offer_setup(7, move)
    bm = BasisManager(M, BasisOptions(reuse_factors=True, reuse_min_nnz=0))
    bm.offer_factors(labels, held)
    bm.factor(*table)
    assert bm.reusing and bm.stats.factorizations == 0
    B = dense_B(bm.kinds, bm.indices, bm.signs, M, None)
    b = rng.standard_normal(B.shape[0])
    x = bm.ftran(b)
    assert bm.stats.reuse_fallbacks == 0 and bm.stats.factorizations == 0
    assert rel_err(x, np.linalg.solve(B, b)) < 1e-10
    assert _backward_error(B, x, b) <= 1e-12


def test_offered_factors_of_another_block_are_not_used_and_bad_ones_fall_back():
    M, labels, held, table, rng = _offer_setup(8, 1e-3)
    bm = BasisManager(M, BasisOptions(reuse_factors=True, reuse_min_nnz=0))
    bm.offer_factors(labels[1:], held)               # another block's size: ignored
    bm.factor(*table)
    assert not bm.reusing and bm.stats.factorizations == 1
    # factors with more fill than their ordering's estimate (off-diagonal pivots): ignored
    from compass_sparse.basis.ordering import Ordering

    est = held.ordering
    if est.method in ("amd", "metis"):
        low = Ordering(est.method, est.rows, est.cols, nnz_lu=held.lu.nnz - 1)
        bm1 = BasisManager(M, BasisOptions(reuse_factors=True, reuse_min_nnz=0))
        bm1.offer_factors(labels, type(held)(held.lu, low, held.n))
        bm1.factor(*table)
        assert not bm1.reusing
    # a useless preconditioner: the solve falls back to a fresh factorization
    bad = type(held)(held.lu, held.ordering, held.n)
    bad.solve = lambda v: -0.01 * v
    bm2 = BasisManager(M, BasisOptions(reuse_factors=True, reuse_min_nnz=0))
    bm2.offer_factors(labels, bad)
    bm2.factor(*table)
    assert bm2.reusing
    B = dense_B(bm2.kinds, bm2.indices, bm2.signs, M, None)
    b = rng.standard_normal(B.shape[0])
    x = bm2.ftran(b)
    assert bm2.stats.reuse_fallbacks == 1 and bm2.stats.factorizations == 1
    assert _backward_error(B, x, b) <= 1e-13


def test_gmres_in_lockstep_solves_each_column_like_alone():
    rng = np.random.default_rng(11)
    n = 70
    A = np.eye(n) * 3 + rng.uniform(-1, 1, (n, n)) / n
    lu = scipy.linalg.lu_factor(A + rng.uniform(-1, 1, (n, n)) * 0.1 / n)
    calls = []

    def psolve(v):
        calls.append(v.shape)
        return scipy.linalg.lu_solve(lu, v)

    Bm = rng.standard_normal((n, 2))
    X, steps, res = preconditioned_gmres(lambda v: A @ v, psolve, Bm, [1e-13, 1e-13], 25)
    for c in range(2):
        assert rel_err(X[:, c], np.linalg.solve(A, Bm[:, c])) < 1e-11
        assert res[c] <= 1e-13
    assert any(s == (n, 2) for s in calls)            # one solve served both columns
    x1, _, _ = preconditioned_gmres(lambda v: A @ v, psolve, Bm[:, 1], 1e-13, 25)
    assert rel_err(X[:, 1], x1) < 1e-11
