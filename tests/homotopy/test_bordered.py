"""The bordered systems of the path tracker (compass_sparse.homotopy.bordered): dense
factors (LAPACK's getrf, the compiled triangular solves) against scipy and the sparse
route, and the end game's dense Newton solve."""

import numpy as np
import pytest

import known_problems as kp

import compass_sparse.homotopy.bordered as bordered
import compass_sparse.homotopy.tracker as hom
from compass_sparse import solve_mcp
from compass_sparse.generators import thesis_family


def test_dense_end_game_and_bordered_factors_match_the_sparse_route(monkeypatch):
    """The dense route (compiled dense copy of J, LAPACK's getrf/getrs called directly)
    follows the same path as the sparse one on a problem that needs the homotopy."""
    F, J, lb, ub, x0 = kp.stationary_quadratic()
    dense = solve_mcp(F, J, lb, ub, x0, options={"homotopy": "only"})
    monkeypatch.setattr(hom, "DENSE_MAX_N", 0)
    monkeypatch.setattr(hom, "DENSE_DENSITY", 2.0)
    sparse = solve_mcp(F, J, lb, ub, x0, options={"homotopy": "only"})
    assert dense.success and sparse.success
    assert dense.residual.natural <= 1e-6
    assert dense.x == pytest.approx(sparse.x, abs=1e-8)
    assert dense.passes["homotopy"].iterations == sparse.passes["homotopy"].iterations


def test_sparse_bordered_solve_follows_the_same_path_as_the_dense_one(monkeypatch):
    g = thesis_family(15, 1, seed=2)
    dense = solve_mcp(g.problem, options={"homotopy": "only"})
    monkeypatch.setattr(hom, "DENSE_MAX_N", 0)
    monkeypatch.setattr(hom, "DENSE_DENSITY", 2.0)
    sparse = solve_mcp(thesis_family(15, 1, seed=2).problem, options={"homotopy": "only"})
    assert dense.success and sparse.success
    assert sparse.x == pytest.approx(dense.x, abs=1e-5)
    assert sparse.passes["homotopy"].iterations == pytest.approx(
        dense.passes["homotopy"].iterations, rel=0.2)


# ------------------------------------------------------------------ compiled dense steps
@pytest.mark.parametrize("m", [1, 2, 7, 40])
def test_compiled_lu_solve_agrees_with_lapack_getrs(m):
    """lu_solve on getrf's factors (row interchanges included) against LAPACK's getrs, to
    rounding; a non-finite solution is reported."""
    import scipy.linalg as sla

    from compass_sparse.homotopy._kernels import lu_solve

    rng = np.random.default_rng(m)
    for _ in range(5):
        B = np.asfortranarray(rng.normal(size=(m, m)))
        lu, piv, info = bordered.lapack_getrf()(B.copy(order="F"), overwrite_a=True)
        assert info == 0
        b = rng.normal(size=m)
        x = b.copy()
        assert lu_solve(lu, piv, x)
        ref = sla.lu_solve((lu, piv), b)
        np.testing.assert_allclose(x, ref, rtol=1e-10, atol=1e-12 * np.abs(ref).max())
        np.testing.assert_allclose(B @ x, b, atol=1e-9 * (1 + np.abs(b).max()))
    lu[-1, -1] = 0.0  # a zero pivot: the solution overflows
    assert not lu_solve(lu, piv, np.ones(m))


def test_end_game_dense_solve_agrees_with_scipy_and_is_not_finite_when_singular():
    """The end game's dense Newton solve (getrf and the compiled triangular solves) gives
    scipy's lu_factor + lu_solve to rounding; an exactly singular matrix gives a
    non-finite step, which the end game refuses."""
    import scipy.linalg as sla

    rng = np.random.default_rng(11)
    for n in (1, 2, 5, 12):
        for _ in range(5):
            A = rng.normal(size=(n, n)) + n * np.eye(n)
            b = rng.normal(size=n)
            want = sla.lu_solve(sla.lu_factor(A), b)
            got = hom.solve_square(A.copy(), b, True)
            assert np.allclose(got, want, rtol=1e-12, atol=1e-12)
    S = np.array([[1.0, 2.0], [2.0, 4.0]])
    assert not np.isfinite(hom.solve_square(S, np.array([1.0, 0.0]), True)).all()


def test_dense_getrf_gives_scipys_factors_bit_for_bit():
    """The compiled tracker's getrf (numba's binding of scipy's LAPACK) against
    scipy.linalg.lapack.dgetrf: the same factors and 0-based pivots, and info > 0 at an
    exactly zero pivot."""
    import scipy.linalg as sla

    assert hom.hk.bind_lapack()
    rng = np.random.default_rng(5)
    for n in (1, 2, 3, 7, 11, 31, 64, 301):
        A = np.asfortranarray(rng.standard_normal((n, n)))
        lu, piv, info = sla.lapack.dgetrf(A)
        B = A.copy(order="F")
        p = np.empty(n, dtype=np.int32)
        assert hom.hk.dense_getrf(B, p) == info == 0
        assert np.array_equal(B, lu) and np.array_equal(p, piv)
    S = np.asfortranarray([[1.0, 2.0], [2.0, 4.0]])
    assert hom.hk.dense_getrf(S, np.empty(2, dtype=np.int32)) > 0
