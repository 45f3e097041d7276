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
