"""One-process A/B measurement of round 12 of the small-problem work (benchmarks/small.md,
"Round 12"), with the harness of ``ab_round8.py`` (variants alternated batch by batch in
one process, the order flipped every round; medians of the solver's time per solve
without the user's F and J).

Round 12 changed, on the solver's path: the NMS descent test (``NMSSolver._descent_ok``,
now one compiled call through ``merit.fb_directional``), the start record of
``Result.history`` (``solve._history``), and the homotopy's dense route (``_Tracker``'s
``follow``, ``_correct`` and ``residual``: a chord iteration and an accepted point's
values and bordered matrix in one compiled call each).  Here they are swapped, in this
process, for their versions in an older worktree (``--old``, a checkout of a923edc,
round 11's last revision); everything else is the same code in both variants.

A second table (``--order``) times each problem solved 30 times in a row against the
same problem solved 3 times in turn with all the others (the benchmark's order within a
sweep), in one process: whether the benchmark's mixed order itself slows a problem down.

Usage:  PYTHONPATH=. python3 benchmarks/ab_round12.py --old <worktree> [--rounds 20]
        PYTHONPATH=. python3 benchmarks/ab_round12.py --order
"""
from __future__ import annotations

import os
import statistics
import sys
import time

sys.path[:0] = [os.path.dirname(__file__), os.path.join(os.path.dirname(__file__), "..", "tests")]

import bench_small as bs
from ab_round8 import old_module, round_main
from ab_round11 import _cases  # the same problems as round 11's A/B

from compass_sparse import solve_mcp


def _swaps(worktree):
    """[(owner, attribute, old value, current value)] of the functions round 12 changed."""
    import compass_sparse.homotopy as H
    import compass_sparse.nms as N
    import compass_sparse.solve as S

    on, os_, oh = (old_module(worktree, m) for m in ("nms", "solve", "homotopy"))
    # the old module's exceptions and enums would not compare with the current ones
    for name in ("HomotopyStatus", "HomotopyOutcome", "_Stop"):
        setattr(oh, name, getattr(H, name))
    swaps = [(N.NMSSolver, "_descent_ok", on.NMSSolver._descent_ok, N.NMSSolver._descent_ok),
             (S, "_history", os_._history, S._history)]
    swaps += [(H._Tracker, k, getattr(oh._Tracker, k), getattr(H._Tracker, k))
              for k in ("follow", "_correct", "residual")]
    swaps.append((H._Tracker, "_chord_dense", oh._Tracker._chord_dense, None))
    return swaps


def _order_table(rounds):
    """Median solver time per solve: in a row of one problem, and in turns with all."""
    cases = bs._known_cases() + bs._thesis_cases([10], [1, 2], [1, 2])
    clock = [0.0, 0.0]
    timed = {c.name: bs._timed_problem(c.problem, clock) for c in cases}

    def one(c):
        clock[:] = [0.0, 0.0]
        p = timed[c.name].with_start(c.problem.x0)
        t = time.perf_counter()
        solve_mcp(p)
        return time.perf_counter() - t - clock[0]

    for c in cases:
        for _ in range(5):
            one(c)
    row = {c.name: [] for c in cases}
    turns = {c.name: [] for c in cases}
    for _ in range(rounds):
        for c in cases:
            row[c.name] += [one(c) for _ in range(30)]
        for _ in range(10):
            for c in cases:
                turns[c.name] += [one(c) for _ in range(3)]
    print("\n### One problem in a row against all problems in turns (one process)\n")
    print("| problem | in a row | in turns | turns / row |")
    print("|---|---|---|---|")
    for c in cases:
        a, b = statistics.median(row[c.name]), statistics.median(turns[c.name])
        print(f"| {c.name} | {a * 1e3:.3f} ms | {b * 1e3:.3f} ms | {b / a:.2f} |")


def main(argv=None):
    round_main(__doc__, 12, _cases, _swaps, argv,
               extra=("--order", lambda rounds: _order_table(max(1, rounds // 10))))


if __name__ == "__main__":
    main()
