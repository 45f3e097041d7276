"""Benchmark of the MCP preprocessor on problems with heavy linear structure.

Problem family: the KKT conditions of a convex QP

    min c'x + 0.5 x'Qx   s.t.  A x >= b (multipliers y >= 0),  E x = e (multipliers w free),
                               l <= x <= u

written as the MCP  F = [c + Qx - A'y - E'w ; A x - b ; E x - e]  _|_  (x, y, w), with
every Jacobian entry declared constant.  Built into it (fractions of n_x):

* fixed variables (l = u),
* inequality rows implied strictly by the bounds (range fixing of their y),
* forcing rows  -sum a_j x_j >= 0  with x >= 0 (forcing: x = 0, y from postsolve),
* duplicated (scaled, weaker) inequality rows (duplicate rows),
* singleton equality rows  x_j = e_i  (singleton row with a free multiplier: fix and
  re-pair),
* variables appearing only in their own cost row (column singletons), the rest coupled
  by a random sparse A.

Run:  python benchmarks/bench_presolve.py [--sizes 1000 10000 100000] [--solve-max 400]

Reports size before/after, nonzeros, presolve time and per-pass counts; for sizes up to
``--solve-max`` it also solves with and without presolve using the dense test reference
solver (``tests/presolve/_ref_solver.py``) and reports times and residuals.

HOOK: when ``compass_sparse.solve_mcp`` exists, ``solver_hook`` below uses it for the
with/without-presolve timing at every size (set ``USE_SOLVE_MCP = True``).
"""
from __future__ import annotations

import argparse
import pathlib
import sys
import time

import numpy as np
import scipy.sparse as sp

from compass_sparse.merit import natural_residual
from compass_sparse.presolve import PresolveOptions, presolve, solve_with_presolve
from compass_sparse.problem import MCP

from compass_sparse._jit import end_cold_start  # noqa: E402

end_cold_start()  # timings of compiled kernels (compass_sparse._jit: "Cold start")

USE_SOLVE_MCP = True  # compass_sparse.solve_mcp; False: the tests' reference solver


def solver_hook():
    """Return a callable problem -> object with .x used for the timing comparison."""
    if USE_SOLVE_MCP:
        from compass_sparse import solve_mcp

        def solve(problem):
            return solve_mcp(problem.F, problem.J, problem.lb, problem.ub, problem.x0)
        return solve
    sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "tests" / "presolve"))
    from _ref_solver import ref_solve
    return lambda problem: ref_solve(problem, tol=1e-10)


def _rows_with_k(m, n, k, rng):
    """m rows with k distinct columns each, coefficients in [0.5, 1.5]."""
    cols = np.argsort(rng.random((m, n)), axis=1)[:, :k] if n <= 2000 else \
        rng.integers(0, n, size=(m, k))
    A = sp.csr_matrix((rng.uniform(0.5, 1.5, m * k), (np.repeat(np.arange(m), k),
                                                       cols.ravel())), shape=(m, n))
    A.sum_duplicates()
    return A


def qp_kkt(nx: int, seed: int = 0):
    rng = np.random.default_rng(seed)
    f_fix, f_imp, f_forc, f_dup, f_eq = 0.05, 0.05, 0.03, 0.03, 0.05
    lx = np.zeros(nx)
    ux = np.full(nx, np.inf)
    nfix = int(f_fix * nx)
    fixed = rng.choice(nx, nfix, replace=False)
    lx[fixed] = ux[fixed] = rng.uniform(0, 1, nfix)
    # general coupling constraints A_g x >= b_g
    mg = nx // 4
    Ag = _rows_with_k(mg, nx, 3, rng)
    bg = rng.uniform(0.5, 1.0, mg)
    rows = [Ag]
    rhs = [bg]
    # rows implied strictly by x >= 0: sum a x >= -1
    mi = int(f_imp * nx)
    Ai = _rows_with_k(mi, nx, 3, rng)
    rows.append(Ai)
    rhs.append(-np.ones(mi))
    # forcing rows: -(x_j + x_k) >= 0 on variables not used elsewhere
    free_pool = np.setdiff1d(np.arange(nx), fixed)
    used_by_A = np.unique(sp.vstack([Ag, Ai]).tocoo().col)
    pool = np.setdiff1d(free_pool, used_by_A)
    rng.shuffle(pool)
    mf = min(int(f_forc * nx), pool.size // 2)
    fr = np.repeat(np.arange(mf), 2)
    fc = pool[:2 * mf]
    Af = sp.csr_matrix((-rng.uniform(0.5, 1.5, 2 * mf), (fr, fc)), shape=(mf, nx))
    rows.append(Af)
    rhs.append(np.zeros(mf))
    # duplicated, weaker copies of general rows: 2 * (A_g x) >= 2 b_g - 1
    md = min(int(f_dup * nx), mg)
    dup = rng.choice(mg, md, replace=False)
    rows.append(2.0 * Ag[dup])
    rhs.append(2.0 * bg[dup] - 1.0)
    A = sp.vstack(rows).tocsr()
    b = np.concatenate(rhs)
    m = A.shape[0]
    # singleton equality rows x_j = e on unused pool variables
    rest = pool[2 * mf:]
    me = min(int(f_eq * nx), rest.size)
    ej = rest[:me]
    E = sp.csr_matrix((np.ones(me), (np.arange(me), ej)), shape=(me, nx))
    e = rng.uniform(0.2, 0.8, me)
    # cost: diagonal Q (some coupling) and c
    Q = sp.diags(rng.uniform(1.0, 2.0, nx)) + 0.1 * sp.random(
        nx, nx, density=min(1.0, 1.0 / nx), random_state=rng)
    Q = ((Q + Q.T) * 0.5).tocsr()
    c = rng.normal(size=nx)
    K = sp.bmat([[Q, -A.T, -E.T], [A, None, None], [E, None, None]]).tocsc()
    K.sort_indices()
    q = np.concatenate([c, -b, -e])
    N = K.shape[0]
    lb = np.concatenate([lx, np.zeros(m), np.full(me, -np.inf)])
    ub = np.concatenate([ux, np.full(m, np.inf), np.full(me, np.inf)])

    def F(z):
        return K @ z + q

    def J(z):
        return K

    return MCP(F, J, lb, ub, np.zeros(N), constant_jac=K, check=False)


def run(sizes, solve_max, repeats=3):
    print(f"{'n_x':>7s} {'n':>8s} {'nnz':>9s} {'n_red':>8s} {'nnz_red':>9s} "
          f"{'removed%':>8s} {'rounds':>6s} {'t_pre[s]':>9s} {'t_post[s]':>9s}")
    out = []
    for nx in sizes:
        p = qp_kkt(nx)
        best = np.inf
        for _ in range(repeats):
            t = time.perf_counter()
            res = presolve(p)
            best = min(best, time.perf_counter() - t)
        s = res.stats
        y = res.reduced.x0 if res.reduced is not None else np.zeros(0)
        t = time.perf_counter()
        res.postsolve(y)
        tpost = time.perf_counter() - t
        print(f"{nx:7d} {s.n_original:8d} {s.nnz_original:9d} {s.n_reduced:8d} "
              f"{s.nnz_reduced:9d} {100.0 * s.removed / s.n_original:8.1f} {s.rounds:6d} "
              f"{best:9.3f} {tpost:9.3f}")
        print("        " + res.counters_line())
        out.append((nx, res))
    solve = solver_hook()
    label = "compass_sparse.solve_mcp" if USE_SOLVE_MCP else "the tests' dense reference solver"
    print(f"\nwith / without presolve ({label})")
    print(f"{'n':>6s} {'n_red':>6s} {'t_off[s]':>9s} {'res_off':>9s} {'t_on[s]':>9s} "
          f"{'res_on':>9s} {'speedup':>8s}")
    for nx in [k for k in (50, 100, 200, 400, 1000, 10000, 100000) if k <= solve_max]:
        p = qp_kkt(nx, seed=1)
        t = time.perf_counter()
        r = solve(p)
        t_off = time.perf_counter() - t
        res_off = natural_residual(r.x, p.F_uncounted(r.x), p.lb, p.ub)
        t = time.perf_counter()
        sol = solve_with_presolve(p, solve, PresolveOptions())
        t_on = time.perf_counter() - t
        print(f"{p.n:6d} {sol.presolve.stats.n_reduced:6d} {t_off:9.3f} {res_off:9.1e} "
              f"{t_on:9.3f} {sol.natural_residual:9.1e} {t_off / t_on:8.1f}")
    return out


if __name__ == "__main__":
    ap = argparse.ArgumentParser()
    ap.add_argument("--sizes", type=int, nargs="*", default=[1000, 10000, 100000])
    ap.add_argument("--solve-max", type=int, default=200)
    args = ap.parse_args()
    run(args.sizes, args.solve_max)
