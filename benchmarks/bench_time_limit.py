"""Time limits at scale: how far past ``time_limit`` a large solve returns.

The problem is a tridiagonal NCP (``compass_sparse.generators.tridiagonal_ncp``, the shape of
a discretized 1-D obstacle problem with a nonlinear term): F(z) = A z + a sin(z) + 0.1 z^3 - b
on z >= 0, A tridiagonal and
diagonally dominant (diagonal in [3, 4], off-diagonals in [-1, 1]), a in [0.1, 0.5], b in
[-1, 1], start z = 2; F and the exact J are vectorized (about 40 ms for both at n = 1e6).
At n = 1e6 it needs more than the limits below; at n = 2e5 a solve may end SOLVED within
them.  What is measured is the wall time of the solve against the limit (``over`` = wall /
limit - 1) and the cost of one evaluation of F and J, which a solve may add after its last
check of the clock.

Every timed solve runs in a fresh child process (a process keeps the orderings of the
patterns it has factored: a second solve of the same problem in one process skips the
ordering that made the first overrun), after an untimed solve at n = 6000 that loads the
compiled kernels of the same routes; ``--repeats`` such processes per case, the median
reported and every wall time listed.  With ``--baseline TREE`` each solve is also run by a
tree (an export) of another revision, in turn with this one, so that before and after
share the same minutes of a shared machine.

    python benchmarks/bench_time_limit.py                       # n = 2e5, 1e6; 1 s, 2 s
    python benchmarks/bench_time_limit.py --baseline /tmp/old --baseline-revision b882765

Results: ``benchmarks/results/time_limit[_SUFFIX].csv`` (one row per tree and case) and
its ``.json`` (command, revisions, machine); the page is ``benchmarks/time_limit.md``.
"""
from __future__ import annotations

import argparse
import csv
import json
import os
import platform
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
from _revision import git_revision

HERE = Path(__file__).resolve().parent
RESULTS = HERE / "results"

FIELDS = ["tree", "n", "limit", "wall", "over", "cpu", "status", "crash", "majors",
          "factorizations", "eval_fj", "walls", "load"]


def run_case(n, limit):
    """One timed solve in this process (after the untimed one): its row's fields."""
    from compass_sparse import solve_mcp
    from compass_sparse._jit import end_cold_start
    from compass_sparse.generators import tridiagonal_ncp

    end_cold_start()  # (compiled kernels, loaded by the untimed solve below)
    solve_mcp(*tridiagonal_ncp(6000, seed=1), options={"time_limit": 30.0})
    F, J, lb, ub, x0 = tridiagonal_ncp(n)
    t = time.perf_counter()
    J(x0), F(x0)
    eval_fj = time.perf_counter() - t
    load = os.getloadavg()[0]
    t, c = time.perf_counter(), time.process_time()
    res = solve_mcp(F, J, lb, ub, x0, options={"time_limit": float(limit)})
    wall, cpu = time.perf_counter() - t, time.process_time() - c
    return dict(wall=wall, cpu=cpu, status=res.status.name, crash=res.crash_iterations,
                majors=res.nit, factorizations=res.factorizations, load=load,
                eval_fj=eval_fj)


def run_child(tree, n, limit):
    """run_case in a fresh child process importing compass_sparse from ``tree``."""
    env = dict(os.environ, PYTHONPATH=str(tree))
    out = subprocess.run([sys.executable, str(Path(__file__).resolve()), "--child",
                          str(n), str(limit)],
                         env=env, cwd=str(tree), capture_output=True, text=True)
    lines = [ln for ln in out.stdout.splitlines() if ln.startswith("{")]
    if not lines:
        raise RuntimeError(f"n = {n}, limit {limit} in {tree}: {out.stderr[-2000:]}")
    return json.loads(lines[-1])


def summary(runs, n, limit):
    """The row of :data:`FIELDS` of one tree's repeats of a case (medians)."""
    wall = statistics.median(r["wall"] for r in runs)
    by_wall = sorted(runs, key=lambda r: r["wall"])
    out = dict(by_wall[len(runs) // 2], n=n, limit=limit, wall=wall,
               over=wall / limit - 1.0, cpu=statistics.median(r["cpu"] for r in runs),
               eval_fj=statistics.median(r["eval_fj"] for r in runs),
               walls=" ".join(f"{r['wall']:.2f}" for r in runs),
               load=statistics.median(r["load"] for r in runs))
    out["status"] = "/".join(sorted({r["status"] for r in runs}))
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sizes", nargs="+", type=float, default=[2e5, 1e6])
    ap.add_argument("--limits", nargs="+", type=float, default=[1.0, 2.0])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--suffix", default="", help="CSV name: time_limit[_SUFFIX].csv")
    ap.add_argument("--baseline", default=None,
                    help="a tree (export) of another revision, run in turn with this one")
    ap.add_argument("--baseline-revision", default="", help="the baseline tree's revision")
    ap.add_argument("--child", nargs=2, default=None, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.child:
        n, limit = args.child
        print(json.dumps(run_case(int(float(n)), float(limit))))
        return
    command = "python " + " ".join([sys.argv[0]] + (argv if argv is not None else sys.argv[1:]))
    info = dict(command=command, revision=git_revision(), baseline=args.baseline_revision,
                date=time.strftime("%Y-%m-%d %H:%M"),
                machine=f"{platform.machine()}, {os.cpu_count()} cores, "
                        f"{platform.python_version()}", numpy=np.__version__)
    print(f"# {command}\n# revision {info['revision']}  {info['date']}  {info['machine']}",
          flush=True)
    trees = ([("baseline", Path(args.baseline))] if args.baseline else []) + [
        ("this", HERE.parent)]
    RESULTS.mkdir(exist_ok=True)
    path = RESULTS / ("time_limit" + (f"_{args.suffix}" if args.suffix else "") + ".csv")
    print(f"{'tree':9s} {'n':>8s} {'limit':>5s} {'wall':>6s} {'over':>6s} {'cpu':>6s} "
          f"{'F+J':>5s} {'load':>4s}  status (walls)", flush=True)
    with open(path, "w", newline="") as fh:
        w = csv.DictWriter(fh, FIELDS, extrasaction="ignore")
        w.writeheader()
        for n in args.sizes:
            for limit in args.limits:
                runs = {tree: [] for tree, _ in trees}
                for _ in range(args.repeats):  # (the trees in turn)
                    for tree, root in trees:
                        runs[tree].append(run_child(root, int(n), limit))
                for tree, _ in trees:
                    r = summary(runs[tree], int(n), limit)
                    r["tree"] = tree
                    w.writerow(r)
                    fh.flush()
                    print(f"{tree:9s} {r['n']:8d} {limit:5.1f} {r['wall']:6.2f} "
                          f"{100 * r['over']:+5.0f}% {r['cpu']:6.2f} {r['eval_fj']:5.2f} "
                          f"{r['load']:4.1f}  {r['status']} ({r['walls']})", flush=True)
    with open(path.with_suffix(".json"), "w") as fh:
        json.dump(info, fh, indent=1)
    print(f"# written {path.relative_to(HERE.parent)}")


if __name__ == "__main__":
    main()
