"""The NMS loop's pure pieces, the monotone variant and the restart schedule."""
from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

import compass_sparse as cs
from compass_sparse.generators import thesis_family
from compass_sparse.nms.state import LOCAL_FACTOR, classify_step, reference_value
from compass_sparse.nms.restarts import FROM_NEAR_BEST, FROM_RANDOM, FROM_START, RestartSchedule


def test_reference_value_turns_monotone_near_a_solution():
    memory = [4.0, 9.0, 1.0]
    assert reference_value(memory, 0.5, 1.0, 10.0) == (9.0, 100.0)
    # within LOCAL_FACTOR of the starting residual: R <= Psi(z_k), no d-step growth
    assert reference_value(memory, 0.5, LOCAL_FACTOR * 10.0, 10.0) == (0.5, 1.0)


@pytest.mark.parametrize("psi,dist,d_allowed,descent,expected", [
    (5.0, 0.1, True, False, "D"),  # near, within 100 R: accepted without descent
    (0.5, 0.1, True, True, "O"),  # a d-step that also passes the m-step test
    (0.5, 0.1, True, False, "D"),
    (5.0, 2.0, True, True, "M"),  # too far for a d-step, sufficient decrease
    (5.0, 0.1, False, True, "M"),  # d-steps used up
    (5.0, 2.0, True, False, None),  # watchdog
    (2000.0, 0.1, True, False, None),  # beyond large * R
])
def test_classify_step(psi, dist, d_allowed, descent, expected):
    assert classify_step(psi, 10.0, 100.0, dist, 1.0, d_allowed, 1e-4,
                         lambda: descent) == expected


def test_monotone_line_search_never_raises_the_merit():
    g = thesis_family(30, family=1, seed=4)
    seen = []
    r = cs.solve_mcp(g.problem, callback=lambda info: seen.append(info.residual),
                     options={"nms": False, "crash_method": "none", "restart_limit": 0})
    assert r.success and len(seen) >= 2
    assert all(b <= a * (1 + 1e-12) for a, b in zip(seen, seen[1:]))
    # the non-monotone default accepts d-steps that may raise it; both solve
    assert cs.solve_mcp(g.problem, options={"crash_method": "none"}).success


@pytest.mark.parametrize("search", ["arc", "line"])
def test_crash_searchtype(search):
    g = thesis_family(40, family=1, seed=2)
    r = cs.solve_mcp(g.problem, options={"crash_searchtype": search,
                                         "crash_minimum_dimension": 1})
    assert r.success and r.passes["crash"].ran
    assert r.check(g.problem).natural <= 1e-6


def test_restart_schedule():
    opt = cs.Options()
    sch = RestartSchedule(opt)
    plans = [sch.plan(k, 0.5) for k in range(6)]
    assert [w for _, w in plans] == [FROM_START] * 3 + [FROM_NEAR_BEST, FROM_RANDOM,
                                                        FROM_NEAR_BEST]
    assert plans[0][0].proximal_perturbation == 0.005 and plans[0][0].crash_method == "none"
    assert plans[1][0].nms_memory_size == 2 and plans[2][0].crash_nbchange_limit == 10
    # the residual of the first restart fixes the perturbation of the later ones
    assert sch.plan(3, 1e-9)[0].proximal_perturbation == 0.005


def test_nms_pass_records_its_time():
    g = thesis_family(20, family=1, seed=5)
    r = cs.solve_mcp(g.problem)
    st = r.passes["nms"]
    assert st.ran and st.iterations == r.nit and 0.0 < st.time <= r.time
    assert f"nms {st.time:.3f}s" in r.summary()


def _badly_scaled_lcps(count, seed=1):
    """Small monotone LCPs in mixed units (row scales 1e-8 ... 1e12, column units 1e-6 ...
    1e6) with large finite bounds, some of them active at the solution."""
    rng = np.random.default_rng(seed)
    for _ in range(count):
        n = int(rng.integers(2, 8))
        B = rng.normal(size=(n, n))
        M = B @ B.T + np.eye(n) * 0.5 + (B - B.T) * 0.3
        D = 10.0 ** rng.integers(-8, 13, size=n)
        C = 10.0 ** rng.integers(-6, 7, size=n)
        A = (D[:, None] * M) / C[None, :]
        xs = rng.normal(size=n) * C * 10
        b = -A @ xs + D * rng.normal(size=n)
        lb = np.where(rng.random(n) < 0.5, -np.inf,
                      xs - np.abs(rng.normal(size=n)) * C * 10.0 ** rng.integers(0, 12, size=n))
        ub = np.where(rng.random(n) < 0.5, np.inf,
                      xs + np.abs(rng.normal(size=n)) * C * 10.0 ** rng.integers(0, 12, size=n))
        ub = np.where(rng.random(n) < 0.2, xs - 0.5 * np.abs(xs) - C, ub)
        yield A, b, lb, np.maximum(ub, lb)


def test_segment_searches_return_points_inside_the_box():
    """The watchdog's line search took z = (1 - a) z_c + a z_N, a convex combination of
    two points in the box, unprojected: with both at one bound it rounded to a unit in the
    last place beyond it, and a SOLVED result returned x outside [l, u] (x_1 = -0.000923..512
    above u_1 = -0.000923..513; in another instance 2.8e-14 above u_2 = -166.3).  The
    projected-gradient fallback's segment search had the same form.  Both are projected
    now; on 150 badly scaled LCPs, with and without the scaling pass, every returned point
    lies in the box (exactly) and every solved one meets the tolerance there."""
    for k, (A, b, lb, ub) in enumerate(_badly_scaled_lcps(150)):
        x0 = np.clip(np.zeros(b.size), lb, ub)
        for scaling in (True, False):
            r = cs.solve_mcp(lambda x: A @ x + b, lambda x: sp.csc_matrix(A), lb, ub, x0,
                             options={"scaling": scaling, "time_limit": 10})
            assert np.all(r.x >= lb) and np.all(r.x <= ub), (k, scaling)
            if r.success:
                assert r.residual.natural <= 1e-6


def _nms_problems(trials):
    """Known small problems, thesis families and ``trials`` random nonlinear ones (some
    with boxes), and problems whose F or J fail at points away from the start."""
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).parent))
    import known_problems as kp

    made = [kp.kojima_shindo(), kp.josephy(), kp.mathiesen(), kp.nash_cournot_mss(),
            kp.separable_box_vi(), kp.degenerate_root(), kp.billups(), kp.sqrt_ncp(),
            kp.log_ncp(raise_errors=False), kp.cournot_duopoly()]
    problems = [cs.MCP(q.F, q.J, q.lb, q.ub, q.x0) for q in made]
    problems += [thesis_family(n, fam, seed).problem for fam in (1, 2) for n in (10, 20)
                 for seed in (1, 2)]
    rng = np.random.default_rng(11)
    for trial in range(trials):
        n = int(rng.integers(1, 30))
        A = sp.random(n, n, density=rng.choice([0.2, 0.5]), random_state=rng, format="csc")
        A = sp.csc_matrix(A + sp.eye(n) * rng.choice([0.0, 0.5, 2.0]))
        b = rng.normal(size=n) * 3.0
        lb = rng.choice([-np.inf, 0.0, -1.0], n)
        ub = np.where((rng.random(n) < 0.3) & np.isfinite(lb), lb + 2.0, np.inf)
        x0 = np.clip(rng.normal(size=n) * 2.0, lb, ub)
        problems.append(cs.MCP(lambda x, A=A, b=b: A @ x + b + 0.2 * x ** 3 - np.sin(x),
                               lambda x, A=A: sp.csc_matrix(
                                   A + sp.diags(0.6 * x ** 2 - np.cos(x))),
                               lb, ub, x0))
    A = sp.csc_matrix(np.array([[2.0, 1.0, 0.0], [1.0, 3.0, 1.0], [0.0, 1.0, 4.0]]))
    b = np.array([-8.0, 1.0, -2.0])

    def F(x):
        if x[0] > 2.5:
            raise ValueError("outside the domain")
        return A @ x + b + 0.1 * x ** 3

    def J(x):
        return sp.csc_matrix(A + sp.diags(0.3 * x ** 2))

    def J_fails(x):
        if x[1] > 0.1:
            raise ValueError("J undefined here")
        return J(x)

    x0 = np.zeros(3)
    problems += [cs.MCP(F, J, -np.inf, np.inf, x0),
                 cs.MCP(lambda x: A @ x + b + 0.1 * x ** 3, J_fails, -np.inf, np.inf, x0)]
    # J undefined on an annulus |x|_inf in (t, 2t): major iterations whose J fails, then
    # the fallback from the best point
    rng = np.random.default_rng(3)
    for trial in range(6):
        n = int(rng.integers(2, 8))
        A = sp.csc_matrix(sp.random(n, n, density=0.5, random_state=rng) + sp.eye(n) * 0.3)
        b = rng.normal(size=n) * 3
        t = rng.choice([1.0, 2.0, 3.0])

        def J_annulus(x, A=A, t=t):
            if t < np.max(np.abs(x)) < 2 * t:
                raise ValueError("J undefined here")
            return sp.csc_matrix(A + sp.diags(0.6 * x ** 2 - np.cos(x)))

        problems.append(cs.MCP(lambda x, A=A, b=b: A @ x + b + 0.2 * x ** 3 - np.sin(x),
                               J_annulus, -np.inf, np.inf, np.zeros(n)))
    # a flat tail: small residuals that are not solutions (judged, rejected)
    problems.append(cs.MCP(lambda x: np.exp(-x), lambda x: sp.csc_matrix(np.diag(-np.exp(-x))),
                           0.0, np.inf, np.array([5.0])))
    return problems


def _solve_record(p, opt):
    """Everything a solve reports that does not measure time."""
    r = cs.solve_mcp(p, options=opt)
    passes = {k: (v.ran, v.iterations, v.pivots, v.factorizations, v.nfev, v.njev, v.reason)
              for k, v in r.passes.items()}
    return (r.status, r.message, r.x.tobytes(), r.fun.tobytes(), r.nit, r.nfev, r.njev,
            r.minor_iterations, r.crash_iterations, r.restarts, r.gradient_steps,
            r.lm_steps, r.factorizations, r.basis_updates, r.domain_errors,
            None if r.basis is None else r.basis.basic.tobytes(),
            [(h.nit, h.residual, h.step, h.pivots, h.prox) for h in r.history or []], passes)


def test_compiled_nms_gives_the_python_routes_points_bit_for_bit(monkeypatch):
    """The major iterations with their bookkeeping in compiled calls (reverse
    communication) against the Python loop they replace, on known, thesis and random
    problems, F and J failing at some points, and the options that change the iteration
    (monotone, memory, watchdogs, the arc search, m-step frequency, no LM fallback, no
    crash, restarts without the homotopy, paths from the Lemke start, the homotopy's
    polishing runs): the same results bit for bit -- status and
    message, point and F, every count, the basis, the history and the passes.  (The
    Python loop: the option engine = "reference".)"""
    import compass_sparse.nms._kernels as nk

    used, asked = [], []  # the answers given, the requests made

    def counted(*a):
        used.append(a[14])
        asked.append(real(*a))
        return asked[-1]

    real = nk.nms_dense
    monkeypatch.setattr(nk, "nms_dense", counted)
    options = ({}, {"nms": False}, {"nms_memory_size": 2, "nms_mstep_frequency": 1},
               {"nms_searchtype": "arc"}, {"nms_maximum_watchdogs": 0},
               {"lm_fallback": False, "crash_method": "none"},
               {"homotopy": "off", "restart_limit": 2, "major_iteration_limit": 15},
               {"lemke_start": "always", "major_iteration_limit": 4}, {"homotopy": "only"})
    steps = set()
    for p in _nms_problems(10):
        for opt in options:
            out = {}
            for compiled in (False, True):
                out[compiled] = _solve_record(
                    p, {**opt, "engine": "auto" if compiled else "reference"})
            assert out[False] == out[True], opt
            steps |= {h[2] for h in out[True][16]}
    assert len(used) > 2000
    assert {nk.A_NEWTON, nk.A_J, nk.A_F_GIVEN, nk.A_F_FAILED, nk.A_JUDGED, nk.A_FRESH,
            nk.A_FRESH_J} <= set(used)
    assert {nk.NEED_PATH, nk.NEED_F_TRIAL, nk.NEED_FALLBACK, nk.JUDGE, nk.STALLED} <= set(asked)
    assert {"SD", "SM", "SO", "SW"} <= steps


def test_compiled_nms_stops_at_the_time_limit_as_the_python_route(monkeypatch):
    """The time limit passing after the K-th evaluation of F (a clock of the NMS module
    that jumps then), for every K of the solves: both routes stop at the same point with
    the same status, counts and history -- the compiled one reads the clock after a
    considered point's tests and before a watchdog trial, as the Python loop does."""
    import time
    import types

    import compass_sparse.nms.best as B
    import compass_sparse.nms.solver as N

    problems = _nms_problems(3)
    picked = [problems[k] for k in (0, 5, 6, 8)] + problems[-9:-6]
    stops = 0
    for p in picked:
        for K in range(1, 30):
            fake = types.SimpleNamespace(perf_counter=lambda K=K, p=p: time.perf_counter() + (
                1e6 if p.evaluator.counters.nfev >= K else 0.0))
            out = {}
            for compiled in (False, True):
                monkeypatch.setattr(N, "time", fake)
                monkeypatch.setattr(B, "time", fake)
                out[compiled] = _solve_record(p, {"time_limit": 1e3, "homotopy": "off",
                                                  "engine": "auto" if compiled else
                                                  "reference"})
            assert out[False] == out[True], K
            stops += out[True][0] is cs.Status.TIME_LIMIT
    assert stops > 40


def test_compiled_nms_keeps_the_python_loop_above_its_order_limit(monkeypatch):
    """Above COMPILED_NMS_MAX_N variables (the work area holds 28 vectors of length n)
    the routes keep the major iterations in the Python loop; below it they take the
    compiled calls; the results are the same either way."""
    from compass_sparse.nms import compiled as C
    from compass_sparse.routes import COMPILED_NMS_MAX_N, choose_routes

    assert choose_routes(COMPILED_NMS_MAX_N, cs.Options()).nms == "compiled"
    assert choose_routes(COMPILED_NMS_MAX_N + 1, cs.Options()).nms == "python"
    calls = []
    real = C.CompiledRun.run
    monkeypatch.setattr(C.CompiledRun, "run",
                        lambda self: calls.append(self.solver.n) or real(self))
    p = thesis_family(20, 1, 3).problem
    below = _solve_record(p, {})
    assert calls and set(calls) == {20}
    calls.clear()
    above = _solve_record(p, {"engine": "reference"})
    assert calls == [] and above == below
