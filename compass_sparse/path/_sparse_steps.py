"""The steps of the sparse engine's LU (:mod:`compass_sparse.path._sparse_lu`): one basis
column, its sparse triangular solve with the columns of L made so far, and the dense tail.

One column's step (Gilbert and Peierls 1988)
--------------------------------------------
Step k of the left-looking LU solves ``L_k x = b`` for the next basis column b with the
k columns of L made so far: the rows reached from b's nonzeros in the graph of L
(depth-first search) are visited in topological order, so the step costs its flops, not n
(:func:`reach_solve`).

The dense tail
--------------
The last columns of a basis' elimination often meet a Schur complement that has become
dense: on the late bases of the traffic model at n = 2452 the last 150 of the 1335 basic
z columns are 90% dense and take 94% of the factorization's 1.5e6 multiply-adds, which the
left-looking steps do through the graph of L (a depth-first search and an indexed update
per entry: ~6 ns a multiply-add measured).  Once the columns just eliminated leave
L-columns that cover ``DENSE_TAIL_SHARE`` of the rows left, ``DENSE_TAIL_RUN`` times in a
row, with at least ``DENSE_TAIL_MIN`` columns left, the rest is eliminated as one dense
block: each remaining column is solved with L_k as above (its entries on pivoted rows are
its part of U), the rest of it -- its column of the Schur complement -- goes to a dense
column-major block, and the block is factorized by right-looking LU with the same pivot
rule (partial pivoting with the matched row kept within the threshold, the rank test
against the column's own norm).  The factors are stored as the sparse steps store them,
but the block's parts whole, zeros too, over consecutive positions, so that FTRAN and BTRAN
run over the tail's columns as dense columns (:mod:`compass_sparse.path._sparse_lu`); the
Forrest-Tomlin updates are unchanged.  The block is factorized in the row-eta storage,
which a factorization empties and which is at least as large as L's; a block that does
not fit returns GROW (the engine grows the storage and runs the path again), as L and U
do.  (The storage was that of the updates alone, about 50 n entries: on the CGE models'
bases at n = 2024, whose Schur complement is dense over ~900 columns, the tail stopped at
318 columns and the sparse steps did the rest: 620 ms a factorization of an all-z basis,
against 47-58 ms with the whole tail, in panels.)
"""
from __future__ import annotations

import numpy as np

from .._jit import LazyExternal, njit
from ..linalg.blas import blas_external
from ._kernels import VAR_T, VAR_Z, unit_sign

DENSE_TAIL_SHARE = 0.4
"""A column's L part covering at least this share of the rows left counts as dense."""

DENSE_TAIL_RUN = 4
"""... this many such columns in a row switch the elimination to the dense tail (one
dense column alone, e.g. a column of many entries early in the order, does not)."""

DENSE_TAIL_MIN = 16
"""The fewest columns left for which the dense tail is worth its set-up."""

DENSE_WORK_DIVISOR = 8
"""A multiply-add of the dense block in the factorization's work units (an entry of L
searched or eliminated by a sparse step, ~2.7 ns; see compass_sparse.path._sparse_lu.
FACTOR_WEIGHT): one unit per DENSE_WORK_DIVISOR of them (measured 0.29 ns each at
200 x 200)."""


@njit(cache=True)
def basis_column(kind, idx, Mp, Mi, Mx, rI, rX, art_sign, rows, vals):
    """The entries (rows, vals) of a slot variable's basis column; returns their count."""
    if kind == VAR_Z:
        c = 0
        for e in range(Mp[idx], Mp[idx + 1]):
            rows[c] = Mi[e]
            vals[c] = Mx[e]
            c += 1
        return c
    if kind == VAR_T:
        for e in range(rI.shape[0]):
            rows[e] = rI[e]
            vals[e] = rX[e]
        return rI.shape[0]
    rows[0] = idx
    vals[0] = unit_sign(kind, idx, art_sign)
    return 1


@njit(cache=True)
def _dfs(j, Lp, Li, pinv, top, xi, pstack, mark):
    """Depth-first search of the graph of L from row j (CSparse's cs_dfs without
    recursion): pushes the rows reached, in reverse topological order, on xi[top - ...];
    returns the new top."""
    head = 0
    xi[0] = j
    while head >= 0:
        j = xi[head]
        J = pinv[j]
        if mark[j] == 0:
            mark[j] = 1
            pstack[head] = 0 if J < 0 else Lp[J]
        done = True
        p2 = 0 if J < 0 else Lp[J + 1]
        p = pstack[head]
        while p < p2:
            i = Li[p]
            if mark[i] == 0:
                pstack[head] = p + 1
                head += 1
                xi[head] = i
                done = False
                break
            p += 1
        if done:
            head -= 1
            top -= 1
            xi[top] = j
    return top


@njit(cache=True)
def reach_solve(nb, crow, cval, Lp, Li, Lx, pinv, xi, pstack, mark, x):
    """x = L_k^{-1} b for the column b with entries (crow, cval)[:nb], L_k the columns of
    L made so far (rows by row index, pinv[row] their position or -1).  The rows reached
    are xi[top:] in topological order, marked; x is zero elsewhere.  Returns (top,
    max |b|, work units: the column, its reach counted three times (search, pivot,
    store) and twice each entry of L searched and eliminated; see
    :func:`compass_sparse.path._sparse_lu.refactor_pays`)."""
    n = xi.shape[0]
    cmax = 0.0
    top = n
    for e in range(nb):
        cmax = max(cmax, abs(cval[e]))
        if mark[crow[e]] == 0:
            top = _dfs(crow[e], Lp, Li, pinv, top, xi, pstack, mark)
    for e in range(nb):
        x[crow[e]] = cval[e]
    work = nb + 3 * (n - top)
    for q in range(top, n):
        j = xi[q]
        J = pinv[j]
        if J < 0:
            continue
        work += 2 * (Lp[J + 1] - Lp[J])
        xj = x[j]
        if xj != 0.0:
            for p in range(Lp[J], Lp[J + 1]):
                x[Li[p]] -= Lx[p] * xj
    return top, cmax, work


@njit(cache=True)
def tail_fits(n, rows, cols, capacity):
    """Whether a dense tail of rows x cols and its index lists fit in ``capacity``
    entries of the row-eta storage."""
    return rows * cols <= capacity and n + rows + 4 * cols <= capacity


@njit(cache=True)
def _solve_by_position(nb, crow, cval, Lp, Li, Lx, prow, k0, x):
    """x = L_k^{-1} b for the column b with entries (crow, cval)[:nb] (x by row, zero
    before), along the positions 0 .. k0 - 1 in order (a topological order of L_k;
    prow[q] the row pivoted at position q): no search, for a column that reaches most of
    L_k.  Returns (max |b|, work units as :func:`reach_solve` counts them, a pass over
    the positions for its search)."""
    cmax = 0.0
    for e in range(nb):
        cmax = max(cmax, abs(cval[e]))
        x[crow[e]] = cval[e]
    work = nb + k0
    for q in range(k0):
        xq = x[prow[q]]
        if xq != 0.0:
            work += 2 * (Lp[q + 1] - Lp[q])
            for p in range(Lp[q], Lp[q + 1]):
                x[Li[p]] -= Lx[p] * xq
    return cmax, work


@njit(cache=True)
def _stage(t0, nc, nr, order, sk, si, Mp, Mi, Mx, rI, rX, art_sign, S, pref, ufree, ix):
    """Solve each tail column with L_k: its entries on pivoted rows (positions) are
    staged in U's storage from ``ufree`` with room for its dense part after them, the
    rest goes to its column of the dense block.  Returns (the new ufree, -1 when U's
    storage is full; the solves' work units).

    A tail of ``BLOCKED_MIN`` columns or more solves its columns along the positions
    (:func:`_solve_by_position`): each reaches most of L_k, and the depth-first search
    of :func:`reach_solve` then costs as much as the elimination (on the CGE endowment
    shock's bases at n = 2024, tails of 826-961 columns: 7.1 -> 3.6 cycles a work unit,
    the staging 283-375 -> 182-194 ms over the solve's 40 factorizations).  The sums
    are taken in another order, as the panels' are; smaller tails keep their bits."""
    (h, Lp, Li, Lx, Us, Ue, Ui, Ux, Ud, Urp, Urj, Urx, dead, Rs, Ri, Rx, Rpos, pinv,
     slot_at, pos_of, iw, fw, ow, seg) = S
    n = sk.shape[0]
    xi, pstack, mark, crow = iw[n:2 * n], iw[2 * n:3 * n], iw[3 * n:4 * n], iw[4 * n:5 * n]
    x, cval, tcmax = fw[0], fw[1], fw[2]
    rowpos, tstart, tcount, tpref, drow = ix
    A = Rx
    capU = Ui.shape[0]
    work = 0
    k0 = n - nr
    by_position = nc >= BLOCKED_MIN
    if by_position:
        prow = xi  # (the search's list is not needed): the row of each position
        for i in range(n):
            if pinv[i] >= 0:
                prow[pinv[i]] = i
    full = False
    for j in range(nc):
        s = order[t0 + j]
        kind = sk[s]
        nb = basis_column(kind, si[s], Mp, Mi, Mx, rI, rX, art_sign, crow, cval)
        pr = pref[s] if kind == VAR_Z else -1
        tpref[j] = pr if pr >= 0 and pinv[pr] < 0 else -1
        col = j * nr
        tstart[j] = ufree
        if by_position:
            tcmax[j], w = _solve_by_position(nb, crow, cval, Lp, Li, Lx, prow, k0, x)
            for q in range(k0):  # U's part, by position
                i = prow[q]
                xv = x[i]
                if xv != 0.0:
                    if ufree < capU:
                        Ui[ufree] = q
                        Ux[ufree] = xv
                        ufree += 1
                    else:
                        full = True
                    x[i] = 0.0
            for r in range(nr):  # the Schur complement's column
                i = drow[r]
                A[col + r] = x[i]
                x[i] = 0.0
        else:
            top, tcmax[j], w = reach_solve(nb, crow, cval, Lp, Li, Lx, pinv, xi, pstack,
                                           mark, x)
            for r in range(nr):
                A[col + r] = 0.0
            for q in range(top, n):
                i = xi[q]
                xv = x[i]
                if xv != 0.0:
                    if pinv[i] < 0:
                        A[col + rowpos[i]] = xv
                    elif ufree < capU:
                        Ui[ufree] = pinv[i]
                        Ux[ufree] = xv
                        ufree += 1
                    else:
                        full = True
                x[i] = 0.0
                mark[i] = 0
        work += w + nr
        tcount[j] = ufree - tstart[j]
        ufree += j  # room for the entries of its column above the dense diagonal
        if full or ufree > capU:
            return -1, work
    return ufree, work


@njit(cache=True, inline="always")
def axpy_run(w, i0, vals, e0, m, x):
    """w[i0 + r] -= vals[e0 + r] * x for r < m: a run of a factor's column over the dense
    tail's rows, stored with its zeros over consecutive positions, so that the solves'
    loop (:mod:`compass_sparse.path._sparse_lu`) runs over contiguous memory and
    vectorizes instead of going through the row indices; each w entry gets the same
    operation as through the indices (an explicit zero subtracts 0)."""
    dst = w[i0:i0 + m]
    src = vals[e0:e0 + m]
    for r in range(m):
        dst[r] -= src[r] * x


@njit(cache=True, inline="always")
def dot_run(s, w, i0, vals, e0, m):
    """s - sum vals[e0 + r] * w[i0 + r], term by term in order (the same operations as
    through the row indices)."""
    src = vals[e0:e0 + m]
    ws = w[i0:i0 + m]
    for r in range(m):
        s -= src[r] * ws[r]
    return s


BLOCKED_MIN = 256
"""A dense block of at least this many columns is factorized in panels of ``PANEL``
columns, each panel's update of the columns after it by BLAS (a triangular solve and a
matrix product); a smaller one column by column (the traffic model's tails, 130-220
columns, keep their bits).  Measured on random square blocks (the block LU alone,
minimum of 3, compiled): 256 columns 1.5 -> 1.2 ms, 400 5.3 -> 2.7 ms, 926 90 -> 20 ms
(0.34 -> 0.08 ns a multiply-add; LAPACK's getrf 17 ms); panels of 64 columns measured the
same as 32.  See :func:`_block_lu`."""

PANEL = 32

BLAS_WORK_DIVISOR = 4
"""A multiply-add of a panel's BLAS update in the factorization's work units: one unit per
DENSE_WORK_DIVISOR * BLAS_WORK_DIVISOR of them (0.08 against 0.29-0.34 ns measured)."""

_DGEMM = LazyExternal(lambda: blas_external("dgemm", 13), "dgemm")
_DTRSM = LazyExternal(lambda: blas_external("dtrsm", 11), "dtrsm")


@njit(cache=True)
def _panel_update(nr, nc, A, j0, j1, rs, r0, tpiv):
    """The columns j1 .. nc-1 of the block updated by the pivots of the panel j0 .. j1-1
    (block rows rs .. r0-1): ``A12 = L11^{-1} A12`` and ``A22 -= L21 A12``, by BLAS when
    every panel column has a pivot (L11 and L21 are then the panel's columns), else pivot
    by pivot as the column-by-column elimination does.  Returns the multiply-adds."""
    p = r0 - rs
    m = nr - r0
    w = nc - j1
    if p == j1 - j0:
        ch = np.empty(4, np.uint8)
        ch[0] = 76  # L: the triangle on the left, lower
        ch[1] = 78  # N: not transposed
        ch[2] = 85  # U: unit diagonal
        iv = np.empty(4, np.int32)
        iv[0] = p
        iv[1] = w
        iv[2] = m
        iv[3] = nr
        dv = np.empty(2)
        dv[0] = 1.0
        dv[1] = -1.0
        a11 = j0 * nr + rs
        a12 = j1 * nr + rs
        _DTRSM(ch[0:].ctypes, ch[0:].ctypes, ch[1:].ctypes, ch[2:].ctypes, iv[0:].ctypes,
               iv[1:].ctypes, dv[0:].ctypes, A[a11:].ctypes, iv[3:].ctypes,
               A[a12:].ctypes, iv[3:].ctypes)
        if m > 0:
            _DGEMM(ch[1:].ctypes, ch[1:].ctypes, iv[2:].ctypes, iv[1:].ctypes,
                   iv[0:].ctypes, dv[1:].ctypes, A[a11 + p:].ctypes, iv[3:].ctypes,
                   A[a12:].ctypes, iv[3:].ctypes, dv[0:].ctypes, A[a12 + p:].ctypes,
                   iv[3:].ctypes)
        return p * m * w + p * p * w // 2
    flops = 0
    for j in range(j0, j1):
        if tpiv[j] >= 0:
            flops += _eliminate(A, nr, j, tpiv[j], j1, nc)
    return flops


@njit(cache=True, inline="always")
def _eliminate(A, nr, j, r0, c0, c1):
    """The columns c0 .. c1-1 of the block updated by column j's pivot on block row r0
    (its multipliers below r0); returns the multiply-adds.  (Views with a loop index from
    0: numba then knows no index is negative and the loop vectorizes; 1.06 -> 0.29 ns per
    multiply-add measured at 200 x 200.)"""
    flops = 0
    lcol = A[j * nr + r0 + 1:j * nr + nr]
    for c in range(c0, c1):
        a = A[c * nr + r0]
        if a != 0.0:
            flops += nr - r0 - 1
            dst = A[c * nr + r0 + 1:c * nr + nr]
            for r in range(nr - r0 - 1):
                dst[r] -= lcol[r] * a
    return flops


@njit(cache=True)
def _block_lu(nr, nc, A, drow, rowpos, tcmax, tpref, tpiv, rank_tol, piv_thresh):
    """Right-looking LU of the dense block A (nr x nc, column-major) with row exchanges
    (drow: the row index of each block row, rowpos its inverse), the pivot rule of the
    sparse steps: the largest |entry| (ties: the smaller row index), the column's matched
    row tpref when within ``piv_thresh`` of it; a column whose largest entry is at most
    ``rank_tol`` times its own norm (tcmax) is dependent (tpiv -1) and skipped.  Returns
    (the number of pivots, the work of its updates in multiply-adds of the column loop);
    tpiv[j] is column j's pivot row in the block.

    From ``BLOCKED_MIN`` columns on, in panels: a panel's columns are eliminated as above
    among themselves, then the columns after it are updated by BLAS
    (:func:`_panel_update`).  The pivot rule is the column loop's (each column is whole
    when its pivot is chosen), but the sums are taken in another order: a near-tie may
    be decided otherwise."""
    r0 = 0
    flops = 0
    panel = nc if nc < BLOCKED_MIN else PANEL
    j0 = 0
    while j0 < nc:
        j1 = min(j0 + panel, nc)
        rs = r0
        for j in range(j0, j1):
            col = j * nr
            amax = 0.0
            piv = -1
            for r in range(r0, nr):
                a = abs(A[col + r])
                if a > amax or (a == amax and piv >= 0 and drow[r] < drow[piv]):
                    amax = a
                    piv = r
            pr = tpref[j]
            if pr >= 0:
                r = rowpos[pr]
                if r >= r0 and abs(A[col + r]) >= piv_thresh * amax:
                    piv = r
            if not (amax > rank_tol * tcmax[j]) or piv < 0:
                tpiv[j] = -1
                continue
            if piv != r0:
                for c in range(nc):
                    a = A[c * nr + r0]
                    A[c * nr + r0] = A[c * nr + piv]
                    A[c * nr + piv] = a
                i0, i1 = drow[r0], drow[piv]
                drow[r0], drow[piv] = i1, i0
                rowpos[i1], rowpos[i0] = r0, piv
            tpiv[j] = r0
            pv = A[col + r0]
            lcol = A[col + r0 + 1:col + nr]
            for r in range(nr - r0 - 1):
                lcol[r] = lcol[r] / pv
            flops += _eliminate(A, nr, j, r0, j + 1, j1)
            r0 += 1
        if j1 < nc and r0 > rs:
            flops += _panel_update(nr, nc, A, j0, j1, rs, r0, tpiv) // BLAS_WORK_DIVISOR
        j0 = j1
    return r0, flops


@njit(cache=True)
def dense_tail(t0, k0, ufree, order, sk, si, Mp, Mi, Mx, rI, rX, art_sign, S, rank_tol,
               piv_thresh, pref, rep_slot, nrep):
    """Eliminate the columns order[t0:] as a dense block after k0 sparse steps (see the
    module docstring; the caller checked :func:`tail_fits`).  Returns (positions made,
    U's next free entry, the count of dependent slots in rep_slot, the work units: the
    solves', the block's multiply-adds / DENSE_WORK_DIVISOR and its entries, the zeros
    stored in L and in U), or (-1, 0, 0, 0, 0, 0) when L or U did not fit in their
    storage."""
    (h, Lp, Li, Lx, Us, Ue, Ui, Ux, Ud, Urp, Urj, Urx, dead, Rs, Ri, Rx, Rpos, pinv,
     slot_at, pos_of, iw, fw, ow, seg) = S
    n = sk.shape[0]
    nc = n - t0
    nr = n - k0
    rowpos, drow = Ri[0:n], Ri[n:n + nr]
    tstart, tcount = Ri[n + nr:n + nr + nc], Ri[n + nr + nc:n + nr + 2 * nc]
    tpref, tpiv = Ri[n + nr + 2 * nc:n + nr + 3 * nc], Ri[n + nr + 3 * nc:n + nr + 4 * nc]
    r = 0
    for i in range(n):
        if pinv[i] < 0:
            rowpos[i] = r
            drow[r] = i
            r += 1
    first = ufree
    ufree, work = _stage(t0, nc, nr, order, sk, si, Mp, Mi, Mx, rI, rX, art_sign, S, pref,
                         ufree, (rowpos, tstart, tcount, tpref, drow))
    if ufree < 0:
        return -1, 0, 0, 0, 0, 0
    A = Rx
    npiv, flops = _block_lu(nr, nc, A, drow, rowpos, fw[2], tpref, tpiv, rank_tol,
                            piv_thresh)
    work += flops // DENSE_WORK_DIVISOR + 2 * nr * nc
    # commit, column by column in pivot order: U (the staged part moved down to w, then
    # the block's part above the diagonal), the diagonal, L (below it, by row index).  The
    # block's parts are stored whole, zeros too, over consecutive positions: the solves
    # then run over them as dense columns (_sparse_lu.solve); h[H_ZL], h[H_ZU] count
    # the zeros, which the counts of entries leave out.
    w = first
    lp = Lp[k0]
    capL = Li.shape[0]
    zl = 0
    zu = 0
    for j in range(nc):
        s = order[t0 + j]
        r = tpiv[j]
        if r < 0:
            rep_slot[nrep] = s
            nrep += 1
            continue
        k = k0 + r
        col = j * nr
        Us[k] = w
        for e in range(tstart[j], tstart[j] + tcount[j]):
            Ui[w] = Ui[e]
            Ux[w] = Ux[e]
            w += 1
        for q in range(r):
            Ui[w] = k0 + q
            Ux[w] = A[col + q]
            zu += A[col + q] == 0.0
            w += 1
        Ue[k] = w
        Ud[k] = A[col + r]
        if lp + nr - r - 1 > capL:
            return -1, 0, 0, 0, 0, 0
        for q in range(r + 1, nr):
            Li[lp] = drow[q]
            Lx[lp] = A[col + q]
            zl += A[col + q] == 0.0
            lp += 1
        Lp[k + 1] = lp
        pinv[drow[r]] = k
        slot_at[k] = s
    return k0 + npiv, w, nrep, work, zl, zu
