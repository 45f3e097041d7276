"""A fresh process's first solves: the interpreted cold start against compiling from the
first call (``COMPASS_SPARSE_JIT=always``), side by side in one run.

Each measurement is a fresh interpreter (warm disk caches: one discarded run first) that
imports numpy and scipy.sparse, then the package, then solves one problem ``--solves``
times (the two modes in turns); reported per problem and mode, medians over ``--repeats``
processes: the import
of the package, the first solve, the median of the later solves, the whole process from
the package's import to the last answer, and whether numba was loaded at the end.  The
user's F and J are included (what a script waits for).

    PYTHONPATH=. python3 benchmarks/bench_cold_start.py [--repeats 5] [--solves 1 200]

Problems: the known problems of bench_small.py and thesis instances at n = 10 and 50
(famF_nN_sS).  Results: the printed tables (copied into small.md, "Round 12").
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
PROBLEMS = ("cournot2", "kojshin", "double_root", "billups", "log_ncp", "fam2_n10_s1",
            "fam1_n50_s1")

CHILD = r"""
import json, sys, time
sys.path[:0] = ["tests"]
name, solves = sys.argv[1], int(sys.argv[2])
import numpy, scipy.sparse
t0 = time.perf_counter()
import compass_sparse
from compass_sparse import solve_mcp
t1 = time.perf_counter()
import known_problems as kp
if name.startswith("fam"):
    from compass_sparse.generators import thesis_family
    f, n, s = name[3:].split("_")
    g = thesis_family(int(n[1:]), int(f), int(s[1:]))
    make = lambda: (g.problem.with_start(g.problem.x0),)
else:
    makers = dict(kp.ALL_SOLVABLE)
    makers.update(double_root=kp.degenerate_root, billups=kp.billups,
                  log_ncp=lambda: kp.log_ncp(raise_errors=False))
    p = makers[name]()
    make = lambda: (p.F, p.J, p.lb, p.ub, p.x0)
times = []
ok = True
for _ in range(solves):
    args = make()
    s = time.perf_counter()
    r = solve_mcp(*args)
    times.append(time.perf_counter() - s)
    ok = ok and r.status.name == "SOLVED"
t2 = time.perf_counter()
print(json.dumps([t1 - t0, times, t2 - t0, ok, "numba" in sys.modules]))
"""


def _run(name, solves, mode):
    env = {k: v for k, v in os.environ.items() if k != "COMPASS_SPARSE_JIT"}
    if mode == "always":
        env["COMPASS_SPARSE_JIT"] = "always"
    env["PYTHONPATH"] = str(HERE.parent)
    out = subprocess.run([sys.executable, "-c", CHILD, name, str(solves)], check=True,
                         capture_output=True, text=True, env=env, cwd=HERE.parent)
    return json.loads(out.stdout.strip().splitlines()[-1])


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--solves", type=int, nargs="+", default=[1, 200])
    ap.add_argument("--problems", nargs="+", default=list(PROBLEMS))
    a = ap.parse_args(argv)
    for solves in a.solves:
        print(f"\n### {solves} solve(s) per process (medians over {a.repeats} processes)\n")
        print("| problem | mode | import | first solve | later solves (median) | "
              "import to last answer | numba loaded | solved |")
        print("|---|---|---|---|---|---|---|---|")
        for name in a.problems:
            for mode in ("always", "auto"):
                _run(name, solves, mode)  # warm disk caches
            # the two modes in turns, the order flipped every repeat: the machine's speed
            # drifts by up to 2x within minutes
            by_mode = {"always": [], "auto": []}
            for k in range(a.repeats):
                for mode in ("always", "auto")[::1 if k % 2 == 0 else -1]:
                    by_mode[mode].append(_run(name, solves, mode))
            for mode, runs in by_mode.items():
                imp = statistics.median(r[0] for r in runs)
                first = statistics.median(r[1][0] for r in runs)
                later = (statistics.median(statistics.median(r[1][1:]) for r in runs)
                         if solves > 1 else float("nan"))
                total = statistics.median(r[2] for r in runs)
                loaded = sum(r[4] for r in runs)
                solved = all(r[3] for r in runs)
                later_s = f"{later * 1e3:.2f} ms" if solves > 1 else "-"
                print(f"| {name} | {mode} | {imp:.3f} s | {first * 1e3:.1f} ms | {later_s} | "
                      f"{total:.3f} s | {loaded}/{len(runs)} | {solved} |", flush=True)


if __name__ == "__main__":
    main()
