"""No false verdicts: a SOLVED point meets the stated tolerance on both residuals and is
not merely in a flat tail of F; INFEASIBLE is never reported for a solvable problem.

Every residual here is recomputed from the test's own F (never from the solver's report)."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from compass_sparse import MCP, Options, Status, solve_lcp, solve_mcp
from compass_sparse.nms.acceptance import judge
from compass_sparse.presolve import presolve

TOL = 1e-6


def residuals(F, x, lb, ub):
    """(||Phi_FB||_2, natural residual) from scratch."""
    x = np.asarray(x, dtype=float)
    f = np.asarray(F(x.copy()), dtype=float)
    lb = np.broadcast_to(lb, x.shape)
    ub = np.broadcast_to(ub, x.shape)
    nat = float(np.max(np.abs(x - np.clip(x - f, lb, ub))))
    a = x - lb
    phi = np.where(np.isfinite(lb), np.hypot(a, f) - a - f, -f)  # NCP/free rows only
    return float(np.linalg.norm(phi)), nat


# ------------------------------------------------------------------ defect: presolve
def test_preprocessor_does_not_declare_infeasible_when_jacobian_drops_zeros_at_start():
    r = solve_mcp(lambda x: x ** 3 - 2, lambda x: sp.csc_matrix([[3 * x[0] ** 2]]), 0.0,
                  np.inf, np.zeros(1))
    assert r.status is Status.SOLVED, r.message
    assert r.x[0] == pytest.approx(2 ** (1 / 3), rel=1e-6)


def test_readme_example_with_an_empty_row_of_A_is_solved_not_infeasible():
    n = 30
    A = sp.random(n, n, density=0.05, random_state=1)
    A = ((A + A.T) * 0.1).tocsr()
    assert (np.diff(A.indptr) == 0).any()  # the case: a row of A without entries
    b = np.random.default_rng(0).uniform(0, 1, n)

    def F(x):
        return A @ x + x ** 3 - b

    r = solve_mcp(F, lambda x: (A + sp.diags(3 * x ** 2)).tocsc(), 0.0, np.inf, np.zeros(n),
                  options={"convergence_tolerance": 1e-8})
    assert r.status is Status.SOLVED, r.message
    assert residuals(F, r.x, 0.0, np.inf)[1] <= 1e-8


def test_infeasibility_verdict_rests_on_a_declared_row_and_says_why():
    # F_0 = -1 for every x (the declared pattern has no entry in row 0), x_0 >= 0: no solution
    pat = sp.csc_matrix(np.array([[0.0, 0.0], [1.0, 1.0]]))

    def F(x):
        return np.array([-1.0, x[0] + 2 * x[1] - 1])

    def J(x):
        return sp.csc_matrix(np.array([[0.0, 0.0], [1.0, 2.0]]))

    r = solve_mcp(F, J, 0.0, np.inf, np.zeros(2), jac_sparsity=pat)
    assert r.status is Status.INFEASIBLE
    assert "F[0]" in r.message and "declared pattern" in r.message
    # the same problem without the declaration is no proof: no INFEASIBLE verdict
    r2 = solve_mcp(F, J, 0.0, np.inf, np.zeros(2), options={"time_limit": 5})
    assert r2.status is not Status.INFEASIBLE and not r2.success


# ------------------------------------------------------------------ defect: success tolerance
def test_success_is_not_reported_with_a_natural_residual_above_the_tolerance():
    r = solve_mcp(lambda x: x, lambda x: sp.identity(1, format="csc"), 0.0, np.inf,
                  np.array([1.5e-6]))
    assert r.status is Status.SOLVED
    fb, nat = residuals(lambda x: x, r.x, 0.0, np.inf)
    assert fb <= TOL and nat <= TOL


def test_both_residual_tests_stress_the_tolerance_boundary():
    # free row: |Phi| = |F|; NCP row at z = t, F = t: |Phi| = (2 - sqrt 2) t < t = natural
    lb, ub = np.zeros(1), np.full(1, np.inf)
    for t in (0.5e-6, 0.99e-6):
        assert judge(np.array([t]), np.array([t]), lb, ub, TOL).solved
    for t in (1.01e-6, 1.5e-6, 2.4e-6):  # ||Phi|| <= 0.59 t <= tol, natural = t > tol
        v = judge(np.array([t]), np.array([t]), lb, ub, TOL)
        assert not v.solved and not v.small_residual


# ------------------------------------------------------------------ defect: flat tails
FLAT = {
    "exp(-x)": (lambda x: np.exp(-x), lambda x: sp.csc_matrix([[-np.exp(-x[0])]])),
    "-1/(1+x)": (lambda x: -1 / (1 + x), lambda x: sp.csc_matrix([[1 / (1 + x[0]) ** 2]])),
    "atan(x)-pi/2": (lambda x: np.arctan(x) - np.pi / 2,
                     lambda x: sp.csc_matrix([[1 / (1 + x[0] ** 2)]])),
}


@pytest.mark.parametrize("name", sorted(FLAT))
def test_flat_tail_is_not_reported_as_solved(name):
    F, J = FLAT[name]
    # (no crash: on exp(-x) it goes straight to the solution x = 0, see below; the Newton
    # iterations alone walk down the flat tail)
    r = solve_mcp(F, J, 0.0, np.inf, np.ones(1), options={"crash_method": "none"})
    assert r.status is Status.FLAT_RESIDUAL, (r.status, r.x, r.message)
    assert not r.success and "flat" in r.message and "F[0]" in r.message
    # with the crash: the genuine solution, or the same verdict (never a false success)
    r = solve_mcp(F, J, 0.0, np.inf, np.ones(1))
    if r.success:
        fb, nat = residuals(F, r.x, 0.0, np.inf)
        assert nat <= TOL and np.max(np.abs(r.x)) <= 1e-6, r.x  # exp(-x): x = 0, F = 1
    else:
        assert r.status is Status.FLAT_RESIDUAL


def test_flat_scaled_mcp_started_above_its_solution_is_not_reported_as_solved():
    n = 20
    rng = np.random.default_rng(0)
    M = sp.random(n, n, density=0.2, random_state=2).toarray()
    M = M + np.diag(np.abs(M).sum(1) + 1)
    zs = rng.uniform(0, 1, n)
    q = -M @ zs

    def F(z):
        return 3.0 * np.exp(-z) * (M @ z + q)

    def J(z):
        e = 3.0 * np.exp(-z)
        return sp.csc_matrix(e[:, None] * M - np.diag(e * (M @ z + q)))

    r = solve_mcp(F, J, 0.0, np.inf, zs + 10)
    if r.success:  # a genuine solution is fine; a flat point must not be called one
        assert np.abs(r.x - zs).max() <= 1e-4
    else:
        assert r.status is Status.FLAT_RESIDUAL


# ------------------------------------------------------------------ properties
def _dropping_problem(seed, n=25):
    """F = A x + x^3 - b with a J built from arrays (zeros dropped at x = 0); A random
    symmetric with some empty rows: solvable (the x^3 term makes F strongly monotone on
    x >= 0 at infinity and F(0) = -b)."""
    rng = np.random.default_rng(seed)
    A = sp.random(n, n, density=0.06, random_state=seed)
    A = ((A + A.T) * 0.2).tocsr()
    b = rng.uniform(-1, 1, n)
    lb = np.where(rng.random(n) < 0.5, 0.0, -np.inf)

    def F(x):
        return A @ x + x ** 3 - b

    def J(x):
        return (A + sp.diags(3 * x ** 2)).tocsc()

    return F, J, lb


@pytest.mark.parametrize("seed", range(12))
def test_property_no_infeasible_and_no_success_above_tolerance_with_dropped_zeros(seed):
    F, J, lb = _dropping_problem(seed)
    r = solve_mcp(F, J, lb, np.inf, np.zeros(lb.size), options={"time_limit": 20})
    assert r.status is not Status.INFEASIBLE, r.message
    if r.success:
        ub = np.full(lb.size, np.inf)
        f = F(r.x.copy())
        nat = float(np.max(np.abs(r.x - np.clip(r.x - f, lb, ub))))
        assert nat <= TOL
        assert r.check(F, lb, ub).fb_norm <= TOL


@pytest.mark.parametrize("seed", range(6))
def test_property_presolve_alone_never_proves_infeasible_with_dropped_zeros(seed):
    F, J, lb = _dropping_problem(seed)
    pre = presolve(MCP(F, J, lb, np.inf, np.zeros(lb.size)))
    assert pre.infeasible is None


@pytest.mark.parametrize("seed", range(8))
def test_property_lcp_success_meets_both_residuals(seed):
    rng = np.random.default_rng(100 + seed)
    n = 15
    B = rng.normal(size=(n, n))
    M = B @ B.T * 0.1 + np.diag(rng.uniform(0.01, 1, n))
    q = rng.normal(size=n)
    r = solve_lcp(sp.csc_matrix(M), q, options=Options(convergence_tolerance=1e-8))
    assert r.success
    f = M @ r.x + q
    assert np.max(np.abs(r.x - np.clip(r.x - f, 0, np.inf))) <= 1e-8


from hypothesis import given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 10 ** 6), tol=st.sampled_from([1e-4, 1e-6, 1e-8]),
       row_scale=st.sampled_from([0, 2, 4]), drop=st.booleans())
def test_property_success_meets_both_residuals_and_infeasible_never_on_solvable(
        seed, tol, row_scale, drop):
    """Random solvable problems F = S (A x + x^3 - b) on boxes, NCP and free rows (S: rows
    in units spread over 10^+-row_scale; A monotone, so F is coercive and a solution
    exists; J a sparse matrix built from arrays, dropping zeros, when ``drop``):
    never INFEASIBLE, and every SOLVED point has both residuals <= tol, recomputed here."""
    rng = np.random.default_rng(seed)
    n = int(rng.integers(2, 15))
    B = sp.random(n, n, density=0.3, random_state=seed).toarray()
    A = B - B.T + np.diag(rng.uniform(0.0, 1.0, n))
    b = rng.normal(size=n)
    S = 10.0 ** rng.uniform(-row_scale, row_scale, n)
    lb = np.where(rng.random(n) < 0.5, 0.0, -np.inf)
    ub = np.where(rng.random(n) < 0.3, 2.0, np.inf)  # boxes [0, 2] and (-inf, 2]

    def F(x):
        return S * (A @ x + x ** 3 - b)

    def J(x):
        Jd = S[:, None] * (A + np.diag(3 * x ** 2))
        return sp.csc_matrix(Jd) if drop else Jd  # a dense array keeps its full pattern

    r = solve_mcp(F, J, lb, ub, np.zeros(n),
                  options={"convergence_tolerance": tol, "time_limit": 10})
    assert r.status is not Status.INFEASIBLE
    if r.success:
        f = F(r.x.copy())
        assert np.max(np.abs(r.x - np.clip(r.x - f, lb, ub))) <= tol
        assert r.check(F, lb, ub).fb_norm <= tol


def test_scaled_solve_takes_the_solvers_verdict_for_its_result(monkeypatch):
    """A scaled solve that stops at a solution judged with the user's J does not judge
    it again for the Result, which is the Result of judging again."""
    import compass_sparse.report as report
    import compass_sparse.solve as solve_mod
    from compass_sparse.generators.cge import ramsey_cge

    p = ramsey_cge(periods=11, sectors=1).with_shock(capital_tax=0.25).problem
    calls = []
    real = report.judge_on
    for module in (solve_mod, report):  # the start point's verdict, and the Result's
        monkeypatch.setattr(module, "judge_on",
                            lambda *a, **k: calls.append(1) or real(*a, **k))
    r = solve_mcp(p.with_start(p.x0))
    assert r.passes["scaling"].ran and r.status is Status.SOLVED
    assert len(calls) == 1  # the start point only
    calls.clear()
    monkeypatch.setattr(solve_mod, "_UserJacobian", lambda *a: None)  # the scaled route
    r2 = solve_mcp(p.with_start(p.x0))
    assert len(calls) == 2
    assert np.array_equal(r.x, r2.x) and r.residual == r2.residual
    assert (r.status, r.nit, r.nfev, r.njev, r.domain_errors, r.point_status) == \
        (r2.status, r2.nit, r2.nfev, r2.njev, r2.domain_errors, r2.point_status)


# ------------------------------------------------- defect: blind at a bound
def _scaled_linear(n=5, s=1e-9):
    """F = s (A x - 1) on x >= 0, A = diag(1..n): the solution x_i = 1/i, where F is flat
    (s = 1e-9): every point of small residual is in a flat region of F."""
    A = sp.diags(np.arange(1.0, n + 1)).tocsc()
    return (lambda x: s * (A @ x - 1.0)), (lambda x: s * A)


def test_flat_residual_verdict_does_not_depend_on_the_start_at_a_bound():
    """b6f9c1f: SOLVED at x = 0 ("the start point is a solution") from x0 = 0 and from x0 =
    3, FLAT_RESIDUAL from x0 = 0.5: at x = 0, F = -1e-9 < 0, the FB row is the bound's
    (H_i ~ -e_i) and its Newton step ~2e-9 looked converged."""
    n = 5
    F, J = _scaled_linear(n)
    sol = 1.0 / np.arange(1.0, n + 1)
    for x0 in (0.0, 0.5, 3.0):
        r = solve_mcp(F, J, 0.0, np.inf, np.full(n, x0))
        if r.success:  # only the genuine solution may be called one
            assert np.abs(r.x - sol).max() <= 1e-3, (x0, r.x)
        else:
            assert r.status is Status.FLAT_RESIDUAL, (x0, r.status)
            assert "flat" in r.message


@pytest.mark.parametrize("scale, accepted", [(1.0, True), (1e-2, True), (4.4e-4, True),
                                             (3.6e-4, False), (1e-6, False)])
def test_flat_step_at_a_bound_reads_the_natural_maps_F_row(scale, accepted):
    """At x = 0 with F = -4e-7 < 0 (||Phi|| = 8e-7, natural residual 4e-7: test (1)
    passes) the F row's Newton step |F| / |J| = 4e-7 / scale must be at most
    FLAT_STEP_RTOL = 1e-3: the tolerance is stressed on both sides of its boundary."""
    from compass_sparse.nms.acceptance import FLAT_STEP_RTOL

    x, f = np.zeros(1), np.array([-4e-7])
    v = judge(x, f, np.zeros(1), np.full(1, np.inf), TOL, jac=lambda y: sp.csc_matrix([[scale]]))
    assert v.small_residual and v.solved is accepted
    assert bool(4e-7 / scale <= FLAT_STEP_RTOL) is accepted
    # the same row with the bound's piece active (F > 0 at the bound): always accepted,
    # whatever the scale of J (a genuine solution at a bound with a flat F row)
    v = judge(x, -f, np.zeros(1), np.full(1, np.inf), TOL, jac=lambda y: sp.csc_matrix([[scale]]))
    assert v.solved


# ----------------------------------------------- defect: underflowed tails
def _flat_tail_ncp(seed=5, n=20, a=1.0):
    """F = a exp(-z) (M z + q), an NCP with a planted solution zs (some components 0)."""
    rng = np.random.default_rng(seed)
    M = sp.random(n, n, density=0.3, random_state=seed).toarray()
    M = M - M.T + np.diag(rng.uniform(1, 2, n))
    zs = rng.uniform(0, 1, n)
    zs[rng.random(n) < 0.4] = 0.0
    q = -M @ zs + np.where(zs == 0, rng.uniform(0.1, 1, n), 0.0)

    def F(z):
        return a * np.exp(-z) * (M @ z + q)

    def J(z):
        e = a * np.exp(-z)
        return sp.csc_matrix(e[:, None] * M + np.diag(e * (M @ z + q)))

    return F, J, zs


@pytest.mark.parametrize("seed, a", [(5, 1.0), (5, 3.0), (8, 1.0)])
def test_flat_tail_ncp_started_past_its_humps_is_not_solved_where_F_underflows(seed, a):
    """b6f9c1f: SOLVED ("solution found", by the homotopy) at z ~ 2e3..3e4, where
    exp(-z) underflows: F and J are exactly 0 there, every residual is 0 and the Newton
    step test had nothing to divide."""
    F, J, zs = _flat_tail_ncp(seed, a=a)
    r = solve_mcp(F, J, 0.0, np.inf, zs + 20.0)
    if r.success:
        assert np.abs(r.x - zs).max() <= 1e-4, r.x
    else:
        assert r.status is Status.FLAT_RESIDUAL, r.status
        assert "vanished" in r.message or "flat" in r.message


def test_vanished_row_is_flat_only_when_its_F_was_not_zero_at_the_start():
    """Test (3) of the acceptance: F_i = 0 and J_i = 0 at z strictly inside the bounds is
    a flat tail when F_i was not 0 at the start point, and may be an identically zero
    row (any value of its variable solves it) when it was; a row at a bound is
    complementary whatever F's sign below the underflow.  (A new argument: b6f9c1f's
    judge knew no start point and accepted every point whose residuals are exactly 0.)"""
    lb, ub = np.array([-np.inf, -np.inf, 0.0]), np.full(3, np.inf)
    z, f = np.array([3e4, 1.0, 0.0]), np.zeros(3)
    J_here = sp.csc_matrix(np.diag([0.0, 2.0, 0.0]))
    v = judge(z, f, lb, ub, TOL, jac=lambda y: J_here, start_f=np.array([1e-9, 0.0, 1.0]))
    assert v.small_residual and not v.solved and v.flat_row == 0 and np.isinf(v.step)
    assert "vanished" in v.flat_message(lambda i: f"F[{i}]")
    # F_0 was 0 at the start too; F_2 vanished at its bound: both accepted
    assert judge(z, f, lb, ub, TOL, jac=lambda y: J_here, start_f=np.array([0.0, 1.0, 1.0])).solved
    assert judge(z, f, lb, ub, TOL, jac=lambda y: J_here).solved  # no start: not tested
    # J_0 not 0: a genuine root of row 0, accepted
    J_root = sp.csc_matrix(np.diag([1e-3, 2.0, 0.0]))
    assert judge(z, f, lb, ub, TOL, jac=lambda y: J_root, start_f=np.ones(3)).solved
