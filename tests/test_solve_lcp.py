"""solve_lcp end to end: statuses, Result fields, pass reports, input errors, limits.

Residuals are recomputed here from M and q (natural residual
||z - clip(z - (M z + q), l, u)||_inf) and compared with the solver's own report.
"""
from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import compass_sparse.generators as gen
from compass_sparse import (BoundsError, Options, PointStatus, Result, ShapeError, Status,
                            solve_lcp)

HYP = settings(derandomize=True, max_examples=40, deadline=None,
               suppress_health_check=[HealthCheck.too_slow])


def nat_res(M, q, lb, ub, z):
    z = np.asarray(z, dtype=float)
    f = M @ z + q
    return float(np.max(np.abs(z - np.clip(z - f, lb, ub))))


def fb_norm(M, q, lb, ub, z):
    """||Phi_FB||_2 recomputed from the definition (PATH's measure), for the report check."""
    z = np.asarray(z, float)
    f = M @ z + q
    phi = np.empty_like(z)

    def fb(a, b):
        return np.sqrt(a * a + b * b) - a - b

    for i in range(z.size):
        l, u, zi, fi = lb[i], ub[i], z[i], f[i]
        if np.isfinite(l) and np.isfinite(u):
            if l == u:
                phi[i] = l - zi
            else:
                phi[i] = fb(zi - l, fb(u - zi, -fi))
        elif np.isfinite(l):
            phi[i] = fb(zi - l, fi)
        elif np.isfinite(u):
            phi[i] = -fb(u - zi, -fi)
        else:
            phi[i] = -fi
    return float(np.linalg.norm(phi))


def check_solved(r: Result, M, q, lb, ub, *, tol=1e-6, solution=None):
    assert isinstance(r, Result)
    assert r.success, r.message
    assert r.status is Status.SOLVED
    assert r.point_status is PointStatus.SOLUTION
    nat = nat_res(M, q, lb, ub, r.x)
    assert nat <= tol
    # the report agrees with an independent recomputation
    rep = r.check(lambda z: M @ z + q, lb, ub)
    assert rep.natural == pytest.approx(nat, abs=1e-14)
    assert r.residual.natural == pytest.approx(nat, abs=1e-12)
    assert r.residual.fb_norm <= r.tolerance
    assert abs(r.residual.fb_norm - fb_norm(M, q, lb, ub, r.x)) <= 1e-10 * (1 + r.residual.fb_norm)
    np.testing.assert_allclose(r.fun, M @ r.x + q, rtol=0, atol=1e-12 * (1 + abs(q).max()))
    assert np.all(r.x >= lb) and np.all(r.x <= ub)
    if solution is not None:
        assert np.max(np.abs(r.x - solution)) <= 1e-6
    return nat


# ----------------------------------------------------------------------------- solved families
LCP_CASES = {
    "pmat_grid_ncp": lambda: gen.p_matrix_lcp(150, "grid", 0, "ncp"),
    "pmat_grid_box": lambda: gen.p_matrix_lcp(196, "grid", 1, "box"),
    "pmat_grid_mixed": lambda: gen.p_matrix_lcp(120, "grid", 2, "mixed"),
    "pmat_banded_ncp": lambda: gen.p_matrix_lcp(150, "banded", 3, "ncp"),
    "pmat_banded_box": lambda: gen.p_matrix_lcp(200, "banded", 4, "box"),
    "pmat_banded_mixed": lambda: gen.p_matrix_lcp(180, "banded", 5, "mixed", 0.3),
    "pmat_large_sparse_manager": lambda: gen.p_matrix_lcp(600, "banded", 6, "mixed"),
    "obstacle_30": lambda: gen.obstacle_problem(30, 0),
    "obstacle_45_deg": lambda: gen.obstacle_problem(45, 1, degenerate_fraction=0.3),
    "obstacle_60": lambda: gen.obstacle_problem(60, 2),
    "monotone_ncp": lambda: gen.monotone_lcp(100, 0),
    "monotone_box": lambda: gen.monotone_lcp(100, 1, bounds="box", degenerate_fraction=0.3),
    "monotone_mixed_lowrank": lambda: gen.monotone_lcp(80, 2, rank=8, bounds="mixed"),
}
UNIQUE = {k for k in LCP_CASES if k.startswith("pmat") or k.startswith("obstacle")}


@pytest.mark.parametrize("crash", ["pnewton", "none"])
@pytest.mark.parametrize("case", list(LCP_CASES))
def test_solve_lcp_families(case, crash):
    g = LCP_CASES[case]()
    M, q, lb, ub = g.lcp
    n = q.size
    if crash == "none" and n > 1000:
        pytest.skip("pure pivoting on the large obstacle problems is slow (not the point)")
    r = solve_lcp(M, q, lb, ub, x0=g.problem.x0, options={"crash_method": crash})
    # obstacle problems have ||M|| ~ 1/h^2: the exact manufactured data still solve to 1e-6
    check_solved(r, M, q, lb, ub, solution=g.solution if case in UNIQUE else None)
    assert set(r.passes) >= {"presolve", "crash", "path"}
    assert not r.passes["presolve"].ran and r.passes["presolve"].reason
    if crash == "pnewton":
        assert r.passes["crash"].ran  # n >= 10
        if not r.passes["path"].ran:
            assert "crash" in r.passes["path"].reason
            assert r.minor_iterations == 0
    else:
        assert not r.passes["crash"].ran
        assert r.passes["path"].ran
        assert r.passes["path"].pivots > 0
        assert r.minor_iterations >= r.passes["path"].pivots


def test_solve_lcp_tight_tolerance():
    g = gen.p_matrix_lcp(200, "banded", 8, "mixed", 0.2)
    M, q, lb, ub = g.lcp
    for crash in ("pnewton", "none"):
        r = solve_lcp(M, q, lb, ub, options={"convergence_tolerance": 1e-12,
                                             "crash_method": crash})
        check_solved(r, M, q, lb, ub, tol=1e-11, solution=g.solution)


@pytest.mark.parametrize("n", [3, 9])
def test_crash_skipped_below_minimum_dimension(n):
    g = gen.p_matrix_lcp(n, "banded", n, "box")
    M, q, lb, ub = g.lcp
    r = solve_lcp(M, q, lb, ub, options={"crash_minimum_dimension": 10})
    check_solved(r, M, q, lb, ub, solution=g.solution)
    assert not r.passes["crash"].ran
    assert "crash_minimum_dimension" in r.passes["crash"].reason
    assert r.passes["path"].ran and r.passes["path"].pivots > 0
    assert r.nit == 1


def test_crash_runs_at_minimum_dimension():
    g = gen.p_matrix_lcp(10, "banded", 10, "box")
    M, q, lb, ub = g.lcp
    r = solve_lcp(M, q, lb, ub)
    check_solved(r, M, q, lb, ub, solution=g.solution)
    assert r.passes["crash"].ran


def test_dense_and_list_input():
    M = np.array([[2.0, 1.0], [1.0, 2.0]])
    q = [-1.0, -1.0]
    lb, ub = np.zeros(2), np.full(2, np.inf)
    r = solve_lcp(M.tolist(), q, lb, ub)
    check_solved(r, M, np.asarray(q), lb, ub, solution=np.array([1 / 3, 1 / 3]))
    lb, ub = np.array([0.5, -1.0]), np.array([1.0, 1.0])
    sols = gen.brute_force_lcp(M, np.asarray(q), lb, ub)
    assert len(sols) == 1  # M is positive definite
    r = solve_lcp(sp.csr_matrix(M), q, lb, ub)
    check_solved(r, M, np.asarray(q), lb, ub, solution=sols[0])




def test_default_ncp_bounds():
    """solve_lcp(M, q) with the default bounds lb = 0, ub = inf (an NCP)."""
    M = np.array([[2.0, 1.0], [1.0, 2.0]])
    q = np.array([-1.0, -1.0])
    r = solve_lcp(M, q)
    check_solved(r, M, q, np.zeros(2), np.full(2, np.inf), solution=np.array([1 / 3, 1 / 3]))


def test_scalar_bounds_inverted_raise_bounds_error():
    with pytest.raises(BoundsError):
        solve_lcp(sp.identity(3, format="csc"), -np.ones(3), lb=1.0, ub=0.0)


def test_bound_length_mismatch_raises_shape_error():
    with pytest.raises(ShapeError):
        solve_lcp(sp.identity(3, format="csc"), np.ones(3), lb=np.zeros(2),
                  ub=np.full(2, np.inf))


# ----------------------------------------------------------------------------- infeasible
@pytest.mark.parametrize("n,seed", [(2, 0), (15, 1), (50, 2)])
def test_infeasible_status(n, seed):
    g = gen.infeasible_lcp(n, seed)
    M, q, lb, ub = g.lcp
    r = solve_lcp(M, q, lb, ub)
    assert r.status is Status.INFEASIBLE
    assert not r.success
    assert r.point_status is PointStatus.CERTIFICATE
    assert nat_res(M, q, lb, ub, r.x) > 1e-3
    assert r.residual.fb_norm > r.tolerance
    assert np.all(r.x >= lb)
    # The certificate: a secondary ray x + theta d of Lemke's method, theta >= 0, with
    # d >= 0, M d >= 0 and d'M d = 0 (copositive-plus theory; Cottle, Pang & Stone 4.4).
    d = r.ray
    scale = np.abs(d).max()
    tol = 1e-9 * scale * (1 + abs(M).max())
    assert d is not None and scale > 0
    assert np.all(d >= -tol) and np.all(M @ d >= -tol)
    assert abs(d @ (M @ d)) <= tol * scale


# Two fixed 2x2 box LCPs (all bounds finite: a solution always exists; both have one at a
# corner, verified by the brute force here).  solve_lcp reports INFEASIBLE for them.
BOX_2x2 = [
    (np.array([[-0.8315178471780087, 0.5673966339768945],
               [-0.3982519948134129, 0.21234604203481044]]),
     np.array([-0.6579556459477627, -0.6677202021053166]),
     np.array([-0.3511938215561454, -0.4181212045958016]),
     np.array([1.1081989217302803, 0.6365963832484993])),
    (np.array([[-0.8712964447078155, 0.9231662489350463],
               [0.8089821044894712, -0.5880187550983025]]),
     np.array([-0.3588389431574259, -0.1331827341491394]),
     np.array([-0.21387474789898198, -0.7766076153755208]),
     np.array([1.1751799876290674, -0.26770219937086703])),
]


@pytest.mark.parametrize("k", [0, 1])
def test_bounded_box_lcp_is_never_infeasible(k):
    M, q, lb, ub = BOX_2x2[k]
    sols = gen.brute_force_lcp(M, q, lb, ub)
    assert len(sols) >= 1 and nat_res(M, q, lb, ub, sols[0]) <= 1e-12
    r = solve_lcp(M, q, lb, ub)
    assert r.status is not Status.INFEASIBLE, r.message
    assert r.success
    assert nat_res(M, q, lb, ub, r.x) <= 1e-6


@HYP
@given(n=st.integers(1, 6), seed=st.integers(0, 10**6))
def test_random_box_lcp_success_is_genuine(n, seed):
    """Random non-P box LCPs: a reported success is a real solution (residual recomputed and
    close to an enumerated one); a failure keeps the best point inside the box."""
    rng = np.random.default_rng(seed)
    M = rng.uniform(-1, 1, (n, n))
    q = rng.uniform(-1, 1, n)
    lb = rng.uniform(-1, 0, n)
    ub = lb + rng.uniform(0.5, 2, n)
    sols = gen.brute_force_lcp(M, q, lb, ub)
    assert sols
    r = solve_lcp(M, q, lb, ub)
    assert np.all(r.x >= lb) and np.all(r.x <= ub)
    nat = nat_res(M, q, lb, ub, r.x)
    if r.success:
        assert nat <= 1e-6
        # nearby an enumerated solution (isolated solutions of a generic instance)
        assert min(np.max(np.abs(r.x - s)) for s in sols) <= 1e-4
    else:
        assert r.point_status is not PointStatus.SOLUTION
        assert r.residual.fb_norm > r.tolerance


# ----------------------------------------------------------------------------- input errors
def test_shape_mismatch_raises():
    M = sp.identity(3, format="csc")
    lb, ub = np.zeros(3), np.full(3, np.inf)
    with pytest.raises(ShapeError):
        solve_lcp(M, np.ones(4), np.zeros(4), np.full(4, np.inf))
    with pytest.raises(ShapeError):
        solve_lcp(np.ones((3, 4)), np.ones(3), lb, ub)
    with pytest.raises(ShapeError):
        solve_lcp(M, np.ones(3), lb, ub, x0=np.zeros(5))


def test_bounds_errors_raise():
    M = sp.identity(3, format="csc")
    q = -np.ones(3)
    with pytest.raises(BoundsError):
        solve_lcp(M, q, lb=np.array([0.0, 2.0, 0.0]), ub=np.array([1.0, 1.0, 1.0]))
    with pytest.raises(BoundsError):
        solve_lcp(M, q, lb=np.ones(3), ub=np.zeros(3))
    with pytest.raises(BoundsError):
        solve_lcp(M, q, lb=np.array([0.0, np.nan, 0.0]), ub=np.ones(3))
    with pytest.raises(BoundsError):
        solve_lcp(M, q, lb=np.array([0.0, np.inf, 0.0]), ub=np.full(3, np.inf))
    # input errors are ValueErrors too
    with pytest.raises(ValueError):
        solve_lcp(M, q, lb=np.ones(3), ub=np.zeros(3))


# ----------------------------------------------------------------------------- limits
def test_major_iteration_limit_zero_reports_start():
    g = gen.p_matrix_lcp(50, "grid", 3, "box")
    M, q, lb, ub = g.lcp
    x0 = np.clip(np.full(50, 0.25), lb, ub)
    r = solve_lcp(M, q, lb, ub, x0=x0, options={"major_iteration_limit": 0})
    assert r.status is Status.MAJOR_ITERATION_LIMIT
    assert not r.success
    assert r.point_status is PointStatus.START_POINT
    np.testing.assert_array_equal(r.x, x0)
    assert r.residual.natural == pytest.approx(nat_res(M, q, lb, ub, x0), abs=1e-14)
    assert r.residual.fb_norm == pytest.approx(fb_norm(M, q, lb, ub, x0), rel=1e-10)
    assert r.minor_iterations == 0 and r.nit == 0


def test_major_iteration_limit_zero_at_solution_is_solved():
    g = gen.p_matrix_lcp(50, "grid", 4, "box")
    M, q, lb, ub = g.lcp
    r = solve_lcp(M, q, lb, ub, x0=g.solution, options={"major_iteration_limit": 0})
    check_solved(r, M, q, lb, ub, solution=g.solution)
    np.testing.assert_array_equal(r.x, g.solution)


def test_start_at_solution_is_solved_without_work():
    g = gen.obstacle_problem(20, 5)
    M, q, lb, ub = g.lcp
    r = solve_lcp(M, q, lb, ub, x0=g.solution)
    check_solved(r, M, q, lb, ub, solution=g.solution)
    assert r.minor_iterations == 0


def test_options_object_and_dict_agree():
    g = gen.p_matrix_lcp(120, "banded", 12, "mixed")
    M, q, lb, ub = g.lcp
    a = solve_lcp(M, q, lb, ub, options=Options(crash_method="none"))
    b = solve_lcp(M, q, lb, ub, options={"crash_method": "none"})
    check_solved(a, M, q, lb, ub, solution=g.solution)
    check_solved(b, M, q, lb, ub, solution=g.solution)
    np.testing.assert_array_equal(a.x, b.x)
    assert a.minor_iterations == b.minor_iterations


def test_summary_and_repr_mention_status():
    g = gen.p_matrix_lcp(30, "grid", 13, "ncp")
    M, q, lb, ub = g.lcp
    r = solve_lcp(M, q, lb, ub)
    check_solved(r, M, q, lb, ub, solution=g.solution)
    assert "SOLVED" in r.summary() and "SOLVED" in repr(r)
