"""The reduced problem: an MCP on the remaining variables that wraps the original F and J.

F_red(y) = F(fill(y))[rows],  J_red(y) = J(fill(y))[rows, cols],

where fill(y) puts y at the remaining variables ``cols`` and the presolve values (or
placeholders no remaining row depends on) elsewhere.  This is exact for nonlinear
remaining parts too.  The reduced Jacobian keeps a fixed pattern: its entries are a fixed
selection (``take``) of the original pattern entries, in canonical CSC order.  Names are the
original labels, so messages about the reduced problem name the user's rows and variables;
declared-constant entries stay declared, so a second presolve sees the same linear
structure.  Its evaluator is a restriction of the original problem's
(:meth:`~compass_sparse.problem.evaluator.Evaluator.restrict`): every call of the user's F is
counted once, in the original problem's counters.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from ..problem.mcp import MCP

__all__ = ["build_reduced"]


def build_reduced(ws):
    P = ws.problem
    stack = ws.stack
    cols = np.flatnonzero(ws.col_active)
    rows = ws.partner_row[cols]
    stack.cols, stack.rows = cols, rows
    stack.base = ws.base.copy()
    m = cols.size
    if m == 0:
        return None
    live = np.flatnonzero(ws.row_active[ws.er] & ws.col_active[ws.ec])
    rpos = np.full(P.n, -1, dtype=np.intp)
    rpos[rows] = np.arange(m)
    cpos = np.full(P.n, -1, dtype=np.intp)
    cpos[cols] = np.arange(m)
    nr = rpos[ws.er[live]]
    nc = cpos[ws.ec[live]]
    order = np.lexsort((nr, nc))
    take = live[order]
    indices = nr[order].astype(np.int32)
    indptr = np.zeros(m + 1, dtype=np.int32)
    np.cumsum(np.bincount(nc, minlength=m), out=indptr[1:])
    shape = (m, m)
    pattern = sp.csc_matrix((np.ones(take.size), indices.copy(), indptr.copy()), shape=shape)
    const = ws.const[take]
    constant_jac = None
    if const.any():
        ccols = np.repeat(np.arange(m), np.diff(indptr))[const]
        constant_jac = sp.csc_matrix((np.ones(int(const.sum())), (indices[const], ccols)),
                                     shape=shape)
    var_names = [P.var_label(int(j)) for j in cols]
    eqn_names = [P.row_label(int(i)) for i in rows]
    ev = P.evaluator.restrict(
        stack.fill, rows, cols, take, pattern, constant_jac=constant_jac, ub=P.ub[cols],
        row_label=eqn_names.__getitem__, var_label=var_names.__getitem__)
    return MCP.from_evaluator(ev, P.lb[cols], P.ub[cols], P.x0[cols], var_names=var_names,
                              eqn_names=eqn_names)
