"""Compiled kernels of the small-problem engine (:mod:`compass_sparse.path.dense_engine`): the
pivot loop, the recomputation of the basic values, the solution check and the path's start, on
the dense factors of :mod:`compass_sparse.path._dense_lu`.

The pivot loop (:func:`path_loop`) is the loop of ``PivotalPath._pivot_loop`` with the
same ratio test, complement rule, cycle rule, value recomputation and solution check, so a
path takes the same pivots as the Python loop on the dense reference basis up to rounding.
"""
from __future__ import annotations

import numpy as np

from .._jit import njit
from ._dense_lu import (P_ROW, P_SLOT, UPD_GROWTH, UPD_OK, UPD_REFUSED, UPD_UNSTABLE,
                        W_FACTOR, W_REP_ROW, W_REP_SLOT, basis_column, factor, ftran,
                        lu_factor, replace_column)
from ._kernels import VAR_A, VAR_S, VAR_T, VAR_V, VAR_W, VAR_Z, project_slots, ratio_test
from ._slot_kernels import slot_table

# path_loop return codes (mapped to LinearCode and messages by dense_engine.py)
RUNNING, SOLVED, RAY, CYCLE, MINOR_LIMIT, SINGULAR, TOLERANCE, ERROR = range(8)
# messages (second status word)
MSG_NONE, MSG_RAY_UNBOUNDED, MSG_T_ZERO, MSG_CYCLE, MSG_LIMIT, MSG_SING_FACTOR, \
    MSG_SING_T, MSG_SING_SLACK, MSG_SING_ART, MSG_TOL, MSG_NO_DISPLACED, MSG_LEAVE_KIND, \
    MSG_BOUNDED_SLACK, MSG_T_STALL = range(14)

# integer state (istate) and float state (fstate) layout
I_EK, I_EI, I_PIV, I_TSLOT, I_NFAC, I_NUPD, I_NETA, I_NBP, I_MSG, I_REFUSED, \
    I_UNSTABLE, I_GROWTH, I_BELOW = range(13)
N_ISTATE = 13
F_ES, F_EV, F_T, F_BEST_T, F_RES, F_TLOW = range(6)
N_FSTATE = 6
# the per-pivot records of path_loop (a minor log): columns, and the two kinds of pivot
REC_COLUMNS = 7
REC_FLIP, REC_EXCHANGE = 0, 1


@njit(cache=True)
def current_point(sk, si, xb, zval, lb, ub, z, w, v):
    """(z, w, v) of the current basic solution (PivotalPath.current_point)."""
    n = sk.shape[0]
    z[:] = zval
    w[:] = 0.0
    v[:] = 0.0
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
    for i in range(n):
        z[i] = min(max(z[i], lb[i]), ub[i])


@njit(cache=True)
def _recompute(M, q, r, sk, si, zval, t, t_slot, L, U, R, perm, nupd, xb, rhs, w, fwork,
               lb, ub, t_lower):
    """x_B = B^{-1}(r (1 - t_nb) - q - M z_N) (PivotalPath._recompute_values); returns t."""
    n = sk.shape[0]
    t_nb = 0.0 if t_slot >= 0 else t
    zn = w  # workspace: nonbasic z values
    zn[:] = zval
    for k in range(n):
        if sk[k] == VAR_Z:
            zn[si[k]] = 0.0
    for i in range(n):
        rhs[i] = r[i] * (1.0 - t_nb) - q[i]
    for j in range(n):
        zj = zn[j]
        if zj != 0.0:
            for i in range(n):
                rhs[i] -= M[i, j] * zj
    ftran(L, U, R, perm, nupd, rhs, xb, fwork[0], fwork[1], False)
    for k in range(n):
        if sk[k] == VAR_T:
            t = xb[k]
            break
    project_slots(sk, si, xb, lb, ub, t_lower)
    return t


@njit(cache=True)
def refactor(M, q, r, sk, si, xb, zval, art_sign, displaced, istate, fstate, L, U, R,
             perm, rank_tol, lb, ub, t_lower, work, fwork):
    """PivotalPath._factor: factorize, repair dependent columns with artificials,
    recompute the basic values.  Returns 0 or a SINGULAR message code."""
    n = sk.shape[0]
    rep_slot = perm[W_REP_SLOT]
    rep_row = perm[W_REP_ROW]
    istate[I_NFAC] += 1
    # A regular basis is factorized as it is (partial pivoting); only a singular one is
    # repaired, by the home-row rule of the thesis (see factor()).
    nrep = lu_factor(M, r, sk, si, art_sign, L, U, perm, fwork, rank_tol)
    if nrep > 0:
        nrep = factor(M, r, sk, si, art_sign, L, U, perm[P_ROW], perm[P_SLOT], rank_tol,
                      rep_slot, rep_row, True, perm[W_FACTOR:W_FACTOR + 4], fwork[2, :n])
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
        # The stable LU (partial pivoting) of the repaired basis for the solves.
        nrep = lu_factor(M, r, sk, si, art_sign, L, U, perm, fwork, rank_tol)
        if nrep > 0:
            return MSG_SING_FACTOR
    istate[I_NETA] = 0
    fstate[F_T] = _recompute(M, q, r, sk, si, zval, fstate[F_T], istate[I_TSLOT], L, U, R,
                             perm, 0, xb, work[0], work[1], fwork, lb, ub, t_lower)
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
def _record(sk, si, xb, zval, lb, ub, t, fstate, istate, best_x, bp_t, bp_x, work):
    if t > fstate[F_BEST_T] + 1e-15:
        n = sk.shape[0]
        z = work[2]
        w = work[3]
        v = work[4]
        current_point(sk, si, xb, zval, lb, ub, z, w, v)
        for i in range(n):
            best_x[i] = z[i] - w[i] + v[i]
        fstate[F_BEST_T] = t
        nb = istate[I_NBP]
        if nb < bp_t.shape[0]:
            bp_t[nb] = t
            bp_x[nb, :] = best_x
            istate[I_NBP] = nb + 1


@njit(cache=True)
def verify(M, q, r, sk, si, xb, zval, art_sign, displaced, istate, fstate, L, U, R, perm,
           rank_tol, lb, ub, t_lower, work, fwork):
    """PivotalPath._verify_solution: (code, message)."""
    n = sk.shape[0]
    qmax = 0.0
    rmax = 0.0
    for i in range(n):
        qmax = max(qmax, abs(q[i]))
        rmax = max(rmax, abs(r[i]))
    tol = 1e-9 * (1.0 + qmax + rmax)
    for k in range(n):
        if sk[k] == VAR_A and abs(xb[k]) > tol:
            return SINGULAR, MSG_SING_ART
    z = work[2]
    w = work[3]
    v = work[4]
    for attempt in range(2):
        current_point(sk, si, xb, zval, lb, ub, z, w, v)
        res = 0.0
        mz_max = 0.0
        for i in range(n):
            s = 0.0
            for j in range(n):
                s += M[i, j] * z[j]
            mz_max = max(mz_max, abs(s))
            res = max(res, abs(s + q[i] - w[i] + v[i]))
        fstate[F_RES] = res
        if res <= 1e-9 * (1.0 + mz_max + qmax):
            return SOLVED, MSG_NONE
        if attempt == 0:
            msg = refactor(M, q, r, sk, si, xb, zval, art_sign, displaced, istate, fstate,
                           L, U, R, perm, rank_tol, lb, ub, t_lower, work, fwork)
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
def path_loop(M, q, r, lb, ub, sk, si, xb, zval, art_sign, displaced, enter_count,
              istate, fstate, L, U, R, perm, best_x, bp_t, bp_x, work, fwork,
              piv_tol_base, ratio_tol, rank_tol, update_tol, stab_tol, growth_limit,
              minor_limit, cycle_limit, max_pivots, free_below, below_limit,
              t_progress, rec, rect):
    """PivotalPath._pivot_loop for at most max_pivots pivots (RUNNING when they are used
    up: the caller checks its clock and calls again).  t's lower bound is fstate[F_TLOW]:
    0, lifted (free_below: a path from the current point) when t blocks at 0 before the
    path has been above t_progress, for at most below_limit pivots (istate[I_BELOW]: the
    pivot that lifted it); see compass_sparse.path.  Returns (code, message).

    ``rec`` (max_pivots x REC_COLUMNS, or no rows: nothing recorded) and ``rect`` receive
    one record per pivot of this call, the Python loop's minor-log line as numbers: row
    k (the call's pivot k) holds the pivot count, REC_FLIP or REC_EXCHANGE, the entering
    kind and index, the leaving kind and index and the update's outcome (UPD_*), rect[k]
    t after the pivot.  The records change nothing the path computes.

    A compiled kernel whose length is the algorithm (one pivot's FTRAN, ratio test, update
    and complement rule, in the Python loop's order): exempt from the package's limit of
    100 lines per function."""
    n = sk.shape[0]
    d = work[5]
    col = work[6]
    start = istate[I_PIV]
    while True:
        pivots = istate[I_PIV]
        if pivots >= minor_limit:
            return MINOR_LIMIT, MSG_LIMIT
        if istate[I_BELOW] >= 0:
            if fstate[F_BEST_T] > t_progress:
                fstate[F_TLOW] = 0.0  # above 0 now: 0 is t's bound again
            elif pivots - istate[I_BELOW] >= below_limit:
                return RAY, MSG_T_STALL
        t_lower = fstate[F_TLOW]
        if pivots - start >= max_pivots:
            return RUNNING, MSG_NONE
        ek = istate[I_EK]
        ei = istate[I_EI]
        es = fstate[F_ES]
        ev = fstate[F_EV]
        enter_count[ek, ei] += 1
        if enter_count[ek, ei] > cycle_limit:
            return CYCLE, MSG_CYCLE
        basis_column(ek, ei, M, r, art_sign, col)
        ftran(L, U, R, perm, istate[I_NETA], col, d, fwork[0], fwork[1], True)
        t_slot = istate[I_TSLOT]
        t = fstate[F_T]
        dmax = 0.0
        for k in range(n):
            dmax = max(dmax, abs(d[k]))
        piv_tol = piv_tol_base * max(1.0, dmax)
        if ek == VAR_Z and es == 0.0:
            # direction free (after an artificial left): increase t; when t does not
            # move with it (a rate within rounding), increase the variable
            if t_slot >= 0 and abs(d[t_slot]) > piv_tol:
                es = -np.sign(d[t_slot])
            else:
                es = 1.0
            fstate[F_ES] = es
        rate = work[7]
        for k in range(n):
            rate[k] = -es * d[k]
        theta_self = _room_self(ek, ei, es, ev, t, lb, ub)
        leave, theta, leave_up = ratio_test(sk, si, xb, rate, lb, ub, piv_tol, ratio_tol,
                                            t_lower)
        if (leave >= 0 and theta < theta_self and sk[leave] == VAR_T and leave_up == 0
                and free_below and istate[I_BELOW] < 0 and fstate[F_BEST_T] <= t_progress):
            # t blocks at 0 before the path has been above 0: lift its bound
            t_lower = -np.inf
            fstate[F_TLOW] = t_lower
            istate[I_BELOW] = pivots
            leave, theta, leave_up = ratio_test(sk, si, xb, rate, lb, ub, piv_tol,
                                                ratio_tol, t_lower)
        if leave < 0 and not np.isfinite(theta_self):
            return RAY, MSG_RAY_UNBOUNDED
        if leave < 0 or theta_self <= theta:
            theta = theta_self
            for k in range(n):
                xb[k] += theta * rate[k]
            project_slots(sk, si, xb, lb, ub, t_lower)
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
                _record(sk, si, xb, zval, lb, ub, fstate[F_T], fstate, istate, best_x,
                        bp_t, bp_x, work)
                _log_pivot(rec, rect, pivots - start, pivots + 1, REC_FLIP, ek, ei, -1, -1,
                           -1, fstate[F_T])
                continue
            return ERROR, MSG_BOUNDED_SLACK
        # a basic variable blocks: update values and exchange columns
        for k in range(n):
            xb[k] += theta * rate[k]
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
        if ek == VAR_T:
            istate[I_TSLOT] = leave
        if ek == VAR_Z:
            zval[ei] = new_val
        upd = replace_column(U, R, perm, istate[I_NETA], leave, d, fwork[1], fwork[2],
                             update_tol, stab_tol, growth_limit)
        if upd == UPD_OK:
            istate[I_NETA] += 1
            istate[I_NUPD] += 1
        else:
            if upd == UPD_REFUSED:
                istate[I_REFUSED] += 1
            elif upd == UPD_UNSTABLE:
                istate[I_UNSTABLE] += 1
            elif upd == UPD_GROWTH:
                istate[I_GROWTH] += 1
            msg = refactor(M, q, r, sk, si, xb, zval, art_sign, displaced, istate, fstate,
                           L, U, R, perm, rank_tol, lb, ub, t_lower, work, fwork)
            if msg != 0:
                _log_pivot(rec, rect, pivots - start, pivots + 1, REC_EXCHANGE, ek, ei, lk,
                           li, upd, fstate[F_T])
                return SINGULAR, msg
        project_slots(sk, si, xb, lb, ub, t_lower)
        if istate[I_TSLOT] >= 0:
            fstate[F_T] = xb[istate[I_TSLOT]]
        _log_pivot(rec, rect, pivots - start, pivots + 1, REC_EXCHANGE, ek, ei, lk, li, upd,
                   fstate[F_T])
        if lk == VAR_T:
            if leave_up:
                return SOLVED, MSG_NONE
            return RAY, MSG_T_ZERO
        _record(sk, si, xb, zval, lb, ub, fstate[F_T], fstate, istate, best_x, bp_t, bp_x,
                work)
        # complement rule
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
                return ERROR, MSG_NO_DISPLACED
            istate[I_EK] = VAR_Z
            istate[I_EI] = j
            fstate[F_ES] = 0.0
            fstate[F_EV] = zval[j]
        else:
            return ERROR, MSG_LEAVE_KIND


@njit(cache=True)
def start_path(M, q, r, lb, ub, sk, si, xb, zval, art_sign, displaced, enter_count,
               istate, fstate, L, U, R, perm, best_x, bp_t, bp_x, work, fwork,
               piv_tol_base, ratio_tol, rank_tol, update_tol, stab_tol, growth_limit,
               minor_limit, cycle_limit, max_pivots, free_below, below_limit, t_progress,
               slack, use_slack, z, w, v, rec, rect):
    """A path on the slot table (sk, si, xb) in one call: fresh state, the factorization
    (again on the slot table of the basis ``slack`` when ``use_slack`` and the first one
    is singular or holds artificials, as DensePathEngine.run_path did in Python), the
    first ``max_pivots`` pivots, and the solution check when t reaches 1 (:func:`run_pivots`).
    Returns (factored, code, message): factored False with the SINGULAR message when no basis
    could be factorized; code RUNNING when the pivots are used up (the caller continues
    with path_loop)."""
    n = sk.shape[0]
    for k in range(istate.shape[0]):
        istate[k] = 0
    for k in range(fstate.shape[0]):
        fstate[k] = 0.0
    istate[I_TSLOT] = -1
    istate[I_BELOW] = -1
    for i in range(n):
        displaced[i] = -1
    msg = refactor(M, q, r, sk, si, xb, zval, art_sign, displaced, istate, fstate, L, U, R,
                   perm, rank_tol, lb, ub, 0.0, work, fwork)
    if use_slack:
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
            msg = refactor(M, q, r, sk, si, xb, zval, art_sign, displaced, istate, fstate,
                           L, U, R, perm, rank_tol, lb, ub, 0.0, work, fwork)
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
    code, msg = run_pivots(M, q, r, lb, ub, sk, si, xb, zval, art_sign, displaced,
                           enter_count, istate, fstate, L, U, R, perm, best_x, bp_t, bp_x,
                           work, fwork, piv_tol_base, ratio_tol, rank_tol, update_tol,
                           stab_tol, growth_limit, minor_limit, cycle_limit, max_pivots,
                           free_below, below_limit, t_progress, rec, rect)
    return True, code, msg


@njit(cache=True)
def run_pivots(M, q, r, lb, ub, sk, si, xb, zval, art_sign, displaced, enter_count,
               istate, fstate, L, U, R, perm, best_x, bp_t, bp_x, work, fwork, piv_tol_base,
               ratio_tol, rank_tol, update_tol, stab_tol, growth_limit, minor_limit,
               cycle_limit, max_pivots, free_below, below_limit, t_progress, rec, rect):
    """Up to ``max_pivots`` pivots of the path (path_loop) and, when t reaches 1, the
    solution check (verify): (code, message), RUNNING when the pivots are used up."""
    code, msg = path_loop(M, q, r, lb, ub, sk, si, xb, zval, art_sign, displaced,
                          enter_count, istate, fstate, L, U, R, perm, best_x, bp_t, bp_x,
                          work, fwork, piv_tol_base, ratio_tol, rank_tol, update_tol,
                          stab_tol, growth_limit, minor_limit, cycle_limit, max_pivots,
                          free_below, below_limit, t_progress, rec, rect)
    if code == SOLVED:
        code, msg = verify(M, q, r, sk, si, xb, zval, art_sign, displaced, istate, fstate, L,
                           U, R, perm, rank_tol, lb, ub, fstate[F_TLOW], work, fwork)
    return code, msg


