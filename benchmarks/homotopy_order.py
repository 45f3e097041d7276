"""When to enter the homotopy: the option homotopy_after_restarts (0, 1, 3, ...) on the
COMPASS thesis families and the known problems of the test suite, in one process.

For each instance every value is solved in turn (same process, same instance), and the
table gives per value: instances solved (natural residual <= 1e-6), total and median time
per cell, restarts, and the instances whose success differs between the values.

    python3 benchmarks/homotopy_order.py --instances 30 --values 3 1 0
    python3 benchmarks/homotopy_order.py --instances 3 --sizes 500 --values 3 0 --no-known

Results: benchmarks/results/homotopy_order*.md (the printed tables).
"""
from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path[:0] = [str(HERE.parent), str(HERE.parent / "tests")]

import known_problems as kp  # noqa: E402
from test_solve_mcp import KNOWN_RUNS  # noqa: E402

from compass_sparse import solve_mcp  # noqa: E402
from compass_sparse.generators import thesis_family  # noqa: E402

from compass_sparse._jit import end_cold_start  # noqa: E402

end_cold_start()  # timings of compiled kernels (compass_sparse._jit: "Cold start")

EXTRA = {"billups": kp.billups, "double_root": kp.degenerate_root, "sqrt_ncp": kp.sqrt_ncp}


def _cases(a):
    cases = [("thesis", f"fam{f} n{n} s{s}", lambda f=f, n=n, s=s: thesis_family(n, f, s).problem)
             for f in (1, 2) for n in a.sizes for s in range(a.instances)]
    if not a.no_known:
        for name, x0 in KNOWN_RUNS + [(k, None) for k in EXTRA]:
            def make(name=name, x0=x0):
                p = (kp.ALL_SOLVABLE.get(name) or EXTRA[name])(x0)
                from compass_sparse import MCP
                return MCP(p.F, p.J, p.lb, p.ub, p.x0)
            cases.append(("known", name if x0 is None else f"{name} (x0 given)", make))
    return cases


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--instances", type=int, default=30, help="seeds 0 .. K-1 per cell")
    ap.add_argument("--sizes", type=int, nargs="+", default=[10, 20, 50, 100, 200])
    ap.add_argument("--values", type=int, nargs="+", default=[3, 1, 0])
    ap.add_argument("--time-limit", type=float, default=60.0)
    ap.add_argument("--no-known", action="store_true")
    a = ap.parse_args(argv)
    rows = []
    for group, label, make in _cases(a):
        out = {}
        for k in a.values:
            prob = make()
            t = time.perf_counter()
            r = solve_mcp(prob, options={"homotopy_after_restarts": k,
                                         "time_limit": a.time_limit})
            dt = time.perf_counter() - t
            out[k] = (r.success and r.residual.natural <= 1e-6, dt, r.restarts, r.nit,
                      r.passes["homotopy"].ran)
        rows.append((group, label, out))
        print(f"# {label}: " + "; ".join(f"{k}: {'ok' if o[0] else 'FAIL'} {o[1] * 1e3:.1f} ms "
                                          f"rst {o[2]}" for k, o in out.items()),
              file=sys.stderr, flush=True)
    print("| homotopy_after_restarts | group | solved | total time | restarts | homotopy ran |")
    print("|---|---|---|---|---|---|")
    for k in a.values:
        for group in ("thesis", "known"):
            sel = [o[k] for g, _, o in rows if g == group]
            if sel:
                print(f"| {k} | {group} | {sum(x[0] for x in sel)}/{len(sel)} | "
                      f"{sum(x[1] for x in sel):.2f} s | {sum(x[2] for x in sel)} | "
                      f"{sum(x[4] for x in sel)} |")
    print("\n| n | " + " | ".join(f"median, after {k}" for k in a.values) + " |")
    print("|---|" + "---|" * len(a.values))
    for n in a.sizes:
        cells = []
        for k in a.values:
            ts = [o[k][1] for g, lab, o in rows
                  if g == "thesis" and lab.split()[1] == f"n{n}" and o[k][0]]
            cells.append(f"{1e3 * statistics.median(ts):.1f} ms ({len(ts)} solved)" if ts
                         else "-")
        print(f"| {n} | " + " | ".join(cells) + " |")
    diff = [(lab, o) for _, lab, o in rows if len({o[k][0] for k in a.values}) > 1]
    print(f"\nInstances whose success differs between the values: {len(diff)}")
    for lab, o in diff:
        print(f"* {lab}: " + ", ".join(f"{k}: {'ok' if o[k][0] else 'fail'}" for k in a.values))


if __name__ == "__main__":
    main()
