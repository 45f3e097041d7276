"""Scaling of compass_sparse on large sparse problems, in "factorization equivalents".

Instances (``compass_sparse.generators``, manufactured solutions):

* ``structured_quadratic(n, seed, structure="grid")``: F = D z^2 + A z + b (shifted), A a
  non-symmetric 5-point grid coupling plus 8 long-range entries, strictly diagonally
  dominant; mixed bounds (free / lower / upper / boxed).  Solved by ``solve_mcp``.
* ``structured_quadratic(n, seed, structure="banded")``: the same with a band of width 2.
* ``obstacle_problem(m, seed)``: n = m^2, the 2-D obstacle LCP.  Solved by ``solve_lcp``.

For each: wall time of the solve, recomputed natural residual, distance to the known
solution, major iterations, crash iterations, pivots, factorizations, and the ratio of the
solve time to the time of ONE scipy ``splu`` factorization of the Jacobian at the returned
point (default SuperLU options, COLAMD ordering; median of 3): the number of
"factorization equivalents" a solve costs.  The design's yardstick: a plain semismooth
Newton method needs about 4-6 of them on grid box-LCPs of n = 5e4 ... 2e5.

Each solve runs in a child process with a time limit (passed to the solver) and a hard
timeout.  Solve times are medians over ``--repeats`` when a solve is fast.

    python benchmarks/bench_scaling.py --quick          # n = 1e3, 1e4
    python benchmarks/bench_scaling.py                  # n = 1e4, 1e5
    python benchmarks/bench_scaling.py --sizes 10000 100000 1000000 --time-limit 600
"""
from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import (  # noqa: E402
    RESULTS, CsvLog, Worker, fmt_e, fmt_time, machine_info, md_table, median, ours_record,
    print_machine, run_task, warm_up, write_json)

FIELDS = ["family", "n", "seed", "success", "reported_success", "status", "natural",
          "fb_norm", "err_to_solution", "time", "time_min", "repeats", "major", "crash",
          "minor", "factorizations", "restarts", "splu_time", "lu_nnz", "jac_nnz",
          "fact_equivalents", "gen_time", "passes", "pass_times", "error"]
FAMILIES = ("structured-grid", "structured-banded", "obstacle")


def _instance(family, n, seed):
    from compass_sparse.generators import obstacle_problem, structured_quadratic

    if family == "obstacle":
        return obstacle_problem(max(2, math.isqrt(int(n))), seed)
    structure = family.split("-", 1)[1]
    return structured_quadratic(n, seed, structure=structure)


def task(family, n, seed, time_limit, repeats, budget):
    import scipy.sparse as sp
    from scipy.sparse.linalg import splu

    from compass_sparse import solve_lcp, solve_mcp

    t0 = time.perf_counter()
    g = _instance(family, n, seed)
    gen_time = time.perf_counter() - t0
    prob = g.problem
    opts = {"time_limit": float(time_limit)}
    if g.lcp is not None:
        M, q, lb, ub = g.lcp

        def once():
            t = time.perf_counter()
            res = solve_lcp(M, q, lb, ub, prob.x0, options=opts)
            wall = time.perf_counter() - t
            return res, wall, M @ res.x + q
    else:
        lb, ub = prob.lb, prob.ub

        def once():
            t = time.perf_counter()
            res = solve_mcp(prob, options=opts)
            wall = time.perf_counter() - t
            return res, wall, prob.F_uncounted(res.x)

    runs = [once()]
    while len(runs) < repeats and runs[0][1] * (len(runs) + 1) <= budget:
        runs.append(once())
    res, wall, f = runs[0]
    rec = ours_record(res, f, lb, ub, wall)
    times = [r[1] for r in runs]
    rec.update(time=median(times), time_min=min(times), repeats=len(runs), gen_time=gen_time)
    rec["err_to_solution"] = (float(np.max(np.abs(res.x - g.solution)))
                              if g.solution is not None else math.nan)
    # one factorization of the Jacobian at the returned point
    J = sp.csc_matrix(M if g.lcp is not None else prob.J(res.x))
    st = []
    lu = None
    for _ in range(3):
        t = time.perf_counter()
        lu = splu(J)
        st.append(time.perf_counter() - t)
        if st[0] > 20.0:
            break
    rec["splu_time"] = median(st)
    rec["lu_nnz"] = int(lu.L.nnz + lu.U.nnz)
    rec["jac_nnz"] = int(J.nnz)
    rec["fact_equivalents"] = rec["time"] / rec["splu_time"]
    rec["n"] = int(q.size if g.lcp is not None else prob.n)
    return rec


def table(rows):
    header = ["family", "n", "solved", "natural res.", "|x - x*|_inf", "time (median)",
              "major", "crash its", "pivots", "factorizations", "1 splu of J",
              "factorization equivalents", "passes ran (time)", "status"]
    out = []
    for r in rows:
        fe = r.get("fact_equivalents")
        out.append([r["family"], r["n"], "yes" if r["success"] else "**no**",
                    fmt_e(r["natural"]), fmt_e(r.get("err_to_solution", math.nan)),
                    fmt_time(r["time"]), r["major"], r["crash"], r["minor"],
                    r["factorizations"], fmt_time(r.get("splu_time", math.nan)),
                    f"{fe:.1f}" if isinstance(fe, float) and math.isfinite(fe) else "–",
                    r["pass_times"].replace(";", ", ") or "–",
                    r["status"] + (f" [{r['error']}]" if r["error"] else "")])
    return md_table(header, out)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="smoke run (< 2 min)")
    ap.add_argument("--sizes", type=int, nargs="+", default=None,
                    help="n (default 10000 100000; obstacle uses m = isqrt(n))")
    ap.add_argument("--families", nargs="+", default=list(FAMILIES), choices=FAMILIES)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--repeat-budget", type=float, default=30.0,
                    help="stop repeating once the repeats would exceed this many seconds")
    ap.add_argument("--time-limit", type=float, default=300.0, help="per-solve limit, s")
    ap.add_argument("--out", type=Path, default=None, help="CSV output")
    a = ap.parse_args(argv)

    info = machine_info()
    print_machine(info)
    sizes = a.sizes or ([1000, 10000] if a.quick else [10000, 100000])
    tl = min(a.time_limit, 30.0) if a.quick else a.time_limit
    budget = 5.0 if a.quick else a.repeat_budget
    hard = tl + budget + 120.0
    out = a.out or RESULTS / ("scaling_quick.csv" if a.quick else "scaling.csv")
    log = CsvLog(out, FIELDS)
    write_json(out.with_suffix(".json"), dict(machine=info, sizes=sizes, families=a.families,
                                              seed=a.seed, time_limit=tl, repeats=a.repeats))
    worker = Worker(warm_up, dict(with_path=False))
    rows = []
    for n in sizes:
        for fam in a.families:
            rec = run_task(worker, task, "compass_sparse", hard, family=fam, n=n, seed=a.seed,
                           time_limit=tl, repeats=a.repeats, budget=budget)
            rec.setdefault("n", n)
            rec.update(family=fam, seed=a.seed)
            log.write(rec)
            rows.append(rec)
            fe = rec.get("fact_equivalents", math.nan)
            print(f"{fam:17s} n={rec['n']:8d} {'OK  ' if rec['success'] else 'FAIL'} natural "
                  f"{fmt_e(rec['natural'])} {fmt_time(rec['time']):>9s} major {rec['major']} "
                  f"fact {rec['factorizations']} splu {fmt_time(rec.get('splu_time', math.nan))} "
                  f"=> {fe:.1f} factorization equivalents  {rec['status']}"
                  + (f" [{rec['error']}]" if rec["error"] else ""), flush=True)
    log.close()
    worker.close()
    print()
    print(table(rows))
    print(f"\n# rows in {out}; worker restarts after hard timeouts: {worker.restarts}",
          flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
