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
from compass_sparse.crash import (CRASH_START_FACTOR, CRASH_STEP_LIMIT,
                                  PERTURB_ATTEMPTS)
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
    runs = {"solve_mcp": lambda: solve_mcp(prob),
            "bare route": lambda: bare_solve(F, J, lb, ub, prob.x0, opt)}
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


if __name__ == "__main__":
    main()
