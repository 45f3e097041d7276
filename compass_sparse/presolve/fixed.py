"""Pass: fixed variables (l_j = u_j).

A variable with l_j = u_j satisfies its complementarity condition whatever F_j is, so
z_j = l_j is substituted and row j (its paired row) leaves the problem.  Needs no linear
information.  F_j is still reported after postsolve (evaluated at the full point).
"""
from __future__ import annotations

from ._kernels import fixed_columns

NAME = "fixed_variables"


def run(ws) -> None:
    cols = fixed_columns(ws.col_active, ws.lb, ws.ub, ws.touched_col)
    if cols.size:
        ws.fix(cols, ws.lb[cols], reason="l = u")
