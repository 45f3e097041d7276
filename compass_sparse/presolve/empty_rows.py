"""Pass: empty rows.

A linear row i with no remaining entry is a constant (a row without pattern entries is
linear only when the pattern is declared; see :mod:`.linear`): F_i(z) = c_i for every z.  With p
its paired variable, the complementarity condition l_p <= z_p <= u_p _|_ c_i means

* c_i > 0: z_p = l_p in every solution (no solution when l_p = -inf);
* c_i < 0: z_p = u_p in every solution (no solution when u_p = +inf);
* c_i = 0: any z_p in [l_p, u_p] satisfies row i.  Then z_p is still determined by the
  other rows it appears in, so it stays -- unless no remaining row depends on it, in which
  case it is fixed at its start value (clipped into the box).

"c_i > 0" means c_i > feasibility_tolerance * (1 + |c_i|).
"""
from __future__ import annotations

import numpy as np

from ._kernels import linear_rows_with

NAME = "empty_rows"


def run(ws) -> None:
    rows = linear_rows_with(ws.linear, ws.row_nnz, ws.touched_row, 0, 0)
    if rows.size == 0:
        return
    p = ws.partner_var[rows]
    c = ws.c[rows]
    t = ws.opts.feasibility_tolerance * ws.scale[rows]
    pos, neg = c > t, c < -t
    bad = (pos & (ws.lb[p] == -np.inf)) | (neg & (ws.ub[p] == np.inf))
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        i, j = rows[k], p[k]
        side = "positive" if pos[k] else "negative"
        why = ("the declared pattern (jac_sparsity) has no entry in it" if ws.certain_rows[i]
               else "its Jacobian entries are declared constant (constant_jac)")
        ws.infeasible(
            f"row {ws.rl(i)} is the constant {c[k]:.6g} ({side}), because {why}; so its "
            f"variable {ws.vl(j)} would have to sit at its {'lower' if pos[k] else 'upper'} "
            "bound, which is infinite: the MCP has no solution", rows=[i], variables=[j])
    zero = ~pos & ~neg & (ws.col_nnz[p] == 0) & (ws.col_nl[p] == 0)
    take = (pos | neg | zero) & ~ws.touched_col[p]
    if not take.any():
        return
    vals = np.where(pos, ws.lb[p], np.where(neg, ws.ub[p], np.clip(ws.base[p], ws.lb[p],
                                                                        ws.ub[p])))
    ws.fix(p[take], vals[take], reason="empty row")

