"""Time-limit overruns on the CGE models: wall time of a solve against its ``time_limit``.

A factorization cannot be interrupted: the rule is that a solve overruns its limit by at
most the cost of the one factorization the budget allowed to start.  Each case runs in a
freshly forked process (numba warmed up first); a CGE model that cannot finish in the
limit (the dynamic capital tax at n >= 3e4 with short limits) shows the overrun.

    python benchmarks/bench_cge_time_limit.py --sizes 3e4 1e5 --cases ktax25 --limits 15 30 90

Results: ``benchmarks/results/cge_time_limit{suffix}.csv``.
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import RESULTS, CsvLog, machine_info, print_machine  # noqa: E402
from bench_cge import SHOCKS, make_model, run_forked, warm_up  # noqa: E402

FIELDS = ["family", "n", "case", "time_limit", "wall", "overrun", "status", "major",
          "crash", "factorizations", "load", "error"]


def task(family, n_target, case, time_limit):
    from compass_sparse import solve_mcp

    m, _ = make_model(family, n_target)
    prob = m.with_shock(**SHOCKS[case]).problem
    load = os.getloadavg()[0]
    t = time.perf_counter()
    res = solve_mcp(prob, options={"time_limit": float(time_limit)})
    wall = time.perf_counter() - t
    return dict(n=m.n, wall=wall, overrun=wall - time_limit, status=res.status.name,
                major=res.nit, crash=res.crash_iterations,
                factorizations=res.factorizations, load=load)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--family", default="dynamic", choices=["static", "dynamic"])
    ap.add_argument("--sizes", nargs="+", type=float, default=[3e4, 1e5])
    ap.add_argument("--cases", nargs="+", default=["ktax25"], choices=sorted(SHOCKS))
    ap.add_argument("--limits", nargs="+", type=float, default=[15.0, 30.0, 90.0])
    ap.add_argument("--suffix", default="")
    args = ap.parse_args(argv)
    print_machine(machine_info())
    warm_up()
    log = CsvLog(RESULTS / f"cge_time_limit{args.suffix}.csv", FIELDS)
    for n in args.sizes:
        for case in args.cases:
            for tl in args.limits:
                row = run_forked(task, 4 * tl + 120 + n / 500, family=args.family,
                                 n_target=int(n), case=case, time_limit=tl)
                row.update(family=args.family, case=case, time_limit=tl)
                log.write(row)
                print(f"  {args.family} n={row.get('n', int(n)):>7} {case:8s} "
                      f"limit={tl:g}s wall={row.get('wall', float('nan')):.1f}s "
                      f"overrun={row.get('overrun', float('nan')):+.1f}s "
                      f"{row.get('status', '')} fact={row.get('factorizations', '')} "
                      f"load={row.get('load', float('nan')):.1f} {row.get('error', '')}",
                      flush=True)
    log.close()


if __name__ == "__main__":
    main()
