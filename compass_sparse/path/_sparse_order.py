"""The elimination order of the sparse engine's basis at each factorization: a numerical
matching of the basic z columns to rows, then a minimum degree order of the matched block.

After the unit columns (slacks, artificials) have taken their rows, what is left to
eliminate is the block A = B[R, Z] of the basic z columns on the rows R no unit column
covers.  In a complementarity basis R is mostly the rows of the basic z themselves, so A
is close to the principal submatrix M[Z, Z] -- a structurally symmetric matrix in many
models -- but its diagonal may be useless as pivots: the linearization's M = J + eps I
puts an entry on every diagonal, and in a saddle-point model (traffic: flows and node
potentials, whose Jacobian block is [[0, -N^T], [N, 0]]) that entry is eps.  A column order
made for partial pivoting (COLAMD of M, which bounds the fill under any row choice) does
not see that such a matrix, once each column is paired with a row of a large entry, is as
sparse to factor as a symmetric one.

So at each factorization:

1. **Matching** (:func:`match_columns`).  Each column c of A gets a row m(c), a
   *numerically acceptable* entry, ``|a_ic| >= MATCH_TOL * max_k |a_kc|``: its own row
   when acceptable; else a *symmetric pair* -- rows i and j of two basic z_j, z_i with
   both a_ij and a_ji acceptable, matched crosswise (j -> i, i -> j), which keeps the
   permuted matrix's pattern close to symmetric (a tree arc and its tail node in the
   traffic model); else any free acceptable row; else an augmenting path (depth-first,
   Duff's MC21) over acceptable entries, and then over all nonzero entries.  A column
   left unmatched is structurally dependent on the others (the factorization repairs it).
2. **Minimum degree** (:func:`min_degree`).  The graph of the matched pairs, with an edge
   c -- c' when a_{m(c') c} or a_{m(c) c'} is nonzero (the pattern of A P + (A P)^T, P the
   matching's column permutation), ordered by minimum degree on its quotient graph:
   eliminated nodes become elements (their neighbour lists), the elements adjacent to a
   pivot are absorbed into its new element, and degrees are the approximate external
   degrees of Amestoy, Davis and Duff ("An approximate minimum degree ordering algorithm",
   SIAM J. Matrix Anal. Appl. 17 (1996) 886-905), with element absorption (also of
   elements that the new one covers) but without supervariables.  Nodes of degree above
   ``DENSE_DEGREE`` (dense rows and columns) are ordered last.
3. The factorization eliminates the columns in that order and prefers each column's
   matched row while it is within the pivoting threshold (see
   :mod:`compass_sparse.path._sparse_lu`).

Measured on the traffic model (n = 2452, late bases of a solve): L + U 22-26e3 entries and
0.2-0.3e6 multiply-adds against 94-102e3 and 4.3-5.0e6 in COLAMD's order of M with partial
pivoting; and on the late bases at n = 912, 6-8e3 against 13-15e3.

Consecutive factorizations (within a path, and from one path to the next, which starts
from the last one's basis) see bases that differ by the few columns the pivots since
exchanged: a factorization reuses the last fresh order -- each column's rank
in it and its matched row, the columns new since ordered after the others and preferring
their own row -- while few of its columns are new and few of the order's have left
(``REUSE_NEW_SHARE``) and the last factors did not fill much beyond the fresh order's
(the caller's rule, :data:`compass_sparse.path._sparse_lu.REORDER_FILL`).  On the bases
of a traffic solve at n = 2452 this took 12-35% off the factorizations for 2-4% more
entries.

Everything runs on preallocated integer work space (:func:`work_size` entries); the
quotient graph compacts its storage when it fills, and returns -1 when even then it does
not fit (the caller then eliminates in column order).
"""
from __future__ import annotations

import numpy as np

from .._jit import njit
from ._kernels import VAR_T, VAR_Z

__all__ = ["DENSE_DEGREE", "MATCH_TOL", "REUSE_NEW_MIN", "REUSE_NEW_SHARE", "block_order",
           "match_columns", "min_degree", "work_size"]

MATCH_TOL = 0.1
"""An entry a_ic may match column c when ``|a_ic| >= MATCH_TOL * max_k |a_kc|`` (over the
block's rows): the pivoting threshold of the factorization
(:data:`compass_sparse.path._sparse_lu.PIVOT_THRESHOLD`), so that a matched row is a pivot
the factorization is likely to accept."""

REUSE_NEW_SHARE = 16
REUSE_NEW_MIN = 4
"""A factorization reuses the last fresh order (its caller allowing it) while at most
nb / REUSE_NEW_SHARE + REUSE_NEW_MIN of the nb basic z columns have entered since, and at
most as many of the columns that order ranked have left the basis.  (Columns that left
count because the order's matching and elimination plan were made with them: on the CGE
endowment shock at n = 2024 the long path's first fresh order, made with all 2023 z
basic, served every later basis while nothing new entered; at the path's end, 1237 z
basic, its factors held 217e3 entries against 68e3 in a fresh order, and the
pivot-weighted mean of L + U over the path was 353e3 against 313e3 with this rule.)"""

DENSE_DEGREE = 16
"""A node whose degree exceeds max(DENSE_DEGREE, 10 sqrt(nodes)) is ordered last (AMD's
rule: a dense row or column would make every degree large and the order meaningless)."""

# the work space's parts (each n entries but the quotient graph's list storage)
(W_ZSLOT, W_ZCOL, W_ROWM, W_COLM, W_STACK, W_PTR, W_RPATH, W_VISIT, W_PE, W_LEN, W_ELEN,
 W_DEG, W_HEAD, W_NEXT, W_PREV, W_WGT, W_STAT, W_LPM, W_ORDER, W_RANK, W_MROW) = range(21)
N_PARTS = 21

# node status in the quotient graph
_ALIVE, _ELEMENT, _GONE, _DENSE = 0, 1, 2, 3


def list_capacity(n: int, nnz: int) -> int:
    """Entries of the quotient graph's list storage for a basis of order n whose M holds
    nnz entries: the symmetric pattern holds at most 2 nnz, and the new elements' lists
    need room besides (compacted when full)."""
    return 4 * int(nnz) + 8 * int(n) + 1024


def work_size(n: int, nnz: int) -> int:
    """Integer entries of the ordering's work space."""
    return N_PARTS * (int(n) + 1) + list_capacity(n, nnz)


@njit(cache=True)
def parts(ow, n):
    """The work space's parts as views (n + 1 entries each) and the list storage."""
    m = n + 1
    return ow[:N_PARTS * m].reshape(N_PARTS, m), ow[N_PARTS * m:]


@njit(cache=True)
def _value(j, i, Mp, Mi, Mx):
    """M[i, j] (0 when not stored)."""
    for e in range(Mp[j], Mp[j + 1]):
        if Mi[e] == i:
            return Mx[e]
    return 0.0


@njit(cache=True)
def _augment(c0, nb, si, zslot, Mp, Mi, Mx, pinv, rowm, colm, cmax, tol, stack, ptr,
             rpath, visit, stamp):
    """Match column c0 by an augmenting path (depth-first over columns, Duff's MC21):
    entries of rows no unit column covers with ``|a| >= tol * cmax`` (and nonzero).
    Returns whether c0 got a row (the columns along the path are rematched)."""
    head = 0
    stack[0] = c0
    ptr[c0] = Mp[si[zslot[c0]]]
    while head >= 0:
        c = stack[head]
        j = si[zslot[c]]
        pushed = False
        while ptr[c] < Mp[j + 1]:
            e = ptr[c]
            ptr[c] = e + 1
            i = Mi[e]
            if pinv[i] >= 0 or visit[i] == stamp:
                continue
            a = abs(Mx[e])
            if a == 0.0 or a < tol * cmax[c]:
                continue
            visit[i] = stamp
            rpath[head] = i
            if rowm[i] < 0:
                for h in range(head, -1, -1):  # the path's columns take the next rows
                    rowm[rpath[h]] = stack[h]
                    colm[stack[h]] = rpath[h]
                return True
            c2 = rowm[i]
            head += 1
            stack[head] = c2
            ptr[c2] = Mp[si[zslot[c2]]]
            pushed = True
            break
        if not pushed:
            head -= 1
    return False


@njit(cache=True)
def match_columns(nb, zslot, si, Mp, Mi, Mx, pinv, P, cmax, tol):
    """The matching of the block's nb columns (column c: z_{si[zslot[c]]}) to the rows
    with ``pinv < 0`` (step 1 of the module docstring): P[W_COLM, c] the row of column c
    (-1: unmatched), P[W_ROWM, i] the column of row i (-1).  P[W_ZCOL, j] must hold the
    block column of a basic z_j and -1 for the others.  ``cmax`` receives each column's
    largest |entry| on those rows.  Returns the number of unmatched columns."""
    n = pinv.shape[0]
    rowm = P[W_ROWM]
    colm = P[W_COLM]
    zcol = P[W_ZCOL]
    visit = P[W_VISIT]
    for i in range(n):
        rowm[i] = -1
        visit[i] = 0
    for c in range(nb):
        colm[c] = -1
        j = si[zslot[c]]
        a = 0.0
        for e in range(Mp[j], Mp[j + 1]):
            if pinv[Mi[e]] < 0:
                a = max(a, abs(Mx[e]))
        cmax[c] = a
    for c in range(nb):  # own rows
        j = si[zslot[c]]
        if pinv[j] < 0:
            a = abs(_value(j, j, Mp, Mi, Mx))
            if a != 0.0 and a >= tol * cmax[c]:
                colm[c] = j
                rowm[j] = c
    for c in range(nb):  # symmetric pairs: z_j on row i and z_i on row j
        j = si[zslot[c]]
        if colm[c] >= 0 or pinv[j] >= 0 or rowm[j] >= 0:
            continue
        for e in range(Mp[j], Mp[j + 1]):
            i = Mi[e]
            c2 = zcol[i]
            if i == j or pinv[i] >= 0 or rowm[i] >= 0 or c2 < 0 or colm[c2] >= 0:
                continue
            a = abs(Mx[e])
            if a == 0.0 or a < tol * cmax[c]:
                continue
            b = abs(_value(i, j, Mp, Mi, Mx))
            if b != 0.0 and b >= tol * cmax[c2]:
                colm[c] = i
                rowm[i] = c
                colm[c2] = j
                rowm[j] = c2
                break
    for c in range(nb):  # any free acceptable row
        if colm[c] >= 0:
            continue
        j = si[zslot[c]]
        for e in range(Mp[j], Mp[j + 1]):
            i = Mi[e]
            a = abs(Mx[e])
            if pinv[i] < 0 and rowm[i] < 0 and a != 0.0 and a >= tol * cmax[c]:
                colm[c] = i
                rowm[i] = c
                break
    stamp = 0
    left = 0
    for strict in range(2):  # augmenting paths: acceptable entries, then any nonzero
        t = tol if strict == 0 else 0.0
        left = 0
        for c in range(nb):
            if colm[c] < 0:
                stamp += 1
                if not _augment(c, nb, si, zslot, Mp, Mi, Mx, pinv, rowm, colm, cmax, t,
                                P[W_STACK], P[W_PTR], P[W_RPATH], visit, stamp):
                    left += 1
    return left


@njit(cache=True)
def block_graph(nb, zslot, si, Mp, Mi, Mx, pinv, P, iw):
    """The graph of the matched pairs (step 2) as lists in ``iw``: node c's neighbours at
    iw[P[W_PE, c] : P[W_PE, c] + P[W_LEN, c]], no duplicates, no self loops; unmatched
    columns get empty lists.  Returns the storage used, or -1 when iw is too small."""
    rowm = P[W_ROWM]
    colm = P[W_COLM]
    pe = P[W_PE]
    ln = P[W_LEN]
    mark = P[W_LPM]
    for c in range(nb):
        ln[c] = 0
    total = 0
    for fill in (False, True):  # count the edges (with duplicates), then store them
        if fill:
            total = 0
            for c in range(nb):
                pe[c] = total
                total += ln[c]
                ln[c] = 0
                mark[c] = -1
            if total > iw.shape[0]:
                return -1
        for c in range(nb):
            if colm[c] < 0:
                continue
            j = si[zslot[c]]
            for e in range(Mp[j], Mp[j + 1]):
                i = Mi[e]
                if pinv[i] < 0 and Mx[e] != 0.0:
                    c2 = rowm[i]
                    if c2 >= 0 and c2 != c:
                        if fill:
                            iw[pe[c] + ln[c]] = c2
                            iw[pe[c2] + ln[c2]] = c
                        ln[c] += 1
                        ln[c2] += 1
    for c in range(nb):  # remove duplicates in place
        k = pe[c]
        for t in range(pe[c], pe[c] + ln[c]):
            c2 = iw[t]
            if mark[c2] != c:
                mark[c2] = c
                iw[k] = c2
                k += 1
        ln[c] = k - pe[c]
    return total


@njit(cache=True, inline="always")
def _bucket_remove(i, d, head, nxt, prv):
    if prv[i] >= 0:
        nxt[prv[i]] = nxt[i]
    else:
        head[d] = nxt[i]
    if nxt[i] >= 0:
        prv[nxt[i]] = prv[i]


@njit(cache=True, inline="always")
def _bucket_insert(i, d, head, nxt, prv):
    nxt[i] = head[d]
    prv[i] = -1
    if head[d] >= 0:
        prv[head[d]] = i
    head[d] = i


@njit(cache=True)
def _compress(nb, pe, ln, stat, iw):
    """Garbage collection of the list storage: the lists of live variables and elements
    moved down in storage order.  Returns the new end of the used storage."""
    live = np.empty(nb, dtype=np.int64)
    m = 0
    for i in range(nb):
        if stat[i] == _ALIVE or stat[i] == _ELEMENT:
            live[m] = i
            m += 1
    keys = np.empty(m, dtype=np.int64)
    for k in range(m):
        keys[k] = pe[live[k]]
    by_start = np.argsort(keys)
    f = 0
    for k in range(m):
        i = live[by_start[k]]
        start = pe[i]
        pe[i] = f
        for t in range(start, start + ln[i]):
            iw[f] = iw[t]
            f += 1
    return f


@njit(cache=True, inline="always")
def _new_element(p, pe, ln, elen, stat, lpm, iw, pfree, stamp):
    """Eliminate p: its element list L_p (the live variables adjacent to p or to one of
    its elements, which are absorbed) appended at iw[pfree:]; p becomes an element.
    Returns the new end of storage."""
    start = pfree
    lpm[p] = stamp
    for t in range(pe[p], pe[p] + elen[p]):
        e = iw[t]
        if stat[e] != _ELEMENT:
            continue
        for t2 in range(pe[e], pe[e] + ln[e]):
            i = iw[t2]
            if stat[i] == _ALIVE and lpm[i] != stamp:
                lpm[i] = stamp
                iw[pfree] = i
                pfree += 1
        stat[e] = _GONE  # absorbed into p
    for t in range(pe[p] + elen[p], pe[p] + ln[p]):
        i = iw[t]
        if stat[i] == _ALIVE and lpm[i] != stamp:
            lpm[i] = stamp
            iw[pfree] = i
            pfree += 1
    stat[p] = _ELEMENT
    pe[p] = start
    ln[p] = pfree - start
    elen[p] = 0
    return pfree


@njit(cache=True, inline="always")
def _update(p, pe, ln, elen, stat, lpm, deg, w, iw, wflg, left):
    """The lists and approximate degrees of the variables of the new element L_p
    (Amestoy-Davis-Duff: d_i = min(left - 1, d_i + |L_p| - 1, |A_i| + |L_p| - 1 +
    sum over the other elements e of i of |L_e \\ L_p|)); elements inside L_p are
    absorbed.  ``left``: live variables after p."""
    stamp = lpm[p]
    lp = ln[p]
    for t in range(pe[p], pe[p] + lp):  # w[e] - wflg = |L_e \ L_p|
        i = iw[t]
        for t2 in range(pe[i], pe[i] + elen[i]):
            e = iw[t2]
            if stat[e] == _ELEMENT:
                if w[e] < wflg:
                    w[e] = ln[e] + wflg
                w[e] -= 1
    for t in range(pe[p], pe[p] + lp):
        i = iw[t]
        k = pe[i]
        ext = 0
        for t2 in range(pe[i], pe[i] + elen[i]):
            e = iw[t2]
            if stat[e] != _ELEMENT:
                continue
            we = w[e] - wflg
            if we <= 0:
                stat[e] = _GONE  # L_e inside L_p: absorbed
                continue
            ext += we
            iw[k] = e
            k += 1
        ne = k - pe[i]
        for t2 in range(pe[i] + elen[i], pe[i] + ln[i]):
            j = iw[t2]
            if stat[j] != _ALIVE or lpm[j] == stamp:
                continue  # eliminated, dense, or reached through p now
            ext += 1
            iw[k] = j
            k += 1
        # p joins the element list (a slot was freed: i was adjacent to p or to one of
        # the elements absorbed into it): the first variable moves to the end
        if k > pe[i] + ne:
            iw[k] = iw[pe[i] + ne]
        iw[pe[i] + ne] = p
        elen[i] = ne + 1
        ln[i] = k + 1 - pe[i]
        deg[i] = min(left - 1, deg[i] + lp - 1, ext + lp - 1)


@njit(cache=True, inline="always")
def _mass_eliminate(p, pe, ln, elen, stat, deg, iw, order, k):
    """Mass elimination: a variable of L_p adjacent to nothing but the new element p
    (its list is p alone) would be eliminated next at no fill, so all such go now, after
    p (order[k:]); they leave L_p and the degrees of its other variables.  Returns the
    new k.  (In the dense block that ends most orders this orders the block at once.)"""
    q = pe[p]
    c = 0
    for t in range(pe[p], pe[p] + ln[p]):
        i = iw[t]
        if elen[i] == 1 and ln[i] == 1:
            order[k] = i
            k += 1
            stat[i] = _GONE
            c += 1
        else:
            iw[q] = i
            q += 1
    ln[p] = q - pe[p]
    if c > 0:
        for t in range(pe[p], q):
            i = iw[t]
            deg[i] = max(0, deg[i] - c)
    return k


@njit(cache=True)
def min_degree(nb, P, iw, used):
    """Minimum degree order (step 2) of the graph set up by :func:`block_graph` (nodes
    with ``P[W_COLM] < 0`` take no part): P[W_ORDER, :k] the k ordered nodes.  Returns k,
    or -1 when the list storage is too small."""
    pe = P[W_PE]
    ln = P[W_LEN]
    elen = P[W_ELEN]
    deg = P[W_DEG]
    head = P[W_HEAD]
    nxt = P[W_NEXT]
    prv = P[W_PREV]
    w = P[W_WGT]
    stat = P[W_STAT]
    lpm = P[W_LPM]
    order = P[W_ORDER]
    colm = P[W_COLM]
    nodes = 0
    for c in range(nb):
        stat[c] = _ALIVE if colm[c] >= 0 else _GONE
        nodes += stat[c] == _ALIVE
    dense = max(DENSE_DEGREE, int(10.0 * np.sqrt(nodes)))
    ndense = 0
    for c in range(nb):
        if stat[c] == _ALIVE and ln[c] > dense:
            stat[c] = _DENSE
            ndense += 1
    for d in range(nb + 1):
        head[d] = -1
    for c in range(nb):
        elen[c] = 0
        w[c] = 0
        lpm[c] = -1
        if stat[c] == _ALIVE:
            d = 0
            for t in range(pe[c], pe[c] + ln[c]):
                d += stat[iw[t]] == _ALIVE
            deg[c] = d
            _bucket_insert(c, d, head, nxt, prv)
    live = nodes - ndense
    k = 0
    mindeg = 0
    wflg = 1
    pfree = used
    cap = iw.shape[0]
    while k < live:
        while head[mindeg] < 0:
            mindeg += 1
        p = head[mindeg]
        _bucket_remove(p, mindeg, head, nxt, prv)
        order[k] = p
        k += 1
        if pfree + deg[p] + 1 > cap:
            pfree = _compress(nb, pe, ln, stat, iw)
            if pfree + deg[p] + 1 > cap:
                return -1
        pfree = _new_element(p, pe, ln, elen, stat, lpm, iw, pfree, k)
        for t in range(pe[p], pe[p] + ln[p]):
            i = iw[t]
            _bucket_remove(i, deg[i], head, nxt, prv)
        _update(p, pe, ln, elen, stat, lpm, deg, w, iw, wflg, live - k)
        wflg += nb + 1
        k = _mass_eliminate(p, pe, ln, elen, stat, deg, iw, order, k)
        for t in range(pe[p], pe[p] + ln[p]):
            i = iw[t]
            _bucket_insert(i, deg[i], head, nxt, prv)
            mindeg = min(mindeg, deg[i])
    for c in range(nb):
        if stat[c] == _DENSE:
            order[k] = c
            k += 1
    return k


@njit(cache=True)
def block_order(sk, si, Mp, Mi, Mx, pinv, colkey, order, m, pref, ow, cmax, tol, reuse):
    """The elimination order of the basis' non-unit columns, after the unit columns took
    the rows with ``pinv >= 0``: order[m:] receives the basic z slots -- the matched ones
    in minimum degree order, then the unmatched ones by ``colkey`` -- and the covering
    vector's slot last; pref[s] the matched row of slot s (-1: none).  With ``reuse``,
    the order and matching of the last fresh call serve again (:func:`_reused_order`)
    when few of the basic z are new since and few of its columns have left.  Returns
    (the new end of ``order``, n when every slot is ordered; whether the order is
    fresh)."""
    n = sk.shape[0]
    P, iw = parts(ow, n)
    zslot = P[W_ZSLOT]
    zcol = P[W_ZCOL]
    rank = P[W_RANK]
    nb = 0
    new = 0
    ranked = 0  # the columns the last fresh order ranked
    for j in range(n):
        zcol[j] = -1
        ranked += rank[j] >= 0
    for s in range(n):
        pref[s] = -1
        if sk[s] == VAR_Z:
            zslot[nb] = s
            zcol[si[s]] = nb
            nb += 1
            new += rank[si[s]] < 0
    gone = ranked - (nb - new)  # ranked columns no longer basic
    if reuse and max(new, gone) <= nb // REUSE_NEW_SHARE + REUSE_NEW_MIN:
        return _reused_order(sk, si, colkey, order, m, pref, P, nb), False
    k = -1
    if nb > 0:
        match_columns(nb, zslot, si, Mp, Mi, Mx, pinv, P, cmax, tol)
        used = block_graph(nb, zslot, si, Mp, Mi, Mx, pinv, P, iw)
        if used >= 0:
            k = min_degree(nb, P, iw, used)
    colm = P[W_COLM]
    mrow = P[W_MROW]
    for j in range(n):
        rank[j] = -1
    for c in range(nb):
        pref[zslot[c]] = colm[c]
        mrow[si[zslot[c]]] = colm[c]
    if k >= 0:
        ordered = P[W_ORDER]
        for t in range(k):
            order[m] = zslot[ordered[t]]
            rank[si[zslot[ordered[t]]]] = t
            m += 1
    # the unmatched columns (or all, when the graph did not fit) by colkey
    mark = P[W_LPM]
    for j in range(n):
        mark[j] = -1
    for c in range(nb):
        if k < 0 or colm[c] < 0:
            mark[colkey[si[zslot[c]]]] = zslot[c]
    for j in range(n):
        if mark[j] >= 0:
            order[m] = mark[j]
            m += 1
    return _t_last(sk, order, m), True


@njit(cache=True)
def _reused_order(sk, si, colkey, order, m, pref, P, nb):
    """The z slots in the rank of their column in the last fresh order, each preferring
    its matched row then; the columns new since (no rank) after them by ``colkey``,
    preferring their own row; t last.  Returns the new end of ``order``."""
    n = sk.shape[0]
    rank = P[W_RANK]
    mrow = P[W_MROW]
    zslot = P[W_ZSLOT]
    at = P[W_LPM]
    for j in range(n):
        at[j] = -1
    for c in range(nb):
        j = si[zslot[c]]
        if rank[j] >= 0:
            at[rank[j]] = zslot[c]
            pref[zslot[c]] = mrow[j]
    for t in range(n):
        if at[t] >= 0:
            order[m] = at[t]
            m += 1
    for j in range(n):
        at[j] = -1
    for c in range(nb):
        j = si[zslot[c]]
        if rank[j] < 0:
            at[colkey[j]] = zslot[c]
            pref[zslot[c]] = j
    for t in range(n):
        if at[t] >= 0:
            order[m] = at[t]
            m += 1
    return _t_last(sk, order, m)


@njit(cache=True, inline="always")
def _t_last(sk, order, m):
    for s in range(sk.shape[0]):
        if sk[s] == VAR_T:
            order[m] = s
            m += 1
    return m
