"""Pass: column singletons (including doubleton rows with a column singleton).

Column j has exactly one remaining entry, in row i, and it is declared constant (b); no
other remaining row depends on z_j.  Row i itself may be nonlinear in its other
variables: a constant partial derivative means F_i(z) = b z_j + g(other variables).
Let p be the variable paired with row i.

* p = j (z_j appears only in its own row): given the other variables, z_j solves the
  one-dimensional MCP  l_j <= z_j <= u_j _|_ b z_j + g.  That problem has a solution for
  every g when b > 0 or when [l_j, u_j] is bounded, and z_j influences no other row, so
  (z_j, row i) are removed and postsolve solves it.  Otherwise nothing is done.
* p != j, z_j and z_p both free: row i must be an equation (z_p free), solved by
  z_j = -g / b after the rest is known; z_j's old row r was an equation too (z_j free), and
  it is re-paired with the free z_p.  This is the MCP form of the LP rule "free column
  singleton" and covers a doubleton equation a z_k + b z_j = c whose z_j is a column
  singleton.  With bounded z_j or z_p the pairing cannot be rearranged and nothing is done.
"""
from __future__ import annotations

import numpy as np

from ._kernels import linear_columns_with
from .postsolve import DiagonalColumnSingletons, FreeColumnSingletons

NAME = "column_singletons"


def run(ws) -> None:
    cols = linear_columns_with(ws.col_active, ws.col_nnz, ws.col_nl, ws.touched_col, ws.lb, ws.ub,
                               1, False)
    if cols.size == 0:
        return
    diag = {"rows": [], "cols": [], "coefs": []}
    free = {"rows": [], "cols": [], "coefs": [], "freed": [], "repaired": []}
    lb, ub = ws.lb, ws.ub
    for j in cols:
        if ws.touched_col[j]:
            continue
        (i,), (b,) = ws.col_entries(j)
        if ws.touched_row[i]:
            continue
        p = ws.partner_var[i]
        if p == j:
            if not (b > 0 or (np.isfinite(lb[j]) and np.isfinite(ub[j]))):
                continue
            ws.remove([j], [i])
            diag["rows"].append(i)
            diag["cols"].append(j)
            diag["coefs"].append(b)
            continue
        if not (ws.free(j) and ws.free(p)) or ws.touched_col[p]:
            continue
        r = ws.remove_and_re_pair(j, i, p)
        if r is None:
            continue
        for key, val in (("rows", i), ("cols", j), ("coefs", b), ("freed", p),
                         ("repaired", r)):
            free[key].append(val)
    if diag["cols"]:
        c = np.array(diag["cols"], dtype=np.intp)
        ws.push(DiagonalColumnSingletons(
            rows=np.array(diag["rows"], dtype=np.intp), cols=c,
            coefs=np.array(diag["coefs"], dtype=float), lb=lb[c].copy(), ub=ub[c].copy()))
    if free["cols"]:
        ws.push(FreeColumnSingletons(
            rows=np.array(free["rows"], dtype=np.intp),
            cols=np.array(free["cols"], dtype=np.intp),
            coefs=np.array(free["coefs"], dtype=float),
            freed=np.array(free["freed"], dtype=np.intp),
            repaired_rows=np.array(free["repaired"], dtype=np.intp)))
