"""Isolated pairs: a variable and its row that form a block of their own.

Variable z_i and its row F_i are an *isolated pair* of the declared pattern when row i has
no entry but (i, i) and column i has no entry but (i, i).  Then F_i depends on z_i alone
and no other row depends on z_i, so the MCP splits into the one-dimensional problem

    l_i <= z_i <= u_i  _|_  F_i(z_i)

and the rest, which does not see z_i.  A value of z_i that solves the one-dimensional
problem can be kept while the rest is solved: every solution of the rest, with it, is a
solution of the MCP.  This needs no linearity: the declared pattern (``jac_sparsity``) is
the contract that no other entry ever appears (a pattern recorded from the Jacobians seen
so far proves nothing and is never used here).

Such a pair is harmless when J_ii is not 0, but a free variable whose F_i is identically 0
(a model's placeholder, an equation that cancels) has a zero row and a zero column in
every Jacobian: each Newton system is singular there, and the paths that work around it
cost many major iterations (a CGE model solved in 4 major iterations took 33, or stopped
with NO_PROGRESS, with such a variable added).  PATH treats it as free with F = 0: any
value solves it, and the start value is kept; so does the preprocessor here
(:mod:`compass_sparse.presolve.isolated_pairs`).

"Solves" is tested exactly (no tolerance): F_i = 0, or z_i at its lower bound with
F_i >= 0, or at its upper bound with F_i <= 0 -- a pair that misses by a rounding error is
left to the solver, which handles it as any other row.
"""
from __future__ import annotations

import numpy as np

__all__ = ["isolated_pairs", "solved_exactly"]


def isolated_pairs(indptr, indices, n: int, removed=None) -> np.ndarray:
    """The indices i whose row and column of the CSC pattern (``indptr``, ``indices``)
    hold no entry but (i, i), once the rows and columns ``removed`` (a mask, or None) have
    left the problem; the removed indices themselves are never returned."""
    cols = np.repeat(np.arange(n), np.diff(indptr))
    rows = np.asarray(indices[:cols.size])
    off = rows != cols
    if removed is not None:
        off &= ~removed[rows] & ~removed[cols]
    row_off = np.bincount(rows[off], minlength=n)
    col_off = np.bincount(cols[off], minlength=n)
    keep = (row_off == 0) & (col_off == 0)
    if removed is not None:
        keep &= ~removed
    return np.flatnonzero(keep)


def solved_exactly(z, f, lb, ub) -> np.ndarray:
    """Mask of the one-dimensional complementarity conditions that (z, f) meet exactly:
    f = 0, or z = l with f >= 0, or z = u with f <= 0 (NaN meets none)."""
    z, f, lb, ub = (np.asarray(a, dtype=float) for a in (z, f, lb, ub))
    return (f == 0.0) | ((z == lb) & (f >= 0.0)) | ((z == ub) & (f <= 0.0))
