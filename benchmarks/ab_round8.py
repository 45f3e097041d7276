"""One-process A/B measurements of the changes of round 8 of the small-problem work
(benchmarks/small.md, "Round 8").  Each experiment alternates two variants of the solver
in one process, batch by batch (the order flipped every round), and reports the medians
of the solver's time per solve without the user's F and J:

  presolve   the preprocessor's cost in a solve: presolve=True against presolve=False
             (same trajectories: on these models it keeps the problem)
  blas       the crash's BLAS thread block from order 16 (BLAS_LIMIT_MIN_N) against
             from order 1
  dense      the direct step's dense route below order 150 (DIRECT_MIN_N) against 50
  overheads  the descent gradient, dense-J and crash-argument changes against the
             functions of an older worktree (``--old``, e.g. a checkout of f4094d3)
  frame      the result's residual report, the spread test and the flat test's canonical
             check against the functions of an older worktree (``--old``, e.g. 65e1fc3)
  crashstep  the crash step of problems of order <= 200 in one compiled call against the
             crash of an older worktree (``--old``, e.g. 77901a7)
  idle       kojshin's solves right after a PATH run, a 0.4 s sleep, an unrelated Python
             subprocess, or nothing (what the side-by-side runs' alternation costs us)

Usage:  PYTHONPATH=. python3 benchmarks/ab_round8.py presolve blas dense \
            [overheads --old <worktree>] [--rounds 20]
"""
from __future__ import annotations

import argparse
import importlib.util
import os
import statistics
import sys
import time

sys.path[:0] = [os.path.dirname(__file__), os.path.join(os.path.dirname(__file__), "..", "tests")]

import bench_small as bs

from compass_sparse import solve_mcp


def _solver_time(case, prob, clock, options, k):
    s = 0.0
    for _ in range(k):
        clock[:] = [0.0, 0.0]
        q = prob.with_start(case.problem.x0)
        t = time.perf_counter()
        solve_mcp(q, options=options)
        s += time.perf_counter() - t - clock[0]
    return s / k


def ab(cases, variants, rounds, per_batch=4):
    """variants: {label: (setup callable, options)}; two labels, the first the reference."""
    (la, va), (lb, vb) = variants.items()
    rows = []
    for case in cases:
        clock = [0.0, 0.0]
        prob = bs._timed_problem(case.problem, clock)
        for setup, opt in (va, vb):
            setup()
            for _ in range(5):
                solve_mcp(prob.with_start(case.problem.x0), options=opt)
        res = {la: [], lb: []}
        for r in range(rounds):
            for lab, (setup, opt) in ((la, va), (lb, vb))[::1 if r % 2 == 0 else -1]:
                setup()
                res[lab].append(_solver_time(case, prob, clock, opt, per_batch))
        a, b = statistics.median(res[la]), statistics.median(res[lb])
        wins = sum(y < x for x, y in zip(res[la], res[lb]))
        rows.append((case.name, case.n, a, b, wins))
    vb[0]()  # the current code again
    return rows


def _print(title, rows, la, lb, rounds):
    print(f"\n### {title}\n")
    print(f"| problem | n | {la} | {lb} | {lb} / {la} | {lb} faster |")
    print("|---|---|---|---|---|---|")
    for name, n, a, b, w in rows:
        print(f"| {name} | {n} | {a * 1e3:.3f} ms | {b * 1e3:.3f} ms | {b / a:.3f} | "
              f"{w}/{rounds} |")


def ab_swapped(cases, swaps, labels, rounds, title):
    """ab() of the functions ``swaps`` ([(owner, attribute, old value, current value)])
    in their old and their current versions, printed under ``title``; ``labels``: the
    (old, current) column names."""
    def use(which):
        return lambda: [setattr(owner, k, pair[which]) for owner, k, *pair in swaps]

    rows = ab(cases, {labels[0]: (use(0), None), labels[1]: (use(1), None)}, rounds)
    _print(title, rows, labels[0], labels[1], rounds)


def round_main(doc, round_no, cases, swaps, argv=None, extra=None):
    """The command line of a round's A/B (``ab_round<N>.py``): ``--old <worktree>`` of
    the previous round and ``--rounds``; ``extra`` = (flag, run): a second table that
    ``--flag`` prints instead, ``run(rounds)``."""
    ap = argparse.ArgumentParser(description=doc.split("\n")[0])
    ap.add_argument("--old", help=f"worktree of round {round_no - 1}'s revision")
    ap.add_argument("--rounds", type=int, default=20)
    if extra is not None:
        ap.add_argument(extra[0], action="store_true")
    a = ap.parse_args(argv)
    if extra is not None and getattr(a, extra[0].lstrip("-")):
        extra[1](a.rounds)
        return
    if a.old is None:
        ap.error("--old <worktree> is required"
                 + (f" (or {extra[0]})" if extra is not None else ""))
    labels = (f"round {round_no - 1}", f"round {round_no}")
    ab_swapped(cases(), swaps(a.old), labels, a.rounds,
               f"Round {round_no}'s changes against round {round_no - 1}'s functions "
               "(solver time per solve)")


def old_module(worktree, name):
    """The module ``name`` of the package in an older worktree, loaded beside the current
    one (as ``compass_sparse.<name>_old``, once per process)."""
    key = f"compass_sparse.{name}_old"
    if key not in sys.modules:
        spec = importlib.util.spec_from_file_location(
            key, os.path.join(worktree, "compass_sparse", f"{name}.py"))
        mod = importlib.util.module_from_spec(spec)
        sys.modules[key] = mod
        spec.loader.exec_module(mod)
    return sys.modules[key]


def _small_cases():
    return [c for c in bs._known_cases() if c.name != "billups"] + bs._thesis_cases(
        [10], [1, 2], [1, 2])


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("experiments", nargs="+",
                    choices=("presolve", "blas", "dense", "overheads", "frame", "crashstep",
                             "idle"))
    ap.add_argument("--rounds", type=int, default=20)
    ap.add_argument("--old", help="worktree of the older revision (overheads)")
    a = ap.parse_args(argv)
    nothing = lambda: None
    if "presolve" in a.experiments:
        cases = bs._cge_cases([11, 40], [91])
        rows = ab(cases, {"off": (nothing, {"presolve": False}),
                          "on": (nothing, {"presolve": True})}, a.rounds)
        _print("The preprocessor's cost in a solve (presolve on against off)", rows, "off",
               "on", a.rounds)
    if "blas" in a.experiments:
        import compass_sparse.crash as C

        def limit(v):
            return lambda: setattr(C, "BLAS_LIMIT_MIN_N", v)

        rows = ab(_small_cases(), {"from 1": (limit(0), None),
                                   "from 16": (limit(16), None)}, a.rounds)
        _print("The crash's BLAS thread block", rows, "from 1", "from 16", a.rounds)
    if "dense" in a.experiments:
        import compass_sparse.direct_step as DS
        import compass_sparse.nms as N

        def bound(v):
            return lambda: (setattr(DS, "DIRECT_MIN_N", v), setattr(N, "DIRECT_MIN_N", v))

        cases = bs._cge_cases([11], [91]) + bs._thesis_cases([50, 100], [1], [1])
        rows = ab(cases, {"50": (bound(50), None), "150": (bound(150), None)}, a.rounds)
        _print("The dense direct step below order 150 (against 50)", rows, "50", "150",
               a.rounds)
    def load(name):
        """The module ``name`` of the worktree --old, loaded beside the current one."""
        if not a.old:
            ap.error("this experiment needs --old <worktree>")
        return old_module(a.old, name)

    def against_old(title, swaps, cases):
        """The current objects against those of --old: ``swaps`` lists (owner, attribute,
        module of the old worktree, attribute path in it); each variant sets them all."""
        def old_value(module, path):
            value = load(module)
            for part in path.split("."):
                value = getattr(value, part)
            return value

        new = [getattr(owner, name) for owner, name, _, _ in swaps]
        old = [old_value(module, path) for _, _, module, path in swaps]

        def use(values):
            def setup():
                for (owner, name, _, _), value in zip(swaps, values):
                    setattr(owner, name, value)
            return setup

        rows = ab(cases, {"old": (use(old), None), "new": (use(new), None)}, a.rounds)
        _print(title, rows, "old", "new", a.rounds)

    if "overheads" in a.experiments:
        import compass_sparse.evaluation as E
        import compass_sparse.nms as N

        against_old("Small-problem overheads (descent gradient, dense J, crash arguments)",
                    [(N, "crash", "crash", "crash"),
                     (N, "fb_gradient", "merit", "fb_gradient"),
                     (E.Evaluator, "_user_J_on_pattern", "evaluation",
                      "Evaluator._user_J_on_pattern")], _small_cases())
    if "frame" in a.experiments:
        import compass_sparse.acceptance as A
        import compass_sparse.solve as S

        against_old("A solve's frame (residual report, spread test, canonical check)",
                    [(S, "residual_report", "merit", "residual_report"),
                     (S, "spread", "scaling", "spread"),
                     (A, "_scale_test", "acceptance", "_scale_test")], _small_cases())
    if "crashstep" in a.experiments:
        import compass_sparse.nms as N

        against_old("The crash step in one compiled call (orders <= 200)",
                    [(N, "crash", "crash", "crash")],
                    _small_cases() + bs._cge_cases([11], [91]))
    if "idle" in a.experiments:
        idle(a.rounds)


def idle(rounds):
    """Medians of kojshin's 3-solve batches after each kind of pause."""
    import subprocess

    case = next(c for c in bs._known_cases() if c.name == "kojshin")
    clock = [0.0, 0.0]
    prob = bs._timed_problem(case.problem, clock)
    pauses = {
        "after a PATH run": case.path_run,
        "after a 0.4 s sleep": lambda: time.sleep(0.4),
        "after a Python subprocess": lambda: subprocess.run(
            [sys.executable, "-c", "import numpy, scipy.sparse; sum(range(3000000))"],
            check=True),
        "in a loop": lambda: _solver_time(case, prob, clock, None, 3),
    }
    for _ in range(3):
        _solver_time(case, prob, clock, None, 1)
    res = {k: [] for k in pauses}
    for _ in range(rounds):
        for k, pause in pauses.items():
            pause()
            for _ in range(3):
                res[k].append(_solver_time(case, prob, clock, None, 1))
    print("\n### kojshin after a pause (medians of the solves, ms)\n")
    print("| before each batch | solver time |")
    print("|---|---|")
    for k, v in res.items():
        print(f"| {k} | {statistics.median(v) * 1e3:.3f} ms |")


if __name__ == "__main__":
    main()
