"""Where the homotopy's first path starts: the option homotopy_start ('start': the user's
start point; 'best': the best point the stabilized Newton method found before it stalled)
on the COMPASS thesis families, in one process.

Every instance is solved with each value in turn; the table sums, over the instances where
the homotopy ran under 'start', the path steps, F and J evaluations and solve times, and
counts the instances solved (natural residual <= 1e-6) and those whose F evaluations moved
by more than 10% either way.

    python3 benchmarks/homotopy_start.py                              # n = 10 ... 200
    python3 benchmarks/homotopy_start.py --sizes 10 20 50 --instances 30

Results: benchmarks/results/homotopy_start.md (the printed table).
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path[:0] = [str(HERE.parent)]

from compass_sparse import solve_mcp  # noqa: E402
from compass_sparse.generators import thesis_family  # noqa: E402

from compass_sparse._jit import end_cold_start  # noqa: E402

end_cold_start()  # timings of compiled kernels (compass_sparse._jit: "Cold start")

VALUES = ("start", "best")


def natural(problem, x):
    f = problem.F_uncounted(x)
    return float(np.max(np.abs(x - np.clip(x - f, problem.lb, problem.ub))))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sizes", type=int, nargs="+", default=[10, 20, 50, 100, 200])
    ap.add_argument("--instances", type=int, default=None,
                    help="seeds 0 .. K-1 per cell (default 30 up to n = 50, 10 above)")
    ap.add_argument("--time-limit", type=float, default=60.0)
    a = ap.parse_args(argv)
    rows = []
    for fam in (1, 2):
        for n in a.sizes:
            k = a.instances if a.instances is not None else (30 if n <= 50 else 10)
            for seed in range(k):
                row = {"cell": f"fam{fam} n{n}"}
                for v in VALUES:
                    prob = thesis_family(n, fam, seed).problem
                    t = time.perf_counter()
                    r = solve_mcp(prob, options={"homotopy_start": v,
                                                 "time_limit": a.time_limit})
                    h = r.passes.get("homotopy")
                    row[v] = dict(ok=natural(prob, r.x) <= 1e-6, time=time.perf_counter() - t,
                                  steps=h.iterations if h is not None and h.ran else 0,
                                  ran=bool(h is not None and h.ran), nfev=r.nfev, njev=r.njev)
                rows.append(row)
    ran = [r for r in rows if r["start"]["ran"]]
    print(f"{len(rows)} instances; the homotopy ran in {len(ran)} under 'start' "
          f"(and in {sum(r['best']['ran'] for r in rows)} under 'best')\n")
    print("| homotopy_start | solved | path steps | F evaluations | J evaluations | time |")
    print("|---|---|---|---|---|---|")
    for v in VALUES:
        print(f"| {v} | {sum(r[v]['ok'] for r in rows)}/{len(rows)} | "
              f"{sum(r[v]['steps'] for r in ran)} | {sum(r[v]['nfev'] for r in ran)} | "
              f"{sum(r[v]['njev'] for r in ran)} | {sum(r[v]['time'] for r in ran):.2f} s |")
    fewer = sum(r["best"]["nfev"] < 0.9 * r["start"]["nfev"] for r in ran)
    more = sum(r["best"]["nfev"] > 1.1 * r["start"]["nfev"] for r in ran)
    print(f"\n'best' against 'start', F evaluations: {fewer} instances >10% fewer, "
          f"{more} >10% more")
    print("\n| cell | instances with the homotopy | F evaluations start / best |")
    print("|---|---|---|")
    for cell in dict.fromkeys(r["cell"] for r in rows):
        c = [r for r in ran if r["cell"] == cell]
        print(f"| {cell} | {len(c)} | {sum(r['start']['nfev'] for r in c)} / "
              f"{sum(r['best']['nfev'] for r in c)} |")


if __name__ == "__main__":
    main()
