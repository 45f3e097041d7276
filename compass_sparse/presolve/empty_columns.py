"""Pass: empty columns.

If no remaining row depends on z_j (no nonlinear entry and no constant entry above the
zero tolerance in column j) and z_j has two finite bounds, then z_j can satisfy its
complementarity condition with its row r whatever F_r is: z_j = l_j if F_r > 0, u_j if
F_r < 0, anything in [l_j, u_j] if F_r = 0.  So row r imposes nothing on the rest of the
problem and (z_j, row r) are removed; postsolve evaluates F_r at the full point and sets
z_j.  With an infinite bound, row r would still constrain the others (e.g. F_r >= 0), which
a square MCP cannot express: nothing is done.
"""
from __future__ import annotations

import numpy as np

from ._kernels import linear_columns_with
from .postsolve import EmptyColumns

NAME = "empty_columns"


def run(ws) -> None:
    cols = linear_columns_with(ws.col_active, ws.col_nnz, ws.col_nl, ws.touched_col, ws.lb,
                               ws.ub, 0, True)
    if cols.size == 0:
        return
    rows = ws.partner_row[cols]
    keep = ~ws.touched_row[rows]
    cols, rows = cols[keep], rows[keep]
    if cols.size == 0:
        return
    ws.remove(cols, rows)
    ws.base[cols] = np.clip(ws.base[cols], ws.lb[cols], ws.ub[cols])
    ws.push(EmptyColumns(cols=cols, rows=rows, lb=ws.lb[cols].copy(), ub=ws.ub[cols].copy()))
