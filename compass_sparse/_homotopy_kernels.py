"""Compiled smoothed projection for :mod:`compass_sparse.homotopy`.

One pass over the vector instead of the ~25 array operations of
:meth:`~compass_sparse.homotopy.SmoothedNormalMap.project_arrays` (about 50 us a call at
n = 1, and the tracker asks it at every corrector iteration).  The same formulas, element
by element: s_mu(r) = max(r, 0) + mu (2 mu / (q + |r|)), q = hypot(r, 2 mu), and
p = base + s_mu(x - l) - s_mu(x - u) with base = l on rows with a lower bound, x elsewhere;
terms of absent bounds are left out instead of multiplied by 0.  The values of the
homotopy map and the bordered matrix of a dense step are one pass each too, in the array
expressions' order of operations.
"""
import math

from ._jit import njit
from ._merit_kernels import csc_matvec


@njit(cache=True, inline="always")
def _splus(r, mu):
    """(s_mu(r), d/dr, d/dmu)."""
    if mu <= 0.0:
        return max(r, 0.0), 1.0 if r > 0.0 else 0.0, 0.0
    q = math.hypot(r, 2.0 * mu)
    return max(r, 0.0) + mu * (2.0 * mu / (q + abs(r))), 0.5 * (1.0 + r / q), 2.0 * mu / q


@njit(cache=True)
def smoothed_projection(x, mu, lb, ub, p, dx, dmu):
    """p = p_mu(x) clipped to [lb, ub], dx = dp/dx, dmu = dp/dmu, in place."""
    for i in range(x.shape[0]):
        xi, li, ui = x[i], lb[i], ub[i]
        has_l = li > -math.inf
        has_u = ui < math.inf
        pi = li if has_l else xi
        di = 0.0 if has_l else 1.0
        mi = 0.0
        if has_l:
            s, d, m = _splus(xi - li, mu)
            pi += s
            di += d
            mi += m
        if has_u:
            s, d, m = _splus(xi - ui, mu)
            pi -= s
            di -= d
            mi -= m
        # the smoothed projection may leave the box by rounding only
        p[i] = min(max(pi, li), ui)
        dx[i] = di
        dmu[i] = mi


@njit(cache=True)
def homotopy_values(f, x, p, a, lam, G, H):
    """G = F(p) + x - p (the smoothed normal map) and H = lam G + (1 - lam)(x - a), in
    place, in the array expressions' order of operations (the same bits)."""
    c = 1.0 - lam
    for i in range(x.shape[0]):
        g = (f[i] + x[i]) - p[i]
        G[i] = g
        H[i] = lam * g + c * (x[i] - a[i])


@njit(cache=True)
def dense_bordered(indptr, indices, data, dx, dmu, lam, mu0, G, x, a, B, work):
    """The first n rows of the bordered matrix [[H_x, H_lam], [v^T]] into B ((n + 1) x
    (n + 1)): H_x = lam J D + I - lam D (D = diag(dx), J in CSC form) and
    H_lam = G - (x - a) - lam mu0 (J dmu - dmu), in the order of operations of the array
    expressions of ``_Tracker.residual`` (the same bits); ``work``: n floats."""
    n = x.shape[0]
    for j in range(n):
        for i in range(n):
            B[i, j] = 0.0
        for k in range(indptr[j], indptr[j + 1]):
            B[indices[k], j] += data[k]
        s = lam * dx[j]
        for i in range(n):
            B[i, j] = B[i, j] * s
    for i in range(n):
        B[i, i] += 1.0 - lam * dx[i]
    csc_matvec(indptr, indices, data, dmu, work)
    lm = lam * mu0
    for i in range(n):
        B[i, n] = (G[i] - (x[i] - a[i])) - lm * (work[i] - dmu[i])


@njit(cache=True, error_model="numpy")  # a zero pivot gives inf, reported, not an exception
def lu_solve(lu, piv, b):
    """b <- B^{-1} b in place with LAPACK getrf's factors of B (``lu``: unit lower L and
    upper U; ``piv``: its row interchanges, 0-based as scipy returns them); whether the
    solution is finite.  What getrs computes, without its Python call (~6 us a solve); the
    last bits may differ from it (another order of the triangular sweeps' sums)."""
    m = b.shape[0]
    for i in range(m):
        k = piv[i]
        if k != i:
            t = b[i]
            b[i] = b[k]
            b[k] = t
    for j in range(m):  # L y = P b, column by column (lu is column-major)
        bj = b[j]
        if bj != 0.0:
            for i in range(j + 1, m):
                b[i] -= lu[i, j] * bj
    for j in range(m - 1, -1, -1):  # U x = y
        b[j] /= lu[j, j]
        bj = b[j]
        if bj != 0.0:
            for i in range(j):
                b[i] -= lu[i, j] * bj
    for i in range(m):
        if not math.isfinite(b[i]):
            return False
    return True


@njit(cache=True)
def bordered_pivots_ok(lu):
    """Whether getrf's U has finite pivots, none at most 1e-14 of the largest (below that
    the bordered matrix [[H_x, H_lam], [v^T]] is taken as singular: the augmented Jacobian
    lost rank, or the tangent row v is orthogonal to the curve)."""
    hi = 0.0
    lo = math.inf
    for i in range(lu.shape[0]):
        d = abs(lu[i, i])
        if not math.isfinite(d):
            return False
        hi = max(hi, d)
        lo = min(lo, d)
    return lo > 1e-14 * max(hi, 1e-300)


@njit(cache=True, error_model="numpy")
def unit_tangent(lu, piv, v, tau):
    """The unit tangent of the curve from the factors of B = [[H_x, H_lam], [v^T]]: tau =
    w / ||w||_2 with B w = e_{n+1}, turned so that tau . v >= 0 (the previous tangent v
    keeps the orientation).  Returns -1 when w is not finite, 1 when lam changed direction
    (tau_lam v_lam < 0: a turning point was passed), else 0."""
    m = tau.shape[0]
    for i in range(m):
        tau[i] = 0.0
    tau[m - 1] = 1.0
    if not lu_solve(lu, piv, tau):
        return -1
    s = 0.0
    for i in range(m):
        s += tau[i] * tau[i]
    nrm = math.sqrt(s)
    dot = 0.0
    for i in range(m):
        tau[i] /= nrm
        dot += tau[i] * v[i]
    if dot < 0.0:
        for i in range(m):
            tau[i] = -tau[i]
    return 1 if tau[m - 1] * v[m - 1] < 0.0 else 0


@njit(cache=True)
def chord_correction(f, y, yp, p, a, v, lu, piv, d):
    """One chord iteration of the corrector at y = (x, lam), where p = p_mu(x) and f = F(p):
    d = -B^{-1} (H(y), v . (y - yp)) with the factors of the bordered matrix B of the last
    accepted point, and y += d in place (``d``: n + 1 floats, overwritten).  H as
    homotopy_values computes it (the same bits).  Returns ||d||_2, or -1.0 when d is not
    finite (the caller shortens the step)."""
    n = f.shape[0]
    lam = y[n]
    c = 1.0 - lam
    for i in range(n):
        g = (f[i] + y[i]) - p[i]
        d[i] = -(lam * g + c * (y[i] - a[i]))
    s = 0.0
    for i in range(n + 1):
        s += v[i] * (y[i] - yp[i])
    d[n] = -s
    if not lu_solve(lu, piv, d):
        return -1.0
    s = 0.0
    for i in range(n + 1):
        s += d[i] * d[i]
        y[i] += d[i]
    return math.sqrt(s)


@njit(cache=True)
def chord_step(f, y, yp, p, a, v, lu, piv, d, mu0, lb, ub, dx, dmu):
    """One chord iteration of the dense corrector in one call: chord_correction at y (p =
    p_mu(x), f = F(p)), then, when its correction is finite, the smoothed projection of
    the corrected point for the next iteration -- p, dx, dmu at the new x with mu = mu0
    max(1 - lam, 0), the tracker's mu(lam) -- in place.  The values of the two kernels
    called in turn (the same bits); returns chord_correction's ||d||_2 or -1.0."""
    dn = chord_correction(f, y, yp, p, a, v, lu, piv, d)
    if dn >= 0.0:
        n = p.shape[0]
        c = 1.0 - y[n]
        # (Python's max(c, 0.0), which the tracker's mu(lam) takes: c unless 0 > c)
        smoothed_projection(y[:n], mu0 * (0.0 if 0.0 > c else c), lb, ub, p, dx, dmu)
    return dn


@njit(cache=True)
def bordered_values(f, x, p, a, lam, G, H, indptr, indices, data, dx, dmu, mu0, B, work):
    """homotopy_values and dense_bordered of an accepted point in one call (the same
    bits): G, H and the first n rows of the bordered matrix B."""
    homotopy_values(f, x, p, a, lam, G, H)
    dense_bordered(indptr, indices, data, dx, dmu, lam, mu0, G, x, a, B, work)

