"""Compiled kernels on CSC matrices given by their arrays (indptr, indices, data).

Products (M x, M^T u), the diagonal, dense copies, entry scalings and their maxima, the
tests of a canonical pattern and of two patterns being one, values copied onto a pattern,
and the block M_FF of the free indices with its right-hand side -(q + M_FN z_N)_F.
Each loops over the stored entries once, in storage order, so that its sums are the ones
a column-by-column product makes (the callers' bits do not depend on scipy's dispatch).
"""
import numpy as np

from .._jit import njit


@njit(cache=True)
def csc_rmatvec(indptr, indices, data, u, out):
    """out = A^T u for A in CSC form (column j of A is row j of A^T)."""
    for j in range(out.shape[0]):
        s = 0.0
        for k in range(indptr[j], indptr[j + 1]):
            s += data[k] * u[indices[k]]
        out[j] = s


@njit(cache=True)
def csc_diagonal(indptr, indices, data, diag):
    """diag[j] = A_jj of a CSC matrix A (duplicates summed, 0 where not stored), as
    scipy's A.diagonal() without its dispatch (~15 us on a small matrix)."""
    for j in range(diag.shape[0]):
        d = 0.0
        for k in range(indptr[j], indptr[j + 1]):
            if indices[k] == j:
                d += data[k]
        diag[j] = d


@njit(cache=True)
def csc_abs_maxima(indptr, indices, data, rows, cols, diag):
    """Of a canonical CSC matrix A: rows[i] = max_j |A_ij|, cols[j] = max_i |A_ij| and
    diag[j] = A_jj (0 where not stored), in one pass over the stored entries (a NaN entry
    makes its row and column maxima NaN, as np.maximum does).  The caller zeroes rows."""
    for j in range(cols.shape[0]):
        c = 0.0
        d = 0.0
        for k in range(indptr[j], indptr[j + 1]):
            i = indices[k]
            a = abs(data[k])
            if a > c or a != a:
                c = a
            if a > rows[i] or a != a:
                rows[i] = a
            if i == j:
                d = data[k]
        cols[j] = c
        diag[j] = d


@njit(cache=True)
def csc_scaled_abs_maxima(indptr, indices, data, row, col, rows, cols):
    """Row and column max-norms of diag(row) A diag(col) for a canonical CSC A, entry
    (|a_ij| row_i) col_j as scaling._maxnorms' array formula (NaN propagates as in
    np.maximum); the caller zeroes rows and cols."""
    for j in range(cols.shape[0]):
        c = 0.0
        for k in range(indptr[j], indptr[j + 1]):
            i = indices[k]
            a = abs(data[k]) * row[i] * col[j]
            if a > c or a != a:
                c = a
            if a > rows[i] or a != a:
                rows[i] = a
        cols[j] = c


@njit(cache=True)
def csc_is_canonical(indptr, indices, nrows, nnz):
    """Whether CSC index arrays are valid and canonical: indptr runs from 0 to nnz without
    decreasing, and every column's row indices lie in [0, nrows) strictly increasing
    (sorted, no duplicates)."""
    if indptr[0] != 0 or indptr[indptr.shape[0] - 1] != nnz or indices.shape[0] < nnz:
        return False
    for j in range(indptr.shape[0] - 1):
        a, b = indptr[j], indptr[j + 1]
        if b < a:
            return False
        prev = -1
        for k in range(a, b):
            i = indices[k]
            if i <= prev or i >= nrows:
                return False
            prev = i
    return True


@njit(cache=True)
def csc_scale(indptr, indices, data, row, col, out):
    """out[k] = (a_k row_i) col_j for every stored entry k = (i, j) of a CSC matrix."""
    for j in range(indptr.shape[0] - 1):
        for k in range(indptr[j], indptr[j + 1]):
            out[k] = data[k] * row[indices[k]] * col[j]


@njit(cache=True)
def csc_max_norm_spread(indptr, indices, data, n):
    """max(positive_spread(rows), positive_spread(cols)) of the row and column max-norms
    of a canonical square CSC matrix of order n (scaling.spread in one call: the scaling
    trigger asks for it in every solve)."""
    rows = np.zeros(n)
    cols = np.zeros(n)
    csc_abs_maxima(indptr, indices, data, rows, cols, np.empty(n))
    return max(positive_spread(rows), positive_spread(cols))


@njit(cache=True)
def csc_matvec(indptr, indices, data, x, out):
    """out = A x for A in CSC form, column by column (scipy's csc_matvec order)."""
    out[:] = 0.0
    for j in range(x.shape[0]):
        xj = x[j]
        for k in range(indptr[j], indptr[j + 1]):
            out[indices[k]] += data[k] * xj


@njit(cache=True)
def csc_to_dense(indptr, indices, data, out):
    """out[:, :] = A for A in CSC form (duplicate entries summed), in place."""
    out[:, :] = 0.0
    for j in range(out.shape[1]):
        for k in range(indptr[j], indptr[j + 1]):
            out[indices[k], j] += data[k]


@njit(cache=True)
def csc_same_pattern(indptr, indices, pindptr, pindices):
    """Whether two CSC index arrays hold the same pattern (pointers equal, the nnz first
    row indices equal; nnz = pindptr[-1] = len(pindices))."""
    m = pindptr.shape[0]
    if indptr.shape[0] != m:
        return False
    for j in range(m):
        if indptr[j] != pindptr[j]:
            return False
    nnz = pindices.shape[0]
    if indptr[m - 1] != nnz or indices.shape[0] < nnz:
        return False
    for k in range(nnz):
        if indices[k] != pindices[k]:
            return False
    return True


@njit(cache=True)
def csc_copy_on_pattern(indptr, indices, data, pindptr, pindices, out):
    """Whether the CSC index arrays (indptr, indices) are exactly the pattern (pindptr,
    pindices) -- the same column pointers and, in the nnz = pindptr[-1] first places, the
    same row indices -- and if so, data[:nnz] copied into ``out`` (length nnz).  A pattern
    that is canonical (sorted, duplicate-free) makes an equal matrix canonical too."""
    nnz = pindices.shape[0]
    if data.shape[0] < nnz or not csc_same_pattern(indptr, indices, pindptr, pindices):
        return False
    for k in range(nnz):
        out[k] = data[k]
    return True


@njit(cache=True)
def free_block(indptr, indices, data, free, z, q):
    """(Kp, Ki, Kx, rhs, nnz) of M_FF (CSC, int32 index arrays with room for nnz(M)) and
    rhs = -(q + M_FN z_N)_F for the indices F where ``free`` is True: the positions in F,
    the arrays and the pass of :func:`free_block_into` in one call."""
    n = free.shape[0]
    pos = np.empty(n, dtype=np.int64)
    nf = 0
    for i in range(n):
        if free[i]:
            pos[i] = nf
            nf += 1
        else:
            pos[i] = -1
    nnz = indptr[n]
    Kp = np.zeros(nf + 1, dtype=np.int32)
    Ki = np.empty(nnz, dtype=np.int32)
    Kx = np.empty(nnz)
    rhs = np.empty(nf)
    k = free_block_into(indptr, indices, data, pos, z, q, Kp, Ki, Kx, rhs)
    return Kp, Ki, Kx, rhs, k


@njit(cache=True)
def free_block_into(indptr, indices, data, pos, z, q, Kp, Ki, Kx, rhs):
    """The CSC arrays of M_FF (``pos[i]``: position of i in F, or -1) into Kp/Ki/Kx and
    rhs = -(q + M_FN z_N)_F; returns nnz(M_FF)."""
    for i in range(pos.shape[0]):
        if pos[i] >= 0:
            rhs[pos[i]] = -q[i]
    k = 0
    Kp[0] = 0
    for j in range(pos.shape[0]):
        pj = pos[j]
        for e in range(indptr[j], indptr[j + 1]):
            pi = pos[indices[e]]
            if pi < 0:
                continue
            if pj >= 0:
                Ki[k] = pi
                Kx[k] = data[e]
                k += 1
            else:
                rhs[pi] -= data[e] * z[j]
        if pj >= 0:
            Kp[pj + 1] = k
    return k


@njit(cache=True)
def csc_scaled_all_finite(indptr, indices, data, row, col):
    """Whether every stored entry of diag(row) J diag(col), computed as the scaling's
    kernel computes it ((a_ij row_i) col_j), is finite -- without building it."""
    for j in range(indptr.shape[0] - 1):
        for k in range(indptr[j], indptr[j + 1]):
            if not np.isfinite(data[k] * row[indices[k]] * col[j]):
                return False
    return True


@njit(cache=True)
def positive_spread(v):
    """max / min of the positive entries of v (1 when there are none)."""
    lo = np.inf
    hi = 0.0
    for x in v:
        if x > 0.0:
            if x < lo:
                lo = x
            if x > hi:
                hi = x
    return hi / lo if hi > 0.0 else 1.0
