"""Two revisions of the whole package timed in one process, batch by batch.

The machine's speed moves by 1.5-2x within minutes, more than a round of changes to a
small solve's cost, so only ratios taken in one process, alternating, are reliable.  The
per-round scripts (``ab_round<N>.py``) swap the functions a round changed for their old
versions; this one loads an older revision's whole ``compass_sparse`` beside the current
one, under another name (its imports inside the package are relative), and solves each
problem with both, alternating batches and flipping the order every round.

Each problem is one of bench_small.py's cases (``cournot2``, ``fam2_n10_s1``,
``ramsey_T11_tax25``, ...): the current package's MCP as that benchmark builds it, and the
same user functions, bounds, start, declared pattern and constant entries given to the old
package's MCP.  Each solve is timed as bench_small.py times it (a copy of the built problem
with its start, ``time_limit = 60``), and its solver time is the wall time without the
time spent inside the user's F and J (and without the timing wrapper's own cost per call,
bench_small.py's calibration).  Reported: the medians over the rounds of the mean
solver time per solve of a batch, their ratio, and in how many rounds the current revision
was faster.  Both revisions must return the same point bit for bit (checked; a change that
moves points is not a trim and needs its own comparison).

With ``--one-shot`` each solve is ``solve_mcp(F, jac, lb, ub, x0)`` from the user's
functions, as a script calls it: the problem's construction, its start check and its
first Jacobian's pattern are timed too (problems with a declared pattern or constant
entries lose them there: the known problems have none).

Usage (the older revision checked out in a worktree first):
    git worktree add /tmp/old <revision>
    PYTHONPATH=. python3 benchmarks/ab_packages.py --old /tmp/old cournot2 fam2_n10_s1 \\
        [--rounds 12] [--per-batch 4] [--one-shot]

The old package is copied to ``<tmp>/compass_ab_<name of --old>/compass_sparse_old`` and
compiles its kernels there on its first run (numba's cache then keeps them).
"""
from __future__ import annotations

import argparse
import importlib
import os
import shutil
import statistics
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path[:0] = [HERE, os.path.join(HERE, "..", "tests")]

import bench_small as bs

OLD_NAME = "compass_sparse_old"


def load_old(root: str):
    """The package of the worktree ``root``, imported as ``compass_sparse_old``."""
    src = os.path.join(os.path.abspath(root), "compass_sparse")
    if not os.path.isfile(os.path.join(src, "__init__.py")):
        raise SystemExit(f"{root} holds no compass_sparse package")
    base = os.path.join(tempfile.gettempdir(),
                        "compass_ab_" + os.path.basename(os.path.abspath(root)))
    dst = os.path.join(base, OLD_NAME)
    if not os.path.isdir(dst):
        shutil.copytree(src, dst, ignore=shutil.ignore_patterns("__pycache__"))
    sys.path.insert(0, base)
    return importlib.import_module(OLD_NAME)


def old_problem(old, p):
    """The MCP ``p`` (the current package's) built again by the old package."""
    ev = p.evaluator
    return old.MCP(ev._user_F, ev._user_jac, p.lb.copy(), p.ub.copy(), p.x0.copy(),
                   jac_sparsity=ev.pattern if ev.pattern_declared else None,
                   constant_jac=ev._constant_spec, var_names=p.var_names,
                   eqn_names=p.eqn_names)


def cases(names):
    """bench_small.py's cases of these names."""
    import compass_sparse.generators  # noqa: F401  (the generators' package path)

    pool = bs._known_cases()
    fam = [x for x in names if x.startswith("fam")]
    for x in fam:
        f, n, s = x[3:].split("_")
        pool += bs._thesis_cases([int(n[1:])], [int(f)], [int(s[1:])])
    if any(x.startswith(("ramsey", "static")) for x in names):
        pool += bs._cge_cases([11, 40, 110], [91, 759])
    by_name = {c.name: c for c in pool}
    missing = [x for x in names if x not in by_name]
    if missing:
        raise SystemExit(f"unknown problems {missing}; known: {sorted(by_name)}")
    return [by_name[x] for x in names]


def _batch(solve_mcp, prob, x0, clock, k, one_shot=False):
    """Mean solver time (wall time without the user's F and J) of k solves, and the last
    point.  ``one_shot``: each solve is ``solve_mcp(F, jac, lb, ub, x0)`` from the user's
    functions (the problem's construction and first Jacobian pattern timed too)."""
    total, r = 0.0, None
    ev = prob.evaluator
    call_wall = bs._instrument_cost()[0]  # (what the timing wrapper adds per call)
    for _ in range(k):
        clock[:] = [0.0, 0.0, 0]
        t = time.perf_counter()
        if one_shot:
            r = solve_mcp(ev._user_F, ev._user_jac, prob.lb, prob.ub, x0,
                          options={"time_limit": 60.0})
        else:
            r = solve_mcp(prob.with_start(x0), options={"time_limit": 60.0})
        total += time.perf_counter() - t - clock[0] - clock[2] * call_wall
    return total / k, r


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("problems", nargs="+")
    ap.add_argument("--old", required=True, help="worktree of the older revision")
    ap.add_argument("--rounds", type=int, default=12)
    ap.add_argument("--per-batch", type=int, default=4)
    ap.add_argument("--one-shot", action="store_true",
                    help="solve_mcp(F, jac, lb, ub, x0) from the user's functions each time "
                         "(problems without a declared pattern or constant entries)")
    a = ap.parse_args(argv)

    import compass_sparse as new
    from compass_sparse._jit import end_cold_start

    old = load_old(a.old)
    end_cold_start()
    importlib.import_module(OLD_NAME + "._jit").end_cold_start()
    print("| problem | n | old | new | new / old | new faster |\n|---|---|---|---|---|---|")
    for case in cases(a.problems):
        x0 = case.problem.x0
        variants = {}
        for label, pkg, built in (("old", old, old_problem(old, case.problem)),
                                  ("new", new, case.problem)):
            clock = [0.0, 0.0, 0]
            prob = bs._timed_problem(built, clock)
            _, r = _batch(pkg.solve_mcp, prob, x0, clock, 5, a.one_shot)  # warm-up
            variants[label] = (pkg.solve_mcp, prob, clock, r)
        ro, rn = variants["old"][3], variants["new"][3]
        if ro.x.tobytes() != rn.x.tobytes() or ro.status.name != rn.status.name:
            raise SystemExit(f"{case.name}: the two revisions return different points "
                             f"({ro.status.name}, {rn.status.name}): not a like-for-like timing")
        times = {"old": [], "new": []}
        for r in range(a.rounds):
            for label in (("old", "new") if r % 2 == 0 else ("new", "old")):
                solve, prob, clock, _ = variants[label]
                times[label].append(_batch(solve, prob, x0, clock, a.per_batch,
                                           a.one_shot)[0])
        mo, mn = statistics.median(times["old"]), statistics.median(times["new"])
        wins = sum(n < o for o, n in zip(times["old"], times["new"]))
        print(f"| {case.name} | {case.n} | {mo * 1e3:.3f} ms | {mn * 1e3:.3f} ms | "
              f"{mn / mo:.3f} | {wins}/{a.rounds} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
