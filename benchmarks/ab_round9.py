"""One-process A/B measurements of the changes of round 9 of the small-problem work
(benchmarks/small.md, "Round 9"), with the harness of ``ab_round8.py`` (variants
alternated batch by batch in one process, the order flipped every round; medians of the
solver's time per solve without the user's F and J):

  onecall   a small problem's path start and dense direct step in one compiled call
            against the PivotalPath route (the call switched off)
  lemke     the Lemke start of a path in one compiled pass against its array version
            (problems whose paths restart from the Lemke ray)
  failure   the fallback steps (the search's stop at a trial that rounds to z, the dense
            LM step) and the homotopy's compiled projection and dense linear algebra,
            against the fallback module and the homotopy tracker of an older worktree
            (``--old``, e.g. a checkout of 449a101); on billups and two thesis
            instances that need the homotopy

Usage:  PYTHONPATH=. python3 benchmarks/ab_round9.py onecall lemke [failure --old <worktree>]
            [--rounds 20]
"""
from __future__ import annotations

import argparse
import os
import sys

sys.path[:0] = [os.path.dirname(__file__), os.path.join(os.path.dirname(__file__), "..", "tests")]

import bench_small as bs
from ab_round8 import _print, _small_cases, ab, old_module


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("experiments", nargs="+", choices=("onecall", "lemke", "failure"))
    ap.add_argument("--rounds", type=int, default=20)
    ap.add_argument("--old", help="worktree of the older revision (failure)")
    a = ap.parse_args(argv)
    if "onecall" in a.experiments:
        import compass_sparse.path as P

        real = P.dense_direct_path

        def route(fn):
            return lambda: setattr(P, "dense_direct_path", fn)

        rows = ab(_small_cases() + bs._thesis_cases([50], [1, 2], [1]),
                  {"path": (route(lambda *args: None), None), "one call": (route(real), None)},
                  a.rounds)
        _print("A path's start and dense direct step in one compiled call", rows, "path",
               "one call", a.rounds)
    if "lemke" in a.experiments:
        from compass_sparse.path import PivotalPath

        compiled = PivotalPath._lemke_start

        def start(fn):
            return lambda: setattr(PivotalPath, "_lemke_start", fn)

        cases = ([c for c in bs._known_cases() if c.name in ("billups", "log_ncp")]
                 + bs._thesis_cases([10], [2], [1, 2]))
        rows = ab(cases, {"arrays": (start(PivotalPath._lemke_start_arrays), None),
                          "compiled": (start(compiled), None)}, a.rounds)
        _print("The Lemke start in one compiled pass", rows, "arrays", "compiled", a.rounds)
    if "failure" in a.experiments:
        if not a.old:
            ap.error("failure needs --old <worktree>")
        import compass_sparse.homotopy as H
        import compass_sparse.nms as N

        old_fb, old_h = old_module(a.old, "fallback"), old_module(a.old, "homotopy")
        new = (N.lm_step, N.gradient_steps, H._Tracker)
        old = (old_fb.lm_step, old_fb.gradient_steps, old_h._Tracker)

        def use(values):
            return lambda: (setattr(N, "lm_step", values[0]),
                            setattr(N, "gradient_steps", values[1]),
                            setattr(H, "_Tracker", values[2]))

        cases = ([c for c in bs._known_cases() if c.name == "billups"]
                 + bs._thesis_cases([10], [2], [1]) + bs._thesis_cases([20], [1], [12]))
        rows = ab(cases, {"old": (use(old), None), "new": (use(new), None)}, a.rounds)
        _print("Fallback steps and the homotopy of a small problem", rows, "old", "new",
               a.rounds)


if __name__ == "__main__":
    main()
