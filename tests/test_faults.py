"""Faults end in a true status with the best point: exceptions and Ctrl-C in F, failures at
the start point, a failing callback, the time limit on every looping path.

Time limits are tested on a simulated clock (every F evaluation advances it by COST
seconds), never on the wall clock: the property is that the solve stops within 10% of the
limit plus one evaluation, whatever the machine's load.
"""
from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from compass_sparse import MCP, MCPSolver, PointStatus, Status, solve_lcp, solve_mcp
from compass_sparse.exceptions import EvaluationError
from compass_sparse.merit import fb_phi

N = 12
_rng = np.random.default_rng(0)
_B = _rng.normal(size=(N, N))
M = _B @ _B.T / N + np.eye(N)
q = _rng.normal(size=N)


def F_ok(x):
    return M @ x + q + 0.1 * x ** 3


def J_ok(x):
    return sp.csc_matrix(M + np.diag(0.3 * x ** 2))


def failing_on_call(k, exc):
    calls = {"i": 0}

    def F(x):
        calls["i"] += 1
        if calls["i"] == k:
            raise exc("boom")
        return F_ok(x)

    return F


@pytest.mark.parametrize("k", [2, 3, 4, 5])
@pytest.mark.parametrize("exc", [ValueError, KeyboardInterrupt])
def test_F_raising_on_its_kth_call_gives_a_result_not_a_crash(k, exc):
    F = failing_on_call(k, exc)
    r = solve_mcp(F, J_ok, 0.0, np.inf, np.zeros(N))
    if exc is KeyboardInterrupt:
        assert r.status is Status.USER_INTERRUPT
    else:
        assert r.status is Status.SOLVED
    assert np.all(np.isfinite(r.x))
    # the reported residual is that of the returned point
    f = F_ok(r.x)
    assert np.linalg.norm(fb_phi(r.x, f, 0.0, np.inf)) == pytest.approx(r.residual.fb_norm)


def test_ctrl_c_at_the_first_evaluation_of_a_solve_returns_the_start_point():
    F = failing_on_call(1, KeyboardInterrupt)
    r = solve_mcp(MCP(F, J_ok, 0.0, np.inf, np.zeros(N), check=False))
    assert r.status is Status.USER_INTERRUPT and r.point_status is PointStatus.START_POINT


@pytest.mark.parametrize("where", ["F", "J"])
def test_ctrl_c_in_the_first_call_of_solve_mcp_from_functions_returns_the_start_point(where):
    # solve_mcp builds the MCP itself: its start check is part of the solve, so Ctrl-C
    # there is USER_INTERRUPT with x0, not a raw KeyboardInterrupt
    def J_stop(x):
        raise KeyboardInterrupt

    F, J = (failing_on_call(1, KeyboardInterrupt), J_ok) if where == "F" else (F_ok, J_stop)
    r = solve_mcp(F, J, 0.0, np.inf, np.full(N, 0.5))
    assert r.status is Status.USER_INTERRUPT and r.point_status is PointStatus.START_POINT
    assert np.array_equal(r.x, np.full(N, 0.5))
    # an error at the start point is still bad input, raised as before
    with pytest.raises(EvaluationError, match="start point"):
        solve_mcp(failing_on_call(1, ValueError), J_ok, 0.0, np.inf, np.zeros(N))


def test_domain_error_at_a_new_start_point_is_a_status_not_an_exception():
    def F(x):
        if np.any(x > 5):
            raise ValueError("log of a negative number")
        return F_ok(x)

    P = MCP(F, J_ok, 0.0, np.inf, np.zeros(N))
    r = MCPSolver(P).solve(x0=np.full(N, 10.0))
    assert r.status is Status.DOMAIN_ERROR and "log of a negative" in r.message
    r = solve_mcp(MCP(F, J_ok, 0.0, np.inf, np.full(N, 10.0), check=False))
    assert r.status is Status.DOMAIN_ERROR


def test_callback_exception_stops_with_the_best_point_not_raw():
    seen = []

    def cb(info):
        seen.append(info.residual)
        raise RuntimeError("plotting failed")

    r = solve_mcp(F_ok, J_ok, 0.0, np.inf, np.full(N, 3.0), callback=cb)
    assert r.status is Status.CALLBACK_STOP and "plotting failed" in r.message
    assert r.residual.fb_norm <= min(seen) + 1e-12


@pytest.mark.parametrize("seed", [0, 1, 6])
def test_best_point_includes_the_crash_trial_points(seed):
    # Stopped by the callback at the first major iteration, after the crash: the returned
    # point is the best of every point where F was evaluated, crash trial points included.
    rng = np.random.default_rng(seed)
    B = rng.normal(size=(N, N))
    A = B - B.T + 0.2 * np.eye(N) + 0.3 * B
    c = rng.normal(size=N) * 3
    evaluated = []

    def F(x):
        f = A @ x + c + 0.5 * np.sin(3 * x) * x + 0.1 * x ** 3
        evaluated.append(float(np.linalg.norm(fb_phi(x, f, 0.0, np.inf))))
        return f

    def J(x):
        return sp.csc_matrix(A + np.diag(0.5 * np.sin(3 * x) + 1.5 * x * np.cos(3 * x)
                                         + 0.3 * x ** 2))

    r = solve_mcp(F, J, 0.0, np.inf, np.ones(N), callback=lambda info: True)
    assert r.status is Status.CALLBACK_STOP and r.crash_iterations >= 0
    assert r.residual.fb_norm <= min(evaluated) * (1 + 1e-12)


def test_point_status_says_start_point_when_nothing_better_was_found():
    # F = 1 + x^2 at x = 0 is already the best point (a stationary point of the merit)
    r = solve_mcp(lambda x: 1 + x ** 2, lambda x: sp.csc_matrix(np.diag(2 * x)), -np.inf,
                  np.inf, np.zeros(3), options={"restart_limit": 1})
    assert not r.success
    assert (r.point_status is PointStatus.START_POINT) == bool(np.array_equal(r.x, np.zeros(3)))


# ------------------------------------------------------------------ time limits
COST = 0.05


def _costly(F, clock):
    def G(x):
        clock.now += COST
        return F(x)

    return G


def _assert_within_limit(r, clock, start, limit):
    assert r.status is Status.TIME_LIMIT or "time limit" in r.message, r.message
    assert clock.now - start <= 1.1 * limit + COST + 1e-9, clock.now - start


@pytest.mark.parametrize("searchtype", ["line", "arc"])
@pytest.mark.parametrize("lm", [True, False])
def test_time_limit_holds_through_watchdog_and_fallback_loops(clock, searchtype, lm):
    # F = x^2 + 1 has no zero; from next to its merit's stationary point x = 0 the Newton
    # point is far away and the watchdog search backtracks through ~60 trial points before
    # the merit decreases (1.55 s on a 1 s limit before the limit was checked there), then
    # the fallbacks and restarts loop until the limit
    F = _costly(lambda x: x ** 2 + 1.0, clock)
    J = lambda x: sp.csc_matrix(np.diag(2 * x))  # noqa: E731
    start = clock.now
    r = solve_mcp(F, J, -np.inf, np.inf, np.full(1, 1e-3),
                  options={"time_limit": 1.0, "restart_limit": 10 ** 6,
                           "nms_searchtype": searchtype, "lm_fallback": lm})
    _assert_within_limit(r, clock, start, 1.0)


def test_time_limit_holds_when_solve_lcp_hands_over_to_the_general_method(clock):
    # w1 = -2 z1 + z2 - 3, w2 = z2 + 2 on z >= 0: the sign conditions can be met (z2 >=
    # 3 + 2 z1), so the feasibility LP proves nothing, but w2 > 0 forces z2 = 0 and then
    # w1 < 0: no solution, M is not monotone, and the general method takes over, within
    # what is left of the limit.  (M = -I, q = -1, used before, is now proved infeasible by
    # the LP: no z >= 0 has w >= 0.)
    Mn = sp.csc_matrix(np.array([[-2.0, 1.0], [0.0, 1.0]]))
    qn = np.array([-3.0, 2.0])
    import compass_sparse.lcp as solve_module

    real = solve_module.MCP

    def costly_mcp(F, *a, **k):
        return real(_costly(F, clock), *a, **k)

    try:
        solve_module.MCP = costly_mcp
        start = clock.now
        r = solve_lcp(Mn, qn, options={"time_limit": 1.0, "restart_limit": 10 ** 6})
    finally:
        solve_module.MCP = real
    _assert_within_limit(r, clock, start, 1.0)


def test_time_limit_holds_through_the_crash_searches(clock):
    # a crash that keeps halving its step (no solution: F_i = x_i^2 + 1 + small coupling)
    C = 0.01 * _B
    F = _costly(lambda x: x ** 2 + 1.0 + C @ x, clock)
    J = lambda x: sp.csc_matrix(np.diag(2 * x) + C)  # noqa: E731
    start = clock.now
    r = solve_mcp(F, J, -np.inf, np.inf, np.full(N, 1e-3),
                  options={"time_limit": 0.5, "restart_limit": 10 ** 6,
                           "crash_minimum_dimension": 1, "crash_iteration_limit": 200})
    _assert_within_limit(r, clock, start, 0.5)


def test_time_limit_holds_through_the_crash_factorizations(clock, monkeypatch):
    # The crash retried up to six factorizations of a singular reduced Jacobian (growing
    # shifts) without looking at the clock: with each factorization costing 0.3 s, a 0.5 s
    # limit ran to 1.8 s.  Now the deadline is checked before every factorization, which is
    # atomic: the overshoot is at most one of them (plus one evaluation).
    import compass_sparse.crash.driver as crash_driver
    import compass_sparse.crash.projected_newton as crash_python
    import compass_sparse.crash.reduced as crash_module
    from compass_sparse.basis.backends import SingularFactorError

    FACTOR = 0.3
    calls = {"n": 0}

    def slow_singular(A, b, deadline=None, labels=None, keep=False, **lu):
        calls["n"] += 1
        clock.now += FACTOR
        raise SingularFactorError("singular (simulated)")

    monkeypatch.setattr(crash_module, "solve_sparse", slow_singular)
    # Slow factorizations are those of large blocks, which go through solve_sparse one
    # attempt at a time; blocks up to DENSE_SOLVE_MAX_N (milliseconds for all attempts)
    # are solved in one compiled call, small sparse ones by KLU.  This small problem
    # stands for a large one.
    for module in (crash_driver, crash_python, crash_module):
        monkeypatch.setattr(module, "DENSE_SOLVE_MAX_N", 0)
    monkeypatch.setattr(crash_module, "klu_suits", lambda J, lu: False)
    F = _costly(lambda x: x - 1.0 + 0.01 * (_B @ x), clock)
    J = lambda x: sp.csc_matrix(np.eye(N) + 0.01 * _B)  # noqa: E731
    start = clock.now
    r = solve_mcp(F, J, -np.inf, np.inf, np.zeros(N),
                  options={"time_limit": 0.5, "crash_minimum_dimension": 1})
    assert r.status is Status.TIME_LIMIT or "time limit" in r.message, r.message
    assert calls["n"] <= 2, calls
    assert clock.now - start <= 0.5 + FACTOR + COST + 1e-9, clock.now - start


def test_time_limit_holds_through_the_levenberg_marquardt_factorizations(clock, monkeypatch):
    # The LM step tried up to four Cholesky factorizations (growing mu) without looking
    # at the clock; each is atomic (12 s of H^T H on the dynamic CGE model at n = 3e4).
    import compass_sparse.nms.fallback as fallback_module
    from compass_sparse.nms.fallback import lm_step
    from compass_sparse.options import Options

    FACTOR = 0.3
    calls = {"n": 0}

    def slow_failing(A, b):
        calls["n"] += 1
        clock.now += FACTOR
        raise RuntimeError("not positive definite (simulated)")

    monkeypatch.setattr(fallback_module, "spd_solve", slow_failing)
    # the sparse route (CHOLMOD), whose factorizations are the long ones: this order
    # would be solved densely
    monkeypatch.setattr(fallback_module, "DENSE_SOLVE_MAX_N", 0)
    p = MCP(lambda x: x - 1.0 + 0.01 * (_B @ x), lambda x: sp.csc_matrix(np.eye(N) + 0.01 * _B),
            -np.inf, np.inf, np.zeros(N))
    z = p.x0
    start = clock.now
    assert lm_step(p.evaluator, z, p.F(z), None, p.lb, p.ub, Options(),
                   deadline=start + 0.5) is None
    assert calls["n"] == 2, calls         # started at 0 and 0.3 s, not at 0.6 and 0.9 s
    assert clock.now - start <= 0.5 + FACTOR + 1e-9


@pytest.mark.parametrize("where", ["F", "J"])
def test_wrong_shape_from_F_or_J_after_the_start_is_a_shape_error_naming_it(where):
    # the bad-input table (docs/bad_inputs.md): a wrong shape is a bug in the user's function, raised
    # (not taken for a domain error that would hide it), at any call
    from compass_sparse.exceptions import ShapeError

    calls = {"i": 0}

    def F(x):
        calls["i"] += where == "F"
        return np.zeros(N + 1) if calls["i"] == 3 else F_ok(x)

    def J(x):
        calls["i"] += where == "J"
        return sp.identity(N + 1, format="csc") if calls["i"] == 3 else J_ok(x)

    with pytest.raises(ShapeError, match=r"F\(x\) returned shape" if where == "F"
                       else "Jacobian has shape"):
        solve_mcp(F, J, 0.0, np.inf, np.zeros(N))


def test_no_progress_message_does_not_blame_a_valid_start_point_for_a_restarts_domain_error():
    # F is defined for x > -1 and positive there (no solution on a free box); x0 = 0 is
    # fine, the restarts' drawn points are not: the message said "domain error at the
    # start point"
    def F(x):
        if np.any(x <= -1):
            raise ValueError("sqrt of a negative number")
        return np.sqrt(1 + x) + 1.0

    def J(x):
        return sp.diags(0.5 / np.sqrt(1 + x)).tocsc()

    r = solve_mcp(F, J, -np.inf, np.inf, np.zeros(2), options={"homotopy": "off"})
    assert r.status is Status.NO_PROGRESS and r.domain_errors > 0
    assert "domain error at the start point" not in r.message
    assert "undefined at the last restart's point" in r.message
    assert np.all(np.isfinite(r.fun)) and np.all(r.x > -1)


def test_crash_solves_on_small_badly_scaled_cge_make_no_illegal_blas_calls(capfd):
    # SuperLU's dense supernode kernels called BLAS with an illegal leading dimension on
    # the crash's small reduced Jacobians of this badly row-scaled CGE model ("On entry to
    # DTRSV parameter number 6 had an illegal value" on stdout, a suspect solve); small
    # systems are now factored densely.
    from compass_sparse.generators.cge import static_cge

    m = static_cge(regions=1, sectors=8, factors=2, households=1, taxes=True,
                   seed=11).with_shock(productivity=0.5)
    P = m.problem
    s = 1e-6 ** np.random.default_rng(0).uniform(-1, 1, P.n)
    r = solve_mcp(lambda z: s * P.F(z), lambda z: sp.diags(s) @ P.evaluator.J(z), P.lb, P.ub,
                  P.x0, options={"scaling": False})
    out, err = capfd.readouterr()
    assert "illegal value" not in out + err
    assert r.x.shape == (P.n,) and np.all(np.isfinite(r.x))
    if r.success:
        assert r.residual.natural <= 1e-6
