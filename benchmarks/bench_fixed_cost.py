"""Where the fixed cost of a small solve goes: Python calls per solve and time per stage.

Wall-clock figures of sub-millisecond solves move by factors of 1.5-3 on a shared machine;
the number of Python function calls a solve makes (counted by cProfile) does not, so it is
reported next to the times as the load-independent measure of the fixed cost.  The stage
times come from timers wrapped around the solver's own functions (each wrapper adds about
0.3 us per call, so they are indicative, and only their proportions should be compared).

    python3 benchmarks/bench_fixed_cost.py                       # cournot2 nash5 sqrt_ncp kojshin
    python3 benchmarks/bench_fixed_cost.py cournot2 --solves 5000

One warm process: every problem is solved 20 times untimed first (numba kernels loaded).
Each solve gets its own copy of the problem (``with_start``), made before timing.
"""
from __future__ import annotations

import argparse
import cProfile
import functools
import pstats
import statistics
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))
sys.path.insert(0, str(HERE.parent / "tests"))

STAGES = [  # (module, owner attribute or None, function, label)
    ("solve", None, "_solve_problem", "solve (inside solve_mcp)"),
    ("evaluation", "Evaluator", "fj", "F and J at the start (with wrappers)"),
    ("solve", None, "_presolve_pass", "presolve decision"),
    ("solve", None, "_judge_on", "acceptance verdict of the start point"),
    ("solve", None, "_scaling_pass", "scaling decision"),
    ("nms", "NMSSolver", "solve", "NMS: all major iterations"),
    ("nms", "NMSSolver", "_newton_point", "  J, linearization, basis and path"),
    ("nms", None, "solve_linear_mcp", "    the pivotal path (set-up, engine, result)"),
    ("nms", "NMSSolver", "_point", "  F at the Newton point (with wrappers)"),
    ("nms", "NMSSolver", "_consider", "  acceptance tests (J at a point that passes (1))"),
    ("solve", None, "_finish", "the Result (residual report, history)"),
]


def _problem(name):
    import known_problems as kp

    from compass_sparse import MCP

    makers = dict(kp.ALL_SOLVABLE)
    makers.update(double_root=kp.degenerate_root, billups=kp.billups, sqrt_ncp=kp.sqrt_ncp,
                  log_ncp=lambda: kp.log_ncp(raise_errors=False))
    p = makers[name]()
    return MCP(p.F, p.J, p.lb, p.ub, p.x0), p.x0


def calls_per_solve(name, solves=200) -> float:
    from compass_sparse import solve_mcp

    prob, x0 = _problem(name)
    for _ in range(20):
        solve_mcp(prob.with_start(x0))
    copies = [prob.with_start(x0) for _ in range(solves)]
    pr = cProfile.Profile()
    pr.enable()
    for q in copies:
        solve_mcp(q)
    pr.disable()
    return pstats.Stats(pr).total_calls / solves


def stage_times(name, solves=2000, repeats=5):
    """(CPU us per solve, {label: (us per solve, calls per solve)}), medians over repeats."""
    import importlib

    from compass_sparse import solve_mcp

    prob, x0 = _problem(name)
    for _ in range(20):
        solve_mcp(prob.with_start(x0))
    acc = {}
    saved = []
    for mod_name, owner_name, fn_name, label in STAGES:
        mod = importlib.import_module(f"compass_sparse.{mod_name}")
        owner = getattr(mod, owner_name) if owner_name else mod
        fn = getattr(owner, fn_name)
        saved.append((owner, fn_name, fn))

        def timed(*a, _fn=fn, _label=label, **k):
            t = time.perf_counter()
            try:
                return _fn(*a, **k)
            finally:
                d = acc.setdefault(_label, [0.0, 0])
                d[0] += time.perf_counter() - t
                d[1] += 1

        setattr(owner, fn_name, functools.wraps(fn)(timed))
    try:
        totals, per = [], {label: [] for *_, label in STAGES}
        calls = {}
        for _ in range(repeats):
            acc.clear()
            copies = [prob.with_start(x0) for _ in range(solves)]
            c = time.process_time()
            for q in copies:
                solve_mcp(q)
            totals.append((time.process_time() - c) / solves * 1e6)
            for label, (t, n) in acc.items():
                per[label].append(t / solves * 1e6)
                calls[label] = n / solves
    finally:
        for owner, fn_name, fn in saved:
            setattr(owner, fn_name, fn)
    return statistics.median(totals), {label: (statistics.median(v), calls[label])
                                       for label, v in per.items() if v}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("problems", nargs="*", default=["cournot2", "nash5", "sqrt_ncp", "kojshin"])
    ap.add_argument("--solves", type=int, default=2000)
    ap.add_argument("--repeats", type=int, default=5)
    a = ap.parse_args(argv)
    from _common import machine_info

    info = machine_info()
    print(f"revision {info.get('git', '?')}, {info.get('date', '')}")
    for name in a.problems:
        total, stages = stage_times(name, a.solves, a.repeats)
        print(f"\n{name}: {calls_per_solve(name):.0f} Python calls per solve; "
              f"{total:.0f} us CPU per solve with the stage timers (median of {a.repeats})")
        for label, (us, n) in stages.items():
            print(f"  {label:52s} {us:7.1f} us  ({n:g} calls)")


if __name__ == "__main__":
    main()
