"""One-process A/B measurement of round 15 of the small-problem work (benchmarks/small.md,
"Round 15"), with the harness of ``ab_round8.py`` (variants alternated batch by batch in
one process, the order flipped every round; medians of the solver's time per solve
without the user's F and J).

Round 15 trimmed the per-solve pipeline around the compiled kernels: the residual report
of the Result (its numbers in one compiled call), the scaling pass's reason (formatted
once per spread), and the acceptance test's norm of Phi (math.sqrt of the product, no
numpy scalar).  They are swapped, in this process, for their versions in an older
worktree (``--old``, a checkout of 8473091, round 14's last revision); everything else is
the same code in both variants.

Usage:  PYTHONPATH=. python3 benchmarks/ab_round15.py --old <worktree> [--rounds 20]
"""
from __future__ import annotations

import os
import sys

sys.path[:0] = [os.path.dirname(__file__), os.path.join(os.path.dirname(__file__), "..", "tests")]

from ab_round8 import old_module, round_main
from ab_round11 import _cases  # the same problems as rounds 11 to 14


def _swaps(worktree):
    """[(owner, attribute, old value, current value)] of the functions round 15 changed."""
    import compass_sparse.acceptance as A
    import compass_sparse.solve as S

    oa, om, os_ = (old_module(worktree, k) for k in ("acceptance", "merit", "solve"))
    return [(S, "residual_report", om.residual_report, S.residual_report),
            (S, "_scaling_pass", os_._scaling_pass, S._scaling_pass),
            (A, "residuals_small", oa.residuals_small, A.residuals_small)]


def main(argv=None):
    round_main(__doc__, 15, _cases, _swaps, argv)


if __name__ == "__main__":
    main()
