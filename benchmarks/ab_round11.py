"""One-process A/B measurement of round 11 of the small-problem work (benchmarks/small.md,
"Round 11"), with the harness of ``ab_round8.py`` (variants alternated batch by batch in
one process, the order flipped every round; medians of the solver's time per solve
without the user's F and J).

The functions round 11 changed are swapped, in this process, for their versions in an
older worktree (``--old``, a checkout of f2aee1a): the evaluator's ``f``, ``jac`` and
``_user_J_on_pattern``, the homotopy pass (its tracker, end game and path loop), the
pivotal path's ``run``, ``_run`` and ``_finish`` with the hand-over from the one-call
direct step (``_dense_direct_result``), the small-problem engine's ``run_path`` (with the
``_factor`` it called), and the major iteration's ``_newton_point``.  The
old functions run on the current package's helpers and objects; everything else is the
same code in both variants.  On a shared machine whose speed moves by up to 2x between
minutes this separates the change from the drift, where timing two checkouts in turns
of fresh processes (``alternate_revisions.py``) did not.

``--stall`` instead compares the option homotopy_stationary_limit = 3 (the stall rule
before round 11) with 2 (its default), both on the current code.

Usage:  PYTHONPATH=. python3 benchmarks/ab_round11.py --old <worktree> [--rounds 20]
        PYTHONPATH=. python3 benchmarks/ab_round11.py --stall [--rounds 20]
"""
from __future__ import annotations

import os
import sys

sys.path[:0] = [os.path.dirname(__file__), os.path.join(os.path.dirname(__file__), "..", "tests")]

import bench_small as bs
from ab_round8 import _print, ab, old_module, round_main


def _swaps(worktree):
    """[(owner, attribute, old value, current value)] of the functions round 11 changed."""
    import compass_sparse.evaluation as E
    import compass_sparse.homotopy as H
    import compass_sparse.nms as N
    import compass_sparse.path as P

    oe, oh, on, op = (old_module(worktree, m) for m in ("evaluation", "homotopy", "nms", "path"))
    # the old modules' own enums and result classes would not compare with the current
    # ones: theirs are made the current ones (looked up when the functions run)
    for name in ("HomotopyStatus", "HomotopyOutcome", "_Stop"):
        setattr(oh, name, getattr(H, name))
    for name in ("LinearCode", "PathResult", "WarmBasis"):
        setattr(op, name, getattr(P, name))
    swaps = [(E.Evaluator, k, getattr(oe.Evaluator, k), getattr(E.Evaluator, k))
             for k in ("f", "jac", "_user_J_on_pattern")]
    swaps.append((H, "homotopy_pass", oh.homotopy_pass, H.homotopy_pass))
    swaps += [(P.PivotalPath, k, getattr(op.PivotalPath, k), getattr(P.PivotalPath, k))
              for k in ("run", "_run", "_finish")]
    swaps.append((P, "_dense_direct_result", op._dense_direct_result, P._dense_direct_result))
    import compass_sparse.dense_path as D

    od = old_module(worktree, "dense_path")
    od.LinearCode = P.LinearCode
    swaps += [(D.DensePathEngine, "run_path", od.DensePathEngine.run_path,
               D.DensePathEngine.run_path),
              (D.DensePathEngine, "_factor", od.DensePathEngine._factor, None)]
    swaps.append((N.NMSSolver, "_newton_point", on.NMSSolver._newton_point,
                  N.NMSSolver._newton_point))
    return swaps


def _cases():
    return ([c for c in bs._known_cases() if c.name in (
        "cournot2", "kojshin", "double_root", "billups", "log_ncp", "boxvi")]
        + bs._thesis_cases([10], [2], [1, 2]) + bs._thesis_cases([50], [2], [1]))


def _stall_table(rounds):
    rows = ab(_cases(), {"limit 3": (lambda: None, {"homotopy_stationary_limit": 3}),
                         "limit 2": (lambda: None, {"homotopy_stationary_limit": 2})},
              rounds)
    _print("homotopy_stationary_limit 2 against 3 (solver time per solve)", rows,
           "limit 3", "limit 2", rounds)


def main(argv=None):
    round_main(__doc__, 11, _cases, _swaps, argv, extra=("--stall", _stall_table))


if __name__ == "__main__":
    main()
