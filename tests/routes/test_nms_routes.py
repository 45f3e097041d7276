"""The compiled major iterations (compass_sparse.nms.compiled) against the Python loop
(compass_sparse.nms.solver): the same points, counts and statuses bit for bit, at the time
limit too, and the Python loop above the compiled route's order limit."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

import compass_sparse as cs
from compass_sparse.generators import thesis_family


def _nms_problems(trials):
    """Known small problems, thesis families and ``trials`` random nonlinear ones (some
    with boxes), and problems whose F or J fail at points away from the start."""

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
