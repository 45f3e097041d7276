"""All-unit bases, set_matrix, API details, options, backends."""

import numpy as np
import pytest
import scipy.sparse as sp

from basis_helpers import check_solves, dominant_matrix, family_start
from compass_sparse.basis import (KIND_DENSE, KIND_M, KIND_UNIT, BasisManager,
                                  BasisOptions, BasisStats, FactorReport, UpdateStatus)
from compass_sparse.exceptions import CompassError, OptionError, ProblemError, ShapeError

pytestmark = pytest.mark.usefixtures("lu_choice")

TOL = 1e-9


def test_all_unit_basis_is_free():
    rng = np.random.default_rng(0)
    n = 5000
    M = dominant_matrix(n, 1e-3, rng)
    bm = BasisManager(M)
    signs = rng.choice([-1.0, 1.0], n)
    perm = rng.permutation(n)
    rep = bm.factor(np.full(n, KIND_UNIT), perm, signs)
    assert rep.ok and not rep.replaced
    assert bm.stats.nnz_L == 0 and bm.stats.nnz_U == n
    b = rng.standard_normal(n)
    x = bm.ftran(b)
    np.testing.assert_allclose(x, b[perm] * signs, rtol=0, atol=0)
    y = bm.btran(b)
    expect = np.zeros(n)
    expect[perm] = b * signs
    np.testing.assert_allclose(y, expect, rtol=0, atol=0)
    # M columns enter one by one (the first pivots of a path)
    for j in range(20):
        s = bm.slot_of_unit(j)
        bm.ftran_column(KIND_M, j, 1.0)
        assert bm.replace(s, KIND_M, j, 1.0) == UpdateStatus.OK
    Bsub = sp.csc_matrix(M)
    x = bm.ftran(b)
    # residual check against the sparse B
    assert bm.backward_error(x, b) < 1e-14
    del Bsub


def test_set_matrix_and_factor():
    rng = np.random.default_rng(1)
    n = 60
    M = dominant_matrix(n, 0.08, rng)
    bm = BasisManager(M)
    k, i, s = family_start(n, rng)
    bm.factor(k, i, s)
    check_solves(bm, M, None, rng, TOL)
    M2 = M.copy()
    M2.data *= rng.uniform(0.5, 1.5, M2.data.size)
    M2 = sp.csc_matrix(M2 + sp.diags(np.full(n, 3.0 * np.abs(M2).max())))
    bm.set_matrix(M2)
    assert not bm.is_factored
    with pytest.raises(CompassError):
        bm.ftran(np.ones(n))
    rep = bm.refactor()
    assert rep.ok
    check_solves(bm, M2, None, rng, TOL)
    # new pattern too
    M3 = dominant_matrix(n, 0.2, rng)
    bm.set_matrix(M3)
    bm.factor(*family_start(n, rng))
    check_solves(bm, M3, None, rng, TOL)
    with pytest.raises(ShapeError):
        bm.set_matrix(sp.eye(n + 1, format="csc"))


def test_slot_maps_and_views():
    rng = np.random.default_rng(2)
    n = 20
    M = dominant_matrix(n, 0.1, rng)
    bm = BasisManager(M.tocsr())          # any format
    bm.set_dense_column(np.ones(n))
    k, i, s = family_start(n, rng, r_index=3)
    bm.factor(k, i, s)
    for slot in range(n):
        if k[slot] == KIND_M:
            assert bm.slot_of_m(i[slot]) == slot
        elif k[slot] == KIND_UNIT:
            assert bm.slot_of_unit(i[slot]) == slot
        else:
            assert bm.slot_of_dense() == slot
    assert bm.slot_of_m(3) == -1 and bm.slot_of_unit(3) == -1
    with pytest.raises(ValueError):
        bm.kinds[0] = 1
    sd = bm.slot_of_dense()
    assert bm.replace(sd, KIND_UNIT, 3, -1.0) == UpdateStatus.OK
    assert bm.slot_of_dense() == -1 and bm.slot_of_unit(3) == sd
    assert isinstance(bm.stats, BasisStats)
    assert bm.condest() > 0 and bm.condest_check()


def test_input_validation():
    n = 5
    M = sp.eye(n, format="csc")
    bm = BasisManager(M)
    with pytest.raises(ShapeError):
        bm.factor(np.zeros(4), np.zeros(4), np.ones(4))
    with pytest.raises(ProblemError):
        bm.factor(np.full(n, KIND_DENSE), np.zeros(n), np.ones(n))  # no dense column
    with pytest.raises(ProblemError):
        bm.factor(np.full(n, KIND_M), np.arange(n) + 1, np.ones(n))
    with pytest.raises(ProblemError):
        bm.factor(np.full(n, KIND_M), np.arange(n), np.zeros(n))
    with pytest.raises(ShapeError):
        BasisManager(sp.random(3, 4, format="csc"))
    with pytest.raises(ShapeError):
        BasisManager(np.eye(3))
    bm.factor(np.full(n, KIND_M), np.arange(n), np.ones(n))
    with pytest.raises(ProblemError):
        bm.replace(0, 7, 0, 1.0)
    with pytest.raises(ProblemError):
        bm.replace(0, KIND_M, n, 1.0)
    with pytest.raises(ShapeError):
        bm.set_dense_column(np.ones(n + 1))


@pytest.mark.parametrize("kw", [dict(update_limit=-1), dict(fill_factor=0.5),
                                dict(pivot_tolerance=1.0), dict(stability_tolerance=0.0),
                                dict(residual_check_frequency=-2), dict(backend="klu"),
                                dict(ordering="foo"), dict(diag_pivot_thresh=2.0),
                                dict(rank_tolerance=-1.0), dict(memory_limit=0.0),
                                dict(backend="umfpack", ordering="metis")])
def test_options_validation(kw):
    with pytest.raises(OptionError):
        BasisOptions(**kw)


def test_factor_report_type():
    bm = BasisManager(sp.eye(3, format="csc"))
    rep = bm.factor([KIND_M] * 3, [0, 1, 2], [1, 1, 1])
    assert isinstance(rep, FactorReport) and rep.ok and rep.rank_deficiency == 0


@pytest.mark.parametrize("backend,ordering", [("superlu", "colamd"), ("superlu", "amd"),
                                              ("superlu", "metis"), ("umfpack", "auto"),
                                              ("auto", "auto")])
def test_lu_backends_and_orderings_solve_and_update(backend, ordering, monkeypatch):
    monkeypatch.delenv("COMPASS_SPARSE_LU", raising=False)   # the options alone decide
    rng = np.random.default_rng(4)
    n = 80
    M = dominant_matrix(n, 0.05, rng)
    bm = BasisManager(M, BasisOptions(backend=backend, ordering=ordering))
    bm.factor(*family_start(n, rng))
    check_solves(bm, M, None, rng, TOL)
    for j in range(10):
        s = max(bm.slot_of_m(j), bm.slot_of_unit(j))
        bm.replace(s, KIND_M if bm.kinds[s] == KIND_UNIT else KIND_UNIT, j, 1.0)
        check_solves(bm, M, None, rng, TOL)
    assert bm.stats.backend == (backend if backend != "auto" else "superlu")
    assert bm.stats.ordering == {"auto": bm.stats.ordering, "colamd": "colamd", "amd": "amd",
                                 "metis": "metis"}[ordering]


def test_both_bases_implement_the_basis_protocol_and_agree():
    from compass_sparse.basis import Basis, DenseBasis

    rng = np.random.default_rng(11)
    n = 30
    M = sp.random(n, n, density=0.15, random_state=11, format="csc") + 4.0 * sp.identity(n)
    bases = [BasisManager(sp.csc_matrix(M)), DenseBasis(M)]
    r = rng.standard_normal(n)
    for bm in bases:
        assert isinstance(bm, Basis)
        bm.set_dense_column(r)
        rep = bm.factor(np.full(n, KIND_UNIT), np.arange(n), -np.ones(n))
        assert rep.rank_deficiency == 0 and bm.last_report is rep
    for j in range(0, n, 3):
        statuses = [bm.replace(j, KIND_M, j, 1.0) for bm in bases]
        # (the sparse manager may carry an update out by a fresh factorization)
        assert statuses[0] in (UpdateStatus.OK, UpdateStatus.REFACTORED)
        assert statuses[1] is UpdateStatus.OK
    statuses = [bm.replace(1, KIND_DENSE, 0, 1.0) for bm in bases]
    assert all(s in (UpdateStatus.OK, UpdateStatus.REFACTORED) for s in statuses)
    b = rng.standard_normal(n)
    x0, x1 = (bm.ftran(b) for bm in bases)
    y0, y1 = (bm.btran(b) for bm in bases)
    assert np.allclose(x0, x1, atol=1e-10) and np.allclose(y0, y1, atol=1e-10)
    for bm in bases:
        assert np.array_equal(np.asarray(bm.kinds), np.asarray(bases[0].kinds))


def test_dense_basis_reports_its_repair():
    from compass_sparse.basis import DenseBasis

    n = 6
    M = np.eye(n)
    M[:, 2] = M[:, 1]  # column 2 duplicates column 1
    bm = DenseBasis(sp.csc_matrix(M))
    rep = bm.factor(np.full(n, KIND_M), np.arange(n), np.ones(n))
    assert rep.rank_deficiency == 1 and bm.last_report is rep
    slot, kind, index, sign, row = rep.replaced[0]
    assert (slot, kind, index) == (2, KIND_M, 2) and bm.kinds[2] == KIND_UNIT
    assert np.allclose(bm.ftran(bm.assemble() @ np.arange(n)), np.arange(n))
