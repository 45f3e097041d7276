"""Compiled kernels of the small-problem engine (:mod:`compass_sparse.dense_path`).

The basis B (n x n) of the pivotal path has one column per slot: ``M[:, i]`` for a basic
z_i, ``-e_i`` for w_i and for the free slack of a fixed variable, ``+e_i`` for v_i,
``art_sign[i] * e_i`` for an artificial on row i, and the covering vector ``r`` for t.

Factorization (left-looking LU with partial pivoting; repair only when singular)
---------------------------------------------------------------------------------
Columns are eliminated one at a time, unit columns first (they are independent: one slot
per index, each unit column on its own row), then the others in slot order.  Step m takes
column ``c = B[:, j]``, applies the earlier eliminations (``c -= L[:, k] c[p_k]`` for
k < m) and chooses as pivot row ``p_m`` the not yet pivoted row with the largest ``|c|``
(partial pivoting).  Then ``U[k, m] = c[p_k]`` (k < m), ``U[m, m] = c[p_m]`` and
``L[:, m] = c / c[p_m]`` on the rows not yet pivoted.  So ``B Q = P^T L U`` with Q the
elimination order; a solve ``B x = b`` is a forward pass over the steps, a backward pass
with U, and the scatter of step m's value to slot ``q_m``.  Cost n^3/3 per factorization
(less when unit columns are many: their eliminations are skipped).

When a pivot is at most ``rank_tol * max(1, ||B[:, j]||_inf)`` the basis is singular and
is repaired as the thesis does (§3.3.1; the dense reference basis does the same): start
from unit columns on every row, give each non-unit slot the next row not covered by a
unit column (its *home* row), and bring the columns in, in slot order, each pivoting on
its home row; a column whose remainder there is tiny is dependent, and an artificial unit
column on that row takes its slot (a dependent covering vector or slack makes the basis
singular: nothing to repair).  The repaired basis is then factorized with partial pivoting
for the solves.

Updates (product form on top of the LU)
---------------------------------------
Replacing slot s by column a with FTRAN column ``d = B^{-1} a`` gives
``B' = B E`` with E the identity whose column s is d, so ``B'^{-1} = E^{-1} B^{-1}``:
after the LU solve, each stored eta (s_k, d_k) in order maps ``y_s <- y_s / d_s`` and
``y_i <- y_i - d_i y_s``.  The update is refused when ``|d_s| <= pivot_tol * ||d||_inf``
(the same test as the sparse manager's) and the basis is refactorized after
``update_limit`` etas: the eta file stays short, so its error growth is bounded by a fresh
LU at least every ``update_limit`` pivots (what a Forrest–Tomlin update with the same
refactorization frequency also relies on).  Cost per FTRAN: n^2 + (number of etas) n.

The pivot loop (:func:`path_loop`) is the loop of ``PivotalPath._pivot_loop`` with the
same ratio test, complement rule, cycle rule, value recomputation and solution check, so a
path takes the same pivots as the Python loop on the dense reference basis up to rounding.
"""
from __future__ import annotations

import numpy as np

from ._jit import njit
from ._path_kernels import VAR_A, VAR_S, VAR_T, VAR_V, VAR_W, VAR_Z, project_slots, ratio_test

# path_loop return codes (mapped to LinearCode and messages by dense_path.py)
RUNNING, SOLVED, RAY, CYCLE, MINOR_LIMIT, SINGULAR, TOLERANCE, ERROR = range(8)
# messages (second status word)
MSG_NONE, MSG_RAY_UNBOUNDED, MSG_T_ZERO, MSG_CYCLE, MSG_LIMIT, MSG_SING_FACTOR, \
    MSG_SING_T, MSG_SING_SLACK, MSG_SING_ART, MSG_TOL, MSG_NO_DISPLACED, MSG_LEAVE_KIND, \
    MSG_BOUNDED_SLACK = range(13)

# integer state (istate) and float state (fstate) layout
I_EK, I_EI, I_PIV, I_TSLOT, I_NFAC, I_NUPD, I_NETA, I_NBP, I_MSG, I_REFUSED = range(10)
F_ES, F_EV, F_T, F_BEST_T, F_RES = range(5)


@njit(cache=True)
def _column(kind, idx, M, r, art_sign, out):
    """Basis column of a slot variable, written into out."""
    out[:] = 0.0
    if kind == VAR_Z:
        out[:] = M[:, idx]
    elif kind == VAR_T:
        out[:] = r
    elif kind == VAR_W or kind == VAR_S:
        out[idx] = -1.0
    elif kind == VAR_A:
        out[idx] = art_sign[idx]
    else:
        out[idx] = 1.0


@njit(cache=True)
def factor(M, r, sk, si, art_sign, L, U, prow, qslot, rank_tol, rep_slot, rep_row, home):
    """LU of the slot basis (see the module docstring); with ``home`` the repair decision.

    With ``home = True`` the non-unit slots pivot on their home rows (the rows not covered
    by unit columns, in increasing order, given to the non-unit slots in slot order): a
    column is dependent when its remainder on its home row is at most ``rank_tol *
    max(1, ||column||_inf)``, and its artificial takes that row.  This is the thesis'
    repair (start from unit columns, bring the others in while regular), the one the dense
    reference basis makes.  With ``home = False`` every column pivots on the free row of
    largest remainder (partial pivoting): the stable factorization used for the solves.
    Returns the number of dependent slots (slot and row in rep_slot, rep_row; row -1 when
    a covering-vector or slack column is dependent, which nothing can repair)."""
    n = sk.shape[0]
    pivoted = np.zeros(n, dtype=np.bool_)
    c = np.empty(n)
    # elimination order: unit columns first, then M columns and the covering vector
    order = np.empty(n, dtype=np.int64)
    covered = np.zeros(n, dtype=np.bool_)
    m = 0
    for j in range(n):
        if sk[j] != VAR_Z and sk[j] != VAR_T:
            order[m] = j
            covered[si[j]] = True
            m += 1
    first_nonunit = m
    for j in range(n):
        if sk[j] == VAR_Z or sk[j] == VAR_T:
            order[m] = j
            m += 1
    free_rows = np.empty(n - first_nonunit, dtype=np.int64)
    f = 0
    for i in range(n):
        if not covered[i]:
            free_rows[f] = i
            f += 1
    nrep = 0
    for m in range(n):
        j = order[m]
        _column(sk[j], si[j], M, r, art_sign, c)
        cmax = 0.0
        for i in range(n):
            a = abs(c[i])
            cmax = max(cmax, a)
        for k in range(m):
            ck = c[prow[k]]
            U[k, m] = ck
            if ck != 0.0:
                for i in range(n):  # L[:, k] is zero on the rows pivoted up to step k
                    c[i] -= L[i, k] * ck
        best = -1
        bv = -1.0
        if m < first_nonunit:
            best = si[j]
            bv = abs(c[best])
        elif home:
            best = free_rows[m - first_nonunit]
            bv = abs(c[best])
        else:
            for i in range(n):
                if not pivoted[i]:
                    a = abs(c[i])
                    if a > bv:
                        bv = a
                        best = i
        if bv <= rank_tol * max(1.0, cmax):
            if sk[j] == VAR_T or (sk[j] != VAR_Z and sk[j] != VAR_A):
                rep_slot[nrep] = j
                rep_row[nrep] = -1
                return nrep + 1
            rep_slot[nrep] = j
            rep_row[nrep] = best
            nrep += 1
            # continue with the unit column of the chosen row in this step
            for k in range(m):
                U[k, m] = 0.0
            for i in range(n):
                c[i] = 0.0
            c[best] = 1.0
        piv = c[best]
        prow[m] = best
        qslot[m] = j
        U[m, m] = piv
        pivoted[best] = True
        for i in range(n):
            L[i, m] = 0.0 if pivoted[i] else c[i] / piv
    return nrep


@njit(cache=True)
def lu_solve(L, U, prow, qslot, b, out, w):
    """out = B^{-1} b for the factorized basis (no etas).  w is workspace (n)."""
    n = b.shape[0]
    y = out  # reuse out as the forward work vector
    y[:] = b
    for m in range(n):
        ym = y[prow[m]]
        w[m] = ym
        if ym != 0.0:
            for i in range(n):
                y[i] -= L[i, m] * ym
    for m in range(n - 1, -1, -1):
        v = w[m] / U[m, m]
        w[m] = v
        if v != 0.0:
            for k in range(m):
                w[k] -= U[k, m] * v
    for m in range(n):
        out[qslot[m]] = w[m]


@njit(cache=True)
def ftran(L, U, prow, qslot, eta_s, eta_d, neta, b, out, w):
    """out = B^{-1} b with the eta file applied after the LU solve."""
    lu_solve(L, U, prow, qslot, b, out, w)
    n = b.shape[0]
    for k in range(neta):
        s = eta_s[k]
        ys = out[s] / eta_d[k, s]
        if ys != 0.0:
            for i in range(n):
                out[i] -= eta_d[k, i] * ys
        out[s] = ys


@njit(cache=True)
def current_point(sk, si, xb, zval, lb, ub, z, w, v):
    """(z, w, v) of the current basic solution (PivotalPath._current_point)."""
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
def _recompute(M, q, r, sk, si, zval, t, t_slot, L, U, prow, qslot, eta_s, eta_d, neta,
               xb, rhs, w, lb, ub):
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
    ftran(L, U, prow, qslot, eta_s, eta_d, neta, rhs, xb, w)
    for k in range(n):
        if sk[k] == VAR_T:
            t = xb[k]
            break
    project_slots(sk, si, xb, lb, ub)
    return t


@njit(cache=True)
def refactor(M, q, r, sk, si, xb, zval, art_sign, displaced, istate, fstate, L, U, prow,
             qslot, rank_tol, lb, ub, work):
    """PivotalPath._factor: factorize, repair dependent columns with artificials,
    recompute the basic values.  Returns 0 or a SINGULAR message code."""
    n = sk.shape[0]
    rep_slot = np.empty(n, dtype=np.int64)
    rep_row = np.empty(n, dtype=np.int64)
    istate[I_NFAC] += 1
    # A regular basis is factorized as it is (partial pivoting); only a singular one is
    # repaired, by the home-row rule of the thesis (see factor()).
    nrep = factor(M, r, sk, si, art_sign, L, U, prow, qslot, rank_tol, rep_slot, rep_row,
                  False)
    if nrep > 0:
        nrep = factor(M, r, sk, si, art_sign, L, U, prow, qslot, rank_tol, rep_slot,
                      rep_row, True)
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
        nrep = factor(M, r, sk, si, art_sign, L, U, prow, qslot, rank_tol, rep_slot,
                      rep_row, False)
        if nrep > 0:
            return MSG_SING_FACTOR
    istate[I_NETA] = 0
    rhs = work[0]
    w = work[1]
    fstate[F_T] = _recompute(M, q, r, sk, si, zval, fstate[F_T], istate[I_TSLOT], L, U,
                             prow, qslot, np.empty(0, dtype=np.int64), np.empty((0, n)), 0,
                             xb, rhs, w, lb, ub)
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
def verify(M, q, r, sk, si, xb, zval, art_sign, displaced, istate, fstate, L, U, prow,
           qslot, rank_tol, lb, ub, work):
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
                           L, U, prow, qslot, rank_tol, lb, ub, work)
            if msg != 0:
                return SINGULAR, msg
    return TOLERANCE, MSG_TOL


@njit(cache=True)
def path_loop(M, q, r, lb, ub, sk, si, xb, zval, art_sign, displaced, enter_count,
              istate, fstate, L, U, prow, qslot, eta_s, eta_d, best_x, bp_t, bp_x, work,
              piv_tol_base, ratio_tol, rank_tol, update_tol, minor_limit, cycle_limit,
              max_pivots):
    """PivotalPath._pivot_loop for at most max_pivots pivots (RUNNING when they are used
    up: the caller checks its clock and calls again).  Returns (code, message)."""
    n = sk.shape[0]
    d = work[5]
    col = work[6]
    update_limit = eta_s.shape[0]
    start = istate[I_PIV]
    while True:
        pivots = istate[I_PIV]
        if pivots >= minor_limit:
            return MINOR_LIMIT, MSG_LIMIT
        if pivots - start >= max_pivots:
            return RUNNING, MSG_NONE
        ek = istate[I_EK]
        ei = istate[I_EI]
        es = fstate[F_ES]
        ev = fstate[F_EV]
        enter_count[ek, ei] += 1
        if enter_count[ek, ei] > cycle_limit:
            return CYCLE, MSG_CYCLE
        _column(ek, ei, M, r, art_sign, col)
        ftran(L, U, prow, qslot, eta_s, eta_d, istate[I_NETA], col, d, work[1])
        t_slot = istate[I_TSLOT]
        t = fstate[F_T]
        if ek == VAR_Z and es == 0.0:
            # direction free (after an artificial left): increase t
            if t_slot >= 0 and d[t_slot] != 0.0:
                es = -np.sign(d[t_slot])
            else:
                es = 1.0
            fstate[F_ES] = es
        dmax = 0.0
        for k in range(n):
            dmax = max(dmax, abs(d[k]))
        rate = work[7]
        for k in range(n):
            rate[k] = -es * d[k]
        theta_self = _room_self(ek, ei, es, ev, t, lb, ub)
        leave, theta, leave_up = ratio_test(sk, si, xb, rate, lb, ub,
                                            piv_tol_base * max(1.0, dmax), ratio_tol)
        if leave < 0 and not np.isfinite(theta_self):
            return RAY, MSG_RAY_UNBOUNDED
        if leave < 0 or theta_self <= theta:
            theta = theta_self
            for k in range(n):
                xb[k] += theta * rate[k]
            project_slots(sk, si, xb, lb, ub)
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
        refused = abs(d[leave]) <= update_tol * max(1.0, dmax)
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
        neta = istate[I_NETA]
        if refused or neta >= update_limit:
            if refused:
                istate[I_REFUSED] += 1
            msg = refactor(M, q, r, sk, si, xb, zval, art_sign, displaced, istate, fstate,
                           L, U, prow, qslot, rank_tol, lb, ub, work)
            if msg != 0:
                return SINGULAR, msg
        else:
            eta_s[neta] = leave
            eta_d[neta, :] = d
            istate[I_NETA] = neta + 1
            istate[I_NUPD] += 1
        project_slots(sk, si, xb, lb, ub)
        if istate[I_TSLOT] >= 0:
            fstate[F_T] = xb[istate[I_TSLOT]]
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
