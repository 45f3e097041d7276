"""Compiled helpers of the evaluation layer and of the direct Newton step: the checks and
copies that every Jacobian evaluation and every sparse direct step of a small problem
makes, each in one pass instead of several array operations (a few microseconds each,
asked several times per major iteration)."""
import numpy as np

from ._jit import njit


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
