"""Compiled hot loops of the basis manager (numba, ``cache=True``).

All vectors are indexed by *position* (the pivot order of the factorization): positions
``0..n-1`` belong to the fresh factorization, position ``n + k`` is created by the k-th
Forrest-Tomlin update. Every loop runs over positions in index order, which is a valid
triangular order for L (positions < n only) and for U (the appended columns have larger
indices than every row they touch).

Storage
-------
L : strictly lower part, CSC (``Lp, Li, Lx``) and its CSR copy (``Lrp, Lri, Lrx``) for
    the transposed solve; unit diagonal implicit.
U : column ``j`` holds ``Ui[Us[j]:Ue[j]]``, ``Ux[...]`` (off-diagonal entries, rows < j)
    and ``Ud[j]`` (the diagonal). A replaced position gets an empty column with diagonal
    1 (a "dead" position); entries of old columns in dead rows stay in place and only
    accumulate ignored values in the backward solve. A row-wise copy of the fresh U
    (``Urp, Urj, Urx``) serves the transposed solve; ``dead`` flags the dead positions.
R : the row-eta file; eta t eliminates position ``Rp_pos[t]`` into ``Rq[t]``:
    ``w[q] = w[p] - sum_e Rx[e] * w[Ri[e]]`` (e in ``Rs[t]:Rs[t+1]``), then ``w[p] = 0``.

The column-oriented solves skip zero entries, so a sparse right-hand side costs O(N)
index checks plus the flops on its actual fill (not O(nnz(L + U))).
"""

from __future__ import annotations

import numpy as np
from .._jit import njit


@njit(cache=True)
def lsolve(Lp, Li, Lx, w, start):
    """In place: w <- L^{-1} w (unit lower triangular, strictly lower part in CSC)."""
    n = Lp.shape[0] - 1
    for j in range(start, n):
        x = w[j]
        if x != 0.0:
            for e in range(Lp[j], Lp[j + 1]):
                w[Li[e]] -= Lx[e] * x


@njit(cache=True)
def ltsolve(Lrp, Lri, Lrx, w, start):
    """In place: w <- L^{-T} w, using the CSR copy (row j of L) of the strict lower part."""
    n = Lrp.shape[0] - 1
    for j in range(n - 1, start - 1, -1):
        x = w[j]
        if x != 0.0:
            for e in range(Lrp[j], Lrp[j + 1]):
                w[Lri[e]] -= Lrx[e] * x


@njit(cache=True)
def apply_etas(Rs, Ri, Rx, Rpos, Rq, k, w):
    """In place: w <- R_k ... R_1 w (FTRAN direction)."""
    for t in range(k):
        p = Rpos[t]
        s = w[p]
        for e in range(Rs[t], Rs[t + 1]):
            s -= Rx[e] * w[Ri[e]]
        w[Rq[t]] = s
        w[p] = 0.0


@njit(cache=True)
def apply_etas_t(Rs, Ri, Rx, Rpos, Rq, k, w):
    """In place: w <- R_1^T ... R_k^T w (BTRAN direction)."""
    for t in range(k - 1, -1, -1):
        q = Rq[t]
        s = w[q]
        w[q] = 0.0
        if s != 0.0:
            w[Rpos[t]] += s
            for e in range(Rs[t], Rs[t + 1]):
                w[Ri[e]] -= Rx[e] * s


@njit(cache=True)
def usolve(Us, Ue, Ui, Ux, Ud, w, N):
    """In place: w <- U^{-1} w over positions 0..N-1 (column-oriented, backward)."""
    for j in range(N - 1, -1, -1):
        x = w[j]
        if x != 0.0:
            x = x / Ud[j]
            w[j] = x
            for e in range(Us[j], Ue[j]):
                w[Ui[e]] -= Ux[e] * x


@njit(cache=True)
def utsolve(Urp, Urj, Urx, dead, n, Us, Ue, Ui, Ux, Ud, w, start, N):
    """In place: w <- U^{-T} w over positions start..N-1 (w[:start] must be zero).

    Positions < n (the fresh factorization) are solved column-oriented through the
    row-wise copy of the fresh U (``Urp, Urj, Urx``), skipping zeros and the entries of
    dead columns; the appended columns (positions >= n, at most update_limit of them)
    are solved in dot-product form from their column storage.
    """
    n0 = min(n, N)
    for j in range(start, n0):
        if dead[j]:
            w[j] = 0.0
            continue
        x = w[j]
        if x != 0.0:
            x = x / Ud[j]
            w[j] = x
            for e in range(Urp[j], Urp[j + 1]):
                k = Urj[e]
                if not dead[k]:
                    w[k] -= Urx[e] * x
    for j in range(max(start, n), N):
        if dead[j]:
            w[j] = 0.0
            continue
        s = w[j]
        for e in range(Us[j], Ue[j]):
            s -= Ux[e] * w[Ui[e]]
        w[j] = s / Ud[j]


@njit(cache=True)
def dot_from(a, b, start):
    """sum_{i >= start} a[i] * b[i] (plain loop: no BLAS thread start-up in the hot path)."""
    s = 0.0
    for i in range(start, a.shape[0]):
        if a[i] != 0.0:
            s += a[i] * b[i]
    return s


def warmup():
    """Compile (or load from the cache) every kernel once."""
    i1 = np.zeros(2, dtype=np.int64)
    i0 = np.zeros(1, dtype=np.int64)
    f0 = np.zeros(0)
    i00 = np.zeros(0, dtype=np.int64)
    w = np.zeros(1)
    lsolve(i1, i00, f0, w, 0)
    ltsolve(i1, i00, f0, w, 0)
    apply_etas(i0, i00, f0, i00, i00, 0, w)
    apply_etas_t(i0, i00, f0, i00, i00, 0, w)
    d = np.ones(1)
    usolve(i0, i0, i00, f0, d, w, 1)
    dead = np.zeros(1, dtype=np.bool_)
    utsolve(i1, i00, f0, dead, 1, i0, i0, i00, f0, d, w, 0, 1)
    dot_from(w, w, 0)
    for it in (np.int64, np.int32):  # (the factors' indices come in either width)
        j0, j00 = i0.astype(it), i00.astype(it)
        assemble_triangle(1, 0, j0, j00, f0, True, j0, j00, f0, i0)
        assemble_triangle(1, 0, j0, j00, f0, False, j0, j00, f0, i0)


@njit(cache=True)
def assemble_triangle(n, m1, Kp, Ki, Kx, lower, Cp, Ci, Cx, rowpos):
    """CSC arrays (data, indices, indptr) of the n x n factor of B over positions.

    Column ``m1 + j`` holds the strictly lower (``lower``) or strictly upper part of column
    j of the block factor (Kp, Ki, Kx), rows shifted by m1, preceded (upper only) by the
    entries of column j of C = (Cp, Ci, Cx) whose row has a position ``rowpos[i] < m1``
    (the unit-covered rows).  Columns 0..m1-1 are empty.  Two passes: count, then fill.
    """
    mk = Kp.shape[0] - 1
    indptr = np.zeros(n + 1, np.int64)
    for j in range(mk):
        cnt = 0
        if not lower:
            for e in range(Cp[j], Cp[j + 1]):
                if rowpos[Ci[e]] < m1:
                    cnt += 1
        for e in range(Kp[j], Kp[j + 1]):
            r = Ki[e]
            if (lower and r > j) or ((not lower) and r < j):
                cnt += 1
        indptr[m1 + j + 1] = cnt
    for c in range(n):
        indptr[c + 1] += indptr[c]
    nnz = indptr[n]
    ind = np.empty(nnz, np.int64)
    val = np.empty(nnz)
    for j in range(mk):
        q = indptr[m1 + j]
        if not lower:
            for e in range(Cp[j], Cp[j + 1]):
                p = rowpos[Ci[e]]
                if p < m1:
                    ind[q] = p
                    val[q] = Cx[e]
                    q += 1
        for e in range(Kp[j], Kp[j + 1]):
            r = Ki[e]
            if (lower and r > j) or ((not lower) and r < j):
                ind[q] = r + m1
                val[q] = Kx[e]
                q += 1
    return val, ind, indptr
