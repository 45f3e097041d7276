"""Compiled inner loops of the pivotal path: the two-pass ratio test and the projection
of basic values onto their bounds, with each slot's bounds derived from its variable kind
(z: [l, u]; w, v: [0, inf); fixed-variable slack: free; t: [0, 1]; artificial: towards 0
from the side it is on)."""
import numpy as np
from numba import njit

VAR_Z, VAR_W, VAR_V, VAR_A, VAR_T, VAR_S = 0, 1, 2, 3, 4, 5


@njit(cache=True, inline="always")
def _slot_bounds(kind, idx, val, lb, ub):
    if kind == VAR_Z:
        return lb[idx], ub[idx]
    if kind == VAR_S:
        return -np.inf, np.inf
    if kind == VAR_T:
        return 0.0, 1.0
    if kind == VAR_A:
        if val >= 0.0:
            return 0.0, np.inf
        return -np.inf, 0.0
    return 0.0, np.inf


@njit(cache=True)
def ratio_test(sk, si, xb, rate, lb, ub, piv_tol, tol):
    """Harris two-pass ratio test.  Returns (slot, theta, leaves_at_upper) or (-1, inf, 0).

    Pass 1: theta1 = min over blocking slots of (room + tol*max(1,|bound|)) / |rate|.
    Pass 2: among slots with room/|rate| <= theta1 pick t (priority 2), then artificials
    (priority 1), then the largest |rate|."""
    n = sk.shape[0]
    theta1 = np.inf
    for k in range(n):
        r = rate[k]
        if -piv_tol <= r <= piv_tol:
            continue
        lo, hi = _slot_bounds(sk[k], si[k], xb[k], lb, ub)
        if r > 0.0:
            bnd = hi
            room = hi - xb[k]
        else:
            bnd = lo
            room = xb[k] - lo
        if not np.isfinite(bnd):
            continue
        if room < 0.0:
            room = 0.0
        th = (room + tol * max(1.0, abs(bnd))) / abs(r)
        if th < theta1:
            theta1 = th
    if not np.isfinite(theta1):
        return -1, np.inf, 0
    best = -1
    best_pri = -1
    best_piv = -1.0
    best_ratio = np.inf
    best_up = 0
    for k in range(n):
        r = rate[k]
        if -piv_tol <= r <= piv_tol:
            continue
        lo, hi = _slot_bounds(sk[k], si[k], xb[k], lb, ub)
        if r > 0.0:
            bnd = hi
            room = hi - xb[k]
        else:
            bnd = lo
            room = xb[k] - lo
        if not np.isfinite(bnd):
            continue
        if room < 0.0:
            room = 0.0
        ratio = room / abs(r)
        if ratio > theta1:
            continue
        kind = sk[k]
        pri = 2 if kind == VAR_T else (1 if kind == VAR_A else 0)
        piv = abs(r)
        if pri > best_pri or (pri == best_pri and piv > best_piv):
            best = k
            best_pri = pri
            best_piv = piv
            best_ratio = ratio
            best_up = 1 if r > 0.0 else 0
    return best, best_ratio, best_up


@njit(cache=True)
def project_slots(sk, si, xb, lb, ub):
    """Clip basic values to their bounds (rounding: thesis §4.2.2)."""
    for k in range(sk.shape[0]):
        lo, hi = _slot_bounds(sk[k], si[k], xb[k], lb, ub)
        v = xb[k]
        if v < lo:
            xb[k] = lo
        elif v > hi:
            xb[k] = hi
