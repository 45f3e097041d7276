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

import numpy as np

from .._jit import interrupts_held, njit
from ..linalg._csc_kernels import csc_matvec
from .._merit_kernels import max_abs_kernel


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



# ------------------------------------------------------------------ the compiled tracker
# LAPACK's getrf for compiled code: numba's own binding of scipy's LAPACK, the library that
# scipy.linalg.lapack's getrf calls, so the factors are the same bits.  It is bound when a
# tracker first needs it (importing numba), never at import, and the kernels that call it
# are never interpreted (the tracker takes its Python route during the cold start).
_XXGETRF = None
_KIND_D = ord("d")


def bind_lapack() -> bool:
    """Bind getrf for :func:`dense_getrf`; False when this numba has no such binding
    (it is numba's internal interface: the tracker then keeps its Python route)."""
    global _XXGETRF
    if _XXGETRF is None:
        try:
            # (with Ctrl-C held: an import it cuts short leaves numba half-imported)
            with interrupts_held():
                # (lazy: numba costs 0.2-0.4 s of import; see compass_sparse._jit)
                import numba
                from numba.np.linalg import _LAPACK

                _XXGETRF = _LAPACK().numba_xxgetrf(numba.types.float64)
        except Exception:  # (ImportError, AttributeError, ... of another numba)
            return False
    return True


@njit(cache=True)
def dense_getrf(B, piv):
    """LU of the square Fortran-ordered B in place by LAPACK's getrf, with its row
    interchanges in ``piv`` made 0-based, as scipy returns them; getrf's info (> 0: an
    exactly zero pivot)."""
    n = B.shape[0]
    info = _XXGETRF(_KIND_D, n, n, B.ctypes, n, piv.ctypes)
    for i in range(n):
        piv[i] -= 1
    return info


# Requests of follow_dense to its caller, and the ends of a path it reports.
NEED_F = 1  #: F at p (a corrector iterate); answer with f, or failed
NEED_FJ = 2  #: F and J at p (the start or an accepted point); answer with f and J
END_GAME = 3  #: lam reached lam_end: the end game runs, then follow_dense again
SINGULAR = 4
STEP_TOO_SMALL = 5
DIVERGED = 6
RETURNED = 7
STEP_LIMIT = 8
LAPACK_ERROR = 9  #: getrf reported an illegal argument

# Rows of the tracker's float work area W ((15, n + 1)); rows 6 ... 14 hold n entries.
W_Y, W_V, W_TAU, W_YP, W_YC, W_RHS = 0, 1, 2, 3, 4, 5
W_P, W_DX, W_DMU, W_A, W_LB, W_UB, W_G, W_H, W_WORK = 6, 7, 8, 9, 10, 11, 12, 13, 14
W_ROWS = 15

# Scalars of a path: sf (floats) and si (ints); the first ones are set by the caller.
(F_H, F_HMIN, F_BOUND, F_LAM_END, F_MU0, F_HMAX, F_TOL, F_CONTRACTION, F_DISTANCE,
 F_KAPPA_NOM, F_DISTANCE_NOM, F_GROWTH, F_END_GAP, F_HC, F_TOL_Y, F_KAPPA, F_FIRST,
 F_PREV) = range(18)
F_SIZE = 18
(I_PHASE, I_STEP_LIMIT, I_CORRECTOR_ITERATIONS, I_ESTIMATE, I_LOOPS, I_STEPS, I_REJECTED,
 I_TURNS, I_FACTORIZATIONS, I_RETRIED, I_ITERATION, I_HAS_PREV, I_AT_START) = range(13)
I_SIZE = 13
# phases: what the next call of follow_dense receives
P_START, P_VALUES, P_STEP, P_CHORD = 0, 1, 2, 3


@njit(cache=True)
def _project_point(sf, W, y, n):
    """p_mu(x) of y = (x, lam) into W's rows P, DX and DMU, with mu = mu0 max(1 - lam, 0)
    (Python's max, as the tracker's mu(lam))."""
    c = 1.0 - y[n]
    smoothed_projection(y[:n], sf[F_MU0] * (0.0 if 0.0 > c else c), W[W_LB, :n],
                        W[W_UB, :n], W[W_P, :n], W[W_DX, :n], W[W_DMU, :n])


@njit(cache=True)
def _predict(sf, si, W, n):
    """The predictor y + h tau (not past lam = 1), the corrector's start at it and the
    smoothed projection of its point: W[W_P] is where F is wanted next."""
    y, tau, yp, yc, t = W[W_Y], W[W_TAU], W[W_YP], W[W_YC], W[W_RHS]
    h = sf[F_H]
    for i in range(n + 1):
        yp[i] = y[i] + h * tau[i]
    if yp[n] > 1.0:  # do not step past the end: mu(lam) must stay >= 0
        hh = (1.0 - y[n]) / tau[n] if tau[n] > 0 else h
        s = hh if hh < h else h  # (Python's min(h, hh))
        for i in range(n + 1):
            yp[i] = y[i] + s * tau[i]
    # the corrector's start, as _Tracker._correct: its distances are BLAS products as
    # box.dot_norm takes them
    for i in range(n + 1):
        yc[i] = yp[i]
        t[i] = yp[i] - y[i]
    hc = math.sqrt(np.dot(t, t))
    sf[F_HC] = 1e-300 if 1e-300 > hc else hc
    sf[F_TOL_Y] = sf[F_TOL] * (1.0 + math.sqrt(np.dot(yp, yp)))
    sf[F_KAPPA] = 0.0
    si[I_HAS_PREV] = 0
    si[I_ITERATION] = 0
    _project_point(sf, W, yc, n)
    si[I_PHASE] = P_CHORD
    return NEED_F


@njit(cache=True)
def _reject(sf, si, W, n):
    """A failed corrector: the step is halved and predicted again, or the path ends."""
    si[I_REJECTED] += 1
    si[I_RETRIED] = 1
    sf[F_H] *= 0.5
    if sf[F_H] < sf[F_HMIN]:
        return STEP_TOO_SMALL
    return _predict(sf, si, W, n)


@njit(cache=True)
def _step(sf, si, W, B, piv, n):
    """The top of a step: the factors of the bordered matrix of the accepted point (its
    first n rows made by bordered_values, the last the previous tangent), the unit
    tangent, and the first prediction."""
    if si[I_LOOPS] >= si[I_STEP_LIMIT]:
        return STEP_LIMIT
    si[I_LOOPS] += 1
    si[I_FACTORIZATIONS] += 1
    v = W[W_V]
    for j in range(n + 1):
        B[n, j] = v[j]
    if dense_getrf(B, piv) < 0:
        return LAPACK_ERROR
    if not bordered_pivots_ok(B):
        return SINGULAR
    turned = unit_tangent(B, piv, v, W[W_TAU])
    if turned < 0:
        return SINGULAR
    si[I_TURNS] += turned
    si[I_RETRIED] = 0
    return _predict(sf, si, W, n)


@njit(cache=True)
def follow_dense(sf, si, W, B, piv, f, indptr, indices, data, failed):
    """The dense route of ``_Tracker.follow`` from one evaluation of the user's F (or F and
    J) to the next, by reverse communication: the call runs until it needs F at W[W_P]
    (NEED_F: the next call brings f, or ``failed`` when F was rejected there), F and J
    there (NEED_FJ: the next call brings both; the caller offers the point as a candidate
    first), the end game (END_GAME) or an end of the path (SINGULAR ... STEP_LIMIT).  The
    path's state is in sf, si (scalars), W (vectors), B and piv (the bordered matrix and
    its factors).  The same steps and formulas as the Python route, in its order: the
    same bits (a test follows both routes)."""
    n = W.shape[1] - 1
    y = W[W_Y]
    phase = si[I_PHASE]
    if phase == P_START:  # the projection of the path's start y = (a, 0)
        _project_point(sf, W, y, n)
        si[I_AT_START] = 1
        si[I_PHASE] = P_VALUES
        return NEED_FJ
    if phase == P_VALUES:  # F and J at the projection of the start or an accepted point
        lam = y[n]
        bordered_values(f, y[:n], W[W_P, :n], W[W_A, :n], lam, W[W_G, :n], W[W_H, :n],
                        indptr, indices, data, W[W_DX, :n], W[W_DMU, :n], sf[F_MU0], B,
                        W[W_WORK, :n])
        si[I_PHASE] = P_STEP
        if si[I_AT_START] == 0 and (lam >= sf[F_LAM_END] or lam >= 1.0 - sf[F_END_GAP]):
            return END_GAME
        return _step(sf, si, W, B, piv, n)
    if phase == P_STEP:  # after the end game
        return _step(sf, si, W, B, piv, n)
    # P_CHORD: F at the corrector's iterate
    if failed:
        return _reject(sf, si, W, n)
    yc = W[W_YC]
    dn = chord_step(f, yc, W[W_YP], W[W_P, :n], W[W_A, :n], W[W_V], B, piv, W[W_RHS],
                    sf[F_MU0], W[W_LB, :n], W[W_UB, :n], W[W_DX, :n], W[W_DMU, :n])
    if dn < 0.0:  # a non-finite correction
        return _reject(sf, si, W, n)
    hc = sf[F_HC]
    tol_y = sf[F_TOL_Y]
    prev = sf[F_PREV]
    if si[I_HAS_PREV]:
        r = dn / (1e-300 if 1e-300 > prev else prev)
        if r > sf[F_KAPPA]:  # (Python's max(kappa, r))
            sf[F_KAPPA] = r
        if sf[F_KAPPA] > sf[F_CONTRACTION]:
            return _reject(sf, si, W, n)
    else:
        sf[F_FIRST] = dn
        lim = sf[F_DISTANCE] * hc
        t = 10.0 * tol_y
        if dn > (t if t > lim else lim):
            return _reject(sf, si, W, n)
    if dn <= tol_y or (si[I_ESTIMATE] and si[I_HAS_PREV] and dn * dn <= tol_y * (prev - dn)):
        # converged: the step factor, then the accepted point (follow's step control)
        k = sf[F_KAPPA] / sf[F_KAPPA_NOM]
        d = sf[F_FIRST] / (sf[F_DISTANCE_NOM] * hc)
        factor = d if d > k else k
        lo = 1.0 / sf[F_GROWTH]
        factor = lo if lo > factor else factor
        factor = 2.0 if 2.0 < factor else factor
        if si[I_RETRIED] and 1.0 > factor:  # no growth right after a rejection
            factor = 1.0
        si[I_STEPS] += 1
        x_max = max_abs_kernel(yc[:n], yc[:n], False)
        t = W[W_RHS]
        for i in range(n + 1):
            t[i] = yc[i] - y[i]
        hn = math.sqrt(np.dot(t, t))
        h = sf[F_H]
        h = (hn if hn > h else h) / factor
        cap = sf[F_HMAX] * (1.0 + x_max)
        sf[F_H] = cap if cap < h else h
        v, tau = W[W_V], W[W_TAU]
        finite = True
        for i in range(n + 1):
            y[i] = yc[i]
            v[i] = tau[i]
            if not math.isfinite(y[i]):
                finite = False
        if not finite or x_max > sf[F_BOUND]:
            return DIVERGED
        if y[n] < -0.5:
            return RETURNED
        # F and J at the corrector's last projection, which is this point's
        si[I_AT_START] = 0
        si[I_PHASE] = P_VALUES
        return NEED_FJ
    sf[F_PREV] = dn
    si[I_HAS_PREV] = 1
    si[I_ITERATION] += 1
    if si[I_ITERATION] >= si[I_CORRECTOR_ITERATIONS]:
        return _reject(sf, si, W, n)
    return NEED_F
