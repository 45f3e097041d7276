"""Compiled Fischer–Burmeister vector, its generalized Jacobian's diagonals, gradient and
directional derivative for :mod:`compass_sparse.merit`, the norms of :mod:`compass_sparse.box`,
the normal map, the residual report and the acceptance test's kernels (the CSC helpers
they call are :mod:`compass_sparse.linalg._csc_kernels`).

Same formulas as merit.fischer / merit.fb_phi, one element at a time: the arguments of
phi(a, b) = sqrt(a^2 + b^2) - a - b are scaled by the power of two of max(|a|, |b|) (exact)
and the cancelling case a + b > 0 is evaluated as -2ab / (sqrt(a^2 + b^2) + a + b).  One
pass over the vector instead of ~30 array operations: a small problem evaluates Phi at
every trial point of every line search, where the array version cost ~50 us per call.
"""
import math

import numpy as np

from ._jit import njit
from .linalg._csc_kernels import csc_abs_maxima


@njit(cache=True, inline="always")
def _fischer(a, b):
    big = max(abs(a), abs(b))
    e = math.frexp(big)[1] if np.isfinite(big) else 1
    a = math.ldexp(a, -e)
    b = math.ldexp(b, -e)
    r = math.hypot(a, b)
    s = a + b
    if s > 0.0:
        out = -2.0 * (a / (r + s)) * b if r + s > 0.0 else 0.0
    else:
        out = r - s
    return math.ldexp(out, e)


@njit(cache=True)
def fb_phi_kernel(z, f, lb, ub, phi):
    for i in range(z.shape[0]):
        fl = np.isfinite(lb[i])
        fu = np.isfinite(ub[i])
        if fl and not fu:
            phi[i] = _fischer(z[i] - lb[i], f[i])
        elif fu and not fl:
            phi[i] = -_fischer(ub[i] - z[i], -f[i])
        elif fl and fu:
            phi[i] = _fischer(z[i] - lb[i], _fischer(ub[i] - z[i], -f[i]))
        else:
            phi[i] = -f[i]


@njit(cache=True)
def max_abs_kernel(x, y, diff):
    """max |x_i - y_i| when ``diff``, else max |x_i| (y unread): NaN when a term is one, as
    np.max; 0 for empty vectors."""
    m = 0.0
    for i in range(x.shape[0]):
        a = abs(x[i] - y[i]) if diff else abs(x[i])
        if a != a:
            return a
        if a > m:
            m = a
    return m


@njit(cache=True)
def all_finite_kernel(x):
    """Whether every entry of the float vector x is finite (evaluation.all_finite)."""
    for i in range(x.shape[0]):
        if not np.isfinite(x[i]):
            return False
    return True


@njit(cache=True, inline="always")
def _fischer_grad(a, b):
    """(d phi / da, d phi / db), the direction (1, 1)/sqrt(2) at (0, 0) (merit._fischer_grad)."""
    r = math.hypot(a, b)
    if r == 0.0:
        g = 1.0 / math.sqrt(2.0)
        return g - 1.0, g - 1.0
    return a / r - 1.0, b / r - 1.0


@njit(cache=True)
def fb_diagonals_kernel(z, f, lb, ub, da, db):
    """The diagonals of merit.fb_jacobian_diagonals, one element at a time."""
    for i in range(z.shape[0]):
        fl = np.isfinite(lb[i])
        fu = np.isfinite(ub[i])
        if fl and not fu:
            da[i], db[i] = _fischer_grad(z[i] - lb[i], f[i])
        elif fu and not fl:
            da[i], db[i] = _fischer_grad(ub[i] - z[i], -f[i])
        elif fl and fu:
            a1 = ub[i] - z[i]
            c = _fischer(a1, -f[i])
            ia, ib = _fischer_grad(a1, -f[i])
            oa, ob = _fischer_grad(z[i] - lb[i], c)
            da[i] = oa - ob * ia
            db[i] = -ob * ib
        else:
            da[i] = 0.0
            db[i] = -1.0


@njit(cache=True)
def fb_gradient_kernel(z, f, lb, ub, phi, indptr, indices, data, g):
    """g = grad Psi(z) = da Phi + J^T (db Phi) for a square CSC J (merit.fb_gradient) in
    one pass, where the array formula made five arrays and three kernel calls per major
    iteration's descent test: the same products and sums, in the same order, as that
    formula with csc_rmatvec (so the same bits)."""
    n = z.shape[0]
    da = np.empty(n)
    db = np.empty(n)
    fb_diagonals_kernel(z, f, lb, ub, da, db)
    u = db * phi
    for j in range(n):
        s = 0.0
        for k in range(indptr[j], indptr[j + 1]):
            s += data[k] * u[indices[k]]
        g[j] = da[j] * phi[j] + s


@njit(cache=True)
def fb_directional_kernel(z, f, lb, ub, phi, indptr, indices, data, zc, g, d):
    """grad Psi(z) . (zc - z), the directional derivative of the descent test of a major
    iteration, in one call: g as fb_gradient_kernel, d = zc - z, and their product by
    np.dot (the same BLAS routine as the array formula's ``g @ (zc - z)``, so the same
    bits).  ``g``, ``d``: work vectors of length n."""
    fb_gradient_kernel(z, f, lb, ub, phi, indptr, indices, data, g)
    for i in range(z.shape[0]):
        d[i] = zc[i] - z[i]
    return np.dot(g, d)


@njit(cache=True, inline="always")
def _absorbed(zi, fi, li, ui):
    """(w, v) of merit.normal_map_at for one index: the part of F absorbed by the normal
    cone at a lower bound (w) or an upper one (v), both at a fixed variable."""
    # max(+-f, 0) exactly as np.maximum: the first argument when larger or NaN, else the
    # second (so max(-0.0, 0.0) is 0.0)
    fp = fi if (fi > 0.0 or fi != fi) else 0.0
    fm = -fi if (-fi > 0.0 or fi != fi) else 0.0
    if li == ui:
        return fp, fm
    if zi <= li:
        return fp, 0.0
    if zi >= ui:
        return 0.0, fm
    return 0.0, 0.0


@njit(cache=True)
def normal_map_kernel(z, f, lb, ub, x, nm):
    """merit.normal_map_at one element at a time: the slack w absorbed at a lower bound,
    v at an upper one (both at a fixed variable); x = z - w + v, nm = f - w + v."""
    for i in range(z.shape[0]):
        zi, fi = z[i], f[i]
        w, v = _absorbed(zi, fi, lb[i], ub[i])
        x[i] = zi - w + v
        nm[i] = fi - w + v


@njit(cache=True)
def flat_step_kernel(z, f, lb, ub, phi, da, db, indptr, indices, data, row_max, col_max,
                     diag):
    """The scale test of :mod:`compass_sparse.nms.acceptance` on a canonical CSC J: over the
    rows with Phi_i != 0, the largest d_i / (1 + |z_i|), where d_i is the larger of the
    Fischer-Burmeister row's Newton step |Phi_i| / ||H_i||_inf, H = diag(da) + diag(db) J,
    and, where the natural map's F-piece is active (z_i - u_i < F_i < z_i - l_i), the F
    row's step |F_i| / ||J_i||_inf (d_i = inf where the row is zero).  Returns (row,
    d_row, ratio), row -1 when Phi = 0; the first row attains a tie.  ``row_max``
    (zeroed), ``col_max`` and ``diag`` are work areas of length n."""
    csc_abs_maxima(indptr, indices, data, row_max, col_max, diag)
    best, best_d, best_ratio = -1, 0.0, -1.0
    for i in range(z.shape[0]):
        if phi[i] == 0.0:
            continue
        h1 = abs(db[i]) * row_max[i]
        h2 = abs(da[i] + db[i] * diag[i])
        h = h1 if (h1 > h2 or h1 != h1) else h2  # np.maximum
        d = abs(phi[i]) / h if h > 0.0 else np.inf
        # At a bound the FB row is mostly the bound's own (da = -1): its step says
        # nothing of F.  The natural map's F row does (F = 1e-9 (x - 1) at x = 0).
        fi = f[i]
        if z[i] - ub[i] < fi < z[i] - lb[i]:
            dn = abs(fi) / row_max[i] if row_max[i] > 0.0 else np.inf
            if dn > d:
                d = dn
        ratio = d / (1.0 + abs(z[i]))
        if best < 0 or ratio > best_ratio:
            best, best_d, best_ratio = i, d, ratio
    return best, best_d, best_ratio


@njit(cache=True)
def scale_test_kernel(z, f, lb, ub, phi, indptr, indices, data):
    """flat_step_kernel with the diagonals of fb_diagonals_kernel and the work areas made
    inside: the whole scale test of a point in one call (z, f, lb, ub, phi float64
    vectors of length n, J canonical CSC)."""
    n = z.shape[0]
    da = np.empty(n)
    db = np.empty(n)
    fb_diagonals_kernel(z, f, lb, ub, da, db)
    return flat_step_kernel(z, f, lb, ub, phi, da, db, indptr, indices, data, np.zeros(n),
                            np.empty(n), np.empty(n))


@njit(cache=True)
def residual_maxima_kernel(z, f, lb, ub, phi, mm):
    """The maxima of merit.residual_report in one pass: mm = |z - pi(z - F)| (as
    merit.min_map, the median form), and (max |Phi|, max mm, max |F_B|), NaN propagating
    as np.max does."""
    fb_inf = 0.0
    natural = 0.0
    nm_inf = 0.0
    for i in range(z.shape[0]):
        zi, fi, li, ui = z[i], f[i], lb[i], ub[i]
        lo = zi - ui
        hi = zi - li
        m = fi if (fi > lo or fi != fi) else lo  # np.maximum(f, z - u)
        m = m if (m < hi or m != m) else hi  # np.minimum(., z - l)
        a = abs(m)
        mm[i] = a
        if a > natural or a != a:
            natural = a
        p = abs(phi[i])
        if p > fb_inf or p != p:
            fb_inf = p
        w, v = _absorbed(zi, fi, li, ui)
        r = abs(fi - w + v)
        if r > nm_inf or r != r:
            nm_inf = r
    return fb_inf, natural, nm_inf


@njit(cache=True)
def residual_report_kernel(z, f, lb, ub, phi, mm, idx):
    """The numbers of merit.residual_report in one call (a Python route of six array
    operations and calls cost a small solve ~10 us): the maxima of
    :func:`residual_maxima_kernel`, ||Phi||_2 as box.norm2 takes it (scaled by
    ||Phi||_inf against over- and underflow: m sqrt(s . s), s = Phi / m; m itself when
    it is 0 or not finite), Phi . Phi (merit.fb_psi's product) and the rows of the
    len(idx) largest |Phi_i| by :func:`top_abs_distinct` (whose answer, False on a tie,
    is returned last).  The products are np.dot's, the same BLAS product as the Python
    route's."""
    fb_inf, natural, nm_inf = residual_maxima_kernel(z, f, lb, ub, phi, mm)
    fb_norm = fb_inf
    if fb_inf != 0.0 and math.isfinite(fb_inf):
        s = phi / fb_inf
        fb_norm = fb_inf * math.sqrt(np.dot(s, s))
    distinct = top_abs_distinct(phi, idx) if idx.shape[0] > 0 else False
    return fb_inf, natural, nm_inf, fb_norm, np.dot(phi, phi), distinct


@njit(cache=True)
def min_map_within(z, f, lb, ub, tol):
    """Whether |z_i - pi(z_i - F_i)| <= tol for every i, with the min-map formed as
    merit.min_map forms it, min(max(F, z - u), z - l), and a NaN anywhere in it (z - u
    or z - l of infinite z, or F) failing the test as it does there."""
    for i in range(z.shape[0]):
        a = z[i] - ub[i]
        b = z[i] - lb[i]
        fi = f[i]
        if a != a or b != b or fi != fi:
            return False
        m = fi if fi > a else a
        if b < m:
            m = b
        if not abs(m) <= tol:
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


@njit(cache=True, inline="always")
def np_max(a, b):
    """np.maximum(a, b) of two floats, b not NaN: b on a tie, as numpy (0.0 and -0.0)."""
    return a if (a > b or a != a) else b


@njit(cache=True, inline="always")
def np_min(a, b):
    """np.minimum(a, b) of two floats, b not NaN: b on a tie, as numpy."""
    return a if (a < b or a != a) else b
