"""Pass: singleton rows.

A linear row i with one remaining entry, in column j:  F_i(z) = a z_j + c.  Let p be the
variable paired with row i.

* j = p: row i is the one-dimensional MCP  l_p <= z_p <= u_p _|_ a z_p + c  (see
  ``_onedim``).  A unique solution s is implied for every solution of the whole problem,
  so z_p = s is fixed.  No solution: the MCP has none (reported).  Several solutions
  (a < 0, or a = c = 0): z_p is fixed only when no other remaining row depends on it
  (then any of them will do); otherwise nothing is done.
* j != p and z_p is free: row i is the equation a z_j + c = 0, so z_j = -c/a in every
  solution (outside [l_j, u_j] beyond the tolerance: no solution, reported).  When -c/a
  lies strictly inside (l_j, u_j), z_j is fixed and row i removed; z_j's old row r then
  needs F_r = 0 (its variable is interior), so it is re-paired with the free z_p --
  a free variable paired with an equation, a valid MCP pair.  When -c/a is at a bound of
  z_j, row r would need only a sign, which a free partner cannot express: nothing is done.
* j != p and z_p bounded: row i only says something about the *sign* of a z_j + c, i.e.
  an implied bound on z_j.  Imposing it as a bound would change z_j's own complementarity
  condition (z_j could then sit at the new bound with the wrong sign of F_r), so it is
  not used.
"""
from __future__ import annotations

import numpy as np

from ._kernels import linear_rows_with
from ._onedim import solve_1d
from .postsolve import FixByEquation, FixVariables

NAME = "singleton_rows"


def run(ws) -> None:
    rows = linear_rows_with(ws.linear, ws.row_nnz, ws.touched_row, 1, 1)
    if rows.size == 0:
        return
    # Fast path, vectorized: j = p with a > 0 has the unique solution clip(-c/a, l, u).
    # Those fixings are implied by every solution and satisfy their own row whatever the
    # rest does, so a whole batch is valid at once.
    ent = np.flatnonzero(ws.nz & (ws.row_nnz[ws.er] == 1))
    is_cand = np.zeros(ws.n, dtype=bool)  # a mask, not np.isin: rows are row numbers
    is_cand[rows] = True
    ent = ent[is_cand[ws.er[ent]]]
    er, ec, ev = ws.er[ent], ws.ec[ent], ws.ev[ent]
    diag = (ec == ws.partner_var[er]) & (ev > 0) & ~ws.touched_col[ec]
    if diag.any():
        j = ec[diag]
        v = np.clip(-ws.c[er[diag]] / ev[diag], ws.lb[j], ws.ub[j])
        ws.fix(j, v, reason="singleton row")
        rows = np.setdiff1d(rows, er[diag])
    fix_cols, fix_vals = [], []
    eq = {"rows": [], "cols": [], "values": [], "freed": [], "repaired": []}
    lb, ub = ws.lb, ws.ub
    for i in rows:
        if ws.touched_row[i]:
            continue
        (j,), (a,) = ws.row_entries(i)
        p = ws.partner_var[i]
        if ws.touched_col[j] or ws.touched_col[p]:
            continue
        c = ws.c[i]
        tol = ws.tol(i)
        if j == p:
            status, v = solve_1d(a, c, lb[j], ub[j], prefer=ws.base[j], tol=tol)
            if status == "none":
                ws.infeasible(
                    f"row {ws.rl(i)} depends only on its own variable: F = {a:.6g}*"
                    f"{ws.vl(j)} + {c:.6g}, which has no complementary value with "
                    f"{ws.vl(j)} in [{lb[j]:g}, {ub[j]:g}]: the MCP has no solution",
                    rows=[i], variables=[j])
            if status == "multiple" and not (ws.col_nnz[j] == 1 and ws.col_nl[j] == 0):
                continue
            ws.remove([j], [i])
            fix_cols.append(j)
            fix_vals.append(v)
            continue
        if not ws.free(p):
            continue
        v = -c / a
        ztol = tol / abs(a)
        if v < lb[j] - ztol * max(1.0, abs(lb[j])) or v > ub[j] + ztol * max(1.0, abs(ub[j])):
            ws.infeasible(
                f"row {ws.rl(i)} is an equation (its variable {ws.vl(p)} is free) in the "
                f"single variable {ws.vl(j)}, forcing {ws.vl(j)} = {v:.6g} outside its "
                f"bounds [{lb[j]:g}, {ub[j]:g}]: the MCP has no solution",
                rows=[i], variables=[j, p])
        if not (lb[j] < v < ub[j]):
            continue
        r = ws.remove_and_re_pair(j, i, p)
        if r is None:
            continue
        ws.base[j] = v
        for key, val in (("rows", i), ("cols", j), ("values", v), ("freed", p),
                         ("repaired", r)):
            eq[key].append(val)
    if fix_cols:
        cols = np.array(fix_cols, dtype=np.intp)
        vals = np.array(fix_vals, dtype=float)
        ws.base[cols] = vals
        ws.push(FixVariables(cols=cols, values=vals, reason="singleton row"))
    if eq["cols"]:
        ws.push(FixByEquation(
            rows=np.array(eq["rows"], dtype=np.intp), cols=np.array(eq["cols"], dtype=np.intp),
            values=np.array(eq["values"], dtype=float),
            freed=np.array(eq["freed"], dtype=np.intp),
            repaired_rows=np.array(eq["repaired"], dtype=np.intp)))
