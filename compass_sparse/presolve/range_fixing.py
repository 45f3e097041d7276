"""Pass (phase two): fixing by the range of F over the box.

For a linear row i, F_i = c + sum_j a_ij z_j, interval arithmetic over the box gives the
exact range [Fmin, Fmax] of F_i.  If Fmin > 0, F_i is positive everywhere, so in every
solution the paired variable z_p sits at l_p (no solution if l_p = -inf); if Fmax < 0,
z_p = u_p.  The fixing is also sufficient: whatever the other variables do, row i's
condition holds.  "> 0" means > feasibility_tolerance * (1 + |c| + sum |a_ij b_j|).

Ranges of nonlinear rows are not computed (that would need an interval extension of the
user's F); such rows are left alone.
"""
from __future__ import annotations

import numpy as np

from ._kernels import range_candidates

NAME = "range_fixing"


def run(ws) -> None:
    pos = np.empty(ws.n, dtype=bool)  # F > 0 on the whole box (else F < 0 there)
    rows = range_candidates(ws.linear, ws.touched_row, ws.fmin, ws.fmax, ws.scale,
                            float(ws.opts.feasibility_tolerance), pos)
    if rows.size == 0:
        return
    p = ws.partner_var[rows]
    low = pos[rows]
    vals = np.where(low, ws.lb[p], ws.ub[p])
    bad = ~np.isfinite(vals)
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        i, j = rows[k], p[k]
        if low[k]:
            what = f"F >= {ws.fmin[i]:.6g} > 0 on the whole box, so {ws.vl(j)} must sit at " \
                   "its lower bound, which is -inf"
        else:
            what = f"F <= {ws.fmax[i]:.6g} < 0 on the whole box, so {ws.vl(j)} must sit at " \
                   "its upper bound, which is +inf"
        ws.infeasible(f"row {ws.rl(i)}: {what}: the MCP has no solution", rows=[i],
                      variables=[j])
    keep = ~ws.touched_col[p]
    ws.fix(p[keep], vals[keep], reason="range of F")
