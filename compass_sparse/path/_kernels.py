"""Compiled inner loops of the pivotal path: the two-pass ratio test and the projection
of basic values onto their bounds, with each slot's bounds derived from its variable kind
(z: [l, u]; w, v: [0, inf); fixed-variable slack: free; t: [t_lower, 1]; artificial:
towards 0 from the side it is on); and the linearization of a major iteration
(:func:`newton_linearization`, :mod:`compass_sparse.path.linearize`).

t's lower bound is the caller's (compass_sparse.path explains it): 0, or -inf while a path
from the current point that has not been above t = 0 is allowed below it.

Ties: t leaving at either bound wins every tie (at 1 the linear problem is solved, at its
lower bound the path ends), then artificials, then the largest |rate|.
"""
import numpy as np

from .._jit import njit
from ..linalg._csc_kernels import csc_matvec

VAR_Z, VAR_W, VAR_V, VAR_A, VAR_T, VAR_S = 0, 1, 2, 3, 4, 5

T_PROGRESS = 1e-9
"""A path has been above t = 0 once t exceeded this: smaller values are the rounding of
zero steps at a degenerate start vertex, not progress."""

BELOW_ZERO_PIVOTS = 8
"""A path whose bound t >= 0 was lifted (t blocked at 0 before the path had been above 0)
ends ("t not above 0") when it has not got above t = 0 within this many pivots from
then.  Leaving a degenerate start vertex through t < 0 takes a few pivots (PATH's path
on thesis family 2, n = 10, seed 1: 7 in all), and on the thesis families nearly all
lifted paths that do not come back within 8 never do (without a limit they ran on to the
cycle limit); 20 saved two more restarts there but cost 12 more pivots on each of ~480
failing paths (benchmarks/small.md, "Degenerate ties at the start vertex")."""

ARTIFICIAL_ZERO = 1e-12
"""An artificial within this of 0 (absolute) is at 0 and on its nonnegative side: it is
placed at exactly 0, and rounding of either sign must not decide which way it may move
(the two path implementations, whose rounding differs, would take different pivots)."""


@njit(cache=True, inline="always")
def unit_sign(kind, idx, art_sign):
    """The sign of a unit basis column: -e_i for w_i and a free slack, art_sign[i] e_i for
    an artificial, +e_i for v_i."""
    if kind == VAR_W or kind == VAR_S:
        return -1.0
    if kind == VAR_A:
        return float(art_sign[idx])
    return 1.0


@njit(cache=True, inline="always")
def _slot_bounds(kind, idx, val, lb, ub, t_lower):
    if kind == VAR_Z:
        return lb[idx], ub[idx]
    if kind == VAR_S:
        return -np.inf, np.inf
    if kind == VAR_T:
        return t_lower, 1.0
    if kind == VAR_A:
        if val >= -ARTIFICIAL_ZERO:
            return 0.0, np.inf
        return -np.inf, 0.0
    return 0.0, np.inf


@njit(cache=True, inline="always")
def _room(kind, idx, val, r, lb, ub, t_lower):
    """(room to the bound the slot moves towards at rate r, that bound)."""
    lo, hi = _slot_bounds(kind, idx, val, lb, ub, t_lower)
    if r > 0.0:
        return max(hi - val, 0.0), hi
    return max(val - lo, 0.0), lo


_CLEARLY = 1.0 + 8.0 * np.finfo(np.float64).eps
"""A ratio a / |r| is certainly above theta when a > theta * |r| * _CLEARLY: the product
and the quotient are each within half a unit in the last place, so the test by a
multiplication skips only slots the division would skip too (:func:`ratio_test` takes
the same slot, bit for bit, and divides only where the answer is in doubt)."""


@njit(cache=True)
def ratio_test(sk, si, xb, rate, lb, ub, piv_tol, tol, t_lower):
    """Harris two-pass ratio test.  Returns (slot, theta, leaves_at_upper) or (-1, inf, 0).

    Pass 1: theta1 = min over blocking slots of (room + tol*max(1,|bound|)) / |rate|.
    Pass 2: among slots with room/|rate| <= theta1 pick t at a bound (priority 2), then
    artificials (priority 1), then the largest |rate|.  Slots whose ratio is clearly
    above the current minimum (pass 1) or theta1 (pass 2) are passed over without a
    division (``_CLEARLY``): a dense rate vector costs two passes of multiplications.
    (The Python loop's call: :func:`ratio_test_bounds` with every slot's bounds worked
    out from its kind.)"""
    unknown = np.full(sk.shape[0], np.nan)
    return ratio_test_bounds(sk, si, xb, rate, lb, ub, unknown, unknown, piv_tol, tol,
                             t_lower, np.empty(sk.shape[0], np.int64),
                             np.empty(sk.shape[0]))


@njit(cache=True, inline="always")
def set_slot_bounds(k, sk, si, lb, ub, lo, hi):
    """lo[k], hi[k]: the bounds of slot k's variable, NaN for the two kinds whose bounds
    move while the slot keeps its variable -- t (its lower bound is lifted and restored)
    and an artificial (its side is its value's sign) -- which :func:`ratio_test_bounds`
    and :func:`project_bounds` take from :func:`_slot_bounds` each time."""
    kind = sk[k]
    if kind == VAR_Z:
        lo[k] = lb[si[k]]
        hi[k] = ub[si[k]]
    elif kind == VAR_S:
        lo[k] = -np.inf
        hi[k] = np.inf
    elif kind == VAR_T or kind == VAR_A:
        lo[k] = np.nan
        hi[k] = np.nan
    else:
        lo[k] = 0.0
        hi[k] = np.inf


@njit(cache=True)
def slot_bounds(sk, si, lb, ub, lo, hi):
    """:func:`set_slot_bounds` of every slot."""
    for k in range(sk.shape[0]):
        set_slot_bounds(k, sk, si, lb, ub, lo, hi)


@njit(cache=True)
def ratio_test_bounds(sk, si, xb, rate, lb, ub, lo, hi, piv_tol, tol, t_lower, cand, croom):
    """:func:`ratio_test` with the slots' bounds read from (lo, hi) (:func:`slot_bounds`;
    NaN: worked out from the slot's kind) -- the same slot and values, bit for bit, as
    with every bound worked out: the compiled engines' loop.  ``cand`` (n integers) and
    ``croom`` (n floats), work space, receive pass 1's candidates and their rooms for
    pass 2.

    Why it is written so (each measured on the pivots of a traffic solve): the bound a
    slot moves towards and its room are chosen by selects, not branches on the rate's
    sign, which a dense rate vector mispredicts half the time; and pass 1 lists every slot
    whose room is within ``theta1 * _CLEARLY * |rate|`` for the theta1 of the moment -- a
    superset of pass 2's slots, since theta1 only decreases and rounding is monotone --
    so that pass 2 reads that short list, with each candidate's room, not all n slots.
    (The bound and the room are worked out in the loop itself: an inlined helper taking
    the arrays made the test 18-21 times slower on those rate vectors, by reference
    counting per slot.)"""
    n = sk.shape[0]
    theta1 = np.inf
    nc = 0
    for k in range(n):
        r = rate[k]
        if -piv_tol <= r <= piv_tol:
            continue
        up = r > 0.0
        bnd = hi[k] if up else lo[k]
        if bnd != bnd:
            b2 = _slot_bounds(sk[k], si[k], xb[k], lb, ub, t_lower)
            bnd = b2[1] if up else b2[0]
        room = max(bnd - xb[k] if up else xb[k] - bnd, 0.0)
        ar = abs(r)
        # an infinite bound: room infinite, a infinite or NaN (tol 0): neither test
        # takes the slot
        a = room + tol * max(1.0, abs(bnd))
        if a <= theta1 * ar * _CLEARLY:
            theta1 = min(theta1, a / ar)
        if room <= theta1 * _CLEARLY * ar and np.isfinite(bnd):
            cand[nc] = k
            croom[nc] = room
            nc += 1
    if not np.isfinite(theta1):
        return -1, np.inf, 0
    bound = theta1 * _CLEARLY
    best = -1
    best_pri = -1
    best_piv = -1.0
    best_ratio = np.inf
    best_up = 0
    for c in range(nc):
        k = cand[c]
        room = croom[c]
        r = rate[k]
        up = r > 0.0
        ar = abs(r)
        if room > bound * ar or room / ar > theta1:
            continue
        kind = sk[k]
        pri = 2 if kind == VAR_T else (1 if kind == VAR_A else 0)
        if pri > best_pri or (pri == best_pri and ar > best_piv):
            best, best_pri, best_piv = k, pri, ar
            best_ratio = room / ar
            best_up = 1 if up else 0
    return best, best_ratio, best_up


@njit(cache=True, inline="always")
def project_slot(k, sk, si, xb, lb, ub, lo, hi, t_lower):
    """Slot k's value clipped to its bounds (:func:`project_bounds` of one slot)."""
    a = lo[k]
    b = hi[k]
    if a != a:
        a, b = _slot_bounds(sk[k], si[k], xb[k], lb, ub, t_lower)
    v = xb[k]
    if v < a:
        xb[k] = a
    elif v > b:
        xb[k] = b


@njit(cache=True)
def project_bounds(sk, si, xb, lb, ub, lo, hi, t_lower):
    """:func:`project_slots` with the bounds of (lo, hi) (NaN: worked out as there).
    (Written out, not through :func:`project_slot`: a helper taking the arrays costs
    reference counting per slot.)"""
    for k in range(sk.shape[0]):
        a = lo[k]
        b = hi[k]
        if a != a:
            a, b = _slot_bounds(sk[k], si[k], xb[k], lb, ub, t_lower)
        v = xb[k]
        if v < a:
            xb[k] = a
        elif v > b:
            xb[k] = b


@njit(cache=True)
def advance_values(sk, si, xb, rate, theta, lb, ub, lo, hi, t_lower, skip):
    """xb += theta rate, each value then clipped to its slot's bounds (the step and
    project_bounds in one pass, the same operations on each slot), but slot
    ``skip`` (-1: none), which the caller sets.  (Written out, as project_bounds.)"""
    for k in range(sk.shape[0]):
        if k != skip:
            v = xb[k] + theta * rate[k]
            a = lo[k]
            b = hi[k]
            if a != a:
                a, b = _slot_bounds(sk[k], si[k], v, lb, ub, t_lower)
            if v < a:
                v = a
            elif v > b:
                v = b
            xb[k] = v


@njit(cache=True)
def project_slots(sk, si, xb, lb, ub, t_lower):
    """Clip basic values to their bounds (rounding: thesis §4.2.2)."""
    for k in range(sk.shape[0]):
        lo, hi = _slot_bounds(sk[k], si[k], xb[k], lb, ub, t_lower)
        v = xb[k]
        if v < lo:
            xb[k] = lo
        elif v > hi:
            xb[k] = hi


@njit(cache=True)
def newton_linearization(jdata, pos_j, scatter, pos_d, eps, indptr, indices, z, f, x,
                         mdata, q, r):
    """The linear MCP of a major iteration in one pass (nms.Linearizer.linearize):
    mdata = the entries of M = J + eps I on M's pattern (``scatter``: J's entry k at
    position pos_j[k], the others 0; else J's entries in M's order), q = f - M z (M z
    summed column by column, as :func:`csc_matvec`) and r = f + x - z: the bits of the
    array formulas."""
    if scatter:
        mdata[:] = 0.0
        for k in range(jdata.shape[0]):
            mdata[pos_j[k]] = jdata[k]
    else:
        for k in range(jdata.shape[0]):
            mdata[k] = jdata[k]
    if eps != 0.0:
        for k in range(pos_d.shape[0]):
            mdata[pos_d[k]] += eps
    csc_matvec(indptr, indices, mdata, z, q)
    for i in range(q.shape[0]):
        q[i] = f[i] - q[i]
        r[i] = f[i] + x[i] - z[i]
