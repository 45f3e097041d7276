"""Refused replacements, rank repair of singular initial bases, ill-conditioned bases."""

import numpy as np
import pytest
import scipy.sparse as sp

from basis_helpers import (check_solves, dense_B, dominant_dense_column,
                           dominant_matrix, family_start)
from compass_sparse.basis import (KIND_DENSE, KIND_M, KIND_UNIT, BasisManager,
                                  BasisOptions, SolveRepairedBasis, UpdateStatus)

pytestmark = pytest.mark.usefixtures("lu_choice")

TOL = 1e-9


def assert_repaired(bm, M, r, kinds0, idx0, signs0, rep):
    """The repaired basis is regular, keeps rank(K) non-unit columns and only the
    reported slots changed (to +e_new_row)."""
    B0 = dense_B(kinds0, idx0, signs0, M, r)
    n = B0.shape[0]
    unit0 = kinds0 == KIND_UNIT
    rows_cov = np.unique(idx0[unit0])
    unc = np.setdiff1d(np.arange(n), rows_cov)
    K = B0[np.ix_(unc, np.flatnonzero(~unit0))]
    rank = np.linalg.matrix_rank(K) if K.size else 0
    B1 = dense_B(bm.kinds, bm.indices, bm.signs, M, r)
    assert np.linalg.matrix_rank(B1) == n
    assert int(np.count_nonzero(bm.kinds != KIND_UNIT)) == rank
    assert rep.rank_deficiency == len(rep.replaced)
    changed = set()
    for (slot, ok, oi, osg, row) in rep.replaced:
        assert (ok, oi, osg) == (kinds0[slot], idx0[slot] if ok != KIND_DENSE else 0,
                                 signs0[slot])
        assert bm.kinds[slot] == KIND_UNIT and bm.indices[slot] == row
        assert bm.signs[slot] == 1.0
        changed.add(slot)
    for s in set(range(n)) - changed:
        assert bm.kinds[s] == kinds0[s] and bm.signs[s] == signs0[s]
    return B1


def test_refuse_duplicate_and_dependent_columns():
    rng = np.random.default_rng(1)
    n = 40
    M = dominant_matrix(n, 0.1, rng)
    r = dominant_dense_column(M, 3, rng)
    bm = BasisManager(M)
    bm.set_dense_column(r)
    kinds, idx, sg = family_start(n, rng)
    bm.factor(kinds, idx, sg)
    before = (bm.kinds.copy(), bm.indices.copy(), bm.signs.copy())
    # 1. a column already in the basis (in another slot)
    s_m = int(np.flatnonzero(bm.kinds == KIND_M)[0])
    other = (s_m + 1) % n
    assert bm.replace(other, KIND_M, int(bm.indices[s_m]), 1.0) == UpdateStatus.REFUSED
    # 2. a unit column already in the basis
    s_u = int(np.flatnonzero(bm.kinds == KIND_UNIT)[0])
    assert bm.replace(s_m, KIND_UNIT, int(bm.indices[s_u]), -1.0) == UpdateStatus.REFUSED
    # 3. the dense column made (nearly) dependent on the other columns
    B = dense_B(bm.kinds, bm.indices, bm.signs, M, r)
    for eps in (0.0, 1e-14):
        rdep = B[:, [1, 2, 5]] @ np.array([0.3, -1.2, 2.0]) + eps * rng.standard_normal(n)
        bm.set_dense_column(rdep)
        bm.refactor()
        assert bm.replace(9, KIND_DENSE, 0, 1.0) == UpdateStatus.REFUSED
        check_solves(bm, M, rdep, rng, TOL)
    assert bm.stats.refused_updates == 4
    assert all(np.array_equal(a, b) for a, b in zip(before, (bm.kinds, bm.indices, bm.signs)))
    check_solves(bm, M, rdep, rng, TOL)


def test_refuse_during_refactor_route_keeps_basis():
    """With update_limit=0 every replacement goes through a factorization: a singular
    new basis is detected there, the old one restored and the replacement refused."""
    rng = np.random.default_rng(2)
    n = 25
    M = dominant_matrix(n, 0.1, rng)
    bm = BasisManager(M, BasisOptions(update_limit=0))
    kinds, idx, sg = family_start(n, rng)
    bm.factor(kinds, idx, sg)
    s_m = int(np.flatnonzero(bm.kinds == KIND_M)[0])
    j = int(bm.indices[s_m])
    kb = bm.kinds.copy()
    st = bm.replace((s_m + 1) % n, KIND_M, j, -1.0)
    assert st == UpdateStatus.REFUSED
    assert np.array_equal(kb, bm.kinds)
    check_solves(bm, M, None, rng, TOL)


def test_nearly_singular_refused_after_updates():
    rng = np.random.default_rng(3)
    n = 30
    M = dominant_matrix(n, 0.15, rng)
    bm = BasisManager(M)
    bm.set_dense_column(np.ones(n))
    kinds, idx, sg = family_start(n, rng)
    bm.factor(kinds, idx, sg)
    # a few updates first
    for j in range(5):
        s = max(bm.slot_of_m(j), bm.slot_of_unit(j))
        bm.replace(s, KIND_M if bm.kinds[s] == KIND_UNIT else KIND_UNIT, j, 1.0)
    assert bm.num_updates == 5
    B = dense_B(bm.kinds, bm.indices, bm.signs, M, None)
    r = B[:, [0, 4]] @ np.array([1.0, 1.0]) * (1 + 1e-13)
    r = B[:, 0] + B[:, 4] + 1e-14 * np.abs(B).max() * rng.standard_normal(n)
    bm.set_dense_column(r)
    bm.refactor()
    assert bm.replace(7, KIND_DENSE, 0, 1.0) == UpdateStatus.REFUSED
    check_solves(bm, M, r, rng, TOL)


def _rank_case(B_kind, n, rng):
    M = dominant_matrix(n, 0.2, rng)
    Md = M.toarray()
    if B_kind == "structural":
        Md[:, 2] = 0.0                  # empty column
        Md[5, :] = 0.0                  # empty row (of the uncovered block)
        Md[:, 7] = 0.0
        Md[1, 7] = 3.0
        Md[:, 8] = 0.0
        Md[1, 8] = -2.0                 # two columns with one shared nonzero
    elif B_kind == "numerical":
        Md[:, 3] = 0.5 * Md[:, 1] - 2.0 * Md[:, 4]
        Md[:, 6] = Md[:, 0] + 1e-15 * Md[:, 6]
    elif B_kind == "lowrank":
        Md = rng.standard_normal((n, 3)) @ rng.standard_normal((3, n))
    return sp.csc_matrix(Md)


@pytest.mark.parametrize("case", ["structural", "numerical", "lowrank"])
@pytest.mark.parametrize("dense_limit", [3000, 0])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_rank_repair(case, dense_limit, seed):
    rng = np.random.default_rng(seed)
    n = 14
    M = _rank_case(case, n, rng)
    r = rng.standard_normal(n)
    bm = BasisManager(M, BasisOptions(dense_rank_limit=dense_limit))
    bm.set_dense_column(r)
    kinds = np.full(n, KIND_M)
    idx = rng.permutation(n)
    sg = rng.choice([-1.0, 1.0], n)
    if seed == 1:          # mix in unit columns and the dense column
        kinds[:4] = KIND_UNIT
        kinds[4] = KIND_DENSE
    rep = bm.factor(kinds, idx, sg)
    assert rep.ok
    assert rep.rank_deficiency > 0
    assert_repaired(bm, M, r, kinds, idx, sg, rep)
    check_solves(bm, M, r, rng, 1e-7)


def test_duplicated_columns_and_units():
    rng = np.random.default_rng(5)
    n = 12
    M = dominant_matrix(n, 0.3, rng)
    r = rng.standard_normal(n)
    bm = BasisManager(M)
    bm.set_dense_column(r)
    kinds = np.array([KIND_M] * 6 + [KIND_UNIT] * 4 + [KIND_DENSE] * 2)
    idx = np.array([0, 1, 2, 0, 1, 5, 7, 8, 7, 7, 0, 0])   # dup M, dup units, dup dense
    sg = np.ones(n)
    rep = bm.factor(kinds, idx, sg)
    assert rep.rank_deficiency == 2 + 2 + 1
    assert_repaired(bm, M, r, kinds, idx, sg, rep)
    check_solves(bm, M, r, rng, TOL)


def test_repair_larger_sparse_path_exactly_singular():
    """Block larger than the dense limit: sparse LU + tiny-pivot detection (with the
    perturbation fallback when the LU backend reports exact singularity)."""
    rng = np.random.default_rng(6)
    n = 300
    M = dominant_matrix(n, 0.01, rng).tolil()
    for j, (a, b) in {10: (3, 4), 50: (51, 52), 200: (7, 199)}.items():
        M[:, j] = M[:, a] + 2.0 * M[:, b]
    _check_sparse_repair_of_three(sp.csc_matrix(M), rng)


def _check_sparse_repair_of_three(M, rng):
    """M (n > the dense limit of 50) has three dependent columns: the sparse repair
    replaces exactly three, and the repaired basis is regular and well conditioned."""
    n = M.shape[0]
    bm = BasisManager(M, BasisOptions(dense_rank_limit=50))
    kinds, idx, sg = np.full(n, KIND_M), np.arange(n), np.ones(n)
    rep = bm.factor(kinds, idx, sg)
    assert rep.rank_deficiency == 3
    B1 = assert_repaired(bm, M, None, kinds, idx, sg, rep)
    assert np.linalg.cond(B1) < 1e8
    check_solves(bm, M, None, rng, TOL)


def test_ill_conditioned_bases():
    """cond(B) up to 1e10: solves are accurate to O(cond * eps), or the manager reports
    a refusal/refactorization; the backward error is always small."""
    rng = np.random.default_rng(8)
    n = 40
    for target in (1e4, 1e7, 1e10):
        U_, _ = np.linalg.qr(rng.standard_normal((n, n)))
        V_, _ = np.linalg.qr(rng.standard_normal((n, n)))
        s = np.logspace(0, -np.log10(target), n)
        M = sp.csc_matrix(U_ @ np.diag(s) @ V_.T)
        bm = BasisManager(M, BasisOptions(residual_check_frequency=1))
        bm.set_dense_column(rng.standard_normal(n))
        rep = bm.factor(np.full(n, KIND_M), np.arange(n), np.ones(n))
        assert rep.rank_deficiency == 0
        for it in range(30):
            B = dense_B(bm.kinds, bm.indices, bm.signs, M, bm._r)
            c = np.linalg.cond(B)
            xt = rng.standard_normal(n)
            b = B @ xt
            try:
                x = bm.ftran(b)
            except SolveRepairedBasis:
                # The residual check refactored a numerically singular basis and its
                # repair changed the slot table: reported, never a silent change.
                assert not np.array_equal(dense_B(bm.kinds, bm.indices, bm.signs, M,
                                                  bm._r), B)
                continue
            assert bm.backward_error(x, b) <= 1e-10   # the residual_tolerance
            assert rel_err_ok(x, xt, c)
            y = bm.btran(b)
            assert np.abs(B.T @ y - b).max() <= 1e-11 * (np.abs(b).max()
                                                         + np.abs(B).sum(1).max() * np.abs(y).max())
            slot = int(rng.integers(n))
            kind = int(rng.choice([KIND_M, KIND_UNIT, KIND_DENSE]))
            col = (kind, int(rng.integers(n)), 1.0)
            st = bm.replace(slot, *col)
            assert st in (UpdateStatus.OK, UpdateStatus.REFACTORED, UpdateStatus.REPAIRED,
                          UpdateStatus.REFUSED)


def rel_err_ok(x, xt, cond):
    return np.abs(x - xt).max() / np.abs(xt).max() <= max(1e-12, 1e3 * cond * 2.2e-16)


def _singular_by_three_dependent_columns(rng, n, structural_rank_n=True):
    """A dominant sparse M whose columns j = a + c b for three disjoint triples (numerical
    rank n - 3); with ``structural_rank_n``, drawn again until the pattern keeps
    structural rank n."""
    from scipy.sparse.csgraph import structural_rank

    while True:
        M = dominant_matrix(n, 0.01, rng).tolil()
        for j, a, b in rng.choice(n, size=9, replace=False).reshape(3, 3):
            M[:, j] = M[:, a] + rng.uniform(0.5, 2.0) * M[:, b]
        M = sp.csc_matrix(M)
        if not structural_rank_n or structural_rank(M) == n:
            return M


@pytest.mark.parametrize("seed", range(6))
def test_rank_repair_frees_rows_that_leave_a_well_conditioned_block(seed):
    """Regression: the sparse repair freed the rows pivoted at the tiny pivots, an
    accident of the rounding; on a machine with other BLAS kernels the kept 297 x 297
    block of the exactly singular test above had cond 1.6e9 with every pivot above 0.018.
    The rows are now chosen on the left null space of the block."""
    rng = np.random.default_rng(100 + seed)
    n = 300
    _check_sparse_repair_of_three(_singular_by_three_dependent_columns(rng, n), rng)


def test_rows_to_free_past_the_null_space_limit_are_the_pivot_rows():
    """More tiny pivots than NULL_SPACE_ROWS_MAX: the rows pivoted there are freed (no
    n x d dense null-space basis is built)."""
    from compass_sparse.basis import repair
    from compass_sparse.basis.backends import LUFactors

    d = repair.NULL_SPACE_ROWS_MAX + 1
    fac = LUFactors(L=None, U=None, row_order=np.arange(d + 5)[::-1].copy(),
                           col_order=np.arange(d + 5))
    bad = np.arange(2, d + 2)
    np.testing.assert_array_equal(repair._rows_to_free(fac, bad), fac.row_order[bad])
    assert repair._rows_to_free(fac, bad[:0]).size == 0


def test_residual_check_that_repairs_the_basis_reports_it():
    """Regression: a residual check that refactored a (numerically) singular basis
    repaired it silently, so a caller's slot table no longer matched the factors and the
    solution returned was of another basis.  Now SolveRepairedBasis is raised, the slot
    table holds the repaired basis, and factoring the caller's table starts afresh."""
    rng = np.random.default_rng(3)
    n = 60
    M = dominant_matrix(n, 0.1, rng)
    bm = BasisManager(M, BasisOptions(residual_check_frequency=1))
    kinds, idx, sg = np.full(n, KIND_M), np.arange(n), np.ones(n)
    assert bm.factor(kinds, idx, sg).rank_deficiency == 0
    # The factors go stale against the matrix the residual check reads (as drift in a
    # long update sequence would): column 7 is now a copy of column 3.
    Mc = bm._M.tolil()
    Mc[:, 7] = Mc[:, 3]
    Mc = sp.csc_matrix(Mc)
    bm._Mc, bm._absMc = Mc, abs(Mc)
    with pytest.raises(SolveRepairedBasis):
        bm.ftran(rng.standard_normal(n))
    assert int(np.count_nonzero(bm.kinds == KIND_UNIT)) == 1
    rep = bm.factor(kinds, idx, sg)
    assert rep.rank_deficiency == 1
    check_solves(bm, Mc, None, rng, TOL)


def test_structurally_singular_block_loses_no_more_columns_than_its_rank_deficiency():
    """Regression: on a structurally singular block (structural rank n - 1, numerical rank
    n - 3) the repair dropped the column the maximum matching left unmatched -- here a
    numerically independent one -- and then the three dependent ones: four replaced for a
    deficiency of three.  Columns and rows are now chosen on the numbers (a perturbed
    factorization on a completed matching)."""
    from scipy.sparse.csgraph import structural_rank

    rng = np.random.default_rng(102)
    n = 300
    M = _singular_by_three_dependent_columns(rng, n, structural_rank_n=False)
    assert structural_rank(M) == n - 1 and np.linalg.matrix_rank(M.toarray()) == n - 3
    _check_sparse_repair_of_three(M, rng)

