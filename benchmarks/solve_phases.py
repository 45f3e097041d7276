"""Where a solve's time goes, by phase: exclusive times per solve of the user's F and J,
the evaluator around them, the homotopy's compiled tracker, its driver and its offers of
accepted points, the crash, the stabilized Newton method's runs, the path engines'
compiled kernels (their start_path and run_pivots calls), the paths around them and the
rest of the pipeline (``solve_mcp`` outside all of these).

Each phase is a function wrapped by a timer that subtracts the wrapped phases called
inside it (~0.3 us of overhead per call, counted in the caller's phase): the split is
a guide to what is left, not a benchmark (``bench_small.py`` and the ``ab_round*.py``
scripts are those).

Usage:  PYTHONPATH=. python3 benchmarks/solve_phases.py [--thesis FAMILY N SEED | --known NAME
                                                          | --traffic DESTINATIONS]
                                                         [--solves 300]
"""
from __future__ import annotations

import argparse
import collections
import os
import statistics
import sys
import time

sys.path[:0] = [os.path.join(os.path.dirname(__file__), "..", "tests")]


def _problem(a):
    from compass_sparse import MCP

    if getattr(a, "traffic", None):
        from compass_sparse.generators import traffic_equilibrium

        return traffic_equilibrium(a.traffic).problem
    if a.known:
        import known_problems as kp

        makers = dict(kp.ALL_SOLVABLE, double_root=kp.degenerate_root, billups=kp.billups,
                      log_ncp=lambda: kp.log_ncp(raise_errors=False), sqrt_ncp=kp.sqrt_ncp)
        p = makers[a.known]()
        return MCP(p.F, p.J, p.lb, p.ub, p.x0)
    from compass_sparse.generators import thesis_family

    # the generator's MCP itself, as bench_small.py solves it (an MCP built on its F and
    # J would time its evaluator as the user's functions)
    return thesis_family(a.thesis[1], a.thesis[0], a.thesis[2]).problem


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--thesis", nargs=3, type=int, default=[2, 10, 1],
                    metavar=("FAMILY", "N", "SEED"))
    ap.add_argument("--known", help="a known problem's name (instead of --thesis)")
    ap.add_argument("--traffic", type=int, metavar="DESTINATIONS",
                    help="the traffic equilibrium with this many destinations (8: n = 912, "
                         "24: n = 2452) instead of --thesis")
    ap.add_argument("--solves", type=int, default=300)
    a = ap.parse_args(argv)

    from compass_sparse import solve_mcp
    from compass_sparse.homotopy import _kernels as hk
    from compass_sparse.homotopy import tracker
    from compass_sparse.nms import newton, solver
    from compass_sparse.path import engine
    from compass_sparse.problem import evaluator as evaluation
    from compass_sparse._jit import end_cold_start

    # compiled kernels from the first call: the warm-up solves of a small problem would
    # otherwise all fall in the interpreted start's window, and so would the timed ones
    end_cold_start()

    spent = collections.Counter()
    inner = []  # time of the wrapped phases inside the running one

    def timed(owner, name, phase):
        fn = getattr(owner, name)

        def wrapper(*args, **kwargs):
            t = time.perf_counter()
            inner.append(0.0)
            try:
                return fn(*args, **kwargs)
            finally:
                d = time.perf_counter() - t
                spent[phase] += d - inner.pop()
                if inner:
                    inner[-1] += d

        setattr(owner, name, wrapper)

    prob = _problem(a)
    ev = prob.evaluator
    timed(ev, "_user_F", "the user's F and J")
    if callable(ev._user_jac):
        timed(ev, "_user_jac", "the user's F and J")
    for name in ("f", "f_once", "fj", "jac"):
        timed(evaluation.Evaluator, name, "the evaluator")
    timed(hk, "follow_dense", "the homotopy's compiled tracker")
    timed(tracker.Tracker, "_offer", "the homotopy's offers of accepted points")
    timed(solver.NMSSolver, "_homotopy", "the homotopy's driver")
    timed(solver, "crash", "the crash")
    timed(solver.NMSSolver, "run", "the NMS runs")
    timed(newton.NewtonStep, "solve_linear", "the paths")
    timed(engine.K, "start_path", "the path kernels")
    timed(engine.K, "run_pivots", "the path kernels")
    for _ in range(30):
        solve_mcp(prob, options={"time_limit": 60})
    rows = []  # per solve: {phase: seconds}, "total"
    for _ in range(a.solves):
        spent.clear()
        t = time.perf_counter()
        solve_mcp(prob, options={"time_limit": 60})
        row = dict(spent, total=time.perf_counter() - t)
        row["the rest of the pipeline"] = row["total"] - sum(spent.values())
        rows.append(row)
    # medians over the solves (a shared machine's slow solves move means, not medians)
    phases = sorted({k for r in rows for k in r} - {"total"},
                    key=lambda k: -statistics.median(r.get(k, 0.0) for r in rows))
    print(f"{a.solves} solves, median {statistics.median(r['total'] for r in rows) * 1e3:.3f}"
          " ms; median exclusive time per solve:")
    for k in phases:
        print(f"  {k:44s} {statistics.median(r.get(k, 0.0) for r in rows) * 1e3:7.3f} ms")


if __name__ == "__main__":
    main()
