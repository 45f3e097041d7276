"""Compiled parts of the crash: its active set, its reduced solve (see
:func:`compass_sparse.crash.reduced.solve_reduced`) and its compiled route (:func:`crash_dense`).

A crash step on a small problem solves (J_II + eps I) d = rhs for a block of order <= 200
in up to eight attempts of growing eps.  Each attempt in Python -- a copy, the diagonal
shift, LAPACK's getrf and getrs through their wrappers, a finiteness test and a max norm --
cost ~20 us, and the structural test that decides whether eps = 0 is tried at all built a
scipy copy of the block without its stored zeros (~60 us): on kojshin's start, a third of a
solve.  Here the attempts run in one compiled call.

The factorization is :func:`compass_sparse.linalg._dense_kernels.dense_solve_or_none`,
LAPACK's gesv as numba compiles it: the bits of scipy's lu_factor + lu_solve (checked by
the tests on orders 1 ... 200), and the package's one dense LU.
"""
from __future__ import annotations

import math

import numpy as np

from .._jit import njit
from .._merit_kernels import fb_phi_kernel, max_abs_kernel, normal_map_kernel, np_max, np_min
from ..linalg._csc_kernels import csc_diagonal, csc_to_dense, free_block
from ..linalg._dense_kernels import dense_solve_or_none
from ..linalg.matching import augmenting_matching

__all__ = ["crash_active_set", "crash_dense", "dense_crash_step", "dense_perturbed_solve",
           "initial_shift", "structurally_singular"]


@njit(cache=True)
def structurally_singular(indptr, indices, data, n):
    """Whether the n x n CSC block has no zero-free diagonal in any row and column order
    (a maximum matching of its NONZERO entries -- stored zeros do not count -- leaves a
    column unmatched): then no value of its entries makes it regular."""
    if n == 0:
        return False
    ptr = np.empty(n + 1, np.int64)
    idx = np.empty(indptr[n], np.int64)
    k = 0
    for j in range(n):
        ptr[j] = k
        for e in range(indptr[j], indptr[j + 1]):
            if data[e] != 0.0:
                idx[k] = indices[e]
                k += 1
    ptr[n] = k
    row_of, _ = augmenting_matching(n, n, ptr, idx[:k])
    for j in range(n):
        if row_of[j] < 0:
            return True
    return False


@njit(cache=True)
def initial_shift(indptr, indices, data, n, perturb, eps0):
    """The first eps of a crash step's attempts on the n x n CSC block: eps0 when
    ``perturb`` and the block is structurally singular (no value of its entries makes it
    regular, so an unperturbed factorization can only fail -- and without a zero-free
    diagonal a sparse one runs in the slow fallback ordering: 40 s at n = 3e4 on the
    dynamic CGE model), else 0.  A full block without a zero entry needs no matching."""
    if not perturb or n == 0:
        return 0.0
    k = indptr[n]
    if k == n * n:
        full = True
        for e in range(k):
            if data[e] == 0.0:
                full = False
                break
        if full:
            return 0.0
    return eps0 if structurally_singular(indptr, indices, data, n) else 0.0


@njit(cache=True)
def dense_perturbed_solve(dense, rhs, eps, eps0, perturb, attempts, step_limit):
    """The attempts of :func:`compass_sparse.crash.reduced.solve_reduced` on a dense block.

    ``dense``: the block (Fortran order); ``eps``: the first shift (0, or eps0 for a
    structurally singular block).  Attempt k solves (dense + eps I) d = rhs; a solution is
    taken when it is finite and, on a shifted matrix, ``max|d| <= step_limit``; otherwise
    eps becomes eps0 (after 0) or grows tenfold -- when ``perturb`` -- up to ``attempts``
    factorizations.  Returns (d, eps of the last attempt, factorizations, found)."""
    n = dense.shape[0]
    A = np.empty((0, 0), dtype=np.float64).T  # the shifted matrix, made when needed
    nf = 0
    for _ in range(attempts):
        nf += 1
        if eps == 0.0:
            d, ok = dense_solve_or_none(dense, rhs)  # (solve factors a copy: dense stays)
        else:
            if A.shape[0] != n:
                A = np.empty((n, n), dtype=np.float64).T  # Fortran order, as LAPACK's
            A[:, :] = dense
            for i in range(n):
                A[i, i] += eps
            d, ok = dense_solve_or_none(A, rhs)
        if ok:
            finite = True
            big = 0.0
            for i in range(n):
                v = d[i]
                if not np.isfinite(v):
                    finite = False
                    break
                big = max(big, abs(v))
            if finite and not (eps > 0.0 and big > step_limit):
                return d, eps, nf, True
        if not perturb:
            break
        eps = eps0 if eps == 0.0 else eps * 10.0
    return rhs, eps, nf, False


NO_BASIS_CHANGE = 1
"""Code of :func:`dense_crash_step`: the active set moved by fewer indices than the limit."""


@njit(cache=True)
def dense_crash_step(indptr, indices, data, z, f, lb, ub, prev_free, has_prev,
                     nbchange_limit, perturb, eps0, attempts, step_limit):
    """One crash step's direction on a problem of order <= 200 (its reduced blocks are
    dense), in one call: the kernels the Python step called one by one, in its order and
    on its arrays -- the diagonal of J, the active set and Newton target
    (``crash_active_set``), the count of changes against ``prev_free`` (a stop when fewer
    than ``nbchange_limit`` and ``has_prev``), the reduced system (``free_block`` with
    q = -F), the test that tries eps = 0 only on a block that may be regular, and the
    perturbed dense attempts (``dense_perturbed_solve``).  So the same bits.

    Returns (code, free, d, changes, inactive count, eps, factorizations, found): code
    ``NO_BASIS_CHANGE`` or 0; ``d`` is the full step (its inactive entries solved when
    ``found``)."""
    n = z.shape[0]
    dg = np.empty(n)
    csc_diagonal(indptr, indices, data, dg)
    free = np.empty(n, dtype=np.bool_)
    d = np.empty(n)
    crash_active_set(z, f, lb, ub, dg, free, d)
    changes = n
    if has_prev:
        changes = 0
        for i in range(n):
            if free[i] != prev_free[i]:
                changes += 1
        if changes < nbchange_limit:
            return NO_BASIS_CHANGE, free, d, changes, 0, 0.0, 0, False
    q = np.empty(n)
    for i in range(n):
        q[i] = -f[i]
    Kp, Ki, Kx, rhs, k = free_block(indptr, indices, data, free, d, q)
    m = rhs.shape[0]
    if m == 0:
        return 0, free, d, changes, 0, 0.0, 0, True
    eps = initial_shift(Kp, Ki[:k], Kx[:k], m, perturb, eps0)
    dense = np.empty((m, m), dtype=np.float64).T  # Fortran order, as LAPACK's
    csc_to_dense(Kp, Ki, Kx, dense)
    di, eps, nf, found = dense_perturbed_solve(dense, rhs, eps, eps0, perturb, attempts,
                                               step_limit)
    if found:
        p = 0
        for i in range(n):
            if free[i]:
                d[i] = di[p]
                p += 1
    return 0, free, d, changes, m, eps, nf, found


# ------------------------------------------------------------------ the compiled crash
# Requests of crash_dense to its caller: J at z (the next call brings it, or J_FAILED),
# F at zt (F_GIVEN or F_FAILED; the caller offers the point first), or the end.
NEED_J, NEED_F, DONE = 1, 2, 3
# What a call brings (``arg``)
NOTHING, J_GIVEN, J_FAILED, F_GIVEN, F_FAILED, STOP = 0, 1, 2, 3, 4, 5
# Stop reasons (the texts of crash.compiled._REASONS, in this order)
(R_ITERATION_LIMIT, R_CONVERGED, R_DOMAIN_J, R_NO_CHANGE, R_SINGULAR, R_NO_PROGRESS,
 R_TIME, R_RAISED) = range(8)
# Rows of the work area W ((CW_ROWS, n)): the current point z, F(z) and its normal-map
# point x, the step d, the trial point and its normal-map values, the best point, the box
# and the line search's segment and Phi.
(CW_Z, CW_F, CW_X, CW_D, CW_ZT, CW_XT, CW_NM, CW_BZ, CW_BF, CW_BX, CW_LB, CW_UB, CW_SEG,
 CW_PHI) = range(14)
CW_ROWS = 14
# Scalars: sf (floats), si (ints); the options first, set by the caller.
(CF_SIGMA, CF_MIN_STEP, CF_TOL, CF_EPS_SCALE, CF_STEP_LIMIT, CF_START_FACTOR, CF_NM,
 CF_BEST, CF_ALPHA, CF_FB, CF_NMT, CF_FB0, CF_REC) = range(13)
CRASH_RECENT = 4  # (crash.CRASH_MEMORY: sf[CF_REC:CF_REC + 4] holds the recent norms)
CF_SIZE = CF_REC + CRASH_RECENT
(CI_PHASE, CI_LIMIT, CI_NBCHANGE, CI_PERTURB, CI_ATTEMPTS, CI_LINE, CI_IT, CI_NREC,
 CI_HAS_PREV, CI_REASON, CI_NFACT, CI_CHANGES, CI_NINACT, CI_K, CI_K_FB, CI_K_BEST,
 CI_ACCEPTED, CI_ROW_IT) = range(18)
CI_SIZE = 18
_C_START, _C_TOP, _C_J, _C_F = 0, 1, 2, 3  # phases: what the next call receives


@njit(cache=True)
def _crash_done(sf, si, W, reason, back):
    """The end of the crash: the stop reason, the iteration count (one less when the
    loop stopped inside an iteration), the best point when the last steps climbed from
    it, and ||Phi|| of the point handed on (the value taken at the last step's start when
    it is that point)."""
    si[CI_REASON] = reason
    if back:
        si[CI_IT] -= 1
    n = W.shape[1]
    k = si[CI_K]
    if sf[CF_BEST] < sf[CF_NM]:
        sf[CF_NM] = sf[CF_BEST]
        for i in range(n):
            W[CW_Z, i] = W[CW_BZ, i]
            W[CW_F, i] = W[CW_BF, i]
            W[CW_X, i] = W[CW_BX, i]
        k = si[CI_K_BEST]
    if si[CI_K_FB] != k:
        phi = W[CW_PHI]
        fb_phi_kernel(W[CW_Z], W[CW_F], W[CW_LB], W[CW_UB], phi)
        sf[CF_FB] = math.sqrt(np.dot(phi, phi))
    return DONE


@njit(cache=True)
def _crash_trial(sf, si, W):
    """The next point of the search (alpha as it is now), or the end of the search."""
    alpha = sf[CF_ALPHA]
    if not alpha >= sf[CF_MIN_STEP]:
        return _crash_done(sf, si, W, R_NO_PROGRESS, True)
    n = W.shape[1]
    z, d, seg, zt = W[CW_Z], W[CW_D], W[CW_SEG], W[CW_ZT]
    lb, ub = W[CW_LB], W[CW_UB]
    for i in range(n):
        t = z[i] - alpha * d[i] if si[CI_LINE] == 0 else z[i] + alpha * seg[i]
        zt[i] = np_min(np_max(t, lb[i]), ub[i])
    si[CI_PHASE] = _C_F
    return NEED_F


@njit(cache=True)
def _crash_direction(sf, si, W, prev_free, indptr, indices, data):
    """The crash step's direction at z with J = J(z) (dense_crash_step), then the first
    trial point."""
    n = W.shape[1]
    z, f = W[CW_Z], W[CW_F]
    nm = sf[CF_NM]
    eps0 = sf[CF_EPS_SCALE] * (nm if nm > 1.0 else 1.0)  # (Python's max(1.0, nm))
    limit = sf[CF_STEP_LIMIT] * (1.0 + max_abs_kernel(z, z, False))
    code, free, d, changes, ninact, eps, nf, found = dense_crash_step(
        indptr, indices, data, z, f, W[CW_LB], W[CW_UB], prev_free, si[CI_HAS_PREV] != 0,
        si[CI_NBCHANGE], si[CI_PERTURB] != 0, eps0, si[CI_ATTEMPTS], limit)
    if code == NO_BASIS_CHANGE:
        return _crash_done(sf, si, W, R_NO_CHANGE, True)
    for i in range(n):
        prev_free[i] = free[i]
    si[CI_HAS_PREV] = 1
    si[CI_NFACT] += nf
    if not found:
        return _crash_done(sf, si, W, R_SINGULAR, True)
    si[CI_CHANGES] = changes
    si[CI_NINACT] = ninact
    lb, ub = W[CW_LB], W[CW_UB]
    for i in range(n):
        W[CW_D, i] = d[i]
        if si[CI_LINE] != 0:  # the segment to the projected Newton point
            W[CW_SEG, i] = np_min(np_max(z[i] - d[i], lb[i]), ub[i]) - z[i]
    sf[CF_ALPHA] = 1.0
    return _crash_trial(sf, si, W)


@njit(cache=True)
def _crash_top(sf, si, W, prev_free, indptr, indices, data, have_j):
    """The start of an iteration: ||Phi(z)||, the convergence test, then J (asked for
    unless given) and the direction."""
    if si[CI_IT] >= si[CI_LIMIT]:
        return _crash_done(sf, si, W, R_ITERATION_LIMIT, False)
    si[CI_IT] += 1
    phi = W[CW_PHI]
    fb_phi_kernel(W[CW_Z], W[CW_F], W[CW_LB], W[CW_UB], phi)
    fb = math.sqrt(np.dot(phi, phi))
    sf[CF_FB] = fb
    si[CI_K_FB] = si[CI_K]
    if si[CI_IT] == 1:
        sf[CF_FB0] = fb  # (the start's: crash.RAISED)
    if fb <= sf[CF_TOL]:
        return _crash_done(sf, si, W, R_CONVERGED, True)
    if not have_j:
        si[CI_PHASE] = _C_J
        return NEED_J
    return _crash_direction(sf, si, W, prev_free, indptr, indices, data)


@njit(cache=True)
def crash_dense(sf, si, W, prev_free, ft, indptr, indices, data, arg):
    """The dense route of ``crash._crash`` from one evaluation of the user's F or J to the
    next, by reverse communication: the call runs until it needs J at W[CW_Z] (NEED_J;
    the next call brings it, J_GIVEN, or says it failed, J_FAILED), F at the trial point
    W[CW_ZT] (NEED_F; the caller offers the point first, then brings F_GIVEN with ``ft``
    or F_FAILED) or the end (DONE; the stop reason in si[CI_REASON], the point handed on
    in W's first rows).  STOP ends the crash at a time limit.  The steps and formulas of
    the Python route in its order, its norms as BLAS products: the same bits."""
    n = W.shape[1]
    phase = si[CI_PHASE]
    if phase == _C_START:  # the start: its normal-map point and norm, the first memory
        normal_map_kernel(W[CW_Z], W[CW_F], W[CW_LB], W[CW_UB], W[CW_X], W[CW_NM])
        nm = W[CW_NM]
        sf[CF_NM] = math.sqrt(np.dot(nm, nm))
        sf[CF_REC] = sf[CF_START_FACTOR] * sf[CF_NM]
        si[CI_NREC] = 1
        sf[CF_BEST] = sf[CF_NM]
        for i in range(n):
            W[CW_BZ, i] = W[CW_Z, i]
            W[CW_BF, i] = W[CW_F, i]
            W[CW_BX, i] = W[CW_X, i]
        si[CI_K] = 0
        si[CI_K_BEST] = 0
        si[CI_K_FB] = -1
        if arg == STOP:
            return _crash_done(sf, si, W, R_TIME, False)
        return _crash_top(sf, si, W, prev_free, indptr, indices, data, arg == J_GIVEN)
    if arg == STOP:  # the time limit: before J, an iteration not made; in the search,
        # a search without progress (as the Python route's loops stop)
        return _crash_done(sf, si, W, R_TIME if phase == _C_J else R_NO_PROGRESS, True)
    if phase == _C_J:
        if arg == J_FAILED:
            return _crash_done(sf, si, W, R_DOMAIN_J, True)
        return _crash_direction(sf, si, W, prev_free, indptr, indices, data)
    # _C_F: F at the trial point
    alpha = sf[CF_ALPHA]
    if arg == F_GIVEN:
        normal_map_kernel(W[CW_ZT], ft, W[CW_LB], W[CW_UB], W[CW_XT], W[CW_NM])
        nm = W[CW_NM]
        nmt = math.sqrt(np.dot(nm, nm))
        k = si[CI_NREC]
        top = sf[CF_REC]
        for j in range(1, k):  # (Python's max over the list: the first largest)
            if sf[CF_REC + j] > top:
                top = sf[CF_REC + j]
        if nmt <= (1.0 - sf[CF_SIGMA] * alpha) * top:
            # ... unless it raises ||Phi|| above the start's (crash.RAISED)
            phi = W[CW_PHI]
            fb_phi_kernel(W[CW_ZT], ft, W[CW_LB], W[CW_UB], phi)
            if math.sqrt(np.dot(phi, phi)) > sf[CF_FB0]:
                return _crash_done(sf, si, W, R_RAISED, True)
            # accepted: the trial point becomes z (its F and x too), the memory moves on
            sf[CF_NMT] = nmt
            si[CI_ACCEPTED] += 1
            si[CI_ROW_IT] = si[CI_IT]
            for i in range(n):
                W[CW_Z, i] = W[CW_ZT, i]
                W[CW_F, i] = ft[i]
                W[CW_X, i] = W[CW_XT, i]
            sf[CF_NM] = nmt
            si[CI_K] += 1
            if k < CRASH_RECENT:
                sf[CF_REC + k] = nmt
                si[CI_NREC] = k + 1
            else:
                for j in range(CRASH_RECENT - 1):
                    sf[CF_REC + j] = sf[CF_REC + j + 1]
                sf[CF_REC + CRASH_RECENT - 1] = nmt
            if nmt < sf[CF_BEST]:
                sf[CF_BEST] = nmt
                si[CI_K_BEST] = si[CI_K]
                for i in range(n):
                    W[CW_BZ, i] = W[CW_Z, i]
                    W[CW_BF, i] = W[CW_F, i]
                    W[CW_BX, i] = W[CW_X, i]
            return _crash_top(sf, si, W, prev_free, indptr, indices, data, False)
    sf[CF_ALPHA] = alpha * 0.5
    return _crash_trial(sf, si, W)


@njit(cache=True)
def crash_active_set(z, f, lb, ub, diag, free, d):
    """The crash's active set and Newton target (projected_newton.py): with g_i = |J_ii| (1 where it
    is 0 or NaN), index i is active at its lower bound when z_i - f_i / g_i <= l_i, else at
    its upper bound when that point is >= u_i (a NaN point is neither); ``free`` is the
    complement, and d_i = z_i - (its bound) on the active indices, 0 elsewhere.  The array
    formulas' values element by element, in one pass."""
    for i in range(z.shape[0]):
        g = abs(diag[i])
        if not g > 0.0:
            g = 1.0
        xm = z[i] - f[i] / g
        if xm <= lb[i]:
            free[i] = False
            d[i] = z[i] - lb[i]
        elif xm >= ub[i]:
            free[i] = False
            d[i] = z[i] - ub[i]
        else:
            free[i] = True
            d[i] = 0.0
