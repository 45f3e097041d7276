"""What a solve of cournot2 costs with no pipeline around the compiled kernels: a floor
for a compiled small-problem route (benchmarks/small.md, round 15), not a solver.

The bare route below does the work a default solve of this problem does -- F and J at the
start (copies in, checked finite, J on its full pattern), the start's residual test, the
crash's compiled calls with the acceptance test of its trial point (residuals, then the
scale test with J there), and a Result with its residual report -- with nothing else: no
options, evaluator, memo, preprocessor or scaling tests, solver object, pass records or
history.  It applies only to problems the crash solves at once (it stops with an error
otherwise), and checks that it returns solve_mcp's point bit for bit.  Both are timed in
one process, alternating, without the user's F and J (timed as bench_small.py does).

Usage:  PYTHONPATH=. python3 benchmarks/experiments/floor_cournot2.py [--rounds 15]
"""
from __future__ import annotations

import argparse
import os
import statistics
import sys
import time

import numpy as np

sys.path[:0] = [os.path.join(os.path.dirname(__file__), "..", "..", "tests")]

from compass_sparse import _crash_kernels as ck
from compass_sparse._merit_kernels import min_map_within, scale_test_kernel
from compass_sparse.crash import CRASH_START_FACTOR, CRASH_STEP_LIMIT, PERTURB_ATTEMPTS
from compass_sparse.merit import dot_norm, fb_phi, residual_report


def bare_solve(F, J, lb, ub, x0, opt):
    """(x, F(x), residual report) of a problem the crash solves (see the module text),
    with the crash options and tolerance of ``opt`` (an Options)."""
    n, tol = x0.size, opt.convergence_tolerance
    cols = np.tile(np.arange(n, dtype=np.int32), n)
    ptr = np.arange(0, n * n + 1, n, dtype=np.int32)

    def f_at(z):
        f = np.asarray(F(z.copy()), dtype=float)
        assert np.isfinite(f).all()
        return f

    def j_at(z):
        d = np.asarray(J(z.copy()), dtype=float).T.ravel()
        assert np.isfinite(d).all()
        return d

    z, f = x0.copy(), f_at(x0)
    jd = j_at(z)
    phi = fb_phi(z, f, lb, ub)
    if min_map_within(z, f, lb, ub, tol) and dot_norm(phi) <= tol:
        raise RuntimeError("the start is a solution: not this experiment's case")
    W = np.empty((ck.CW_ROWS, n))
    W[ck.CW_Z], W[ck.CW_F], W[ck.CW_LB], W[ck.CW_UB] = z, f, lb, ub
    sf = np.zeros(ck.CF_SIZE)
    sf[[ck.CF_SIGMA, ck.CF_MIN_STEP, ck.CF_TOL, ck.CF_EPS_SCALE, ck.CF_STEP_LIMIT,
        ck.CF_START_FACTOR]] = (opt.crash_sigma, opt.crash_stepsize_minimum, tol, 1e-8,
                                CRASH_STEP_LIMIT, CRASH_START_FACTOR)
    si = np.zeros(ck.CI_SIZE, dtype=np.int64)
    si[[ck.CI_LIMIT, ck.CI_NBCHANGE, ck.CI_PERTURB, ck.CI_ATTEMPTS, ck.CI_LINE]] = (
        opt.crash_iteration_limit, opt.crash_nbchange_limit, bool(opt.crash_perturb),
        PERTURB_ATTEMPTS, opt.crash_searchtype == "line")
    free = np.zeros(n, dtype=np.bool_)
    code = ck.crash_dense(sf, si, W, free, f, ptr, cols, jd, ck.J_GIVEN)
    if code != ck.NEED_F:
        raise RuntimeError("not this experiment's case")
    zt = W[ck.CW_ZT].copy()
    ft = f_at(zt)
    phi = fb_phi(zt, ft, lb, ub)
    if not (dot_norm(phi) <= tol and min_map_within(zt, ft, lb, ub, tol)):
        raise RuntimeError("the crash's first point is not a solution: not this case")
    row, _, ratio = scale_test_kernel(zt, ft, lb, ub, phi, ptr, cols, j_at(zt))
    if row >= 0 and ratio > 1e-3:
        raise RuntimeError("flat residual: not this experiment's case")
    return zt, ft, residual_report(zt, ft, lb, ub, phi=phi)


class _Solved(Exception):
    pass


def lean_solve(problem, options=None):
    """A lean route around the compiled crash that keeps what a Result reports (round 16's
    estimate of a small-problem route, not the solver): the options, the evaluator (its
    memo and counts), the start's verdict, the preprocessor's and the scaling's tests, the
    best point, the trial point's acceptance test, the pass records, the history and the
    Result with its residual report.  Only for problems the crash solves (else an error)."""
    import math

    from compass_sparse import crash as cr
    from compass_sparse.acceptance import judge, residuals_small
    from compass_sparse.options import Options
    from compass_sparse.result import Iteration, PassStats, Status
    from compass_sparse.solve import _judge_on, _presolve_pass, _result, _scaling_pass

    opt = Options.coerce(options)
    ev = problem.evaluator
    ev.forget()
    ev.counters.reset()
    t0 = time.perf_counter()
    z0 = problem.x0
    f0, J0 = ev.fj(z0)
    ev.pin(z0)
    lb, ub, tol = problem.lb, problem.ub, opt.convergence_tolerance
    phi0 = fb_phi(z0, f0, lb, ub)
    if _judge_on(problem, z0, f0, opt, phi0).solved:
        raise RuntimeError("the start is a solution: not this experiment's case")
    passes = {}
    pre, passes["presolve"] = _presolve_pass(problem, opt, f0, J0)
    sc, passes["scaling"] = _scaling_pass(J0, opt)
    if pre is not None or sc is not None:
        raise RuntimeError("a reduced or scaled problem: not this experiment's case")
    found = []

    def on_point(z, f):
        phi = fb_phi(z, f, lb, ub)
        psi = 0.5 * float(phi.dot(phi))
        if math.sqrt(2.0 * psi) <= tol and residuals_small(z, f, lb, ub, tol, phi):
            v = judge(z, f, lb, ub, tol, jac=lambda y: ev.jac(y, f), phi=phi, small=True)
            if v.solved:
                found.append((z.copy(), f.copy(), phi, v))
                raise _Solved

    st = passes["crash"] = PassStats(ran=True)
    try:
        cr._crash_dense(ev, z0, f0, J0, lb, ub, opt, tol, None, None, on_point, st, t0)
    except _Solved:
        pass
    if not found:
        raise RuntimeError("the crash did not solve it: not this experiment's case")
    z, f, phi, v = found[0]
    for k in ("path", "fallback", "homotopy"):
        passes[k] = PassStats()
    passes["nms"] = PassStats(ran=True)
    hist = [Iteration(0, dot_norm(phi0), "", 0, 0.0, 0.0),
            Iteration(0, dot_norm(phi), "", 0, 0.0, time.perf_counter() - t0)]
    return _result(problem, Status.SOLVED, "solution found", z, f, opt, t0, start_z=z0,
                   verdict=v, phi=phi, passes=passes, crash_iterations=st.iterations,
                   history=hist)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--rounds", type=int, default=15)
    ap.add_argument("--batch", type=int, default=200)
    a = ap.parse_args(argv)
    import known_problems as kp

    from compass_sparse import MCP, Options, solve_mcp
    from compass_sparse._jit import end_cold_start

    end_cold_start()
    p = kp.ALL_SOLVABLE["cournot2"]()
    clock = [0.0]

    def timed(fn):
        def call(x):
            t = time.perf_counter()
            try:
                return fn(x)
            finally:
                clock[0] += time.perf_counter() - t
        return call

    F, J = timed(p.F), timed(p.J)
    prob = MCP(F, J, p.lb, p.ub, p.x0)
    lb, ub, opt = prob.lb, prob.ub, Options()
    ref = solve_mcp(prob)
    x, _, rep = bare_solve(F, J, lb, ub, prob.x0, opt)
    assert ref.success and np.array_equal(x, ref.x), "not solve_mcp's point"
    assert rep.fb_norm == ref.residual.fb_norm
    lean = lean_solve(prob.with_start(prob.x0))
    assert np.array_equal(lean.x, ref.x) and (lean.nfev, lean.njev) == (ref.nfev, ref.njev)
    runs = {"solve_mcp": lambda: solve_mcp(prob.with_start(prob.x0)),
            "bare route": lambda: bare_solve(F, J, lb, ub, prob.x0, opt),
            "lean route": lambda: lean_solve(prob.with_start(prob.x0))}
    times = {k: [] for k in runs}
    for r in range(a.rounds):
        for k in (list(runs) if r % 2 == 0 else list(runs)[::-1]):
            clock[0] = 0.0
            t = time.perf_counter()
            for _ in range(a.batch):
                runs[k]()
            times[k].append((time.perf_counter() - t - clock[0]) / a.batch)
    med = {k: statistics.median(v) * 1e3 for k, v in times.items()}
    print(f"cournot2, solver time without the user's F and J, median of {a.rounds} batches "
          f"of {a.batch}:")
    for k, v in med.items():
        print(f"  {k:12s} {v:.4f} ms")
    print(f"  bare / solve_mcp {med['bare route'] / med['solve_mcp']:.3f}")
    print(f"  lean / solve_mcp {med['lean route'] / med['solve_mcp']:.3f}")


if __name__ == "__main__":
    main()
