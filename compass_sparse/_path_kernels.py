"""Compiled inner loops of the pivotal path: the two-pass ratio test and the projection
of basic values onto their bounds, with each slot's bounds derived from its variable kind
(z: [l, u]; w, v: [0, inf); fixed-variable slack: free; t: [0, 1]; artificial: towards 0
from the side it is on)."""
import numpy as np
from ._jit import njit

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


@njit(cache=True, inline="always")
def _room(kind, idx, val, r, lb, ub):
    """(room to the bound the slot moves towards at rate r, that bound)."""
    lo, hi = _slot_bounds(kind, idx, val, lb, ub)
    if r > 0.0:
        return max(hi - val, 0.0), hi
    return max(val - lo, 0.0), lo


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
        room, bnd = _room(sk[k], si[k], xb[k], r, lb, ub)
        if np.isfinite(bnd):
            theta1 = min(theta1, (room + tol * max(1.0, abs(bnd))) / abs(r))
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
        room, bnd = _room(sk[k], si[k], xb[k], r, lb, ub)
        if not np.isfinite(bnd) or room / abs(r) > theta1:
            continue
        kind = sk[k]
        pri = 2 if kind == VAR_T else (1 if kind == VAR_A else 0)
        if pri > best_pri or (pri == best_pri and abs(r) > best_piv):
            best, best_pri, best_piv = k, pri, abs(r)
            best_ratio = room / abs(r)
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
