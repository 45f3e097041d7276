"""One-process A/B measurement of round 13 of the small-problem work (benchmarks/small.md,
"Round 13"), with the harness of ``ab_round8.py`` (variants alternated batch by batch in
one process, the order flipped every round; medians of the solver's time per solve
without the user's F and J).

Round 13 changed, on the solver's path: the guarded evaluations (``Evaluator.f``,
``f_once`` and ``jac`` call F, the user's F and J without the general ``guarded`` helper
between them; the memo's look-up, inlined in the measured code, is ``_Memo.get`` again
since the final review, and round 12's is swapped in whole) and the
homotopy's accepted points (``_Tracker.residual`` takes the smoothed projection that the
corrector's last chord step made, ``_Tracker._correct`` keeps it), and the compiled
tracker and crash (``homotopy.COMPILED_TRACKER``, ``crash.COMPILED_CRASH``: a dense
problem's homotopy path and crash in one compiled call between two evaluations; round
12 had the Python routes only).  Here they are swapped, in this process, for their versions in an older worktree (``--old``, a checkout
of bdfbf13, round 12's last revision); everything else is the same code in both
variants.

Usage:  PYTHONPATH=. python3 benchmarks/ab_round13.py --old <worktree> [--rounds 20]
"""
from __future__ import annotations

import os
import sys

sys.path[:0] = [os.path.dirname(__file__), os.path.join(os.path.dirname(__file__), "..", "tests")]

from ab_round8 import old_module, round_main
from ab_round11 import _cases  # the same problems as rounds 11 and 12


def _swaps(worktree):
    """[(owner, attribute, old value, current value)] of the functions round 13 changed."""
    import compass_sparse.crash as C
    import compass_sparse.evaluation as E
    import compass_sparse.homotopy as H

    oe, oh = old_module(worktree, "evaluation"), old_module(worktree, "homotopy")
    swaps = [(E.Evaluator, k, getattr(oe.Evaluator, k), getattr(E.Evaluator, k))
             for k in ("f", "f_once", "jac", "F", "J", "guarded")]
    swaps += [(E.Evaluator, k, getattr(oe.Evaluator, k), None)  # (round 12's only)
              for k in ("_guarded", "_F_value")]
    swaps += [(H._Tracker, k, getattr(oh._Tracker, k), getattr(H._Tracker, k))
              for k in ("residual", "_correct")]
    swaps.append((H, "COMPILED_TRACKER", False, True))
    swaps.append((C, "COMPILED_CRASH", False, True))
    return swaps


def main(argv=None):
    round_main(__doc__, 13, _cases, _swaps, argv)


if __name__ == "__main__":
    main()
