"""The sparse LU of the compiled path engine's basis and its Forrest-Tomlin updates
(:mod:`compass_sparse.path._path_kernels` runs the path on them; the engine is
:mod:`compass_sparse.path.sparse_engine`).

The basis B (n x n) has one column per slot, as in :mod:`compass_sparse.path._dense_lu`:
``M[:, i]`` for a basic z_i, ``-e_i`` for w_i and for a fixed variable's free slack,
``+e_i`` for v_i, ``art_sign[i] e_i`` for an artificial and the covering vector r for t.

Factorization: left-looking LU (Gilbert-Peierls) with threshold partial pivoting
---------------------------------------------------------------------------------
Columns are eliminated in the order :func:`compass_sparse.path._sparse_order.block_order`
computes for each basis (or reuses from an earlier one of the path, see
``REORDER_FILL``): the unit columns first (each pivots on its own row and
eliminates nothing), then the basic z columns, matched to rows of large entries and
ordered by minimum degree on the matched block's pattern, then r.  Step k takes the
column b = B[:, s] and solves ``L_k x = b`` with the k columns of L made so far: the rows
reached from b's nonzeros in the graph of L (depth-first search, Gilbert and Peierls
1988) in topological order, so a step costs its flops, not n.  The entries of x on
pivoted rows are column k of U; among the rest the pivot row is the column's matched row
r when ``|x_r| >= piv_thresh * max |x_i|``, else the row of largest |x_i| (threshold
partial pivoting, multipliers at most 1 / piv_thresh; the engine uses
``PIVOT_THRESHOLD`` = 0.1).  L's column k is x / pivot on the remaining rows.  So
``P B Q = L U`` over *positions* (step indices), with L and U held in CSC arrays over
positions after the factorization.  When the Schur complement left has become dense, the
last columns are eliminated as one dense block with partial pivoting
(``TAIL_PIVOT_THRESHOLD``, the matched row kept on ties;
:mod:`compass_sparse.path._sparse_steps`, the dense tail; ``h[H_TAIL]`` its columns): on
the late bases of the traffic model at n = 2452 (a 200 x 200 tail holding most of the
1.5e6 multiply-adds) it took the factorization from 4-8 ms to 2.5-4 ms.

Rank repair (thesis §3.3.1, as the basis manager and the dense engine do): a column
whose largest remaining entry is at most ``rank_tol * ||B[:, s]||_inf`` (or a second unit
column on a row already covered) is dependent; it gets no position.  After the last
column the rows left without a pivot, in increasing order, go to the dependent slots in
increasing slot order: each such slot becomes an artificial unit column on its row, and
the caller factors the repaired table again (a dependent covering vector or slack column
cannot be repaired: the basis is singular).

Why a compiled LU and not the backends' (SuperLU, UMFPACK, KLU) with reverse
communication: measured on the traffic model (n = 912), the Python around a backend
factorization of the basis -- the slot table's column assembly, the non-unit block's
extraction, an ordering of its pattern, the triangular factors' conversion -- cost
1-3 ms per factorization against 0.05-0.4 ms for the numeric LU itself, and a path
refactorizes every 50 updates and at every declined update.  The compiled LU orders and
factors a basis in one call and costs its flops.  Bases that fill much factor more
slowly here than by a supernodal LU: dense Jacobians (the thesis families, n >= 600)
stay on the manager (see sparse_engine.py).

FTRAN, BTRAN and the Forrest-Tomlin update
------------------------------------------
As the basis manager's factors (:mod:`compass_sparse.basis.manager`, the same formulas;
Forrest and Tomlin 1972): after k updates ``R_k ... R_1 L^{-1} P B Q_k = U_k`` with U on
positions 0 .. n+k-1 (a replaced position is *dead*: empty column, unit diagonal);
FTRAN ``w = P a; w = L^{-1} w; w = R_k...R_1 w; w = U^{-1} w; x = Q^T w``, each solve
column-oriented and skipping zeros, so a sparse right-hand side costs O(n) index checks
plus its flops.  The dense tail's columns and rows (the last ``h[H_TAIL]`` positions)
are stored whole, zeros too, over consecutive positions: the solves run over them as
contiguous loops (:func:`axpy_run`, :func:`dot_run`) with the same operation on each
entry as through the indices, so the same bits (on a late traffic basis, n = 2452 and a
184-column tail: FTRAN 66-81 -> 36-54 us, BTRAN 82-86 -> 54-55 us).  The update replacing
position p by a column with spike s:
``y = U^{-T} e_p`` (row form of the fresh U plus the appended columns), row eta
``c_i = -u_pp y_i`` (i > p), new diagonal ``d2 = u_pp y^T s`` appended as position
n + k with column s (row p dropped); position p dies.  A spike's rows in the dense tail
are stored whole, with their row indices, when at least ``SPIKE_SEGMENT_SHARE`` of them
are nonzero (``S[23]``: where that run starts in the column, or -1), and the solves read
them as one contiguous run, the same terms in the same order.

Safeguards (each declines the update: the path refactorizes, with the repair):

* ``update_tol`` (the manager's ``pivot_tolerance``, 1e-11): refused when
  ``|d_p u_pp| <= update_tol ||s||_inf``, ``|d_p| <= update_tol ||d||_inf`` or
  ``|d2| <= update_tol ||s||_inf`` (d = B^{-1} a);
* ``stab_tol`` (1e-8): ``|d1 - d2| > stab_tol |d1|`` with ``d1 = d_p u_pp`` (the two
  computations of the new diagonal disagree);
* ``growth_limit`` (the engine's ``GROWTH_LIMIT``, 1e8): a row-eta multiplier ``|c_i|``
  above it;
* fill (the manager's ``fill_factor``, 2): L, U and the etas would hold more than
  ``fill_factor`` times the fresh factorization's entries, or the preallocated storage
  is full;

and the update limit (``factorization_update_limit``) refactorizes in any case.

When to refactorize (:func:`refactor_pays`): with the updates a pivot's solves read more
entries (the appended columns of U, the row etas); a factorization costs its work once.
The average cost per pivot of a cycle (factorization + k pivots) is smallest where the
next pivot's solves would cost more than that average; the engine refactorizes there
(the classic rule of the simplex codes), counting work in entries touched, never by the
clock.  The update limit stays a hard maximum (automatic: ``AUTO_UPDATE_LIMIT`` of the
engine); the fill limit and the safeguards above decline updates as before.
"""
from __future__ import annotations

import numpy as np

from .._jit import njit
from ._dense_lu import UPD_GROWTH, UPD_LIMIT, UPD_OK, UPD_REFUSED, UPD_UNSTABLE
from ._kernels import VAR_A, VAR_T, VAR_Z, unit_sign
from ._sparse_order import MATCH_TOL, block_order, work_size
from ._sparse_steps import (DENSE_TAIL_MIN, DENSE_TAIL_RUN, DENSE_TAIL_SHARE, axpy_run,
                            basis_column, dense_tail, dot_run, reach_solve, tail_fits)

UPD_FILL = 5
"""replace_column's outcome when the update would exceed the fill limit or the storage."""

PIVOT_THRESHOLD = 0.1
"""The sparse steps' pivoting threshold: a column pivots on its matched row
(:mod:`compass_sparse.path._sparse_order`) while that entry is at least a tenth of the
column's largest remaining one (multipliers at most 10, UMFPACK's default for
unsymmetric matrices), else on the largest.  The matched rows are the minimum degree
order's plan, and partial pivoting (1.0) left it wherever a matched entry was not the
column's largest: on the bases of the CGE endowment shock at n = 2024 the long path's
pivot-weighted L + U went from 313e3 to 254e3 and the solve took 0.91 of the time
(process pairs, median of 6), the same pivots and final point; a mid-path basis of 1237
basic z factored in 52e3 entries against 70e3.  The traffic solves keep their
factorizations (57 at n = 2452) and their time (process pairs: 1.03 and 0.96 at
n = 2452 and 912).  The dense tail keeps partial pivoting: ``TAIL_PIVOT_THRESHOLD``."""

TAIL_PIVOT_THRESHOLD = 1.0
"""The dense tail's pivoting threshold: partial pivoting, the matched row kept on ties.
The tail's columns are stored whole, so a looser threshold there saves no entries; with
0.1 there too, the traffic solve at n = 2452 made 61 factorizations instead of 57 (the
same pivots) and its replayed path kernels took 213-288 ms against 182-211 ms."""

GROW = -1
"""factor()'s return when L or U did not fit in the preallocated storage (the engine
grows it and runs the path again)."""

# the header array h (int64) of the factors; H_FWORK .. H_UFACT: the refactorization
# rule's counts (see refactor_pays)
# (H_SPNNZ: the nonzeros of the last column FTRAN's spike, their positions in iw; see
# solve: iw is the factorization's work space, free between factorizations)
# (H_TAIL: the columns of the last factorization's dense tail, see _sparse_steps; H_ZL,
# H_ZU: the zeros its block stores in L and U, which the counts of entries leave out)
# (H_NEED: after GROW, the entries of L's storage the factorization is known to need, or 0)
H_M1, H_NNZL, H_UFREE, H_NNZU, H_NNZR, H_BASE, H_N, H_FRESH, H_LAST, H_FWORK, H_XWORK, \
    H_KSOL, H_UFACT, H_FWEIGHT, H_SPNNZ, H_TAIL, H_ZL, H_ZU, H_NEED = range(19)
N_HEADER = 19

FACTOR_WEIGHT = 2.5
"""The cost of one work unit of a factorization (an entry of L visited by the depth-first
search or the elimination, a row reached, an entry stored) in units of one entry of the
update's solves (an entry of an appended U column or of a row eta read by FTRAN or by
U^{-T} e_p), for :func:`refactor_pays`; held in the factors' header in 1/1024ths
(``h[H_FWEIGHT]``).  Measured on the bases of a traffic solve at n = 2452 (compiled,
quiet machine): 2.6-2.8 ns per factorization unit on the later bases (L + U 4e4-5e4,
2.5e6-3.8e6 units, 6.6-10.8 ms), and a pivot's time grew by 0.9-1.1 ns per update unit
(least squares over the pivots of a path without a refactorization).  The rule's optimum
is flat: weights 1 to 8 gave 55 to 44 factorizations and path kernels equal within the
noise (replayed)."""

REORDER_FILL = 1.2
"""A factorization computes a fresh elimination order when the last one's L + U held
more than REORDER_FILL times the entries of the last factorization in a fresh order
(or when many basic columns are new or have left:
:data:`compass_sparse.path._sparse_order.REUSE_NEW_SHARE`); else it reuses that order,
also from one path to the next (the next path starts from the last one's basis, and M
keeps its pattern).  ``h[H_FRESH] = 0`` (new factors) forces a fresh one.  Measured
(the paths of a traffic solve replayed, one process per tree, interleaved): reusing
across paths took 6% off the path kernels at n = 912 and 20% at n = 2452 against a fresh
order at each path's start."""


SPIKE_SEGMENT_SHARE = 0.2
"""An update's new column of U (the spike) stores its rows in the dense tail whole, zeros
too, when at least this share of them is nonzero: the solves then read them as one
contiguous run (:func:`axpy_run`, :func:`dot_run`), the same terms in the same order.
One pass over contiguous entries cost 0.15 ns an entry against 0.78 through row indices
(a triangle of 0.5e6 entries, compiled, one core), so a run of at least a fifth nonzeros
reads faster whole.  On the CGE endowment shock's path (n = 2024, tails of 800-900
columns) 69e6 of the 80e6 spike entries its pivots read lie in the tail rows."""

ETA_ROOM_UPDATES = 50
"""The appended columns of U and the row etas get room for at most this many updates of n
entries each (more updates fit when they are sparser: a traffic basis' updates hold a few
hundred entries); an update that does not fit is declined (UPD_FILL) and the path
refactorizes.  The same storage holds the dense tail's block while a factorization makes
it (see :mod:`compass_sparse.path._sparse_steps`), so it is never smaller than L's: a
block that does not fit returns GROW like L and U."""


def _capacities(n: int, update_limit: int, nnz_guess: int):
    lim = max(int(update_limit), 1)
    capL = max(int(nnz_guess), 4 * n, 1024)
    eta = min(lim, ETA_ROOM_UPDATES) * (n + 1)
    return lim, n + lim + 1, capL, capL + eta, max(eta, capL)


def storage_bytes(n: int, update_limit: int, nnz_guess: int) -> int:
    """The bytes :func:`allocate` takes for these arguments (the engine checks them
    against the memory budget before allocating)."""
    lim, N, capL, capU, capR = _capacities(n, update_limit, nnz_guess)
    ints = N_HEADER + (n + 1) + capL + 2 * N + capU + (n + 1) + capU + N \
        + 2 * (lim + 1) + capR + 2 * n + 2 * N + max(6 * n + 4, N) + work_size(n, nnz_guess)
    floats = capL + capU + N + capU + capR + 3 * N
    return 8 * (ints + floats)


def allocate(n: int, update_limit: int, nnz_guess: int):
    """The factor tuple of an n x n basis with room for ``update_limit`` updates and about
    ``nnz_guess`` entries in L and in U: nothing is allocated by a path after this (a
    factorization that does not fit returns GROW)."""
    lim, N, capL, capU, capR = _capacities(n, update_limit, nnz_guess)
    h = np.zeros(N_HEADER, dtype=np.int64)
    h[H_N] = n
    h[H_FWEIGHT] = round(FACTOR_WEIGHT * 1024)
    i64 = np.int64
    return (h,
            np.zeros(n + 1, i64), np.zeros(capL, i64), np.zeros(capL),          # L
            np.zeros(N, i64), np.zeros(N, i64), np.zeros(capU, i64), np.zeros(capU),
            np.ones(N),                                                         # U
            np.zeros(n + 1, i64), np.zeros(capU, i64), np.zeros(capU),          # U rows
            np.zeros(N, i64),                                                   # dead
            np.zeros(lim + 1, i64), np.zeros(capR, i64), np.zeros(capR),
            np.zeros(lim + 1, i64),                                             # R
            np.zeros(n, i64), np.zeros(N, i64), np.zeros(n, i64),   # pinv, slot_at, pos_of
            np.zeros(max(6 * n + 4, N), i64),                           # int work (iw)
            np.zeros((3, N)),                                                   # float work
            np.zeros(work_size(n, nnz_guess), i64),                             # ordering
            np.full(N, -1, i64))                           # appended columns' segments


def grown_size(S, factor: float = 2.0):
    """(n, update limit, L's capacity) of a factor tuple like S with ``factor`` times its
    L and U storage, or more when the factorization that returned GROW knew it needed more
    (a dense tail: without this a CGE basis at n = 2024 grew five times in a row, 19 ms of
    factorization lost each time)."""
    h = S[0]
    return int(h[H_N]), S[13].shape[0] - 1, max(int(factor * S[2].shape[0]),
                                                 int(1.25 * h[H_NEED]))


def empty():
    """The factor tuple of the dense engine's calls (no sparse factors)."""
    return allocate(1, 1, 0)


@njit(cache=True)
def factor(Mp, Mi, Mx, rI, rX, colkey, sk, si, art_sign, S, rank_tol, piv_thresh,
           rep_slot, rep_row):
    """LU of the slot basis (see the module docstring).  Returns 0 (the factors are
    valid), the number of dependent slots (slots in rep_slot, their rows in rep_row, row
    -1 for a covering-vector or slack column, which nothing repairs) or GROW.

    A compiled kernel whose length is the algorithm (the elimination order, one
    Gilbert-Peierls step per column with the pivot choice and the rank test, the repair's
    row assignment and the conversion to positions): exempt from the package's limit of
    100 lines per function."""
    (h, Lp, Li, Lx, Us, Ue, Ui, Ux, Ud, Urp, Urj, Urx, dead, Rs, Ri, Rx, Rpos, pinv,
     slot_at, pos_of, iw, fw, ow, seg) = S
    n = sk.shape[0]
    capL = Li.shape[0]
    capU = Ui.shape[0]
    order = iw[0:n]
    xi = iw[n:2 * n]
    pstack = iw[2 * n:3 * n]
    mark = iw[3 * n:4 * n]
    crow = iw[4 * n:5 * n]
    pref = iw[5 * n:6 * n]
    x = fw[0]
    cval = fw[1]
    # elimination order: unit slots in slot order, then (once their rows are known) the
    # z slots and t by block_order
    m = 0
    for s in range(n):
        if sk[s] != VAR_Z and sk[s] != VAR_T:
            order[m] = s
            m += 1
    nunit = m
    for i in range(n):
        mark[i] = 0
        pinv[i] = -1
        x[i] = 0.0
    k = 0
    nrep = 0
    ufree = 0
    fresh = False
    dense_run = 0
    h[H_TAIL] = 0
    h[H_ZL] = 0
    h[H_ZU] = 0
    h[H_NEED] = 0
    work = 4 * n  # the factorization's work units (refactor_pays): the passes over n, ...
    Lp[0] = 0
    for t in range(n):
        if t == nunit:
            reuse = h[H_FRESH] > 0 and h[H_LAST] <= REORDER_FILL * h[H_FRESH]
            fresh = block_order(sk, si, Mp, Mi, Mx, pinv, colkey, order, nunit, pref, ow,
                                fw[2], MATCH_TOL, reuse)[1]
        s = order[t]
        kind = sk[s]
        if t < nunit:
            row = si[s]
            if pinv[row] >= 0:  # a second unit column on a covered row: dependent
                rep_slot[nrep] = s
                nrep += 1
                continue
            pinv[row] = k
            slot_at[k] = s
            Ud[k] = unit_sign(kind, row, art_sign)
            Lp[k + 1] = Lp[k]
            Us[k] = ufree
            Ue[k] = ufree
            k += 1
            continue
        nb = basis_column(kind, si[s], Mp, Mi, Mx, rI, rX, art_sign, crow, cval)
        # (reach_solve's work: the column, its reach (search, pivot, store), L's entries
        # searched and eliminated)
        top, cmax, w = reach_solve(nb, crow, cval, Lp, Li, Lx, pinv, xi, pstack, mark, x)
        work += w
        amax = 0.0
        piv = -1
        for q in range(top, n):
            i = xi[q]
            if pinv[i] < 0:
                a = abs(x[i])
                if a > amax or (a == amax and piv >= 0 and i < piv):
                    amax = a
                    piv = i
        pr = pref[s] if kind == VAR_Z else -1
        if pr >= 0 and pinv[pr] < 0 and mark[pr] == 1 and abs(x[pr]) >= piv_thresh * amax:
            piv = pr
        if not (amax > rank_tol * cmax) or piv < 0:
            rep_slot[nrep] = s
            nrep += 1
            for q in range(top, n):
                x[xi[q]] = 0.0
                mark[xi[q]] = 0
            continue
        # column k of U (pivoted rows, by position) and of L (the others, by row)
        cu = 0
        cl = 0
        for q in range(top, n):
            i = xi[q]
            if x[i] != 0.0 and i != piv:
                if pinv[i] >= 0:
                    cu += 1
                else:
                    cl += 1
        if ufree + cu > capU or Lp[k] + cl > capL:
            for q in range(top, n):
                x[xi[q]] = 0.0
                mark[xi[q]] = 0
            return GROW
        Us[k] = ufree
        lp = Lp[k]
        pv = x[piv]
        for q in range(top, n):
            i = xi[q]
            xv = x[i]
            if xv != 0.0 and i != piv:
                if pinv[i] >= 0:
                    Ui[ufree] = pinv[i]
                    Ux[ufree] = xv
                    ufree += 1
                else:
                    Li[lp] = i
                    Lx[lp] = xv / pv
                    lp += 1
            x[i] = 0.0
            mark[i] = 0
        Ue[k] = ufree
        Lp[k + 1] = lp
        Ud[k] = pv
        pinv[piv] = k
        slot_at[k] = s
        k += 1
        # the dense tail (see _sparse_steps): when the L columns cover most rows left
        dense_run = dense_run + 1 if lp - Lp[k - 1] >= DENSE_TAIL_SHARE * (n - k) else 0
        if dense_run >= DENSE_TAIL_RUN and n - t - 1 >= DENSE_TAIL_MIN:
            # (the block in R, its lower part and the staged columns in L and U: at most
            # (n - k)(n - t - 1) entries more in each)
            block = (n - k) * (n - t - 1)
            if not tail_fits(n, n - k, n - t - 1, Rx.shape[0]):
                h[H_NEED] = max(block + n + 5 * (n - k), Lp[k] + block, ufree + block)
                return GROW
            k0, ufree0 = k, ufree
            k, ufree, nrep, w, zl, zu = dense_tail(t + 1, k, ufree, order, sk, si, Mp, Mi,
                                                   Mx, rI, rX, art_sign, S, rank_tol,
                                                   TAIL_PIVOT_THRESHOLD, pref, rep_slot,
                                                   nrep)
            work += w
            if k < 0:
                h[H_NEED] = max(Lp[k0] + block, ufree0 + block)
                return GROW
            h[H_TAIL] = n - t - 1
            h[H_ZL] = zl
            h[H_ZU] = zu
            break
    if nrep > 0:
        # dependent slots in increasing order get the rows left without a pivot
        for a in range(1, nrep):
            v = rep_slot[a]
            b = a - 1
            while b >= 0 and rep_slot[b] > v:
                rep_slot[b + 1] = rep_slot[b]
                b -= 1
            rep_slot[b + 1] = v
        f = 0
        for i in range(n):
            if pinv[i] < 0:
                rep_row[f] = i
                f += 1
        for a in range(nrep):
            kind = sk[rep_slot[a]]
            if kind != VAR_Z and kind != VAR_A:
                rep_slot[0] = rep_slot[a]
                rep_row[0] = -1
                return 1
        return nrep
    # L's rows to positions; U's row form (for U^{-T} e_p in the updates)
    for p in range(Lp[n]):
        Li[p] = pinv[Li[p]]
    for i in range(n + 1):
        Urp[i] = 0
    for j in range(n):
        for e in range(Us[j], Ue[j]):
            Urp[Ui[e] + 1] += 1
    for i in range(n):
        Urp[i + 1] += Urp[i]
    for i in range(n):
        crow[i] = Urp[i]
    for j in range(n):
        for e in range(Us[j], Ue[j]):
            r = Ui[e]
            Urj[crow[r]] = j
            Urx[crow[r]] = Ux[e]
            crow[r] += 1
    N = Us.shape[0]
    for j in range(n, N):
        slot_at[j] = -1
        Us[j] = ufree
        Ue[j] = ufree
        Ud[j] = 1.0
        seg[j] = -1
    for j in range(N):
        dead[j] = 0
    for j in range(n):
        pos_of[slot_at[j]] = j
    h[H_M1] = nunit
    # (the counts are of entries, nonzeros: the dense tail's stored zeros left out)
    nnzl = Lp[n] - h[H_ZL]
    nnzu = ufree - h[H_ZU]
    h[H_LAST] = nnzl + nnzu
    if fresh:
        h[H_FRESH] = max(nnzl + nnzu, 1)
    h[H_NNZL] = nnzl
    h[H_UFREE] = ufree
    h[H_NNZU] = nnzu + n
    h[H_NNZR] = 0
    h[H_BASE] = nnzl + nnzu + n
    h[H_FWORK] = (work + 2 * (nnzl + nnzu)) * h[H_FWEIGHT] // 1024
    h[H_XWORK] = 0
    h[H_KSOL] = 0
    h[H_UFACT] = ufree
    Rs[0] = 0
    return 0


@njit(cache=True, inline="always")
def update_work(h):
    """The work units the updates since the factorization add to a pivot's solves: the
    appended columns of U, read by FTRAN's U solve and by U^{-T} e_p, and the row etas."""
    return 2 * (h[H_UFREE] - h[H_UFACT]) + h[H_NNZR]


@njit(cache=True)
def count_solve(S):
    """Counts one pivot's solves since the factorization for :func:`refactor_pays`."""
    h = S[0]
    h[H_KSOL] += 1
    h[H_XWORK] += update_work(h)


@njit(cache=True)
def refactor_pays(S):
    """Whether a refactorization now costs less per pivot than going on with updates
    (the classic rule; Chvatal's and the simplex codes'): with F the last
    factorization's work and c_1 .. c_k the update work (:func:`update_work`) of the k
    pivots since, a refactorization pays when the next pivot's c_k+1 exceeds the average
    (F + c_1 + ... + c_k) / k, which the average per pivot of a cycle of updates is
    smallest where it meets.  c_k+1 is taken as c_k (the last update's growth is not
    known before it is made), and the work common to every pivot (L and the fresh U,
    the passes over n) cancels on both sides.  All counts are integers: the rule never
    depends on the clock."""
    h = S[0]
    k = h[H_KSOL]
    return k > 0 and k * update_work(h) > h[H_FWORK] + h[H_XWORK]


@njit(cache=True)
def solve(S, nupd, w, out, keep, rate, sign):
    """out = B^{-1} b (by slot) for w = P b scattered over positions (w: fw[0], zero past
    the scattered entries, overwritten); returns max |out_s| (over the slots in order).
    With ``keep`` (a column's FTRAN) the spike (the vector before the U solve) is left in
    fw[2], its largest |entry| in fw[2]'s last element (never a position of a spike) and
    its nonzeros' count in h[H_SPNNZ] and their positions, increasing, in iw (for
    replace_column), and ``rate`` = sign * out: the passes the path would make over these
    vectors, made in the solve's own."""
    (h, Lp, Li, Lx, Us, Ue, Ui, Ux, Ud, Urp, Urj, Urx, dead, Rs, Ri, Rx, Rpos, pinv,
     slot_at, pos_of, iw, fw, ow, seg) = S
    n = out.shape[0]
    m1 = h[H_M1]
    kt = n - h[H_TAIL]
    for j in range(m1, kt):
        x = w[j]
        if x != 0.0:
            for p in range(Lp[j], Lp[j + 1]):
                w[Li[p]] -= Lx[p] * x
    for j in range(kt, n):
        x = w[j]
        if x != 0.0:
            axpy_run(w, j + 1, Lx, Lp[j], n - 1 - j, x)
    for t in range(nupd):
        p = Rpos[t]
        s = w[p]
        for e in range(Rs[t], Rs[t + 1]):
            s -= Rx[e] * w[Ri[e]]
        w[n + t] = s
        w[p] = 0.0
    N = n + nupd
    if keep:
        sp = fw[2]
        snorm = 0.0
        nnz = 0
        for j in range(N):
            x = w[j]
            sp[j] = x
            a = abs(x)
            snorm = max(snorm, a)
            if a != 0.0:
                iw[nnz] = j
                nnz += 1
        sp[sp.shape[0] - 1] = snorm
        h[H_SPNNZ] = nnz
    for j in range(N - 1, -1, -1):
        x = w[j]
        if x != 0.0:
            x = x / Ud[j]
            w[j] = x
            e1 = Ue[j]
            e0 = e1  # (a run of the column over the tail's rows: where, how long)
            m = 0
            if kt <= j < n and dead[j] == 0:
                # the tail's block part: rows kt .. j-1, the column's last j - kt entries
                m = j - kt
                e0 = e1 - m
            elif seg[j] >= 0:  # an appended column's tail rows, stored whole
                e0 = seg[j]
                m = n - kt
            for e in range(Us[j], e0):
                w[Ui[e]] -= Ux[e] * x
            axpy_run(w, kt, Ux, e0, m, x)
            for e in range(e0 + m, e1):
                w[Ui[e]] -= Ux[e] * x
    dmax = 0.0
    if keep:
        for s in range(n):
            x = w[pos_of[s]]
            out[s] = x
            dmax = max(dmax, abs(x))
            rate[s] = sign * x
    else:
        for s in range(n):
            x = w[pos_of[s]]
            out[s] = x
            dmax = max(dmax, abs(x))
    return dmax


@njit(cache=True)
def ftran_column(kind, idx, Mp, Mi, Mx, rI, rX, art_sign, S, nupd, d, rate, sign):
    """d = B^{-1} a for the basis column a of a slot variable and rate = sign * d;
    returns max |d_s|; the spike kept (fw[2], see :func:`solve`)."""
    pinv = S[17]
    fw = S[21]
    n = d.shape[0]
    w = fw[0]
    N = n + nupd
    for j in range(N):
        w[j] = 0.0
    if kind == VAR_Z:
        for e in range(Mp[idx], Mp[idx + 1]):
            w[pinv[Mi[e]]] = Mx[e]
    elif kind == VAR_T:
        for e in range(rI.shape[0]):
            w[pinv[rI[e]]] = rX[e]
    else:
        w[pinv[idx]] = unit_sign(kind, idx, art_sign)
    return solve(S, nupd, w, d, True, rate, sign)


@njit(cache=True)
def ftran_dense(S, nupd, b, out):
    """out = B^{-1} b for a dense b (by row)."""
    pinv = S[17]
    w = S[21][0]
    n = b.shape[0]
    for j in range(n + nupd):
        w[j] = 0.0
    for i in range(n):
        w[pinv[i]] = b[i]
    solve(S, nupd, w, out, False, out, 1.0)


@njit(cache=True)
def btran(S, nupd, c, out):
    """out = B^{-T} c (c by slot, out by row): U^{-T}, the etas' transposes, L^{-T}."""
    (h, Lp, Li, Lx, Us, Ue, Ui, Ux, Ud, Urp, Urj, Urx, dead, Rs, Ri, Rx, Rpos, pinv,
     slot_at, pos_of, iw, fw, ow, seg) = S
    n = c.shape[0]
    N = n + nupd
    w = fw[0]
    for j in range(N):
        w[j] = 0.0
    for s in range(n):
        w[pos_of[s]] = c[s]
    _utsolve(S, w, 0, N)
    for t in range(nupd - 1, -1, -1):
        q = n + t
        s = w[q]
        w[q] = 0.0
        if s != 0.0:
            w[Rpos[t]] += s
            for e in range(Rs[t], Rs[t + 1]):
                w[Ri[e]] -= Rx[e] * s
    m1 = h[H_M1]
    kt = n - h[H_TAIL]
    for j in range(n - 1, m1 - 1, -1):  # L^T: row j of L^T is column j of L
        s = w[j]
        if j >= kt:  # (the tail's column: rows j+1 .. n-1 in order, zeros stored)
            s = dot_run(s, w, j + 1, Lx, Lp[j], n - 1 - j)
        else:
            for p in range(Lp[j], Lp[j + 1]):
                s -= Lx[p] * w[Li[p]]
        w[j] = s
    for i in range(n):
        out[i] = w[pinv[i]]


@njit(cache=True)
def _utsolve(S, w, start, N):
    """In place w <- U^{-T} w over positions start..N-1 (w[:start] zero): the fresh U by
    its row form skipping dead positions, the appended columns in dot-product form."""
    (h, Lp, Li, Lx, Us, Ue, Ui, Ux, Ud, Urp, Urj, Urx, dead, Rs, Ri, Rx, Rpos, pinv,
     slot_at, pos_of, iw, fw, ow, seg) = S
    n = pinv.shape[0]
    kt = n - h[H_TAIL]
    for j in range(start, min(n, N)):
        if dead[j] != 0:
            w[j] = 0.0
            continue
        x = w[j]
        if x != 0.0:
            x = x / Ud[j]
            w[j] = x
            if j >= kt:
                # a row of the dense tail: columns j+1 .. n-1 in order, zeros stored; a
                # dead column's entry lands on w[k], which is zeroed when k is reached
                axpy_run(w, j + 1, Urx, Urp[j], n - 1 - j, x)
                continue
            for e in range(Urp[j], Urp[j + 1]):
                k = Urj[e]
                if dead[k] == 0:
                    w[k] -= Urx[e] * x
    for j in range(max(start, n), N):
        if dead[j] != 0:
            w[j] = 0.0
            continue
        s = w[j]
        # (the same terms in the same order, a run over the tail's rows contiguously)
        e0, m = (seg[j], n - kt) if seg[j] >= 0 else (Ue[j], 0)
        for e in range(Us[j], e0):
            s -= Ux[e] * w[Ui[e]]
        s = dot_run(s, w, kt, Ux, e0, m)
        for e in range(e0 + m, Ue[j]):
            s -= Ux[e] * w[Ui[e]]
        w[j] = s / Ud[j]


@njit(cache=True)
def replace_column(S, nupd, slot, d, dnorm, update_tol, stab_tol, growth_limit,
                   fill_factor):
    """Forrest-Tomlin replacement of the column of ``slot`` by the column whose FTRAN is
    d (``dnorm`` = max |d_s|, as ftran_column returned it), its spike in fw[2] with its
    norm and nonzeros (:func:`ftran_column`).  Returns UPD_OK (the factors represent
    the new basis) or why the caller must refactorize (UPD_REFUSED, UPD_LIMIT,
    UPD_UNSTABLE, UPD_GROWTH, UPD_FILL; the factors are unchanged then).

    A compiled kernel whose length is the algorithm (the three safeguards, the fill test
    and the commit of the row eta and the spike column): exempt from the package's limit
    of 100 lines per function."""
    (h, Lp, Li, Lx, Us, Ue, Ui, Ux, Ud, Urp, Urj, Urx, dead, Rs, Ri, Rx, Rpos, pinv,
     slot_at, pos_of, iw, fw, ow, seg) = S
    n = d.shape[0]
    if nupd >= Rpos.shape[0] - 1:
        return UPD_LIMIT
    N = n + nupd
    spike = fw[2]
    y = fw[1]
    p = pos_of[slot]
    alpha = d[slot]
    upp = Ud[p]
    d1 = alpha * upp
    snorm = spike[spike.shape[0] - 1]
    nc = h[H_SPNNZ]  # the spike's entries but row p (the new column of U)
    if spike[p] != 0.0:
        nc -= 1
    if (not np.isfinite(d1) or not np.isfinite(dnorm) or abs(d1) <= update_tol * snorm
            or abs(alpha) <= update_tol * dnorm or d1 == 0.0):
        return UPD_REFUSED
    for i in range(N):
        y[i] = 0.0
    y[p] = 1.0
    _utsolve(S, y, p, N)
    d2 = y[p] * spike[p] if y[p] != 0.0 else 0.0
    ne = 0  # the row eta's entries and its largest multiplier
    gmax = 0.0
    for i in range(p + 1, N):
        if y[i] != 0.0:
            d2 += y[i] * spike[i]
            ne += 1
            gmax = max(gmax, abs(upp * y[i]))
    d2 *= upp
    if not np.isfinite(d2) or abs(d1 - d2) > stab_tol * abs(d1):
        return UPD_UNSTABLE
    if abs(d2) <= update_tol * snorm:
        return UPD_REFUSED
    if not gmax <= growth_limit:
        return UPD_GROWTH
    old_len = 0  # (column p's entries: the dense tail stores zeros)
    for e in range(Us[p], Ue[p]):
        if Ux[e] != 0.0:
            old_len += 1
    # the spike's rows in the dense tail are stored whole, zeros too, when enough of them
    # are nonzero (SPIKE_SEGMENT_SHARE); its stored entries count for the room left
    tail = h[H_TAIL]
    kt = n - tail
    ntail = 0
    for e in range(h[H_SPNNZ]):
        i = iw[e]
        if kt <= i < n and i != p:
            ntail += 1
    whole = tail > 0 and ntail >= SPIKE_SEGMENT_SHARE * tail
    stored = nc - ntail + tail if whole else nc
    if (h[H_NNZL] + h[H_NNZU] - old_len + nc + h[H_NNZR] + ne > fill_factor * h[H_BASE]
            or h[H_UFREE] + stored > Ui.shape[0] or Rs[nupd] + ne > Ri.shape[0]):
        return UPD_FILL
    # commit: the spike as column q = N, position p dead, the row eta
    f = h[H_UFREE]
    Us[N] = f
    seg[N] = -1
    for e in range(h[H_SPNNZ]):  # the spike's nonzeros, listed by the FTRAN (solve)
        i = iw[e]
        if whole and kt <= i < n:
            if seg[N] < 0:  # the tail rows kt .. n-1 in order, row p's entry zero
                seg[N] = f
                for r in range(tail):
                    Ui[f + r] = kt + r
                    Ux[f + r] = spike[kt + r]
                if kt <= p < n:
                    Ux[f + p - kt] = 0.0
                f += tail
            continue
        if i != p:
            Ui[f] = i
            Ux[f] = spike[i]
            f += 1
    Ue[N] = f
    h[H_UFREE] = f
    Ud[N] = d2
    Ue[p] = Us[p]
    Ud[p] = 1.0
    dead[p] = 1
    seg[p] = -1
    r0 = Rs[nupd]
    for i in range(p + 1, N):
        if y[i] != 0.0:
            Ri[r0] = i
            Rx[r0] = -upp * y[i]
            r0 += 1
    Rs[nupd + 1] = r0
    Rpos[nupd] = p
    slot_at[p] = -1
    slot_at[N] = slot
    pos_of[slot] = N
    h[H_NNZU] += nc - old_len
    h[H_NNZR] += ne
    return UPD_OK
