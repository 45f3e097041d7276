"""solve_mcp and MCPSolver end to end on problems with known solutions.

Every success is checked independently: the natural residual
||z - clip(z - F(z), l, u)||_inf is recomputed from the problem's own formulas (never from
the solver's report), and compared with the known solutions of tests/known_problems.py.
"""

from __future__ import annotations


import numpy as np
import pytest
import scipy.sparse as sp

import compass_sparse.generators as gen
from compass_sparse import (MCP, EvaluationError, IntermediateResult, MCPSolver, OptionError,
                            Options, PointStatus, StartPointError, Status, solve_mcp)
from compass_sparse.exceptions import ProblemError
from compass_sparse.generators.sparse import BandedNonlinear, draw_bounds

import known_problems as kp

TOL = 1e-6  # the default convergence tolerance, applied to the natural residual


def nat_res(F, x, lb, ub):
    x = np.asarray(x, dtype=float)
    f = np.asarray(F(x.copy()), dtype=float)
    return float(np.max(np.abs(x - np.clip(x - f, lb, ub))))


def fd_jacobian(F, x, h=1e-7):
    f0 = F(x)
    return np.column_stack([(F(x + h * e) - f0) / h for e in np.eye(x.size)])


def check_success(r, F, lb, ub, tol=TOL):
    assert r.success, f"{r.status.name}: {r.message}"
    assert r.status is Status.SOLVED
    assert r.point_status is PointStatus.SOLUTION
    nat = nat_res(F, r.x, lb, ub)
    assert nat <= tol, nat
    assert np.all(r.x >= lb) and np.all(r.x <= ub)
    # the formula z - clip(z - F) here rounds z - F: up to an ulp of max|z| off (the
    # mathiesen run ends at |z| ~ 6e6, where that is 1e-9 against a residual of 7e-7)
    ulp = 4.0 * np.finfo(float).eps * float(np.max(np.abs(r.x), initial=0.0))
    assert r.residual.natural == pytest.approx(nat, rel=1e-6, abs=1e-14 + ulp)
    np.testing.assert_allclose(r.fun, F(r.x.copy()), rtol=1e-12, atol=1e-12)
    return nat


# ----------------------------------------------------------------------------- the module itself
ALL_KNOWN = {**kp.ALL_SOLVABLE, "double_root": kp.degenerate_root, "billups": kp.billups,
             "log_ncp": kp.log_ncp, "sqrt_ncp": kp.sqrt_ncp}


@pytest.mark.parametrize("name", list(ALL_KNOWN))
def test_known_problems_are_consistent(name):
    """The analytic Jacobians match finite differences; the known solutions solve."""
    p = ALL_KNOWN[name]()
    rng = np.random.default_rng(1)
    x = rng.uniform(1.2, 2.0, p.n)  # inside every domain
    J = p.J(x)
    J = J.toarray() if sp.issparse(J) else np.asarray(J)
    np.testing.assert_allclose(J, fd_jacobian(p.F, x), rtol=1e-5, atol=1e-5)
    for s in p.solutions:
        # published to 4 decimals for nash5; exact (up to rounding) for the others
        assert nat_res(p.F, s, p.lb, p.ub) <= (1e-3 if name == "nash5" else 1e-12)


def test_mathiesen_solution_continuum():
    p = kp.mathiesen()
    for lam in (0.0, 0.5, 1.7, 3.0):
        assert nat_res(p.F, np.array([lam, 0, 0, 0]), p.lb, p.ub) == 0.0
    assert nat_res(p.F, np.array([3.5, 0, 0, 0]), p.lb, p.ub) > 0.1


# ----------------------------------------------------------------------------- known problems
KNOWN_RUNS = [
    ("kojshin", None), ("kojshin", np.ones(4)), ("kojshin", np.array([2.0, 0.5, 0.0, 1.0])),
    ("josephy", None), ("josephy", np.ones(4)),
    ("mathiesen", None), ("mathiesen", np.array([2.0, 1.0, 0.5, 0.5])),
    ("cournot2", None), ("cournot2", np.array([8.0, 8.0])),
    ("nash5", None), ("nash5", np.ones(5)),
    ("boxvi", None), ("boxvi", np.array([3.0, 1.0, 2.0, -1.0, 3.0, 4.0])),
]


@pytest.mark.parametrize("tol", [1e-6, 1e-10])
@pytest.mark.parametrize("name,x0", KNOWN_RUNS)
def test_known_problem_solved(name, x0, tol):
    p = kp.ALL_SOLVABLE[name](x0)
    r = solve_mcp(p.F, p.J, p.lb, p.ub, p.x0, options={"convergence_tolerance": tol})
    nat = check_success(r, p.F, p.lb, p.ub, tol=TOL if tol == 1e-6 else 1e-9)
    # which solution: nash5's reference is published to 4 decimals
    dist_tol = 1e-3 if name == "nash5" else (1e-4 if tol == 1e-6 else 1e-8)
    assert p.distance_to_solutions(r.x) <= dist_tol, (r.x, nat)


def test_kojima_shindo_finds_a_listed_solution_from_many_starts():
    p = kp.kojima_shindo()
    rng = np.random.default_rng(7)
    for _ in range(6):
        x0 = rng.uniform(0.0, 3.0, 4)
        r = solve_mcp(p.F, p.J, p.lb, p.ub, x0)
        check_success(r, p.F, p.lb, p.ub)
        # every start ends at one of the two listed solutions (from these starts, always
        # the one with z_3 = 0.5); a set of the solutions found could never be empty
        d = [np.max(np.abs(r.x - s)) for s in p.solutions]
        assert min(d) <= 1e-4


def test_degenerate_double_root():
    """(x - 1)^2 = 0, x free: a singular Jacobian at the root; linear convergence."""
    p = kp.degenerate_root()
    for x0 in (3.0, -2.0, 1.5):
        r = solve_mcp(p.F, p.J, p.lb, p.ub, np.array([x0]))
        check_success(r, p.F, p.lb, p.ub)
        assert abs(r.x[0] - 1.0) <= 2e-3  # |F| = (x - 1)^2 <= 1e-6
    r = solve_mcp(p.F, p.J, p.lb, p.ub, np.array([3.0]), options={"convergence_tolerance": 1e-10})
    check_success(r, p.F, p.lb, p.ub, tol=1e-9)


@pytest.mark.parametrize("x0", [0.0, 0.5, 1.0, 3.0])
def test_billups_never_a_wrong_success(x0):
    """From x0 = 0 PATH fails on billups; we either solve it or say we did not."""
    p = kp.billups(np.array([x0]))
    xstar = p.solutions[0][0]
    r = solve_mcp(p.F, p.J, p.lb, p.ub, p.x0)
    nat = nat_res(p.F, r.x, p.lb, p.ub)
    if r.success:
        assert nat <= TOL
        assert abs(r.x[0] - xstar) <= 1e-5
    else:
        assert r.status is not Status.SOLVED
        assert r.point_status in (PointStatus.BEST_POINT, PointStatus.START_POINT)
        start = nat_res(p.F, p.x0, p.lb, p.ub)
        assert r.residual.fb_norm > r.tolerance
        assert nat <= start + 1e-12  # the best point is no worse than the start
    assert r.x[0] >= 0.0


# ----------------------------------------------------------------------------- domain errors
@pytest.mark.parametrize("raise_errors", [True, False])
def test_log_domain_errors_rejected(raise_errors):
    """F = log(x) - c: the first Newton steps land outside the domain (x_i = 0 after
    projection); those points are rejected, counted, and the solve still succeeds."""
    p = kp.log_ncp(raise_errors=raise_errors)
    # a full Newton step from x0 = 2 in the first component (c = -3) leaves the domain
    f0, J0 = p.F(p.x0), p.J(p.x0).toarray()
    assert p.x0[0] - f0[0] / J0[0, 0] < 0
    r = solve_mcp(p.F, p.J, p.lb, p.ub, p.x0)
    check_success(r, p.F, p.lb, p.ub)
    assert r.domain_errors > 0
    np.testing.assert_allclose(r.x, p.solutions[0], rtol=1e-5)


def test_sqrt_domain_errors_rejected():
    p = kp.sqrt_ncp(np.array([50.0]))
    r = solve_mcp(p.F, p.J, p.lb, p.ub, p.x0)
    check_success(r, p.F, p.lb, p.ub)
    assert r.domain_errors > 0
    assert abs(r.x[0] - 2.0) <= 1e-6


def test_nash_oligopoly_domain_from_small_start():
    """nash5 is undefined at Q = 0; from a start near zero the iterates must stay defined."""
    p = kp.nash_cournot_mss(np.full(5, 0.1))
    r = solve_mcp(p.F, p.J, p.lb, p.ub, p.x0)
    check_success(r, p.F, p.lb, p.ub)
    assert np.max(np.abs(r.x - kp.MSS_SOLUTION)) <= 1e-3


def test_nonfinite_start_is_an_input_error():
    p = kp.log_ncp()
    with pytest.raises(EvaluationError):
        solve_mcp(p.F, p.J, p.lb, p.ub, np.array([0.0, 1.0, 1.0, 1.0]))
    with pytest.raises(StartPointError):
        solve_mcp(p.F, p.J, p.lb, p.ub, np.array([np.nan, 1.0, 1.0, 1.0]))


# ----------------------------------------------------------------------------- manufactured
def manufactured_case(n, seed, degenerate=0.0, bound_mix=(0.25, 0.25, 0.25, 0.25)):
    base = BandedNonlinear(n, seed)
    lb, ub, _ = draw_bounds(n, np.random.default_rng(1000 + seed), bound_mix)
    g = gen.manufacture(base.F, base.J, None, lb, ub, seed, degenerate_fraction=degenerate,
                        x0=np.clip(np.zeros(n), lb, ub))
    info = g.info
    shift = info["w_star"] - info["v_star"] - info["F_star"]

    def F_indep(z):  # F~ rebuilt here from the base F and the recorded data
        return base.F(z) + shift

    return g, base, F_indep, g.problem.lb, g.problem.ub


@pytest.mark.parametrize("n,seed,deg", [(20, 0, 0.0), (20, 1, 0.3), (60, 2, 0.0),
                                        (60, 3, 0.5), (200, 4, 0.0), (200, 5, 0.2)])
def test_manufactured_nonlinear(n, seed, deg):
    g, base, F, lb, ub = manufactured_case(n, seed, deg)
    kinds = np.isfinite(lb).astype(int) + 2 * np.isfinite(ub).astype(int)
    assert set(kinds.tolist()) == {0, 1, 2, 3}  # free, lower, upper and boxed variables
    assert nat_res(F, g.solution, lb, ub) <= 1e-12
    r = solve_mcp(g.problem)
    check_success(r, F, lb, ub)
    # strongly monotone F (diagonally dominant A + monotone terms): the solution is unique
    assert np.max(np.abs(r.x - g.solution)) <= 1e-4
    r = solve_mcp(g.problem, options={"convergence_tolerance": 1e-10})
    check_success(r, F, lb, ub, tol=1e-9)
    assert np.max(np.abs(r.x - g.solution)) <= 1e-8


@pytest.mark.parametrize("n,seed,structure", [(50, 0, "grid"), (120, 1, "banded"),
                                              (200, 2, "grid")])
def test_manufactured_structured_quadratic(n, seed, structure):
    g = gen.structured_quadratic(n, seed, structure=structure, degenerate_fraction=0.1)
    D, A, b = g.info["D"], g.info["A"], g.info["b"]
    shift = g.info["w_star"] - g.info["v_star"] - g.info["F_star"]

    def F(z):
        return D * z * z + A @ z + b + shift

    p = g.problem
    assert nat_res(F, g.solution, p.lb, p.ub) <= 1e-12
    r = solve_mcp(p)
    check_success(r, F, p.lb, p.ub)
    r = solve_mcp(p, options={"convergence_tolerance": 1e-10, "crash_method": "none"})
    check_success(r, F, p.lb, p.ub, tol=1e-9)


def fixed_variables_case(n=40):
    """A manufactured nonlinear MCP in which every fifth variable is fixed (presolve
    removes those): (generated, F with the solution's shift, lb, ub, z*, fixed)."""
    base = BandedNonlinear(n, 11)
    lb, ub, _ = draw_bounds(n, np.random.default_rng(11))
    zstar = np.clip(np.random.default_rng(12).uniform(-1, 1, n), lb, ub)
    fix = np.arange(0, n, 5)
    lb, ub = lb.copy(), ub.copy()
    lb[fix] = ub[fix] = zstar[fix]
    g = gen.manufacture(base.F, base.J, zstar, lb, ub, 3, x0=np.clip(np.zeros(n), lb, ub))
    shift = g.info["w_star"] - g.info["v_star"] - g.info["F_star"]

    def F(z):
        return base.F(z) + shift

    return g, F, lb, ub, zstar, fix


def test_manufactured_with_fixed_variables_goes_through_presolve():
    g, F, lb, ub, zstar, fix = fixed_variables_case()

    r = solve_mcp(g.problem)
    check_success(r, F, lb, ub)
    np.testing.assert_array_equal(r.x[fix], zstar[fix])
    assert r.passes["presolve"].ran


def test_fixed_variables_alone_are_left_to_the_solver():
    """Fixing l = u variables is the only reduction: the solver keeps them fixed in the
    user's problem (no reduced problem to build and evaluate through) and says so."""
    from compass_sparse.presolve import presolve

    g, F, lb, ub, zstar, fix = fixed_variables_case()
    pre = presolve(g.problem, leave_simple_to_solver=True)
    assert pre.reduced is g.problem and pre.stats.kept_fixed == fix.size
    assert pre.stats.removed == 0 and len(pre.stack) == 0
    full = presolve(g.problem)
    assert full.stats.removed == fix.size and full.reduced is not g.problem
    r = solve_mcp(g.problem)
    check_success(r, F, lb, ub)
    np.testing.assert_array_equal(r.x[fix], zstar[fix])
    assert f"{fix.size} fixed variables (l = u) left to the solver" in \
        r.passes["presolve"].reason


def test_large_problems_still_solve_a_reduced_problem_without_fixed_variables():
    """Above LEAVE_SIMPLE_MAX_N the preprocessor's reduced problem is kept even when it only
    fixes l = u variables (a different trajectory had cost the dynamic CGE model at
    n = 1e4 its crash-only solve)."""
    from compass_sparse.solve import LEAVE_SIMPLE_MAX_N

    n = LEAVE_SIMPLE_MAX_N + 1
    d = np.linspace(1.0, 2.0, n)
    lb, ub = np.zeros(n), np.full(n, np.inf)
    lb[::7] = ub[::7] = 0.5
    p = MCP(lambda z: d * z - 1.0, lambda z: sp.diags(d, format="csc"), lb, ub, np.ones(n))
    r = solve_mcp(p)
    assert r.success and r.passes["presolve"].reason.startswith(
        f"Preprocessor removed {lb[::7].size} rows/cols")
    np.testing.assert_allclose(r.x[::7], 0.5)


# ----------------------------------------------------------------------------- Jacobian forms
def test_jac_true_and_fd_forms():
    p = kp.kojima_shindo()
    ref = solve_mcp(p.F, p.J, p.lb, p.ub, p.x0)
    check_success(ref, p.F, p.lb, p.ub)
    r = solve_mcp(lambda x: (p.F(x), p.J(x)), True, p.lb, p.ub, p.x0)
    check_success(r, p.F, p.lb, p.ub)
    assert p.distance_to_solutions(r.x) <= 1e-4
    r = solve_mcp(p.F, None, p.lb, p.ub, p.x0, jac_sparsity=np.ones((4, 4)))
    check_success(r, p.F, p.lb, p.ub)
    assert p.distance_to_solutions(r.x) <= 1e-4
    assert r.nfev > ref.nfev  # finite differences cost extra evaluations


def test_jac_forms_on_sparse_manufactured():
    g, base, F, lb, ub = manufactured_case(80, 21)
    shift = F(np.zeros(80)) - base.F(np.zeros(80))
    x0 = np.clip(np.zeros(80), lb, ub)
    r1 = solve_mcp(lambda z: (base.F(z) + shift, base.J(z)), True, lb, ub, x0)
    check_success(r1, F, lb, ub)
    pattern = base.J(np.zeros(80))
    r2 = solve_mcp(F, None, lb, ub, x0, jac_sparsity=pattern)
    check_success(r2, F, lb, ub)
    # the tridiagonal pattern needs only 3 colours: few extra evaluations per Jacobian
    assert r2.nfev <= 4 * (r2.njev + 1) + r1.nfev + 50
    assert np.max(np.abs(r1.x - g.solution)) <= 1e-4
    assert np.max(np.abs(r2.x - g.solution)) <= 1e-4


# ----------------------------------------------------------------------------- limits & stops
def test_major_iteration_limit_returns_best_point():
    # needs several major iterations from 0 (without the crash); without the homotopy,
    # which would take over after the stall of homotopy_stationary_limit = 2 iterations
    p = kp.kojima_shindo()
    o = {"crash_method": "none", "homotopy": "off"}
    full = solve_mcp(p.F, p.J, p.lb, p.ub, p.x0, options=o)
    check_success(full, p.F, p.lb, p.ub)
    assert full.nit > 2
    start_fb = solve_mcp(p.F, p.J, p.lb, p.ub, p.x0,
                         options={"major_iteration_limit": 0}).residual.fb_norm
    for k in (1, 2):
        r = solve_mcp(p.F, p.J, p.lb, p.ub, p.x0, options={"major_iteration_limit": k, **o})
        assert r.status is Status.MAJOR_ITERATION_LIMIT
        assert not r.success
        assert r.nit == k
        assert r.point_status in (PointStatus.BEST_POINT, PointStatus.START_POINT)
        # the best point by merit: no worse than the start
        assert r.residual.fb_norm <= start_fb + 1e-12
        assert r.residual.natural == pytest.approx(nat_res(p.F, r.x, p.lb, p.ub), rel=1e-9)


def test_major_iteration_limit_zero():
    p = kp.josephy(np.ones(4))
    r = solve_mcp(p.F, p.J, p.lb, p.ub, p.x0, options={"major_iteration_limit": 0})
    assert r.status is Status.MAJOR_ITERATION_LIMIT
    assert r.point_status is PointStatus.START_POINT
    np.testing.assert_array_equal(r.x, p.x0)
    assert r.nit == 0
    assert r.residual.natural == pytest.approx(nat_res(p.F, p.x0, p.lb, p.ub))


def test_time_limit():
    p = kp.kojima_shindo()
    r = solve_mcp(p.F, p.J, p.lb, p.ub, p.x0, options={"time_limit": 1e-9})
    assert r.status is Status.TIME_LIMIT
    assert not r.success
    assert r.residual.fb_norm > r.tolerance
    g, base, F, lb, ub = manufactured_case(200, 31)
    r = solve_mcp(g.problem, options={"time_limit": 1e-9, "crash_method": "none"})
    assert r.status is Status.TIME_LIMIT


def test_callback_stop():
    p = kp.kojima_shindo()
    seen = []

    def cb(info):
        assert isinstance(info, IntermediateResult)
        seen.append(info)
        return True

    r = solve_mcp(p.F, p.J, p.lb, p.ub, p.x0, callback=cb)
    assert r.status is Status.CALLBACK_STOP
    assert not r.success
    assert len(seen) == 1
    assert r.status.path_code() == 6


def test_callback_stop_iteration_and_information():
    p = kp.kojima_shindo()
    seen = []

    def cb(info):
        # the intermediate point is consistent: fun = F(x), residual = ||Phi||
        np.testing.assert_allclose(info.fun, p.F(info.x), rtol=1e-12, atol=1e-12)
        seen.append(info.nit)
        if len(seen) == 3:
            raise StopIteration

    # (without the crash and the homotopy: kojshin then takes more than 3 major iterations
    # from 0; the homotopy would take over after 2)
    r = solve_mcp(p.F, p.J, p.lb, p.ub, p.x0, callback=cb,
                  options={"crash_method": "none", "homotopy": "off"})
    assert r.status is Status.CALLBACK_STOP
    assert seen == sorted(seen) and len(seen) == 3
    # a callback that never stops changes nothing
    r = solve_mcp(p.F, p.J, p.lb, p.ub, p.x0, callback=lambda info: False)
    check_success(r, p.F, p.lb, p.ub)


def test_warm_start_from_solution_zero_major_iterations():
    p = kp.josephy()
    r = solve_mcp(p.F, p.J, p.lb, p.ub, p.x0)
    check_success(r, p.F, p.lb, p.ub)
    assert r.nit > 0
    again = solve_mcp(p.F, p.J, p.lb, p.ub, r.x, basis=r.basis)
    check_success(again, p.F, p.lb, p.ub)
    assert again.nit == 0
    assert again.minor_iterations == 0
    g, base, F, lb, ub = manufactured_case(100, 41)
    r = solve_mcp(g.problem, options={"crash_method": "none"})
    check_success(r, F, lb, ub)
    again = solve_mcp(g.problem, x0=r.x, basis=r.basis)
    check_success(again, F, lb, ub)
    assert again.nit == 0


def test_mcpsolver_object_api_warm_start():
    p = kp.kojima_shindo()
    solver = MCPSolver(MCP(p.F, p.J, p.lb, p.ub, p.x0))
    r1 = solver.solve()
    check_success(r1, p.F, p.lb, p.ub)
    assert r1.nit > 0
    r2 = solver.solve()
    check_success(r2, p.F, p.lb, p.ub)
    assert r2.nit == 0
    np.testing.assert_allclose(r2.x, r1.x, atol=1e-12)
    r3 = solver.solve(x0=p.x0, warm_start=False)  # cold again
    check_success(r3, p.F, p.lb, p.ub)
    assert r3.nit > 0
    with pytest.raises(ProblemError, match="MCPSolver takes an MCP"):
        MCPSolver(p.F)


def test_mcpsolver_scenario_loop():
    """Change the data the closure reads; the warm-started solves stay correct."""
    n = 60
    base = BandedNonlinear(n, 51)
    lb, ub, _ = draw_bounds(n, np.random.default_rng(51))
    data = {"b": np.random.default_rng(52).uniform(-1, 1, n)}

    def F(z):
        return base.F(z) + data["b"]

    solver = MCPSolver(MCP(F, base.J, lb, ub, np.clip(np.zeros(n), lb, ub)),
                       options={"convergence_tolerance": 1e-8})
    for k in range(4):
        data["b"] = data["b"] + 0.05 * k
        r = solver.solve()
        check_success(r, F, lb, ub, tol=1e-8)


# ----------------------------------------------------------------------------- options
def test_options_unknown_key_raises():
    p = kp.josephy()
    with pytest.raises(OptionError, match="convergence_tolerance"):
        solve_mcp(p.F, p.J, p.lb, p.ub, p.x0, options={"convergence_tolerence": 1e-8})
    with pytest.raises(OptionError):
        solve_mcp(p.F, p.J, p.lb, p.ub, p.x0, options={"no_such_option": 1})
    with pytest.raises(OptionError):
        solve_mcp(p.F, p.J, p.lb, p.ub, p.x0, options={"convergence_tolerance": -1.0})
    with pytest.raises(ValueError):  # OptionError is a ValueError
        Options(major_iteration_limit=-1)


# ----------------------------------------------------------------------------- thesis family
def test_thesis_family_one_n10():
    """Family 1 of the thesis (dense random quadratic, bounded boxes), n = 10, seeds 0..9:
    at least 9 of 10 must solve (residual recomputed from the raw data)."""
    solved = []
    for seed in range(10):
        g = gen.thesis_family(10, 1, seed)
        D, A, b = g.info["D"], g.info["A"], g.info["b"]
        lb, ub = g.info["lb"], g.info["ub"]

        def F(z, D=D, A=A, b=b):
            return D * z * z + A @ z + b

        r = solve_mcp(g.problem)
        nat = nat_res(F, r.x, lb, ub)
        if r.success:
            assert nat <= 1.7072 * r.tolerance  # ||min-map|| <= ||Phi|| / (2 - sqrt 2)
        else:
            assert r.residual.fb_norm > r.tolerance
        solved.append(bool(r.success and nat <= TOL))
    assert sum(solved) >= 9, solved


def test_problem_that_needs_a_restart():
    """Thesis family 1, n = 10, seed 57: the first run stalls at a local minimizer of the
    merit function; a restart (PATH's configurations, then multi-start) solves it.  The
    homotopy fallback is off: it would solve the instance without restarts.  (Seed 10
    served here until the restart rule counted from the reference value: its first run
    was cut short in a non-monotone excursion and now goes on to the solution, 15 major
    iterations without a restart.)"""
    from compass_sparse.generators import thesis_family

    g = thesis_family(10, family=1, seed=57)
    stuck = solve_mcp(g.problem, options={"restart_limit": 0, "homotopy": "off"})
    assert not stuck.success and stuck.status is Status.NO_PROGRESS
    assert stuck.point_status is not PointStatus.SOLUTION
    r = solve_mcp(g.problem, options={"homotopy": "off"})
    assert r.success and r.restarts >= 1
    p = g.problem
    f = p.F_uncounted(r.x)
    assert np.max(np.abs(r.x - np.clip(r.x - f, p.lb, p.ub))) <= 1e-6
    # the best point is never lost: the failed run returned its best merit, not the start
    assert stuck.residual.fb_norm <= solve_mcp(
        g.problem, options={"major_iteration_limit": 0}).residual.fb_norm


def test_keyboard_interrupt_returns_best_point():
    from compass_sparse.generators import thesis_family

    g = thesis_family(20, family=1, seed=5)
    calls = []

    def interrupt(info):
        calls.append(info.residual)
        if len(calls) == 2:
            raise KeyboardInterrupt

    r = solve_mcp(g.problem, callback=interrupt, options={"crash_method": "none"})
    assert r.status is Status.USER_INTERRUPT and not r.success
    assert r.x.shape == (20,) and np.all(np.isfinite(r.x))
    assert r.residual.fb_norm <= min(calls) + 1e-12


def test_cge_sector_shutdown_regression():
    """A 90% output tax on one sector drives its activity towards 0; Newton steps near the
    solution then raise the merit (the Jacobian is not Lipschitz there).  This diverged at
    residual 3e-4 until the NMS turned monotone near a solution."""
    from compass_sparse.generators.cge import size_for, static_cge

    m = static_cge(**size_for(1000), seed=0)
    R, N = m.block_shapes["Y"]
    tax = np.zeros((R, N))
    tax[0, 0] = 0.9
    shocked = m.with_shock(output_tax=tax)
    r = solve_mcp(shocked.problem, options={"time_limit": 60})
    assert r.success, r.message
    rep = r.check(shocked.problem)
    assert rep.natural <= 1e-6
    y = r.x[m.index("Y[r1,s1]")]
    assert 0.0 <= y < 0.5  # the taxed sector shrinks a lot


def test_evaluation_counts_through_presolve():
    """The reduced problem's evaluations are counted once (not again in the original)."""
    from compass_sparse.generators.cge import static_cge

    m = static_cge(regions=2, sectors=5, households=2, seed=0)
    p = m.with_shock(tariff=(0, 0.25)).problem
    r = solve_mcp(p)
    assert r.success and r.passes["presolve"].ran
    assert r.njev <= r.nit + r.crash_iterations + 8


def _with_linear_singleton(problem):
    """``problem`` with one more variable z_n >= 0 and the row F_n = 2 z_n - 1 declared
    linear: a singleton row that presolve removes (fixing l = u variables alone leaves the
    problem to the solver, which keeps them fixed itself)."""
    n = problem.n

    def F(z):
        return np.append(problem.F(z[:n]), 2.0 * z[n] - 1.0)

    def J(z):
        return sp.block_diag((problem.J(z[:n]), sp.csc_matrix([[2.0]])), format="csc")

    const = sp.csc_matrix(([1.0], ([n], [n])), shape=(n + 1, n + 1))
    return MCP(F, J, np.append(problem.lb, 0.0), np.append(problem.ub, np.inf),
               np.append(problem.x0, 1.0), constant_jac=const)


def test_warm_basis_survives_presolve():
    """Result.basis is in the user's index space after presolve removed variables, and a
    re-solve from it (presolve runs again) needs no pivots; a basis of the wrong size is
    an input error, not a silent cold start."""
    import compass_sparse.path.linear_mcp as linear_mcp_mod  # (NewtonStep calls it)
    from compass_sparse import ShapeError

    n = 40
    g, F, lb, ub, zstar, fix = fixed_variables_case(n)
    problem = _with_linear_singleton(g.problem)

    r = solve_mcp(problem, options={"convergence_tolerance": 1e-8})
    assert r.success and r.residual.natural <= 1e-8 and abs(r.x[n] - 0.5) <= 1e-12
    np.testing.assert_array_equal(r.x[fix], zstar[fix])
    assert r.passes["presolve"].ran and r.passes["presolve"].reason.startswith(
        "Preprocessor removed 9 rows/cols")
    assert r.basis.basic.shape == (n + 1,)
    warm_seen = []
    # the linear MCP of each major iteration (a small problem's direct step may end it
    # without running a PivotalPath), with the warm basis it is handed
    solve_linear = linear_mcp_mod.solve_linear_mcp

    def spy(*args, warm=None, **kw):
        warm_seen.append(None if warm is None else warm.basic.copy())
        return solve_linear(*args, warm=warm, **kw)

    linear_mcp_mod.solve_linear_mcp = spy
    try:
        # A tighter tolerance makes the re-solve take a Newton step from the solution.
        again = solve_mcp(problem, x0=r.x, basis=r.basis,
                          options={"convergence_tolerance": 1e-13, "major_iteration_limit": 1,
                                   "crash_method": "none"})
    finally:
        linear_mcp_mod.solve_linear_mcp = solve_linear
    keep = np.setdiff1d(np.arange(n), fix)
    assert warm_seen and warm_seen[0] is not None
    np.testing.assert_array_equal(warm_seen[0], r.basis.basic[keep])
    assert again.nit == 1 and again.minor_iterations == 0
    assert again.residual.fb_norm <= r.residual.fb_norm
    with pytest.raises(ShapeError, match="warm-start basis"):
        solve_mcp(problem, basis=type(r.basis)(r.basis.basic[:-1]))


def test_diagonal_column_singletons_are_left_to_the_solver():
    """A small static CGE model whose preprocessor finds one fixed price and one diagonal
    column singleton: no reduced problem is built (the solver settles both itself; the
    reduced problem's set-up and restricted evaluations cost more than they save), the
    summary says so, and the solution is the one the reduced problem gives."""
    from compass_sparse.generators.cge import size_for, static_cge
    from compass_sparse.presolve import presolve

    p = static_cge(**size_for(90)).with_shock(output_tax=0.25).problem
    full = presolve(p)
    assert full.stack.counts_by_kind() == {"fix": 1, "diagonal_column_singleton": 1}
    kept = presolve(p, leave_simple_to_solver=True)
    assert kept.reduced is p and len(kept.stack) == 0
    assert (kept.stats.kept_fixed, kept.stats.kept_singletons) == (1, 1)
    assert kept.stats.f_evals <= full.stats.f_evals  # no linearity check at sample points
    r = solve_mcp(p)
    assert "1 diagonal column singletons left to the solver" in r.passes["presolve"].reason
    check_success(r, p.F, p.lb, p.ub)
    reduced = presolve(p).reduced
    assert reduced is not p
    ref = solve_mcp(p, options={"presolve": False})
    np.testing.assert_allclose(r.x, ref.x, rtol=1e-7, atol=1e-9)


def test_other_reductions_are_still_made_for_small_problems():
    """Reductions other than those two are still made: on a linear diagonal NCP every
    row is a singleton row that fixes its variable (records of kind "fix" from another
    pass than the l = u one), so the preprocessor solves the whole problem."""
    from compass_sparse.presolve import presolve

    n = 6
    A = sp.csc_matrix(np.diag(np.arange(1.0, n + 1)))
    q = -np.ones(n)
    p = MCP(lambda z: A @ z + q, lambda z: A, np.zeros(n), np.full(n, np.inf), np.zeros(n),
            constant_jac=A)
    pre = presolve(p, leave_simple_to_solver=True)
    assert pre.reduced is None and pre.stats.kept_fixed == pre.stats.kept_singletons == 0
    r = solve_mcp(p)
    assert r.message == "solved by the preprocessor"
    check_success(r, lambda z: A @ z + q, 0.0, np.inf)


def test_preprocessor_point_missing_the_tolerance_is_solved_again_not_an_internal_error():
    """The preprocessor solved a 3 x 3 linear MCP by itself and postsolved x_0 = -1.3e17
    from the row 0.0057 x_0 + 3.70 x_2 - 7.55 = 0 with x_2 = 1.98e14 at its bound: F_0 is
    exact there only to ~0.1, and the user's problem read F_0 = -0.049.  The point was
    reported SOLVED, which the final check turned into Status.ERROR ("internal error: a
    non-solution was marked solved").  Now a preprocessor's point that misses the
    tolerance on the user's problem is solved again without the preprocessor, from that
    point; here no point does better at these magnitudes, and the status says so."""
    import warnings

    M = np.array([[5.6637305561408518e-03, 0.0, 3.6970301919591009e+00],
                  [0.0, 1.0894321570792496e+01, 0.0],
                  [0.0, -1.6341482356188744e+06, 0.0]])
    q = np.array([-7.5489941768819815e+00, -8.7005936066453689e-03, -1.6426934876217497e+03])
    lb = np.array([-np.inf, 0.0, -np.inf])
    ub = np.array([np.inf, np.inf, 1.9791005503999338e+14])
    A = sp.csc_matrix(M)
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)   # (the homotopy's step cap overflowed)
        r = solve_mcp(lambda z: A @ z + q, lambda z: A, lb, ub, np.zeros(3), constant_jac=A)
    assert r.status is not Status.ERROR
    assert "solved again without it" in r.passes["presolve"].reason
    assert np.all(r.x >= lb) and np.all(r.x <= ub)
    assert r.success == (r.residual.natural <= 1e-6) and not r.success


def test_reduced_solve_whose_postsolved_point_misses_the_tolerance_is_solved_again(
        monkeypatch):
    """The same check after a solve of the reduced problem: a postsolve that loses
    accuracy (simulated: 1e-3 added to the recovered variable) gave a point that is no
    solution of the user's problem; the solve goes on without the preprocessor from it
    and finds the solution."""
    from compass_sparse.presolve.core import PresolveResult

    n = 4
    A = sp.csc_matrix(np.array([[2.0, 0.0, 0.0, 0.0],     # a singleton row: x_0 = 1
                                [1.0, 3.0, 1.0, 0.0],
                                [0.0, 1.0, 4.0, 1.0],
                                [0.0, 0.0, 1.0, 5.0]]))
    q = np.array([-2.0, -1.0, -2.0, -3.0])
    const = sp.csc_matrix(np.array([[2.0, 0, 0, 0], [0, 0, 0, 0], [0, 0, 0, 0], [0, 0, 0, 0]]))

    calls = [0]

    def F(z):
        calls[0] += 1
        return A @ z + q + np.array([0.0, 0.1, 0.1, 0.1]) * z ** 3

    def J(z):
        return sp.csc_matrix(A + sp.diags(np.array([0.0, 0.3, 0.3, 0.3]) * z ** 2))

    real = PresolveResult.postsolve

    def lossy(self, z_red):
        z = real(self, z_red)
        if z_red.size:
            z = z.copy()
            z[0] += 1e-3
        return z

    monkeypatch.setattr(PresolveResult, "postsolve", lossy)
    p = MCP(F, J, np.full(n, -np.inf), np.full(n, np.inf), np.zeros(n), constant_jac=const)
    calls[0] = 0
    r = solve_mcp(p)
    assert r.success and "solved again without it" in r.passes["presolve"].reason
    assert r.nfev == calls[0] and r.nit >= 2  # the work of both solves is counted
    check_success(r, F, -np.inf, np.inf)


def test_solving_one_mcp_object_twice_counts_each_solve_alone():
    """Result.nfev read the MCP object's counters, which ran on from its construction
    (the start check) and over every earlier solve: the second solve of one object
    reported the evaluations of both.  Each solve now counts its own calls."""
    calls = [0]

    def F(x):
        calls[0] += 1
        return x ** 3 + x - 1.0

    def J(x):
        return sp.diags(3 * x ** 2 + 1).tocsc()

    p = MCP(F, J, 0.0, np.inf, np.zeros(3))
    counts = []
    for _ in range(2):
        calls[0] = 0
        r = solve_mcp(p)
        assert r.success and r.nfev == calls[0] == p.counters.nfev
        counts.append(r.nfev)
    assert counts[0] == counts[1]


def test_start_point_at_a_solution_runs_no_pass():
    """A solve started at a solution (a re-solve, a scenario that changed nothing) is
    judged on the user's problem before any pass: the preprocessor, which would reduce
    this CGE model (a fixed price and a column singleton), does not run, F and J are
    evaluated once, and the Result is the start point with its verdict."""
    from compass_sparse.generators.cge import size_for, static_cge

    p = static_cge(**size_for(90)).with_shock(output_tax=0.25).problem
    first = solve_mcp(p)
    assert first.success and first.passes["presolve"].ran  # it reduces this model
    again = solve_mcp(p.with_start(first.x))
    assert again.success and again.message == "the start point is a solution"
    assert again.nit == 0 and again.nfev == 1 and again.njev == 1
    assert not again.passes["presolve"].ran
    assert again.passes["presolve"].reason == "start point already solved"
    np.testing.assert_array_equal(again.x, first.x)
    f = p.F(again.x)
    assert np.max(np.abs(again.x - np.clip(again.x - f, p.lb, p.ub))) <= 1e-6
    # a start point that is not a solution still gets the preprocessor
    moved = solve_mcp(p.with_start(first.x * 1.01))
    assert moved.success and moved.passes["presolve"].ran
