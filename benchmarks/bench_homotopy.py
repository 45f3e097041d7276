"""Cost of the homotopy fallback on the thesis families where the solver already succeeds:
the same instances solved with ``homotopy = "auto"`` and ``"off"``, interleaved instance by
instance in one process, timed in CPU seconds of this thread (BLAS limited to one thread) so
that the load of other jobs on a shared machine does not enter the comparison.

    PYTHONPATH=. python benchmarks/bench_homotopy.py                 # n = 10 20 50 100, 10 seeds
    PYTHONPATH=. python benchmarks/bench_homotopy.py --sizes 10 20 --instances 5

Prints per cell the success counts and the median CPU time of a success for both settings,
and the median ratio auto/off over the instances both solved, split into instances where
the homotopy ran and where it did not (identical computations: their ratio is the noise).
Rows go to ``benchmarks/results/homotopy_cost.csv``.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from statistics import median

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _common import RESULTS, CsvLog, fmt_time, md_table  # noqa: E402

FIELDS = ["family", "n", "seed", "homotopy", "success", "cpu", "wall", "restarts",
          "homotopy_ran", "homotopy_cpu_share"]


def solve_once(family, n, seed, mode, time_limit):
    from compass_sparse import solve_mcp
    from compass_sparse.generators import thesis_family
    from compass_sparse.merit import natural_residual

    g = thesis_family(n, family, seed=seed)
    info = g.info
    c0, t0 = time.thread_time(), time.perf_counter()
    res = solve_mcp(g.problem, options={"homotopy": mode, "time_limit": time_limit})
    cpu, wall = time.thread_time() - c0, time.perf_counter() - t0
    f = info["D"] * res.x ** 2 + info["A"] @ res.x + info["b"]
    h = res.passes.get("homotopy")
    return dict(family=family, n=n, seed=seed, homotopy=mode,
                success=bool(natural_residual(res.x, f, info["lb"], info["ub"]) <= 1e-6),
                cpu=cpu, wall=wall, restarts=res.restarts, homotopy_ran=bool(h and h.ran),
                homotopy_cpu_share=h.time / wall if h and h.ran and wall > 0 else 0.0)


def summarize(rows, out=print):
    cells = sorted({(r["family"], r["n"]) for r in rows})
    table = []
    for fam, n in cells:
        by = {}
        for r in rows:
            if (r["family"], r["n"]) == (fam, n):
                by.setdefault(r["seed"], {})[r["homotopy"]] = r
        pairs = [d for d in by.values() if "auto" in d and "off" in d]
        both = [d for d in pairs if d["auto"]["success"] and d["off"]["success"]]
        ran = [d["auto"]["cpu"] / d["off"]["cpu"] for d in both if d["auto"]["homotopy_ran"]]
        idle = [d["auto"]["cpu"] / d["off"]["cpu"] for d in both if not d["auto"]["homotopy_ran"]]

        def med(mode):
            ok = [d[mode]["cpu"] for d in pairs if d[mode]["success"]]
            return fmt_time(median(ok)) if ok else "–"

        table.append([
            fam, n, f"{sum(d['auto']['success'] for d in pairs)}/{len(pairs)}",
            f"{sum(d['off']['success'] for d in pairs)}/{len(pairs)}", med("auto"), med("off"),
            f"{median(ran):.2f} ({len(ran)})" if ran else "–",
            f"{median(idle):.2f} ({len(idle)})" if idle else "–"])
    out(md_table(["family", "n", "solved auto", "solved off", "median CPU (success) auto",
                  "median CPU (success) off", "ratio auto/off, homotopy ran (inst.)",
                  "ratio auto/off, homotopy not run (inst.)"], table))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[10, 20, 50, 100])
    ap.add_argument("--families", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--instances", type=int, default=10)
    ap.add_argument("--time-limit", type=float, default=30.0)
    ap.add_argument("--out", type=Path, default=RESULTS / "homotopy_cost.csv")
    a = ap.parse_args(argv)
    from threadpoolctl import threadpool_limits

    log = CsvLog(a.out, FIELDS)
    rows = []
    with threadpool_limits(limits=1, user_api="blas"):
        solve_once(1, 10, 0, "off", a.time_limit)  # warm-up: numba compilation
        for n in a.sizes:
            for fam in a.families:
                for seed in range(a.instances):
                    for mode in ("auto", "off"):
                        rec = solve_once(fam, n, seed, mode, a.time_limit)
                        log.write(rec)
                        rows.append(rec)
                        print(f"family {fam} n={n:4d} seed {seed:2d} {mode:4s} "
                              f"{'OK  ' if rec['success'] else 'FAIL'} cpu {fmt_time(rec['cpu'])} "
                              f"restarts {rec['restarts']}"
                              f"{' homotopy' if rec['homotopy_ran'] else ''}", flush=True)
    log.close()
    summarize(rows)
    return 0


if __name__ == "__main__":
    sys.exit(main())
