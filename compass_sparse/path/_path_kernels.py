"""Compiled kernels of the path engines (:mod:`compass_sparse.path.engine`): the pivot
loop, the recomputation of the basic values, the solution check and the path's start,
written once over two factor kinds: the dense LU of :mod:`compass_sparse.path._dense_lu`
(``FAC_DENSE``, the small-problem engine) and the sparse LU of
:mod:`compass_sparse.path._sparse_lu` (``FAC_SPARSE``, the sparse engine).

The pivot loop (:func:`path_loop`) is the loop of ``PivotalPath._pivot_loop`` with the
same ratio test, complement rule, cycle rule, t's lower-bound rules, value recomputation
and solution check, so a path takes the same pivots as the Python loop up to rounding.
The factor kind only decides four operations (:func:`_ftran_column`, :func:`_replace`,
:func:`_factor`, :func:`_ftran_rhs`) and how M multiplies a vector; everything else is one
code path, compiled once (one signature serves both engines).

Arguments come in bundles: ``prob`` = (M dense or a 2 x 2 placeholder, M's CSC arrays
(Mp, Mi, Mx; empty for the dense kind), q, r, r's nonzeros (rI, rX), lb, ub, colkey (the
sparse LU's column order)); ``tab`` = the slot table (sk, si, xb, zval, art_sign,
displaced, enter_count); ``state`` = (istate, fstate, best_x, work); ``D`` and
``S`` the dense and the sparse factors (the unused kind's are small placeholders);
``tol`` = the float tolerances (T_*), ``lim`` = the integer limits (L_*).
"""
from __future__ import annotations

import numpy as np

from .._jit import njit
from ._sparse_lu import GROW as SP_GROW, UPD_FILL
from ._sparse_lu import factor as sp_factor, ftran_column as sp_ftran_column
from ._sparse_lu import ftran_dense as sp_ftran_dense, replace_column as sp_replace_column
from ._sparse_lu import H_NNZL, H_NNZR, H_NNZU, count_solve, refactor_pays
from ._dense_lu import (P_ROW, P_SLOT, UPD_GROWTH, UPD_LIMIT, UPD_OK, UPD_REFUSED, UPD_UNSTABLE,
                        W_CAND, W_FACTOR, W_REP_ROW, W_REP_SLOT, basis_column, factor, ftran,
                        lu_factor, replace_column)
from ._kernels import (VAR_A, VAR_S, VAR_T, VAR_V, VAR_W, VAR_Z, advance_values,
                       project_bounds, project_slot, ratio_test_bounds, set_slot_bounds,
                       slot_bounds)
from ._slot_kernels import slot_table

FAC_DENSE, FAC_SPARSE = 0, 1

# path_loop return codes (mapped to LinearCode and messages by engine.py)
RUNNING, SOLVED, RAY, CYCLE, MINOR_LIMIT, SINGULAR, TOLERANCE, ERROR, GROW = range(9)
# messages (second status word)
MSG_NONE, MSG_RAY_UNBOUNDED, MSG_T_ZERO, MSG_CYCLE, MSG_LIMIT, MSG_SING_FACTOR, \
    MSG_SING_T, MSG_SING_SLACK, MSG_SING_ART, MSG_TOL, MSG_NO_DISPLACED, MSG_LEAVE_KIND, \
    MSG_BOUNDED_SLACK, MSG_T_STALL, MSG_GROW = range(15)

# integer state (istate) and float state (fstate) layout
I_EK, I_EI, I_PIV, I_TSLOT, I_NFAC, I_NUPD, I_NETA, I_MSG, I_REFUSED, I_UNSTABLE, \
    I_GROWTH, I_BELOW, I_FILL, I_LUSUM = range(14)
N_ISTATE = 14
# (I_LUSUM: the sparse factors' nonzero entries, L + U with the updates' columns and row
# etas, held at each pivot's FTRAN, summed over the path's pivots: what its pivots read,
# but for the zeros a dense tail stores, h[H_ZL] + h[H_ZU], which its loops read too)
F_ES, F_EV, F_T, F_BEST_T, F_RES, F_TLOW = range(6)
N_FSTATE = 6
# tolerances (tol) and limits (lim)
T_PIV, T_RATIO, T_RANK, T_UPDATE, T_STAB, T_GROWTH, T_PROGRESS, T_FILL, T_THRESH = range(9)
N_TOL = 9
L_MINOR, L_CYCLE, L_CHUNK, L_FREE_BELOW, L_BELOW = range(5)
N_LIM = 5
# the per-pivot records of path_loop (a minor log): columns, and the two kinds of pivot
REC_COLUMNS = 7
REC_FLIP, REC_EXCHANGE = 0, 1


@njit(cache=True)
def _slot_values(sk, si, xb, zval, z, w, v):
    """(z, w, v) of the current basic solution before z is clipped to its bounds: two
    passes over n."""
    n = sk.shape[0]
    for i in range(n):
        z[i] = zval[i]
        w[i] = 0.0
        v[i] = 0.0
    for k in range(n):
        kind = sk[k]
        i = si[k]
        val = xb[k]
        if kind == VAR_Z:
            z[i] = val
        elif kind == VAR_W:
            w[i] = max(val, 0.0)
        elif kind == VAR_V:
            v[i] = max(val, 0.0)
        elif kind == VAR_S:
            w[i] = max(val, 0.0)
            v[i] = max(-val, 0.0)


@njit(cache=True)
def current_point(sk, si, xb, zval, lb, ub, z, w, v):
    """(z, w, v) of the current basic solution (PivotalPath.current_point)."""
    _slot_values(sk, si, xb, zval, z, w, v)
    for i in range(sk.shape[0]):
        z[i] = min(max(z[i], lb[i]), ub[i])


# ------------------------------------------------------------------ the four factor operations
@njit(cache=True)
def _ftran_column(fk, prob, tab, D, S, nupd, ek, ei, col, d, rate, sign):
    """d = B^{-1} a for the entering variable's column a, its spike kept for _replace,
    and rate = sign * d; returns max |d_k| (in slot order)."""
    M, Mp, Mi, Mx, q, r, rI, rX, lb, ub, colkey = prob
    art_sign = tab[4]
    if fk == FAC_DENSE:
        L, U, R, perm, fwork = D
        basis_column(ek, ei, M, r, art_sign, col)
        ftran(L, U, R, perm, nupd, col, d, fwork[0], fwork[1], True)
        dmax = 0.0
        for k in range(d.shape[0]):
            dmax = max(dmax, abs(d[k]))
            rate[k] = sign * d[k]
        return dmax
    dmax = sp_ftran_column(ek, ei, Mp, Mi, Mx, rI, rX, art_sign, S, nupd, d, rate, sign)
    count_solve(S)
    return dmax


@njit(cache=True)
def _replace(fk, D, S, nupd, slot, d, dmax, tol):
    """The Forrest-Tomlin replacement of ``slot``'s column: UPD_OK or why not (the sparse
    kind: UPD_LIMIT also when a refactorization pays, _sparse_lu.refactor_pays)."""
    if fk == FAC_DENSE:
        L, U, R, perm, fwork = D
        return replace_column(U, R, perm, nupd, slot, d, fwork[1], fwork[2], tol[T_UPDATE],
                              tol[T_STAB], tol[T_GROWTH])
    if refactor_pays(S):
        return UPD_LIMIT
    return sp_replace_column(S, nupd, slot, d, dmax, tol[T_UPDATE], tol[T_STAB],
                             tol[T_GROWTH], tol[T_FILL])


@njit(cache=True)
def _ftran_rhs(fk, D, S, nupd, rhs, out):
    """out = B^{-1} rhs for a dense right-hand side."""
    if fk == FAC_DENSE:
        L, U, R, perm, fwork = D
        ftran(L, U, R, perm, nupd, rhs, out, fwork[0], fwork[1], False)
    else:
        sp_ftran_dense(S, nupd, rhs, out)


@njit(cache=True)
def _factor(fk, prob, tab, D, S, rank_tol, piv_thresh, repair):
    """The LU of the slot table; returns 0, the number of dependent slots (their slots
    and rows in the factors' repair rows) or SP_GROW.  Dense kind: partial pivoting, and
    with ``repair`` the home-row rule of the thesis (see _dense_lu.factor)."""
    M, Mp, Mi, Mx, q, r, rI, rX, lb, ub, colkey = prob
    sk, si, xb, zval, art_sign, displaced, enter_count = tab
    L, U, R, perm, fwork = D
    if fk == FAC_DENSE:
        n = sk.shape[0]
        if repair:
            return factor(M, r, sk, si, art_sign, L, U, perm[P_ROW], perm[P_SLOT],
                          rank_tol, perm[W_REP_SLOT], perm[W_REP_ROW], True,
                          perm[W_FACTOR:W_FACTOR + 4], fwork[2, :n])
        return lu_factor(M, r, sk, si, art_sign, L, U, perm, fwork, rank_tol)
    return sp_factor(Mp, Mi, Mx, rI, rX, colkey, sk, si, art_sign, S, rank_tol, piv_thresh,
                     perm[W_REP_SLOT], perm[W_REP_ROW])


@njit(cache=True)
def _times_m(fk, prob, x, out):
    """out -= M x (the dense kind: column by column over the nonzero x_j, as before)."""
    M, Mp, Mi, Mx, q, r, rI, rX, lb, ub, colkey = prob
    n = x.shape[0]
    if fk == FAC_DENSE:
        for j in range(n):
            xj = x[j]
            if xj != 0.0:
                for i in range(n):
                    out[i] -= M[i, j] * xj
    else:
        for j in range(n):
            xj = x[j]
            if xj != 0.0:
                for e in range(Mp[j], Mp[j + 1]):
                    out[Mi[e]] -= Mx[e] * xj


# ------------------------------------------------------------------ values, factorization, check
@njit(cache=True)
def _recompute(fk, prob, tab, D, S, t, t_slot, nupd, rhs, w, t_lower, lo, hi):
    """x_B = B^{-1}(r (1 - t_nb) - q - M z_N) (PivotalPath._recompute_values); returns t.
    (The sparse kind subtracts M z_N as one product, as the Python loop does.)"""
    M, Mp, Mi, Mx, q, r, rI, rX, lb, ub, colkey = prob
    sk, si, xb, zval, art_sign, displaced, enter_count = tab
    n = sk.shape[0]
    t_nb = 0.0 if t_slot >= 0 else t
    zn = w  # workspace: nonbasic z values
    zn[:] = zval
    for k in range(n):
        if sk[k] == VAR_Z:
            zn[si[k]] = 0.0
    if fk == FAC_DENSE:
        for i in range(n):
            rhs[i] = r[i] * (1.0 - t_nb) - q[i]
        _times_m(fk, prob, zn, rhs)
    else:
        mz = xb  # workspace: xb is recomputed below
        mz[:] = 0.0
        for j in range(n):
            for e in range(Mp[j], Mp[j + 1]):
                mz[Mi[e]] += Mx[e] * zn[j]
        for i in range(n):
            rhs[i] = r[i] * (1.0 - t_nb) - q[i] - mz[i]
    _ftran_rhs(fk, D, S, nupd, rhs, xb)
    for k in range(n):
        if sk[k] == VAR_T:
            t = xb[k]
            break
    project_bounds(sk, si, xb, lb, ub, lo, hi, t_lower)
    return t


@njit(cache=True)
def refactor(fk, prob, tab, state, D, S, tol, t_lower):
    """PivotalPath._factor: factorize, repair dependent columns with artificials,
    recompute the basic values.  Returns 0 or a SINGULAR message code (MSG_GROW: the
    sparse factors need more storage)."""
    sk, si, xb, zval, art_sign, displaced, enter_count = tab
    istate, fstate, best_x, work = state
    perm = D[3]
    rep_slot = perm[W_REP_SLOT]
    rep_row = perm[W_REP_ROW]
    istate[I_NFAC] += 1
    # A regular basis is factorized as it is; only a singular one is repaired (the dense
    # kind by the home-row rule of the thesis, see _dense_lu.factor).
    rank_tol = tol[T_RANK]
    nrep = _factor(fk, prob, tab, D, S, rank_tol, tol[T_THRESH], False)
    if nrep > 0 and fk == FAC_DENSE:
        nrep = _factor(fk, prob, tab, D, S, rank_tol, tol[T_THRESH], True)
    if nrep == SP_GROW:
        return MSG_GROW
    if nrep > 0:
        if rep_row[nrep - 1] < 0:
            if sk[rep_slot[nrep - 1]] == VAR_T:
                return MSG_SING_T
            return MSG_SING_SLACK
        for k in range(nrep):
            slot = rep_slot[k]
            new_row = rep_row[k]
            if sk[slot] == VAR_Z:
                j = si[slot]
                zval[j] = xb[slot]  # stranded on the right-hand side
                displaced[new_row] = j
            else:  # an artificial again dependent: move its displaced z along
                j = displaced[si[slot]]
                displaced[si[slot]] = -1
                if j >= 0:
                    displaced[new_row] = j
            sk[slot] = VAR_A
            si[slot] = new_row
            art_sign[new_row] = 1
        # The LU of the repaired basis for the solves.
        nrep = _factor(fk, prob, tab, D, S, rank_tol, tol[T_THRESH], False)
        if nrep == SP_GROW:
            return MSG_GROW
        if nrep > 0:
            return MSG_SING_FACTOR
    istate[I_NETA] = 0
    # the slots' bounds (work[8], work[9]) for the ratio tests and projections: after the
    # repair, which makes artificials of dependent slots
    slot_bounds(sk, si, prob[8], prob[9], work[8], work[9])
    fstate[F_T] = _recompute(fk, prob, tab, D, S, fstate[F_T], istate[I_TSLOT], 0,
                             work[0], work[1], t_lower, work[8], work[9])
    return 0


@njit(cache=True)
def _room_self(ek, ei, es, ev, t, lb, ub):
    if ek == VAR_T:
        return max(0.0, 1.0 - t)
    if ek == VAR_Z:
        bound = ub[ei] if es > 0 else lb[ei]
        if np.isfinite(bound):
            return abs(bound - ev)
        return np.inf
    return np.inf


@njit(cache=True)
def _record(sk, si, xb, zval, lb, ub, t, fstate, best_x, work):
    """The best point when t is the largest yet: z - w + v of :func:`current_point`, its
    passes over n fused into three (the same operations on each entry, so the same
    bits)."""
    if t > fstate[F_BEST_T] + 1e-15:
        n = sk.shape[0]
        z = work[2]
        w = work[3]
        v = work[4]
        _slot_values(sk, si, xb, zval, z, w, v)
        fstate[F_BEST_T] = t
        for i in range(n):
            zi = min(max(z[i], lb[i]), ub[i])
            best_x[i] = zi - w[i] + v[i]


@njit(cache=True)
def verify(fk, prob, tab, state, D, S, tol):
    """PivotalPath._verify_solution: (code, message)."""
    M, Mp, Mi, Mx, q, r, rI, rX, lb, ub, colkey = prob
    sk, si, xb, zval, art_sign, displaced, enter_count = tab
    istate, fstate, best_x, work = state
    n = sk.shape[0]
    qmax = 0.0
    rmax = 0.0
    for i in range(n):
        qmax = max(qmax, abs(q[i]))
        rmax = max(rmax, abs(r[i]))
    art_tol = 1e-9 * (1.0 + qmax + rmax)
    for k in range(n):
        if sk[k] == VAR_A and abs(xb[k]) > art_tol:
            return SINGULAR, MSG_SING_ART
    z = work[2]
    w = work[3]
    v = work[4]
    mz = work[5]
    for attempt in range(2):
        current_point(sk, si, xb, zval, lb, ub, z, w, v)
        res = 0.0
        mz_max = 0.0
        if fk == FAC_DENSE:
            for i in range(n):
                s = 0.0
                for j in range(n):
                    s += M[i, j] * z[j]
                mz_max = max(mz_max, abs(s))
                res = max(res, abs(s + q[i] - w[i] + v[i]))
        else:
            mz[:] = 0.0
            for j in range(n):
                for e in range(Mp[j], Mp[j + 1]):
                    mz[Mi[e]] += Mx[e] * z[j]
            for i in range(n):
                mz_max = max(mz_max, abs(mz[i]))
                res = max(res, abs(mz[i] + q[i] - w[i] + v[i]))
        fstate[F_RES] = res
        if res <= 1e-9 * (1.0 + mz_max + qmax):
            return SOLVED, MSG_NONE
        if attempt == 0:
            msg = refactor(fk, prob, tab, state, D, S, tol, fstate[F_TLOW])
            if msg == MSG_GROW:
                return GROW, MSG_GROW
            if msg != 0:
                return SINGULAR, msg
    return TOLERANCE, MSG_TOL


@njit(cache=True, inline="always")
def _log_pivot(rec, rect, k, pivots, kind, ek, ei, lk, li, upd, t):
    """Pivot record k of a call (see :func:`path_loop`), when the caller asked for them."""
    if k < rec.shape[0]:
        rec[k, 0] = pivots
        rec[k, 1] = kind
        rec[k, 2] = ek
        rec[k, 3] = ei
        rec[k, 4] = lk
        rec[k, 5] = li
        rec[k, 6] = upd
        rect[k] = t


@njit(cache=True)
def _complement(lk, li, leave_up, istate, fstate, lb, ub, zval, displaced):
    """The complement rule: the next entering variable after (lk, li) left (at its upper
    bound: ``leave_up``) into istate / fstate; returns 0 or an ERROR message."""
    if lk == VAR_W:
        istate[I_EK] = VAR_Z
        istate[I_EI] = li
        fstate[F_ES] = 1.0
        fstate[F_EV] = lb[li]
    elif lk == VAR_V:
        istate[I_EK] = VAR_Z
        istate[I_EI] = li
        fstate[F_ES] = -1.0
        fstate[F_EV] = ub[li]
    elif lk == VAR_Z:
        istate[I_EK] = VAR_V if leave_up else VAR_W
        istate[I_EI] = li
        fstate[F_ES] = 1.0
        fstate[F_EV] = 0.0
    elif lk == VAR_A:
        j = displaced[li]
        displaced[li] = -1
        if j < 0:
            return MSG_NO_DISPLACED
        istate[I_EK] = VAR_Z
        istate[I_EI] = j
        fstate[F_ES] = 0.0
        fstate[F_EV] = zval[j]
    else:
        return MSG_LEAVE_KIND
    return 0


@njit(cache=True)
def path_loop(fk, prob, tab, state, D, S, tol, lim, rec, rect):
    """PivotalPath._pivot_loop for at most lim[L_CHUNK] pivots (RUNNING when they are
    used up: the caller checks its clock and calls again).  t's lower bound is
    fstate[F_TLOW]: 0, lifted (lim[L_FREE_BELOW]: a path from the current point) when t
    blocks at 0 before the path has been above tol[T_PROGRESS], for at most
    lim[L_BELOW] pivots (istate[I_BELOW]: the pivot that lifted it); see
    compass_sparse.path.  Returns (code, message).

    ``rec`` (lim[L_CHUNK] x REC_COLUMNS, or no rows: nothing recorded) and ``rect``
    receive one record per pivot of this call, the Python loop's minor-log line as
    numbers: row k (the call's pivot k) holds the pivot count, REC_FLIP or REC_EXCHANGE,
    the entering kind and index, the leaving kind and index and the update's outcome
    (UPD_*), rect[k] t after the pivot.  The records change nothing the path computes.

    A compiled kernel whose length is the algorithm (one pivot's FTRAN, ratio test, update
    and complement rule, in the Python loop's order): exempt from the package's limit of
    100 lines per function."""
    M, Mp, Mi, Mx, q, r, rI, rX, lb, ub, colkey = prob
    sk, si, xb, zval, art_sign, displaced, enter_count = tab
    istate, fstate, best_x, work = state
    n = sk.shape[0]
    d = work[5]
    col = work[6]
    slo = work[8]  # the slots' bounds (refactor sets them; each exchange its slot's)
    shi = work[9]
    cand = D[3][W_CAND]  # (the ratio test's candidates and their rooms)
    croom = work[10]
    start = istate[I_PIV]
    t_progress = tol[T_PROGRESS]
    while True:
        pivots = istate[I_PIV]
        if pivots >= lim[L_MINOR]:
            return MINOR_LIMIT, MSG_LIMIT
        if istate[I_BELOW] >= 0:
            if fstate[F_BEST_T] > t_progress:
                fstate[F_TLOW] = 0.0  # above 0 now: 0 is t's bound again
            elif pivots - istate[I_BELOW] >= lim[L_BELOW]:
                return RAY, MSG_T_STALL
        t_lower = fstate[F_TLOW]
        if pivots - start >= lim[L_CHUNK]:
            return RUNNING, MSG_NONE
        ek = istate[I_EK]
        ei = istate[I_EI]
        es = fstate[F_ES]
        ev = fstate[F_EV]
        enter_count[ek, ei] += 1
        if enter_count[ek, ei] > lim[L_CYCLE]:
            return CYCLE, MSG_CYCLE
        # d = B^{-1} a, its largest |d_k| and the basic variables' rates -es d
        rate = work[7]
        dmax = _ftran_column(fk, prob, tab, D, S, istate[I_NETA], ek, ei, col, d, rate, -es)
        if fk != FAC_DENSE:
            istate[I_LUSUM] += S[0][H_NNZL] + S[0][H_NNZU] + S[0][H_NNZR]
        t_slot = istate[I_TSLOT]
        t = fstate[F_T]
        piv_tol = tol[T_PIV] * max(1.0, dmax)
        if ek == VAR_Z and es == 0.0:
            # direction free (after an artificial left): increase t; when t does not
            # move with it (a rate within rounding), increase the variable
            if t_slot >= 0 and abs(d[t_slot]) > piv_tol:
                es = -np.sign(d[t_slot])
            else:
                es = 1.0
            fstate[F_ES] = es
            for k in range(n):
                rate[k] = -es * d[k]
        theta_self = _room_self(ek, ei, es, ev, t, lb, ub)
        leave, theta, leave_up = ratio_test_bounds(sk, si, xb, rate, lb, ub, slo, shi,
                                                   piv_tol, tol[T_RATIO], t_lower, cand,
                                                   croom)
        if (leave >= 0 and theta < theta_self and sk[leave] == VAR_T and leave_up == 0
                and lim[L_FREE_BELOW] != 0 and istate[I_BELOW] < 0
                and fstate[F_BEST_T] <= t_progress):
            # t blocks at 0 before the path has been above 0: lift its bound
            t_lower = -np.inf
            fstate[F_TLOW] = t_lower
            istate[I_BELOW] = pivots
            leave, theta, leave_up = ratio_test_bounds(sk, si, xb, rate, lb, ub, slo, shi,
                                                       piv_tol, tol[T_RATIO], t_lower, cand,
                                                       croom)
        if leave < 0 and not np.isfinite(theta_self):
            return RAY, MSG_RAY_UNBOUNDED
        if leave < 0 or theta_self <= theta:
            theta = theta_self
            advance_values(sk, si, xb, rate, theta, lb, ub, slo, shi, t_lower, -1)
            if ek == VAR_T:
                fstate[F_T] = 1.0
                return SOLVED, MSG_NONE
            istate[I_PIV] = pivots + 1
            if ek == VAR_Z:
                # bound flip: z_i moves to its other bound; its other slack enters
                zval[ei] = ub[ei] if es > 0 else lb[ei]
                istate[I_EK] = VAR_V if es > 0 else VAR_W
                fstate[F_ES] = 1.0
                fstate[F_EV] = 0.0
                if t_slot >= 0:
                    fstate[F_T] = xb[t_slot]
                _record(sk, si, xb, zval, lb, ub, fstate[F_T], fstate, best_x, work)
                _log_pivot(rec, rect, pivots - start, pivots + 1, REC_FLIP, ek, ei, -1, -1,
                           -1, fstate[F_T])
                continue
            return ERROR, MSG_BOUNDED_SLACK
        # a basic variable blocks: update values (but the leaving slot's, which the
        # entering variable takes) and exchange columns
        advance_values(sk, si, xb, rate, theta, lb, ub, slo, shi, t_lower, leave)
        new_val = ev + es * theta
        lk = sk[leave]
        li = si[leave]
        if lk == VAR_Z:
            leave_val = ub[li] if leave_up else lb[li]
        elif lk == VAR_T:
            leave_val = 1.0 if leave_up else 0.0
        else:
            leave_val = 0.0
        istate[I_PIV] = pivots + 1
        # set the slot (PivotalPath._set_slot)
        if lk == VAR_Z:
            zval[li] = leave_val
        if lk == VAR_T:
            fstate[F_T] = leave_val
            istate[I_TSLOT] = -1
        sk[leave] = ek
        si[leave] = ei
        xb[leave] = new_val
        set_slot_bounds(leave, sk, si, lb, ub, slo, shi)
        if ek == VAR_T:
            istate[I_TSLOT] = leave
        if ek == VAR_Z:
            zval[ei] = new_val
        upd = _replace(fk, D, S, istate[I_NETA], leave, d, dmax, tol)
        if upd == UPD_OK:
            istate[I_NETA] += 1
            istate[I_NUPD] += 1
            project_slot(leave, sk, si, xb, lb, ub, slo, shi, t_lower)
        else:
            if upd == UPD_REFUSED:
                istate[I_REFUSED] += 1
            elif upd == UPD_UNSTABLE:
                istate[I_UNSTABLE] += 1
            elif upd == UPD_GROWTH:
                istate[I_GROWTH] += 1
            elif upd == UPD_FILL:
                istate[I_FILL] += 1
            msg = refactor(fk, prob, tab, state, D, S, tol, t_lower)
            if msg == MSG_GROW:
                return GROW, MSG_GROW
            if msg != 0:
                _log_pivot(rec, rect, pivots - start, pivots + 1, REC_EXCHANGE, ek, ei, lk,
                           li, upd, fstate[F_T])
                return SINGULAR, msg
            project_bounds(sk, si, xb, lb, ub, slo, shi, t_lower)
        if istate[I_TSLOT] >= 0:
            fstate[F_T] = xb[istate[I_TSLOT]]
        _log_pivot(rec, rect, pivots - start, pivots + 1, REC_EXCHANGE, ek, ei, lk, li, upd,
                   fstate[F_T])
        if lk == VAR_T:
            if leave_up:
                return SOLVED, MSG_NONE
            return RAY, MSG_T_ZERO
        _record(sk, si, xb, zval, lb, ub, fstate[F_T], fstate, best_x, work)
        msg = _complement(lk, li, leave_up, istate, fstate, lb, ub, zval, displaced)
        if msg != 0:
            return ERROR, msg


@njit(cache=True)
def start_path(fk, prob, tab, state, D, S, tol, lim, slack, use_slack, z, w, v, rec, rect):
    """A path on the slot table ``tab`` in one call: fresh state, the factorization (again
    on the slot table of the basis ``slack`` when ``use_slack`` and the first one is
    singular or holds artificials, as PivotalPath.run does in Python), the first
    lim[L_CHUNK] pivots, and the solution check when t reaches 1 (:func:`run_pivots`).
    Returns (factored, code, message): factored False with the SINGULAR message when no basis
    could be factorized (code GROW: the sparse factors need more storage); code RUNNING
    when the pivots are used up (the caller continues with run_pivots)."""
    sk, si, xb, zval, art_sign, displaced, enter_count = tab
    istate, fstate, best_x, work = state
    n = sk.shape[0]
    for k in range(istate.shape[0]):
        istate[k] = 0
    for k in range(fstate.shape[0]):
        fstate[k] = 0.0
    istate[I_TSLOT] = -1
    istate[I_BELOW] = -1
    for i in range(n):
        displaced[i] = -1
    msg = refactor(fk, prob, tab, state, D, S, tol, 0.0)
    if use_slack and msg != MSG_GROW:
        artificial = False
        for k in range(n):
            if sk[k] == VAR_A:
                artificial = True
                break
        if msg != 0 or artificial:
            # PivotalPath._reset_slots on the basis without the inward guess
            slot_table(slack, z, w, v, sk, si, xb)
            for i in range(n):
                zval[i] = z[i]
                art_sign[i] = 1
                displaced[i] = -1
            msg = refactor(fk, prob, tab, state, D, S, tol, 0.0)
    if msg == MSG_GROW:
        return False, GROW, msg
    if msg != 0:
        return False, SINGULAR, msg
    fstate[F_T] = 0.0
    istate[I_EK] = VAR_T
    istate[I_EI] = 0
    fstate[F_ES] = 1.0
    fstate[F_EV] = 0.0
    for j in range(enter_count.shape[1]):
        for k in range(enter_count.shape[0]):
            enter_count[k, j] = 0
    code, msg = run_pivots(fk, prob, tab, state, D, S, tol, lim, rec, rect)
    return True, code, msg


@njit(cache=True)
def run_pivots(fk, prob, tab, state, D, S, tol, lim, rec, rect):
    """Up to lim[L_CHUNK] pivots of the path (path_loop) and, when t reaches 1, the
    solution check (verify): (code, message), RUNNING when the pivots are used up."""
    code, msg = path_loop(fk, prob, tab, state, D, S, tol, lim, rec, rect)
    if code == SOLVED:
        code, msg = verify(fk, prob, tab, state, D, S, tol)
    return code, msg
