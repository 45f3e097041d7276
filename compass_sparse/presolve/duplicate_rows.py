"""Pass: duplicate (proportional) linear rows.

Candidates are found by hashing in the spirit of Tomlin and Welch: each linear row gets a
key from its column pattern (a sum of random weights of its columns, bitwise equal for
equal patterns) and its coefficients scaled by the first one; rows with equal patterns are
sorted by the value key and neighbours are compared entry by entry (relative tolerance
1e-12, so the coefficients are proportional up to rounding only).

For proportional rows i, k:  F_k = lam F_i + delta  as functions (both affine, with the same
remaining columns).  At any solution F_i lies in the set R_i allowed by the bounds of its
paired variable p_i: [0, inf) if u = +inf, (-inf, 0] if l = -inf, {0} if free, anything if
boxed.  Hence F_k lies in lam R_i + delta; if that set is strictly positive, p_k = l_{p_k}
in every solution (no solution when l_{p_k} = -inf), strictly negative: p_k = u_{p_k}.

Both partners free with delta = 0 (two copies of one equation) cannot be reduced in a
square MCP: it is reported as a warning (the Jacobian is singular).

Validity of removing row k relies on row i's condition holding in the reduced problem, so
row i ("the witness") is protected for the rest of the round; a later reduction that
removes row i is itself valid only if it satisfies row i's condition, which keeps
F_i in R_i.

Duplicate *columns* are not merged.  Merging z_j and z_k (columns proportional with factor
mu, constant) would be valid only when their rows are also proportional with the same
factor and delta = 0; the merged variable needs the bounds [l_j + mu l_k, u_j + mu u_k]
and a split in postsolve.  Such pairs are rare outside LP and are left to the solver.
"""
from __future__ import annotations

import numpy as np

from ._kernels import duplicate_row_keys, linear_rows_with
from .postsolve import FixVariables

NAME = "duplicate_rows"
_RTOL = 1e-12


def _sign_set(lb, ub):
    lo = 0.0 if ub == np.inf else -np.inf
    hi = 0.0 if lb == -np.inf else np.inf
    return lo, hi


_WEIGHTS: dict = {}
"""n -> (w1, w2), the hash weights of the columns: the same numbers in every call (a fixed
seed), drawn once per order (a generator and its two draws cost a small model's pass as
much as the rest of it: 35 of 180 us at n = 102, measured)."""


def hash_weights(n):
    w = _WEIGHTS.get(n)
    if w is None:
        rng = np.random.default_rng(12345)
        w1 = rng.random(n) + 0.5
        w2 = rng.random(n) + 0.5
        w1.flags.writeable = w2.flags.writeable = False  # shared between calls
        if len(_WEIGHTS) >= 8:  # a few orders are kept: a process solving many sizes
            _WEIGHTS.pop(next(iter(_WEIGHTS)))
        w = _WEIGHTS[n] = (w1, w2)
    return w


def run(ws) -> None:
    n = ws.n
    rows = linear_rows_with(ws.linear, ws.row_nnz, ws.touched_row, 1, n)
    if rows.size < 2:
        return
    w1, w2 = hash_weights(n)
    cand = np.zeros(n, dtype=bool)
    cand[rows] = True
    h1 = np.zeros(n)
    h2 = np.zeros(n)
    duplicate_row_keys(ws.row_order, ws.nz, ws.er, ws.ec, ws.ev, cand, w1, w2, h1, h2)
    order = np.lexsort((h2[rows], h1[rows], ws.row_nnz[rows]))
    rows = rows[order]
    hb, ha = h2[rows[1:]], h2[rows[:-1]]
    same = (ws.row_nnz[rows[1:]] == ws.row_nnz[rows[:-1]]) & (h1[rows[1:]] == h1[rows[:-1]]) \
        & (np.abs(hb - ha) <= 1e-9 * (np.abs(hb) + np.abs(ha)))
    fixes_c, fixes_v = [], []
    warned = 0
    for k in np.flatnonzero(same):
        i, m = rows[k], rows[k + 1]
        if ws.touched_row[i] or ws.touched_row[m]:
            continue
        ci, ai = ws.row_entries(i)
        cm, am = ws.row_entries(m)
        if not np.array_equal(ci, cm):
            continue
        lam = am[0] / ai[0]
        if not np.allclose(am, lam * ai, rtol=_RTOL, atol=0.0):
            continue
        delta = ws.c[m] - lam * ws.c[i]
        pi, pm = ws.partner_var[i], ws.partner_var[m]
        tol_m, tol_i = ws.tol(m), ws.tol(i)
        done = False
        # witness i, target m (F_m = lam F_i + delta), then the other way round
        for wit, tgt, lm, dl, tol in ((i, m, lam, delta, tol_m),
                                      (m, i, 1.0 / lam, -delta / lam, tol_i)):
            pw, pt = ws.partner_var[wit], ws.partner_var[tgt]
            lo, hi = _sign_set(ws.lb[pw], ws.ub[pw])
            a, b = (lm * lo, lm * hi) if lm > 0 else (lm * hi, lm * lo)
            a, b = (a + dl if np.isfinite(a) else a), (b + dl if np.isfinite(b) else b)
            val = None
            if a > tol:
                val = ws.lb[pt]
            elif b < -tol:
                val = ws.ub[pt]
            if val is None:
                continue
            if not np.isfinite(val):
                ws.infeasible(
                    f"rows {ws.rl(tgt)} and {ws.rl(wit)} are proportional: "
                    f"{ws.rl(tgt)} = {lm:.6g} * {ws.rl(wit)} + {dl:.6g}; with the bounds of "
                    f"{ws.vl(pw)} this fixes the sign of {ws.rl(tgt)}, which its variable "
                    f"{ws.vl(pt)} cannot match (infinite bound): the MCP has no solution",
                    rows=[tgt, wit], variables=[pt, pw])
            if ws.touched_col[pt]:
                continue
            ws.remove([pt], [tgt])
            ws.touch(rows=[wit])
            fixes_c.append(pt)
            fixes_v.append(val)
            done = True
            break
        if not done and ws.free(pi) and ws.free(pm) and abs(delta) <= tol_m and warned < 20:
            warned += 1
            ws.warnings.append(
                f"rows {ws.rl(i)} and {ws.rl(m)} are proportional equations (both "
                "variables free): the Jacobian is singular")
    if fixes_c:
        cols = np.array(fixes_c, dtype=np.intp)
        vals = np.array(fixes_v, dtype=float)
        ws.base[cols] = vals
        ws.push(FixVariables(cols=cols, values=vals, reason="duplicate row"))
