"""Scaling pass: row and column equilibration of the Jacobian at the start point.

With positive diagonal matrices R (rows) and C (columns) the MCP

    l <= z <= u  _|_  F(z)

has exactly the solutions z = C y of the scaled MCP

    l / C <= y <= u / C  _|_  G(y) = R F(C y),

because positive factors keep every sign condition of complementarity (row i of G is
still paired with variable i).  G's Jacobian R J(C y) C has J's pattern.  A model written
in badly chosen units (a row in millions next to a row in millionths) has Jacobian rows
and columns of very different size; the pivotal path's tolerances, the merit function and
the step tests then weigh the rows unequally, and a row scaled by 1e-6 is all but ignored.

R and C are computed once from J(z0) as PATH does, by equilibration: ``SWEEPS`` sweeps of
Ruiz's method (divide every row and every column by the square root of its largest
|entry|), so that the largest |entry| of every non-empty row and column of R J C is close
to 1.  The factors are rounded to powers of two (scaling is then exact in floating point)
and kept within [1 / FACTOR_LIMIT, FACTOR_LIMIT].  The pass applies only when J(z0) is
badly scaled: when the largest row or column norm exceeds the smallest (non-empty) one by
more than ``SPREAD_TRIGGER``.

The solve's tolerance still refers to the user's problem: a point of the scaled problem
is accepted only when z = C y meets the acceptance test on F itself
(see :class:`compass_sparse.acceptance.Acceptance`), and the Result is reported on F.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from .problem import MCP

__all__ = ["SPREAD_TRIGGER", "SWEEPS", "FACTOR_LIMIT", "Scaling", "equilibrate", "scale_problem"]

SPREAD_TRIGGER = 1e2
"""Apply the pass when the row or column max-norms of J(z0) spread over more than this."""

SWEEPS = 5
"""Ruiz equilibration sweeps."""

FACTOR_LIMIT = 2.0 ** 40
"""Largest row or column factor (and 1 / smallest): about 1e12."""


@dataclass
class Scaling:
    """z = col * y and G = row * F."""

    row: np.ndarray
    col: np.ndarray
    spread_before: float
    spread_after: float

    def summary(self) -> str:
        return (f"row/column max-norm spread {self.spread_before:.1e} -> "
                f"{self.spread_after:.1e}")


def _maxnorms(A: sp.csc_matrix):
    absA = abs(A)
    rows = np.zeros(A.shape[0])
    cols = np.zeros(A.shape[1])
    if A.nnz:
        rows = np.asarray(absA.max(axis=1).todense()).ravel()
        cols = np.asarray(absA.max(axis=0).todense()).ravel()
    return rows, cols


def _spread(v) -> float:
    v = v[v > 0]
    return float(v.max() / v.min()) if v.size else 1.0


def spread(J) -> float:
    """max / min of the non-zero row and column max-norms of J (1 for a well-scaled J)."""
    r, c = _maxnorms(sp.csc_matrix(J))
    return max(_spread(r), _spread(c))


def equilibrate(J) -> Scaling:
    """Power-of-two factors with R J C equilibrated (see the module docstring)."""
    A = sp.csc_matrix(J, copy=True)
    n = A.shape[0]
    row = np.ones(n)
    col = np.ones(n)
    before = spread(A)
    for _ in range(SWEEPS):
        r, c = _maxnorms(sp.diags(row) @ A @ sp.diags(col))
        row /= np.sqrt(np.where(r > 0, r, 1.0))
        col /= np.sqrt(np.where(c > 0, c, 1.0))
    row = np.clip(2.0 ** np.round(np.log2(row)), 1.0 / FACTOR_LIMIT, FACTOR_LIMIT)
    col = np.clip(2.0 ** np.round(np.log2(col)), 1.0 / FACTOR_LIMIT, FACTOR_LIMIT)
    after = spread(sp.diags(row) @ A @ sp.diags(col))
    return Scaling(row, col, before, after)


def scale_problem(problem: MCP, s: Scaling) -> MCP:
    """The scaled MCP G(y) = R F(C y) on l / C <= y <= u / C (names and pattern kept)."""
    R, C = s.row, s.col
    DR, DC = sp.diags(R), sp.diags(C)
    mode = problem._jac

    def on_pattern(J):
        J = sp.csc_matrix(J)
        J = (DR @ J @ DC).tocsc()  # row/column products keep the stored entries
        return J

    if mode is True:
        def G(y):
            f, J = problem.FJ_uncounted(C * y)
            return R * f, on_pattern(J)
        jac = True
    else:
        def G(y):
            return R * problem.F_uncounted(C * y)
        if mode is None:
            jac = None
        else:
            def jac(y):
                return on_pattern(problem.J_uncounted(C * y))
    P = problem.pattern
    constant_jac = None
    if problem.constant_mask is not None and problem.constant_mask.any():
        mask = problem.constant_mask
        cols = np.repeat(np.arange(problem.n), np.diff(P.indptr))
        constant_jac = sp.csc_matrix((np.ones(int(mask.sum())), (P.indices[mask], cols[mask])),
                                     shape=P.shape)
    out = MCP(G, jac, lb=problem.lb / C, ub=problem.ub / C, x0=problem.x0 / C,
              jac_sparsity=P, var_names=[problem.var_label(j) for j in range(problem.n)],
              eqn_names=[problem.row_label(i) for i in range(problem.n)],
              constant_jac=constant_jac, fd_step=problem.fd_step, check=False)
    out.pattern_declared = problem.pattern_declared
    return out
