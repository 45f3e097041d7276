"""One-process A/B measurements of round 10 of the small-problem work
(benchmarks/small.md, "Round 10"), with the harness of ``ab_round8.py`` (variants
alternated batch by batch in one process, the order flipped every round; medians of the
solver's time per solve without the user's F and J):

  corrector  the homotopy's dense steps in compiled calls (the tangent, and each chord
             iteration of the corrector around F) against the homotopy tracker of an
             older worktree (``--old``, e.g. a checkout of fa31d82, the commit before);
             on billups and thesis instances that end in the homotopy
  start      homotopy_start = 'best' against 'start' on the same instances
  steps      the step control of round 10 (nominal contraction 0.3, distance 0.2, initial
             step 0.1) against round 9's (0.2, 0.1, 0.01), on these and three more
             instances
  construction  building an MCP from the user's functions with its start check (what
             solve_mcp(F, J, lb, ub, x0) does before solving): the problem and evaluation
             modules of ``--old`` against the current ones, per construction
  round      the whole homotopy of round 10 (compiled steps, new step control, from the
             best point) against round 9's: the tracker of ``--old`` (a checkout of
             d6e724e) with homotopy_initial_step = 0.01 and homotopy_start = 'start'

Usage:  PYTHONPATH=. python3 benchmarks/ab_round10.py corrector round --old <worktree> [start]
            [--rounds 20]
"""
from __future__ import annotations

import argparse
import os
import sys

sys.path[:0] = [os.path.dirname(__file__), os.path.join(os.path.dirname(__file__), "..", "tests")]

import bench_small as bs
from ab_round8 import _print, ab, old_module


def _cases():
    return ([c for c in bs._known_cases() if c.name == "billups"]
            + bs._thesis_cases([10], [2], [1, 5]) + bs._thesis_cases([20], [1], [12])
            + bs._thesis_cases([50], [2], [22]))


def _trackers(worktree, rounds, title, old_variant, new_variant):
    """The homotopy tracker of ``worktree`` (with the options of ``old_variant``: (label,
    options)) against the current one."""
    import compass_sparse.homotopy as H

    old, new = old_module(worktree, "homotopy")._Tracker, H._Tracker

    def use(tracker):
        return lambda: setattr(H, "_Tracker", tracker)

    rows = ab(_cases(), {old_variant[0]: (use(old), old_variant[1]),
                         new_variant[0]: (use(new), new_variant[1])}, rounds)
    _print(title, rows, old_variant[0], new_variant[0], rounds)


def _construction(worktree, rounds, per_batch=200):
    """Median time per construction (with the start check) of each problem, the old and
    the current problem/evaluation modules alternated batch by batch in this process."""
    import statistics
    import time

    import known_problems as kp

    from compass_sparse.generators import thesis_family
    from compass_sparse.problem import MCP

    old_problem = old_module(worktree, "problem")
    old_problem.Evaluator = old_module(worktree, "evaluation").Evaluator
    g = thesis_family(50, 1, 1).problem
    ev = g.evaluator
    users = [("cournot2", kp.cournot_duopoly()), ("kojshin", kp.kojima_shindo())]
    cases = [(name, (k.F, k.J, k.lb, k.ub, k.x0)) for name, k in users]
    cases.append(("fam1_n50_s1 (sparse J)", (ev._user_F, ev._user_jac, g.lb, g.ub, g.x0)))
    print("\n### Building an MCP from the user's functions, with its start check\n")
    print("| problem | old | new | new / old | new faster |")
    print("|---|---|---|---|---|")
    for name, args in cases:
        times = {"old": [], "new": []}
        for r in range(rounds):
            order = (("old", old_problem.MCP), ("new", MCP))[::1 if r % 2 == 0 else -1]
            for label, cls in order:
                t = time.perf_counter()
                for _ in range(per_batch):
                    cls(*args)
                times[label].append((time.perf_counter() - t) / per_batch)
        o, w = statistics.median(times["old"]), statistics.median(times["new"])
        wins = sum(y < x for x, y in zip(times["old"], times["new"]))
        print(f"| {name} | {o * 1e6:.1f} us | {w * 1e6:.1f} us | {w / o:.2f} | "
              f"{wins}/{rounds} |")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("experiments", nargs="+",
                    choices=("corrector", "start", "round", "construction", "steps"))
    ap.add_argument("--rounds", type=int, default=20)
    ap.add_argument("--old", help="worktree of the older revision (corrector, round, "
                    "construction)")
    a = ap.parse_args(argv)
    nothing = lambda: None  # noqa: E731
    for name in ("corrector", "construction", "round"):
        if name in a.experiments and not a.old:
            ap.error(f"{name} needs --old <worktree>")
    if "corrector" in a.experiments:
        _trackers(a.old, a.rounds, "The homotopy's dense tangent and corrector steps in "
                  "compiled calls", ("old", None), ("new", None))
    if "construction" in a.experiments:
        _construction(a.old, a.rounds)
    if "round" in a.experiments:
        _trackers(a.old, a.rounds, "The homotopy of round 10 against round 9's",
                  ("round 9", {"homotopy_initial_step": 0.01, "homotopy_start": "start"}),
                  ("round 10", None))
    if "steps" in a.experiments:
        import compass_sparse.homotopy as H

        def control(kappa, dist):
            return lambda: (setattr(H, "KAPPA_NOMINAL", kappa),
                            setattr(H, "DISTANCE_NOMINAL", dist))

        cases = (_cases() + bs._thesis_cases([20], [2], [3, 7])
                 + bs._thesis_cases([100], [1], [2]))
        rows = ab(cases, {
            "round 9": (control(0.2, 0.1), {"homotopy_initial_step": 0.01}),
            "round 10": (control(H.KAPPA_NOMINAL, H.DISTANCE_NOMINAL), None)}, a.rounds)
        _print("The homotopy's step control", rows, "round 9", "round 10", a.rounds)
    if "start" in a.experiments:
        rows = ab(_cases(), {"start": (nothing, {"homotopy_start": "start"}),
                             "best": (nothing, {"homotopy_start": "best"})}, a.rounds)
        _print("The homotopy from the best point (homotopy_start)", rows, "start", "best",
               a.rounds)


if __name__ == "__main__":
    main()
