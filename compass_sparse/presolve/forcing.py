"""Pass: forcing rows.

Row i is linear, F_i = c + sum_j a_ij z_j over the remaining variables S of the row, and
its paired variable z_p does not appear in it.  Over the box, F_i <= Fmax with
Fmax = c + sum_{a>0} a u_j + sum_{a<0} a l_j.  If Fmax = 0 and u_p = +inf, every solution
has F_i >= 0 (z_p cannot sit at an upper bound) hence F_i = 0, which the box allows only
with every z_j (j in S) at the bound attaining Fmax: the row *forces* its variables.
(Symmetrically Fmin = 0 with l_p = -inf.)

Fixing z_S removes the rows r_j paired with them, whose sign conditions (F_rj >= 0 for z_j
at its lower bound, <= 0 at its upper) would be lost.  They are kept by z_p, which is then
determined in postsolve, as the LP dual postsolve of a forcing constraint does (Theorem 4 of
the thesis, §2.4, applied to one row and column).  The reduction is made only when

* column p has remaining entries exactly in the rows r_j (j in S), all declared constant
  (d_j), so z_p influences nothing else and F_rj = g_j + d_j z_p;
* moving z_p towards its infinite bound fixes every sign: sigma * d_j * need_j > 0, where
  sigma = +1 for the Fmax case (z_p -> +inf) and -1 for the Fmin case, need_j = +1 for z_j
  at its lower bound and -1 at its upper.  (The KKT system of an LP/QP has d_j = -a_ij and
  satisfies this.)

Then every solution of the reduced problem extends: F_i = 0 holds, and z_p is taken just
far enough that every row r_j has its sign.  Removed: S and p, rows i and r_j.
"""
from __future__ import annotations

import numpy as np

from ._kernels import forcing_candidates
from .postsolve import ForcingRows

NAME = "forcing_rows"


def run(ws) -> None:
    # candidates: linear rows with an entry whose activity reaches 0 only at the box's
    # corner, on the side their partner's infinite bound leaves open (up: F <= 0 side)
    up = np.empty(ws.n, dtype=bool)
    rows = forcing_candidates(ws.linear, ws.row_nnz, ws.touched_row, ws.partner_var, ws.lb,
                              ws.ub, ws.fmin, ws.fmax, ws.scale,
                              float(ws.opts.feasibility_tolerance), up)
    if rows.size == 0:
        return
    acc = {"rows": [], "cols": [], "values": [], "seg": [], "dual_cols": [], "dual_rows": [],
           "dual_coefs": [], "need": [], "sigma": []}
    for i in rows:
        if ws.touched_row[i]:
            continue
        p = ws.partner_var[i]
        if ws.touched_col[p] or ws.col_nl[p] != 0:
            continue
        S, a = ws.row_entries(i)
        if p in S or ws.touched_col[S].any():
            continue
        sigma = 1 if up[i] else -1
        at_upper = (a > 0) if sigma > 0 else (a < 0)
        vals = np.where(at_upper, ws.ub[S], ws.lb[S])
        need = np.where(at_upper, -1, 1)
        rS = ws.partner_row[S]
        if ws.touched_row[rS].any():
            continue
        prow, d = ws.col_entries(p)
        if prow.size != S.size:
            continue
        order = np.argsort(prow)
        prow, d = prow[order], d[order]
        pos = np.searchsorted(prow, rS)
        if np.any(pos >= prow.size) or np.any(prow[np.minimum(pos, prow.size - 1)] != rS):
            continue
        dS = d[pos]
        if not np.all(sigma * dS * need > 0):
            continue
        ws.remove(np.append(S, p), np.append(rS, i))
        ws.base[S] = vals
        k = len(acc["rows"])
        acc["rows"].append(i)
        acc["cols"].append(S)
        acc["values"].append(vals)
        acc["seg"].append(np.full(S.size, k, dtype=np.intp))
        acc["dual_cols"].append(p)
        acc["dual_rows"].append(rS)
        acc["dual_coefs"].append(dS)
        acc["need"].append(need)
        acc["sigma"].append(sigma)
    if not acc["rows"]:
        return
    dual_cols = np.array(acc["dual_cols"], dtype=np.intp)
    ws.push(ForcingRows(
        rows=np.array(acc["rows"], dtype=np.intp),
        cols=np.concatenate(acc["cols"]),
        values=np.concatenate(acc["values"]),
        seg=np.concatenate(acc["seg"]),
        dual_cols=dual_cols,
        dual_rows=np.concatenate(acc["dual_rows"]),
        dual_coefs=np.concatenate(acc["dual_coefs"]),
        need=np.concatenate(acc["need"]),
        sigma=np.array(acc["sigma"], dtype=np.int8),
        dual_lb=ws.lb[dual_cols].copy(),
        dual_ub=ws.ub[dual_cols].copy()))
