"""Structural rank of an MCP's Jacobian by maximum bipartite matching.

Rows and variables form a bipartite graph with an edge for every pattern entry; the size
of a maximum matching is the structural rank (the largest rank J can have for any values
of its entries).  Variables with l = u are left out together with their rows.

For an MCP a structurally singular J is a warning, not an error: a variable that ends at a
bound with F_i != 0 does not need its row matched.  But for equations with free variables
(square systems, CGE models) it means the model has no unique solution: a common cause in
CGE models is a missing numeraire (every price can be scaled: fix one price or income).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..linalg.matching import matching
from ..linalg.csc import reduced_system

__all__ = ["StructuralReport", "structural_rank_check"]

_SHOW = 10


@dataclass
class StructuralReport:
    """Result of :func:`structural_rank_check` (indices are the problem's own)."""

    n: int
    rank: int
    unmatched_rows: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.intp))
    unmatched_vars: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.intp))
    row_names: list = field(default_factory=list)
    var_names: list = field(default_factory=list)
    message: str = ""

    @property
    def ok(self) -> bool:
        return self.rank == self.n

    @property
    def deficiency(self) -> int:
        return self.n - self.rank

    def __str__(self):
        return self.message


def _names(labels, idx):
    out = [labels(int(i)) for i in idx[:_SHOW]]
    if idx.size > _SHOW:
        out.append(f"... ({idx.size - _SHOW} more)")
    return out


def structural_rank_check(problem, *, include_fixed: bool = False) -> StructuralReport:
    """Match rows to variables on J's pattern; name what cannot be matched."""
    P = problem.pattern
    n = problem.n
    keep = np.ones(n, dtype=bool) if include_fixed else problem.lb < problem.ub
    idx = np.flatnonzero(keep)
    m = idx.size
    if m == 0:
        return StructuralReport(n=0, rank=0, message="no non-fixed variables")
    # P[keep, keep] (the pattern's data are ones: no stored zeros to drop)
    S = reduced_system(P, keep, np.zeros(n), np.zeros(n))[0]
    row_of_col, col_of_row = matching(S)
    rank = int(np.count_nonzero(col_of_row >= 0))
    ur = idx[col_of_row < 0]
    uv = idx[row_of_col < 0]
    rn = _names(problem.row_label, ur)
    vn = _names(problem.var_label, uv)
    if rank == m:
        msg = f"structurally nonsingular: all {m} rows matched to variables"
    else:
        k = m - rank
        msg = (
            f"the model is structurally singular: {k} row{'s' if k > 1 else ''} cannot be "
            f"matched to distinct variables (structural rank {rank} of {m}). "
            f"Unmatched rows: {', '.join(rn)}. Unmatched variables: {', '.join(vn)}. "
            "(A different maximum matching may name other rows/variables of the same "
            "dependent block.) For an MCP this is a warning: a variable that ends at a bound "
            "with F != 0 needs no matched row. A common cause in CGE models is a missing "
            "numeraire (fix one price or income), or an equation written twice.")
    return StructuralReport(n=m, rank=rank, unmatched_rows=ur, unmatched_vars=uv,
                            row_names=rn, var_names=vn, message=msg)
