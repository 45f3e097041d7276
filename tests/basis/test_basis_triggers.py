"""Each refactorization trigger fires in a constructed scenario; solves agree after."""

import numpy as np
import pytest

from basis_helpers import (check_solves, dominant_dense_column, dominant_matrix,
                           family_move, family_start)
from compass_sparse.basis import BasisManager, BasisOptions, UpdateStatus

pytestmark = pytest.mark.usefixtures("lu_choice")

TOL = 1e-9


def setup(n, seed, **opts):
    rng = np.random.default_rng(seed)
    M = dominant_matrix(n, 0.08, rng)
    r = dominant_dense_column(M, 0, rng)
    bm = BasisManager(M, BasisOptions(**opts))
    bm.set_dense_column(r)
    bm.factor(*family_start(n, rng))
    return bm, M, r, rng


def test_count_trigger():
    bm, M, r, rng = setup(60, 1, update_limit=5, residual_check_frequency=0)
    statuses = []
    for _ in range(30):
        s, col = family_move(bm, rng, 60, r_index=0)
        statuses.append(bm.replace(s, *col))
        assert bm.num_updates <= 5
        check_solves(bm, M, r, rng, TOL)
    assert bm.stats.refactor_by_count == 5
    assert statuses.count(UpdateStatus.REFACTORED) == 5
    assert bm.stats.updates == 25


def test_update_limit_zero_refactors_every_time():
    bm, M, r, rng = setup(20, 2, update_limit=0)
    for _ in range(10):
        s, col = family_move(bm, rng, 20, r_index=0)
        assert bm.replace(s, *col) == UpdateStatus.REFACTORED
    assert bm.stats.updates == 0 and bm.stats.refactor_by_count == 10
    check_solves(bm, M, r, rng, TOL)


def test_fill_trigger():
    bm, M, r, rng = setup(80, 3, fill_factor=1.05, residual_check_frequency=0)
    for _ in range(40):
        s, col = family_move(bm, rng, 80, r_index=0)
        bm.replace(s, *col)
        base = bm.stats.nnz_L + bm.stats.nnz_U + bm.stats.nnz_eta
        assert base > 0
        check_solves(bm, M, r, rng, TOL)
    assert bm.stats.refactor_by_fill > 0
    assert bm.stats.refactor_by_count == 0


def test_stability_trigger_on_damaged_factor():
    """The factor drifts (simulated by perturbing U by 1e-6 relatively) between the FTRAN
    of the entering column and the update: the two computations of the new diagonal
    disagree, the update is done by a fresh factorization and solves are exact again."""
    bm, M, r, rng = setup(50, 4, residual_check_frequency=0)
    fired = 0
    for _ in range(20):
        s, col = family_move(bm, rng, 50, r_index=0)
        bm.ftran_column(*col)
        N = bm.n + bm.num_updates
        bm.factors.Ud[:N] *= 1.0 + 1e-6 * rng.standard_normal(N)   # damage the factor
        st = bm.replace(s, *col)
        assert st == UpdateStatus.REFACTORED
        fired += 1
        check_solves(bm, M, r, rng, TOL)
    assert bm.stats.refactor_by_stability == fired


def test_stability_trigger_tight_tolerance():
    bm, M, r, rng = setup(40, 5, stability_tolerance=1e-300, residual_check_frequency=0)
    for _ in range(20):
        s, col = family_move(bm, rng, 40, r_index=0)
        bm.replace(s, *col)
        check_solves(bm, M, r, rng, TOL)
    assert bm.stats.refactor_by_stability > 0


def test_residual_trigger_on_damaged_factor():
    bm, M, r, rng = setup(50, 6, residual_check_frequency=1, stability_tolerance=1.0)
    for _ in range(3):
        s, col = family_move(bm, rng, 50, r_index=0)
        bm.replace(s, *col)
    assert bm.num_updates > 0
    bm.factors.Lx *= 1.01          # damage L: solves become wrong
    bm.factors.Ud[: bm.n] *= 1.01  # (also when L is empty)
    before = bm.stats.refactor_by_residual
    check_solves(bm, M, r, rng, TOL)   # the check catches it and refactors
    assert bm.stats.refactor_by_residual == before + 1
    assert bm.num_updates == 0


def test_residual_check_fresh_factor_damage():
    bm, M, r, rng = setup(30, 7, residual_check_frequency=1)
    bm.factors.Ud[: bm.n] *= 1.001
    check_solves(bm, M, r, rng, TOL)
    assert bm.stats.refactor_by_residual == 1


def test_ftran_column_checked_as_well():
    bm, M, r, rng = setup(30, 8, residual_check_frequency=1, stability_tolerance=1.0)
    s, col = family_move(bm, rng, 30, r_index=0)
    bm.replace(s, *col)
    bm.factors.Ud[: bm.n] *= 1.01
    s, col = family_move(bm, rng, 30, r_index=0)
    bm.ftran_column(*col)
    assert bm.stats.refactor_by_residual == 1
    assert bm.replace(s, *col) == UpdateStatus.OK
    check_solves(bm, M, r, rng, TOL)
