"""One-process A/B measurement of round 14 of the small-problem work (benchmarks/small.md,
"Round 14"), with the harness of ``ab_round8.py`` (variants alternated batch by batch in
one process, the order flipped every round; medians of the solver's time per solve
without the user's F and J).

Round 14 changed, on the solver's path: the major iterations (``NMSSolver._run``: their
bookkeeping in compiled calls between the evaluations, ``_run_compiled``, with a small
dense problem's Newton point -- its linear MCP and dense direct step -- inside them; the
Python loop's ``_newton_point`` makes that Newton point in one compiled call too), and
the homotopy's dense tracker (``_Tracker._follow_dense`` syncs its counts at the end
instead of at every step when nothing logs them; ``homotopy_pass`` gives it no log
function then), and per solve: the options' Mapping
test (``collections.abc``'s, not ``typing``'s), the acceptance test's Phi = 0 check, the
preprocessor's fixed-variable test and the residual report.  They are swapped, in this process,
for their versions in an older worktree (``--old``, a checkout of c27967c, round 13's
last revision); everything else is the same code in both variants.

Usage:  PYTHONPATH=. python3 benchmarks/ab_round14.py --old <worktree> [--rounds 20]
"""
from __future__ import annotations

import os
import sys

sys.path[:0] = [os.path.dirname(__file__), os.path.join(os.path.dirname(__file__), "..", "tests")]

from ab_round8 import old_module, round_main
from ab_round11 import _cases  # the same problems as rounds 11 to 13


def _swaps(worktree):
    """[(owner, attribute, old value, current value)] of the functions round 14 changed."""
    import compass_sparse.homotopy as H
    import compass_sparse.nms as N

    on, oh = old_module(worktree, "nms"), old_module(worktree, "homotopy")
    for k in ("Point", "_Stop", "NMSState"):  # the old methods make and catch today's
        setattr(on, k, getattr(N, k))
    oh._Stop = H._Stop
    import typing

    import compass_sparse._options_base as O
    import compass_sparse.acceptance as A
    import compass_sparse.solve as S

    oa, om, os_ = (old_module(worktree, k) for k in ("acceptance", "merit", "solve"))
    return ([(N.NMSSolver, k, getattr(on.NMSSolver, k), getattr(N.NMSSolver, k))
             for k in ("_newton_point", "_run")]
            + [(H._Tracker, "_follow_dense", oh._Tracker._follow_dense,
                H._Tracker._follow_dense),
               (H, "homotopy_pass", oh.homotopy_pass, H.homotopy_pass),
               (O, "Mapping", typing.Mapping, O.Mapping),
               (A, "judge", oa.judge, A.judge), (S, "judge", oa.judge, S.judge),
               (S, "_presolve_pass", os_._presolve_pass, S._presolve_pass),
               (S, "residual_report", om.residual_report, S.residual_report)])


def main(argv=None):
    round_main(__doc__, 14, _cases, _swaps, argv)


if __name__ == "__main__":
    main()
