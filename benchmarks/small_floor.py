"""How many interpreted steps a tiny problem's solve takes, counted rather than sampled.

The profiles of the small problems are flat (benchmarks/small.md, rounds 10-12): no
function takes more than a few percent, and the time is spread over a few hundred Python
calls, each a microsecond or two of interpreter, numpy dispatch and compiled-kernel
dispatch.  This script counts those steps in one warm solve of each problem (sys.setprofile:
every Python function entered, by where it lives, and every builtin or numpy C function
called) and sets them against the solver's time per solve (medians over repeats, the
user's F and J left out, as bench_small.py measures it) and, when a CSV of bench_small.py
is given, against PATH's time: the budget per step that a ratio of 3 to PATH would leave.

    PYTHONPATH=. python3 benchmarks/small_floor.py [--repeats 200] [--path-csv CSV]

Numba kernel calls are not counted (a dispatcher is not a builtin function to the
profiler); each costs 1-5 us of argument dispatch (benchmarks/small.md, round 11).
"""
from __future__ import annotations

import argparse
import csv
import os
import statistics
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path[:0] = [HERE, os.path.join(HERE, "..", "tests")]

import bench_small as bs

from compass_sparse import solve_mcp

PROBLEMS = ("cournot2", "kojshin", "double_root", "log_ncp", "billups", "fam2_n10_s1",
            "fam2_n10_s2")


def _cases():
    cases = {c.name: c for c in bs._known_cases()}
    cases.update({c.name: c for c in bs._thesis_cases([10], [2], [1, 2])})
    return [cases[name] for name in PROBLEMS]


def _where(filename: str) -> str:
    f = filename.replace("\\", "/")
    if "/compass_sparse/" in f and "/generators/" not in f:
        return "package"
    if "/numpy/" in f or "/scipy/" in f:
        return "numpy/scipy"
    if "known_problems" in f or "/generators/" in f or "bench_small" in f:
        return "user"
    return "other"


def count_steps(case) -> dict:
    """Python calls by location and builtin/C calls in one solve of a warm process."""
    prob = case.problem
    solve_mcp(prob.with_start(prob.x0))  # warm: kernels loaded, patterns made
    counts = {"package": 0, "numpy/scipy": 0, "user": 0, "other": 0, "c_calls": 0}

    def hook(frame, event, arg):
        if event == "call":
            counts[_where(frame.f_code.co_filename)] += 1
        elif event == "c_call":
            counts["c_calls"] += 1

    p = prob.with_start(prob.x0)
    sys.setprofile(hook)
    try:
        res = solve_mcp(p)
    finally:
        sys.setprofile(None)
    counts.update(nit=res.nit, nfev=res.nfev, njev=res.njev, status=res.status.name)
    return counts


def solver_time(case, repeats: int) -> float:
    """Median seconds per solve without the user's F and J (bench_small's measure)."""
    clock = [0.0, 0.0]
    prob = bs._timed_problem(case.problem, clock)
    for _ in range(10):
        solve_mcp(prob.with_start(case.problem.x0))
    times = []
    for _ in range(repeats):
        clock[:] = [0.0, 0.0]
        p = prob.with_start(case.problem.x0)
        t = time.perf_counter()
        solve_mcp(p)
        times.append(time.perf_counter() - t - clock[0])
    return statistics.median(times)


def _path_times(path_csv):
    if not path_csv:
        return {}
    with open(path_csv) as fh:
        return {r["name"]: float(r["time"]) for r in csv.DictReader(fh)
                if r["solver"] == "PATH" and r["success"] == "True"}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--repeats", type=int, default=200)
    ap.add_argument("--path-csv", help="a results CSV of bench_small.py (PATH's times)")
    a = ap.parse_args(argv)
    path = _path_times(a.path_csv)
    print("| problem | n | majors | F / J | package calls | numpy/scipy calls | builtin calls "
          "| solver time | per package call | 3x PATH per package call |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for case in _cases():
        c = count_steps(case)
        t = solver_time(case, a.repeats)
        per = t / c["package"] * 1e6
        budget = (f"{3 * path[case.name] / c['package'] * 1e6:.2f} us"
                  if case.name in path else "-")
        print(f"| {case.name} | {case.n} | {c['nit']} | {c['nfev']} / {c['njev']} | "
              f"{c['package']} | {c['numpy/scipy']} | {c['c_calls']} | {t * 1e3:.3f} ms | "
              f"{per:.2f} us | {budget} |")


if __name__ == "__main__":
    main()
