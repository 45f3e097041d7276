"""Compiled helpers of the problem layer: the bounds' validation, the memo's look-up key,
and the test for fixed variables, each in one pass instead of several array operations (a
few microseconds each, asked at every evaluation or every solve)."""
import numpy as np

from .._jit import njit


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


@njit(cache=True)
def memo_key_kernel(x, out):
    """out = x with -0.0 made 0.0 (the bytes of equal points are then equal); returns
    whether x holds a NaN (evaluation._Memo.probe)."""
    nan = False
    for i in range(x.shape[0]):
        v = x[i]
        if v == 0.0:
            v = 0.0
        elif v != v:
            nan = True
        out[i] = v
    return nan
