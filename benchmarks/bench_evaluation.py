"""Calls of the user's F and J per solve, and solve time, for two source trees.

    python3 benchmarks/bench_evaluation.py [--other PATH] [--repeats 5]

runs the same problems with the package of this tree and (when ``--other`` names another
checkout's root, e.g. an export of the main branch) with that one, each in its own
process, and prints a table: F and J calls over the whole solve, calls at the start point
x0, and the median wall time of ``repeats`` solves (construction of the MCP included;
the trees take turns in three rounds, the median of the rounds is reported).
Every solve's returned point is checked by its natural residual.  Only the public API is
used: the user's functions count their own calls.
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import scipy.sparse as sp

from compass_sparse._jit import end_cold_start  # noqa: E402

end_cold_start()  # timings of compiled kernels (compass_sparse._jit: "Cold start")

ROOT = Path(__file__).resolve().parent.parent


def _tridiag(n):
    return sp.diags([np.full(n - 1, -1.0), np.full(n, 4.0), np.full(n - 1, -1.0)],
                    [-1, 0, 1], format="csc")


def problems():
    """(name, builder) pairs; a builder returns (F, J, lb, ub, x0, kwargs, calls)."""

    def counting(Ffun, Jfun):
        calls = {"F": [], "J": []}

        def F(x):
            calls["F"].append(x.copy())
            return Ffun(x)

        def J(x):
            calls["J"].append(x.copy())
            return Jfun(x)

        return F, J, calls

    def thesis(n):
        from compass_sparse.generators import thesis_family

        i = thesis_family(n, family=1, seed=1).info
        A = sp.csc_matrix(i["A"])
        D, b = i["D"], i["b"]
        F, J, calls = counting(lambda z: D * z * z + A @ z + b,
                               lambda z: (A + sp.diags(2 * D * z)).tocsc())
        return F, J, i["lb"], i["ub"], i["x0"], {}, calls

    def cubic(n):
        A = _tridiag(n)
        b = np.random.default_rng(0).normal(size=n)
        F, J, calls = counting(lambda x: A @ x + 0.1 * x ** 3 + b,
                               lambda x: (A + sp.diags(0.3 * x ** 2)).tocsc())
        return F, J, 0.0, np.inf, np.full(n, 0.5), {}, calls

    def linear_fixed(n):
        A = _tridiag(n)
        b = np.random.default_rng(1).normal(size=n)
        F, J, calls = counting(lambda x: A @ x + b, lambda x: A)
        lb, ub, x0 = np.zeros(n), np.full(n, np.inf), np.full(n, 0.25)
        fix = np.arange(0, n, 5)
        lb[fix] = ub[fix] = x0[fix] = 1.0
        return F, J, lb, ub, x0, {"constant_jac": A}, calls

    return [("thesis family 1, n = 50", lambda: thesis(50)),
            ("tridiagonal cubic NCP, n = 2000", lambda: cubic(2000)),
            ("linear, 20% fixed (presolve), n = 2000", lambda: linear_fixed(2000))]


def worker(repeats):
    import compass_sparse as cs
    from compass_sparse.merit import natural_residual

    out = []
    for name, build in problems():
        times, rec = [], None
        for k in range(repeats):
            F, J, lb, ub, x0, kw, calls = build()
            t = time.perf_counter()
            r = cs.solve_mcp(F, J, lb, ub, x0, **kw)
            times.append(time.perf_counter() - t)
            if k == 0:
                x0p = np.clip(x0, lb, ub)
                at = lambda pts: sum(1 for p in pts if np.array_equal(p, x0p))  # noqa: E731
                nat = natural_residual(r.x, F(r.x), np.broadcast_to(lb, r.x.shape),
                                       np.broadcast_to(ub, r.x.shape))
                rec = dict(name=name, status=r.status.name, natural=nat,
                           F=len(calls["F"]) - 1, J=len(calls["J"]),  # -1: the check above
                           F_x0=at(calls["F"]), J_x0=at(calls["J"]), nit=r.nit)
        rec["median_s"] = statistics.median(times)
        out.append(rec)
    print(json.dumps(out))


def run_tree(root, repeats):
    env = dict(os.environ, PYTHONPATH=str(root), OPENBLAS_NUM_THREADS="1")
    res = subprocess.run([sys.executable, str(Path(__file__).resolve()), "--worker",
                          "--repeats", str(repeats)], cwd=root, env=env, check=True,
                         capture_output=True, text=True)
    return json.loads(res.stdout.strip().splitlines()[-1])


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--other", default=None, help="root of another checkout to compare")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--worker", action="store_true")
    a = ap.parse_args()
    if a.worker:
        worker(a.repeats)
        return
    trees = [("this tree", ROOT)] + ([("other", Path(a.other))] if a.other else [])
    # The trees take turns (3 rounds) so that a change of the machine's load hits both;
    # the time reported is the median over the rounds of each round's median.
    rounds = {label: [] for label, _ in trees}
    for _ in range(3):
        for label, root in trees:
            rounds[label].append(run_tree(root, a.repeats))
    rows = {}
    for label, runs in rounds.items():
        rows[label] = runs[0]
        for i, r in enumerate(rows[label]):
            r["median_s"] = statistics.median(run[i]["median_s"] for run in runs)
    print("| problem | tree | status | natural res. | F calls | J calls | F at x0 | J at x0 "
          "| median time [s] |")
    print("|---|---|---|---|---|---|---|---|---|")
    for i, (name, _) in enumerate(problems()):
        for label, _root in trees:
            r = rows[label][i]
            print(f"| {name} | {label} | {r['status']} | {r['natural']:.1e} | {r['F']} | "
                  f"{r['J']} | {r['F_x0']} | {r['J_x0']} | {r['median_s']:.4f} |")


if __name__ == "__main__":
    main()
