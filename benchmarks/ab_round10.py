"""One-process A/B measurements of round 10 of the small-problem work
(benchmarks/small.md, "Round 10"), with the harness of ``ab_round8.py`` (variants
alternated batch by batch in one process, the order flipped every round; medians of the
solver's time per solve without the user's F and J):

  corrector  the homotopy's dense steps in compiled calls (the tangent, and each chord
             iteration of the corrector around F) against the homotopy tracker of an
             older worktree (``--old``, e.g. a checkout of 2c3f9a1, the commit before);
             on billups and thesis instances that end in the homotopy
  start      homotopy_start = 'best' against 'start' on the same instances

Usage:  PYTHONPATH=. python3 benchmarks/ab_round10.py corrector --old <worktree> [start]
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


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("experiments", nargs="+", choices=("corrector", "start"))
    ap.add_argument("--rounds", type=int, default=20)
    ap.add_argument("--old", help="worktree of the older revision (corrector)")
    a = ap.parse_args(argv)
    nothing = lambda: None  # noqa: E731
    if "corrector" in a.experiments:
        if not a.old:
            ap.error("corrector needs --old <worktree>")
        import compass_sparse.homotopy as H

        old, new = old_module(a.old, "homotopy")._Tracker, H._Tracker

        def use(tracker):
            return lambda: setattr(H, "_Tracker", tracker)

        rows = ab(_cases(), {"old": (use(old), None), "new": (use(new), None)}, a.rounds)
        _print("The homotopy's dense tangent and corrector steps in compiled calls", rows,
               "old", "new", a.rounds)
    if "start" in a.experiments:
        rows = ab(_cases(), {"start": (nothing, {"homotopy_start": "start"}),
                             "best": (nothing, {"homotopy_start": "best"})}, a.rounds)
        _print("The homotopy from the best point (homotopy_start)", rows, "start", "best",
               a.rounds)


if __name__ == "__main__":
    main()
