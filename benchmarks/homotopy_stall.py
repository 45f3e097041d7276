"""How many stalled major iterations NMS waits before the homotopy (option
``homotopy_stationary_limit``), on the COMPASS thesis families and the known problems.

Every instance is solved once per limit (default: 3, the restart rule's value before
round 11, and 2); reported per limit: instances solved (natural residual <= 1e-6), how
many reach the homotopy, major iterations, pivots, F and J evaluations (deterministic) and
time (one pass: only a rough guide on a shared machine); then the instances whose counts
differ.

    python3 benchmarks/homotopy_stall.py
    python3 benchmarks/homotopy_stall.py --limits 3 2 1 --sizes 10 20

Results: benchmarks/results/homotopy_stall.md (the printed tables).
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path[:0] = [str(HERE.parent), str(HERE.parent / "tests"), str(HERE)]

import known_problems as kp  # noqa: E402

from homotopy_steps import _instances as thesis_and_billups  # noqa: E402

from compass_sparse import MCP, solve_mcp  # noqa: E402

from compass_sparse._jit import end_cold_start  # noqa: E402

end_cold_start()  # timings of compiled kernels (compass_sparse._jit: "Cold start")


def _instances(sizes):
    yield from thesis_and_billups(sizes, seeds_small=22, seeds_large=8)
    for name, make in kp.ALL_SOLVABLE.items():
        k = make()
        yield name, lambda k=k: MCP(k.F, k.J, k.lb, k.ub, k.x0)


def _solve(make, limit):
    p = make()
    t = time.perf_counter()
    r = solve_mcp(p, options={"homotopy_stationary_limit": limit, "time_limit": 60.0})
    dt = time.perf_counter() - t
    f = p.F_uncounted(r.x)
    nat = float(np.max(np.abs(r.x - np.clip(r.x - f, p.lb, p.ub)))) if r.x.size else 0.0
    h = r.passes.get("homotopy")
    return dict(ok=nat <= 1e-6, hom=bool(h is not None and h.ran), nit=r.nit,
                piv=r.minor_iterations, nfev=r.nfev, njev=r.njev, time=dt)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--limits", type=int, nargs="+", default=[3, 2])
    ap.add_argument("--sizes", type=int, nargs="+", default=[10, 20, 50, 100, 200])
    a = ap.parse_args(argv)
    cases = list(_instances(a.sizes))
    rows = {lim: [_solve(make, lim) for _, make in cases] for lim in a.limits}
    print(f"{len(cases)} instances\n")
    print("| limit | solved | reach the homotopy | majors | pivots | F | J | time |")
    print("|---|---|---|---|---|---|---|---|")
    for lim, rs in rows.items():
        print(f"| {lim} | {sum(r['ok'] for r in rs)}/{len(rs)} | {sum(r['hom'] for r in rs)} | "
              f"{sum(r['nit'] for r in rs)} | {sum(r['piv'] for r in rs)} | "
              f"{sum(r['nfev'] for r in rs)} | {sum(r['njev'] for r in rs)} | "
              f"{sum(r['time'] for r in rs):.2f} s |")
    keys = ("ok", "hom", "nit", "piv", "nfev", "njev")
    first = a.limits[0]
    changed = [(label, [rows[lim][k] for lim in a.limits]) for k, (label, _) in enumerate(cases)
               if any(tuple(rows[lim][k][c] for c in keys) != tuple(rows[first][k][c] for c in keys)
                      for lim in a.limits)]
    print(f"\n{len(changed)} instances with other counts (solved, homotopy, majors, pivots, F, "
          "J per limit):\n")
    for label, rs in changed:
        print(f"- {label}: " + "; ".join(
            f"{lim}: {'ok' if r['ok'] else 'FAIL'} {'H' if r['hom'] else '-'} {r['nit']} "
            f"{r['piv']} {r['nfev']} {r['njev']}" for lim, r in zip(a.limits, rs)))


if __name__ == "__main__":
    main()
