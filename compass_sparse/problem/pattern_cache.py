"""Objects computed from a Jacobian pattern alone, kept with that pattern.

A loop of solves of one problem meets the same pattern in every solve; what depends on
the pattern only (index maps, counts) is made once.  Each kind has its own slot here,
named for the pass that fills and reads it; the evaluator hands out the cache of its
current pattern object (:attr:`compass_sparse.problem.evaluator.Evaluator.pattern_cache`),
shared by its :meth:`~compass_sparse.problem.evaluator.Evaluator.fresh` copies and by the
scaled problem's evaluator, which keep that pattern.  A pattern that grows is a new
object and gets a new, empty cache; before the first Jacobian there is no pattern, and
the cache handed out then is not kept.
"""
from __future__ import annotations

__all__ = ["PatternCache"]


class PatternCache:
    """The objects of one pattern object, one slot per kind (None: not made yet)."""

    __slots__ = ("isolated_pairs", "linear_rows", "linearizer", "pattern", "presolve_index",
                 "structural_reports")

    def __init__(self, pattern):
        #: the pattern object these objects were made for (identity, never a copy)
        self.pattern = pattern
        #: the solve's count of rows whose entries are all declared constant
        #: (:mod:`compass_sparse.solve`, the preprocessor's applicability test)
        self.linear_rows: int | None = None
        #: the indices whose row and column hold no entry but the diagonal
        #: (:func:`compass_sparse.problem.isolated.isolated_pairs`; the solve's
        #: preprocessor applicability test)
        self.isolated_pairs = None
        #: the Newton linearizer of M = J + eps I on this pattern
        #: (:class:`compass_sparse.path.linearize.Linearizer`)
        self.linearizer = None
        #: the preprocessor's index arrays of the pattern (:mod:`compass_sparse.presolve`)
        self.presolve_index = None
        #: the preprocessor's structural-rank reports, by the fixed-variable mask
        #: (:mod:`compass_sparse.presolve.core`)
        self.structural_reports: dict = {}
