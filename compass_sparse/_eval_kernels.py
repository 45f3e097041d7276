"""Compiled helpers of the evaluation layer and of the direct Newton step: the checks and
copies that every Jacobian evaluation and every sparse direct step of a small problem
makes, each in one pass instead of several array operations (a few microseconds each,
asked several times per major iteration)."""
import numpy as np

from ._jit import njit


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
def top_abs_distinct(v, idx):
    """The indices of the k = len(idx) largest |v_i|, largest first, into idx, when that
    answer is unique: the k largest values distinct and the k-th larger than the next
    (ties are ordered by the caller's own sort instead, which this pass need not
    imitate).  Returns False (idx undefined) on a tie, a NaN, or k > len(v)."""
    k = idx.shape[0]
    n = v.shape[0]
    if k == 0 or k > n:
        return False
    vals = np.empty(k + 1)
    ids = np.empty(k + 1, dtype=np.int64)
    cnt = 0
    for i in range(n):
        a = abs(v[i])
        if a != a:  # NaN
            return False
        if cnt == k + 1 and not a > vals[k]:
            continue
        # insertion into the descending list (the last entry drops when it is full)
        p = cnt if cnt < k + 1 else k
        while p > 0 and vals[p - 1] < a:
            if p < k + 1:
                vals[p] = vals[p - 1]
                ids[p] = ids[p - 1]
            p -= 1
        vals[p] = a
        ids[p] = i
        if cnt < k + 1:
            cnt += 1
    for j in range(1, k):
        if not vals[j - 1] > vals[j]:
            return False
    if cnt > k and not vals[k - 1] > vals[k]:
        return False
    for j in range(k):
        idx[j] = ids[j]
    return True


@njit(cache=True)
def clean_bounds(lo, hi, big):
    """Bounds at or beyond ``big`` in magnitude made infinite (in place, either side), and
    whether the pair is then valid: no NaN, lo < +inf, hi > -inf, lo <= hi.  One pass for
    what problem.as_bounds asks with eight array operations; on False the caller finds and
    names the first offending variable."""
    ok = True
    for i in range(lo.shape[0]):
        a = lo[i]
        b = hi[i]
        if a <= -big:
            a = -np.inf
        elif a >= big:
            a = np.inf
        if b >= big:
            b = np.inf
        elif b <= -big:
            b = -np.inf
        lo[i] = a
        hi[i] = b
        if not (a <= b and a < np.inf and b > -np.inf):  # (False on a NaN)
            ok = False
    return ok


@njit(cache=True)
def any_equal(a, b):
    """Whether a_i == b_i for some i (a fixed variable, l_i = u_i: the preprocessor's test
    in every solve, where (lb == ub).any() costs ~2.5 us on a short vector)."""
    for i in range(a.shape[0]):
        if a[i] == b[i]:
            return True
    return False
