"""The dense LU of the small-problem engine's basis and its Forrest-Tomlin updates
(:mod:`compass_sparse.path._dense_kernels` runs the path on them).

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
elimination order.  The m1 unit columns (the first m1 steps) eliminate nothing: their
columns of L are zero and their columns of U are zero above the diagonal, so the
factorization costs about n (n - m1)^2 / 2 and the solves and updates below skip them
(the work is that of the non-unit block; ``perm[P_INFO, 0]`` holds m1).

When a pivot is at most ``rank_tol * max(1, ||B[:, j]||_inf)`` the basis is singular and
is repaired as the thesis does (§3.3.1; the dense reference basis does the same): start
from unit columns on every row, give each non-unit slot the next row not covered by a
unit column (its *home* row), and bring the columns in, in slot order, each pivoting on
its home row; a column whose remainder there is tiny is dependent, and an artificial unit
column on that row takes its slot (a dependent covering vector or slack makes the basis
singular: nothing to repair).  The repaired basis is then factorized with partial pivoting
for the solves.

Solves with the fresh factors
-----------------------------
After the factorization the rows of L are permuted to step order (``L[m, k]`` is the
multiplier of step k on the row pivoted at step m > k), so both factors are triangular in
step index: FTRAN ``B x = b`` is ``w = P b`` (``w_m = b[p_m]``), ``w <- L^{-1} w``,
``w <- U^{-1} w``, ``x[q_m] = w_m``; BTRAN ``B^T y = c`` is ``w_m = c[q_m]``,
``w <- U^{-T} w``, ``w <- L^{-T} w``, ``y[p_m] = w_m``.  Each costs at most n^2 flops (L
and U half each, less the unit steps), on contiguous columns of column-major arrays.

Updates: Forrest-Tomlin on the dense factors
--------------------------------------------
A column replacement keeps L and modifies U in place, as the sparse basis manager does
on its sparse factors (same formulas; Forrest and Tomlin 1972).  After k updates

    R_k ... R_1 L^{-1} P B Q_k = U_k,

where U_k lives on *positions* 0 .. n+k-1: positions < n are the elimination steps, the
update number t appends position n+t, and a replaced position is *dead* (``slot_at = -1``:
its column is ignored and its row is zero in every vector the solves meet).  The live
positions in index order are a triangular order of U_k.  Replacing the column of slot s
(position p) by a column a:

* the *spike* ``v = R_k ... R_1 L^{-1} P a`` is the FTRAN of a stopped before U (the path
  computes it anyway for the ratio test and keeps it);
* ``y = U_k^{-T} e_p`` (zero before p), and the row eta ``R_{k+1}`` maps
  ``w_q = w_p - sum_{i>p} c_i w_i`` and ``w_p = 0`` with ``c_i = -u_pp y_i``, q = n + k:
  it eliminates row p of U_k against the rows below it and moves it to the new last
  position q;
* column q of U_{k+1} is v (row p set to zero) with the new diagonal ``d2 = u_pp y^T v``;
  position p dies.

FTRAN applies the row etas between L and U, BTRAN their transposes between U^T and L^T
(``w_p += w_q``, ``w_i -= c_i w_q``, ``w_q = 0``).  Solve cost after k updates with
N = n + k positions: at most n^2/2 (L) + k N (etas) + N^2/2 (U); an update costs one
partial transposed solve from max(p, m1), at most (N - p)^2 / 2, plus O(N) — the price of
stability over the product form, which costs nothing at the update (measured in
benchmarks/dense_engine.md).  Nothing is allocated per pivot or per factorization: U is
preallocated with n + limit positions, R with limit rows, and the work of the
factorization with them (:func:`allocate_factors`).

Why Forrest-Tomlin, and its safeguards
--------------------------------------
Bartels-Golub would allow row interchanges while U is restored to triangular form, but
on a dense U it shifts every column after the replaced one (an upper Hessenberg matrix)
and keeps one stored elimination per subdiagonal entry: O(n^2) data movement and a longer
transformation file per update, where the row-eta form writes one column and one row.
Measured (benchmarks/dense_engine.md), Forrest-Tomlin with the checks below is more
accurate than the product form the engine used before, and the updates it has to decline
for stability are rare on the measured paths (0.6%), so the simpler form with a
refactorization as its fallback was chosen.  Forrest-Tomlin takes no
interchanges, so its error can grow through large multipliers c_i; it is guarded by
three tests, each of which makes the path refactorize (with the thesis' repair when the
new basis is singular) instead of updating:

* ``update_tol`` (the pivot tolerance of the update, 1e-11, the sparse manager's):
  ``|d_s| <= update_tol * max(1, ||d||_inf)`` with d = B^{-1} a: the new basis is
  (nearly) singular;
* ``stab_tol`` (1e-8, the sparse manager's stability tolerance): the new diagonal is
  computed twice, ``d1 = d_s u_pp`` from the FTRAN column and ``d2`` from the row eta;
  ``|d1 - d2| > stab_tol |d1|`` means one of them lost its digits;
* ``growth_limit`` (100): ``max_i |c_i| > growth_limit``: a row eta multiplies rows of U
  by up to max |c_i| and every later solve meets it; a fresh LU with partial pivoting
  (multipliers <= 1) is the stable alternative.  Measured (benchmarks/dense_engine.md):
  on random replacement sequences with small leaving pivots (n = 50) the worst backward
  error of a solve after 26-50 updates was 1.4e-12 without the limit and 9.4e-15 with it
  (the product form: 4.0e-14); on the thesis families' paths (n = 50 ... 500) the two
  tests together declined 0.6% of the updates (4% on the worst problem);

and the factors are refreshed after ``update_limit`` updates (``factorization_update_limit``,
50 as in PATH) in any case.  Fresh factors also recompute the basic values from scratch
(as the Python loop does after a refactorization).
"""
from __future__ import annotations

import numpy as np

from .._jit import njit
from ._kernels import VAR_A, VAR_T, VAR_Z, unit_sign


# rows of the integer factor array ``perm`` (N_PERM x (n + limit)): the pivot row of each
# elimination step, the slot at each position (-1: replaced), the position of each slot,
# the position eliminated by each row eta, and P_INFO; then the work of a factorization
# (the slots and rows of a repair, and four rows for factor()), and the ratio test's
# candidate slots (W_CAND, _kernels.ratio_test_bounds), preallocated with the rest
P_ROW, P_SLOT, P_POS, P_ETA, P_INFO, W_REP_SLOT, W_REP_ROW, W_FACTOR = range(8)
W_CAND = W_FACTOR + 4
N_PERM = W_CAND + 1
# perm[P_INFO, 0]: the number m1 of unit columns of the factorization; they are its first
# steps, their columns of L are zero and their columns of U are zero above the diagonal,
# so every solve and update skips them


# outcomes of replace_column (UPD_OK: updated; otherwise the caller refactorizes)
UPD_OK, UPD_UNSTABLE, UPD_GROWTH, UPD_REFUSED, UPD_LIMIT = range(5)


@njit(cache=True)
def basis_column(kind, idx, M, r, art_sign, out):
    """Basis column of a slot variable, written into out."""
    out[:] = 0.0
    if kind == VAR_Z:
        out[:] = M[:, idx]
    elif kind == VAR_T:
        out[:] = r
    else:
        out[idx] = unit_sign(kind, idx, art_sign)


@njit(cache=True)
def factor(M, r, sk, si, art_sign, L, U, prow, qslot, rank_tol, rep_slot, rep_row, home,
           iwork, c):
    """LU of the slot basis (see the module docstring); with ``home`` the repair decision.

    With ``home = True`` the non-unit slots pivot on their home rows (the rows not covered
    by unit columns, in increasing order, given to the non-unit slots in slot order): a
    column is dependent when its remainder on its home row is at most ``rank_tol *
    max(1, ||column||_inf)``, and its artificial takes that row.  This is the thesis'
    repair (start from unit columns, bring the others in while regular), the one the dense
    reference basis makes.  With ``home = False`` every column pivots on the free row of
    largest remainder (partial pivoting): the stable factorization used for the solves.
    Returns the number of dependent slots (slot and row in rep_slot, rep_row; row -1 when
    a covering-vector or slack column is dependent, which nothing can repair).  Work: iwork
    (4 x n integers), c (n)."""
    n = sk.shape[0]
    order = iwork[0]  # elimination order: unit columns first, then M columns and t
    free_rows = iwork[1]
    pivoted = iwork[2]
    covered = iwork[3]
    for i in range(n):
        pivoted[i] = 0
        covered[i] = 0
    m = 0
    for j in range(n):
        if sk[j] != VAR_Z and sk[j] != VAR_T:
            order[m] = j
            covered[si[j]] = 1
            m += 1
    first_nonunit = m
    for j in range(n):
        if sk[j] == VAR_Z or sk[j] == VAR_T:
            order[m] = j
            m += 1
    f = 0
    for i in range(n):
        if covered[i] == 0:
            free_rows[f] = i
            f += 1
    nrep = 0
    for m in range(n):
        j = order[m]
        basis_column(sk[j], si[j], M, r, art_sign, c)
        cmax = 0.0
        for i in range(n):
            a = abs(c[i])
            cmax = max(cmax, a)
        for k in range(m):
            ck = c[prow[k]]
            U[k, m] = ck
            # L[:, k] is zero on the rows pivoted up to step k, and everywhere for the
            # unit steps k < first_nonunit (a unit column eliminates nothing)
            if ck != 0.0 and k >= first_nonunit:
                for i in range(n):
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
                if pivoted[i] == 0:
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
        pivoted[best] = 1
        for i in range(n):
            L[i, m] = 0.0 if pivoted[i] != 0 else c[i] / piv
    return nrep


@njit(cache=True)
def _rows_to_steps(L, prow, n, done, tmp):
    """Permute the rows of L (n x n) from basis rows to elimination steps in place: row m
    of the result is row ``prow[m]`` of the input (cycle by cycle, one row in flight in
    tmp; done: n integers of work)."""
    for i in range(n):
        done[i] = 0
    for start in range(n):
        if done[start] != 0:
            continue
        for i in range(n):
            tmp[i] = L[start, i]
        m = start
        while True:
            done[m] = 1
            src = prow[m]
            if src == start:
                for i in range(n):
                    L[m, i] = tmp[i]
                break
            L[m, :] = L[src, :]
            m = src


@njit(cache=True)
def lu_factor(M, r, sk, si, art_sign, L, U, perm, fwork, rank_tol):
    """Stable LU of the slot table for the solves (partial pivoting, no repair) in the
    form the solves and updates use: L by steps, no update applied.  Returns the number
    of dependent slots found (0: the factors are valid; else their slots and rows are in
    perm[W_REP_SLOT], perm[W_REP_ROW]).  Uses fwork[0] and fwork[2] as work."""
    n = sk.shape[0]
    prow = perm[P_ROW]
    slot_at = perm[P_SLOT]
    nrep = factor(M, r, sk, si, art_sign, L, U, prow, slot_at, rank_tol, perm[W_REP_SLOT],
                  perm[W_REP_ROW], False, perm[W_FACTOR:W_FACTOR + 4], fwork[2, :n])
    if nrep > 0:
        return nrep
    _rows_to_steps(L, prow, n, perm[W_FACTOR], fwork[0])
    m1 = 0
    for j in range(n):
        if sk[j] != VAR_Z and sk[j] != VAR_T:
            m1 += 1
    perm[P_INFO, 0] = m1
    pos_of = perm[P_POS]
    for m in range(n):
        pos_of[slot_at[m]] = m
    for m in range(n, slot_at.shape[0]):
        slot_at[m] = -1
    return 0


@njit(cache=True)
def _forward(L, R, perm, nupd, b, w):
    """w[:n + nupd] = R_nupd ... R_1 L^{-1} P b: the spike of b (w has length n + limit)."""
    n = b.shape[0]
    prow = perm[P_ROW]
    eta_p = perm[P_ETA]
    for m in range(n):
        w[m] = b[prow[m]]
    for m in range(n, n + nupd):
        w[m] = 0.0
    m1 = perm[P_INFO, 0]
    for m in range(m1, n):
        x = w[m]
        if x != 0.0:
            for i in range(m + 1, n):
                w[i] -= L[i, m] * x
    for t in range(nupd):
        p = eta_p[t]
        s = w[p]
        for i in range(max(p + 1, m1), n + t):  # (zero between p and m1)
            s -= R[t, i] * w[i]
        w[n + t] = s
        w[p] = 0.0


@njit(cache=True)
def _backward(U, perm, N, w, out):
    """out[slot] = (U^{-1} w)[position of slot] over positions 0..N-1 (w overwritten)."""
    slot_at = perm[P_SLOT]
    m1 = perm[P_INFO, 0]
    for j in range(N - 1, -1, -1):
        if slot_at[j] < 0:  # a replaced position: its column is gone
            continue
        x = w[j] / U[j, j]
        w[j] = x
        if x != 0.0 and j >= m1:
            for i in range(j):
                w[i] -= U[i, j] * x
        out[slot_at[j]] = x


@njit(cache=True)
def ftran(L, U, R, perm, nupd, b, out, w, spike, keep):
    """out = B^{-1} b (out indexed by slot).  w and spike are work vectors of length
    n + limit; with ``keep`` the spike of b (what :func:`ft_update` needs) is left in
    spike[:n + nupd]."""
    n = b.shape[0]
    N = n + nupd
    _forward(L, R, perm, nupd, b, w)
    if keep:
        spike[:N] = w[:N]
    _backward(U, perm, N, w, out)


@njit(cache=True)
def btran(L, U, R, perm, nupd, c, out, w):
    """out = B^{-T} c (c indexed by slot, out by row); w is work of length n + limit."""
    n = c.shape[0]
    N = n + nupd
    prow = perm[P_ROW]
    slot_at = perm[P_SLOT]
    pos_of = perm[P_POS]
    eta_p = perm[P_ETA]
    for j in range(N):
        w[j] = 0.0
    for s in range(n):
        w[pos_of[s]] = c[s]
    m1 = perm[P_INFO, 0]
    for j in range(N):  # U^T v = Q^T c, forward over the positions
        if slot_at[j] < 0:
            w[j] = 0.0
            continue
        s = w[j]
        if j >= m1:
            for i in range(j):
                s -= U[i, j] * w[i]
        w[j] = s / U[j, j]
    for t in range(nupd - 1, -1, -1):  # R_1^T ... R_k^T
        q = n + t
        s = w[q]
        w[q] = 0.0
        if s != 0.0:
            p = eta_p[t]
            w[p] += s
            for i in range(p + 1, q):
                w[i] -= R[t, i] * s
    for m in range(n - 1, -1, -1):  # L^T
        s = w[m]
        if m >= m1:
            for i in range(m + 1, n):
                s -= L[i, m] * w[i]
        w[m] = s
        out[prow[m]] = s


@njit(cache=True)
def ft_update(U, R, perm, n, nupd, slot, spike, alpha, y, stab_tol, growth_limit):
    """Forrest-Tomlin replacement of the column of ``slot`` (see the module docstring).

    spike: the spike of the entering column (:func:`ftran` with keep), alpha = d[slot]
    its FTRAN entry; y is work (n + limit).  Returns UPD_OK (the factors now represent
    the new basis: the caller counts the update), UPD_UNSTABLE (the two computations of
    the new diagonal disagree) or UPD_GROWTH (a row-eta multiplier above growth_limit);
    the factors are left unchanged unless UPD_OK."""
    N = n + nupd
    slot_at = perm[P_SLOT]
    pos_of = perm[P_POS]
    p = pos_of[slot]
    upp = U[p, p]
    m1 = perm[P_INFO, 0]
    # y = U^{-T} e_p: zero before p, on dead positions and on the unit positions after p
    # (their columns of U are zero above the diagonal)
    y[p] = 1.0 / upp
    for j in range(p + 1, N):
        if slot_at[j] < 0 or j < m1:
            y[j] = 0.0
            continue
        s = -U[p, j] * y[p]
        for i in range(max(p + 1, m1), j):
            s -= U[i, j] * y[i]
        y[j] = s / U[j, j]
    # row eta c_i = -u_pp y_i and the new diagonal from it: d2 = s_p - c^T s = u_pp y^T s
    gmax = 0.0
    d2 = 0.0
    for i in range(p, N):
        d2 += y[i] * spike[i]
        if i > p:
            gmax = max(gmax, abs(upp * y[i]))
    d2 *= upp
    d1 = alpha * upp
    if not (np.isfinite(d2) and d2 != 0.0 and abs(d1 - d2) <= stab_tol * abs(d1)):
        return UPD_UNSTABLE
    if not gmax <= growth_limit:
        return UPD_GROWTH
    q = N
    for i in range(p + 1, N):
        R[nupd, i] = -upp * y[i]
    perm[P_ETA, nupd] = p
    for i in range(N):
        U[i, q] = spike[i]
    U[p, q] = 0.0
    U[q, q] = d2
    slot_at[p] = -1
    slot_at[q] = slot
    pos_of[slot] = q
    return UPD_OK


@njit(cache=True)
def replace_column(U, R, perm, nupd, slot, d, spike, y, update_tol, stab_tol,
                   growth_limit):
    """Replace the column of ``slot`` by the column whose FTRAN is d (slots) and spike
    ``spike`` (:func:`ftran` with keep), after ``nupd`` updates.  Returns UPD_OK (the
    factors now represent the new basis) or why the caller must refactorize: UPD_REFUSED
    (``|d[slot]| <= update_tol * max(1, ||d||_inf)``: a (nearly) singular replacement),
    UPD_LIMIT (``nupd`` is the update limit, the number of rows of R), UPD_UNSTABLE or
    UPD_GROWTH (:func:`ft_update`); the factors are unchanged then."""
    n = d.shape[0]
    dmax = 0.0
    for k in range(n):
        dmax = max(dmax, abs(d[k]))
    if abs(d[slot]) <= update_tol * max(1.0, dmax):
        return UPD_REFUSED
    if nupd >= R.shape[0]:
        return UPD_LIMIT
    return ft_update(U, R, perm, n, nupd, slot, spike, d[slot], y, stab_tol, growth_limit)


def allocate_factors(n: int, update_limit: int):
    """The preallocated factor arrays of an n x n basis with up to ``update_limit``
    updates: L (n x n), U ((n + limit)^2, column-major), R (limit x (n + limit)), perm
    (N_PERM x (n + limit), rows P_ROW ... and work rows) and fwork (3 x (n + limit)):
    nothing else is allocated by the path, its updates or its factorizations."""
    nmax = n + max(int(update_limit), 0)
    L = np.zeros((n, n), order="F")
    U = np.zeros((nmax, nmax), order="F")
    R = np.zeros((max(int(update_limit), 0), nmax))
    perm = np.zeros((N_PERM, nmax), dtype=np.int64)
    fwork = np.zeros((3, nmax))
    return L, U, R, perm, fwork
