"""Pass: isolated pairs (:mod:`compass_sparse.problem.isolated`).

Variable z_p and its row i form an isolated pair when, among the remaining entries of the
declared pattern (nonlinear entries, and declared-constant ones above the zero
tolerance), row i has none outside column p and column p none outside row i.  Then F_i
depends on z_p alone (and on removed variables, at their values) and no remaining row
depends on z_p.  When the base value of z_p already solves the one-dimensional problem
l_p <= z_p <= u_p _|_ F_i exactly -- F_i = 0, or z_p at a bound with F_i of that bound's
sign -- z_p is fixed there and the pair leaves the problem; nothing else changes.  This is
how a free variable whose F is identically 0, with a zero row and column of J (a singular
Newton system at every iterate), is kept at its start value, as PATH does.

Needs no linearity, but needs the declared pattern (``jac_sparsity``): a pattern recorded
from the Jacobians seen so far may still grow.
"""
from __future__ import annotations

import numpy as np

from ..problem.isolated import solved_exactly

NAME = "isolated_pairs"


def run(ws) -> None:
    if not ws.problem.pattern_declared:
        return
    counted = ws.nz | ws.nl  # (both are live entries only)
    off = counted & (ws.ec != ws.partner_var[ws.er])
    n = ws.n
    row_off = np.bincount(ws.er[off], minlength=n)
    col_off = np.bincount(ws.ec[off], minlength=n)
    rows = np.flatnonzero(ws.row_active & (row_off == 0) & ~ws.touched_row)
    if rows.size == 0:
        return
    p = ws.partner_var[rows]
    keep = ws.col_active[p] & (col_off[p] == 0) & ~ws.touched_col[p] & (ws.lb[p] < ws.ub[p])
    rows, p = rows[keep], p[keep]
    take = solved_exactly(ws.base[p], ws.f_base[rows], ws.lb[p], ws.ub[p])
    if take.any():
        ws.fix(p[take], ws.base[p[take]], reason="isolated pair solved at its start value")
