"""Compiled set-up and read-out of a pivotal path's slot table (see :mod:`.path`).

Every major iteration builds a path: the slot table from the start basis, and at its end
the point (z, w, v) read off the table and the basis handed to the next path.  Written
with array operations these are some thirty numpy calls per path (~20 us on a
1-variable problem, about a third of a small solve's time in its paths); here each is one
pass.  They compute exactly what the array versions in :class:`.path.PivotalPath` compute
(kept there as the reference and for other argument types): np.maximum / np.minimum
semantics (a NaN propagates; on a tie the second argument: max(-0.0, 0.0) = 0.0), and,
where several slots name the same index, the assignment order of the array version
(kinds in the order z, w, v, fixed slack; slots in order within a kind).
"""

import numpy as np

from .._jit import njit
from ..linalg._csc_kernels import csc_matvec
from ._kernels import VAR_S, VAR_V, VAR_W, VAR_Z


@njit(cache=True, inline="always")
def _max0(a):
    """np.maximum(a, 0.0): a when larger or NaN, else 0.0 (so max(-0.0, 0.0) is 0.0)."""
    return a if (a > 0.0 or a != a) else 0.0


@njit(cache=True, inline="always")
def _clip(a, lb, ub):
    """np.minimum(np.maximum(a, lb), ub) for bounds without NaN (a NaN a stays NaN; on a
    tie the bound, as numpy's second argument)."""
    a = a if (a > lb or a != a) else lb
    return a if (a < ub or a != a) else ub


@njit(cache=True)
def components(x, lb, ub, z, w, v):
    """path.components into z, w, v: z = pi(x), w = (z - x)+, v = (x - z)+."""
    for i in range(x.shape[0]):
        zi = _clip(x[i], lb[i], ub[i])
        z[i] = zi
        w[i] = _max0(zi - x[i])
        v[i] = _max0(x[i] - zi)


@njit(cache=True)
def slot_point(sk, si, xb, zval, lb, ub, z, w, v):
    """PivotalPath.current_point into z, w, v: z from zval with the basic z's from the
    table, w and v the nonnegative parts of basic slacks (a fixed variable's free slack s
    gives w = max(s, 0), v = max(-s, 0)), z projected onto [lb, ub]."""
    n = z.shape[0]
    for i in range(n):
        z[i] = zval[i]
        w[i] = 0.0
        v[i] = 0.0
    for k in range(sk.shape[0]):
        if sk[k] == VAR_Z:
            z[si[k]] = xb[k]
    for k in range(sk.shape[0]):
        if sk[k] == VAR_W:
            w[si[k]] = _max0(xb[k])
    for k in range(sk.shape[0]):
        if sk[k] == VAR_V:
            v[si[k]] = _max0(xb[k])
    for k in range(sk.shape[0]):
        if sk[k] == VAR_S:
            w[si[k]] = _max0(xb[k])
            v[si[k]] = _max0(-xb[k])
    for i in range(n):
        z[i] = _clip(z[i], lb[i], ub[i])


@njit(cache=True)
def slot_basis(z, lb, ub, sk, si, basic):
    """The basis of a finished path into ``basic`` (int8): path.default_basis(z, lb, ub)
    overwritten by the kind of every z, w, v or fixed-slack slot of the table."""
    for i in range(z.shape[0]):
        if lb[i] == ub[i]:
            basic[i] = VAR_S
        elif z[i] <= lb[i]:
            basic[i] = VAR_W
        elif z[i] >= ub[i]:
            basic[i] = VAR_V
        else:
            basic[i] = VAR_Z
    for kind in (VAR_Z, VAR_W, VAR_V, VAR_S):
        for k in range(sk.shape[0]):
            if sk[k] == kind:
                basic[si[k]] = kind


@njit(cache=True)
def slot_table(basic, z, w, v, sk, si, xb):
    """PivotalPath._reset_slots' table: slot i holds index i's basic variable (kind
    ``basic[i]``) at its value in (z, w, v); a fixed variable's slack at w - v."""
    for i in range(basic.shape[0]):
        b = basic[i]
        sk[i] = b
        si[i] = i
        if b == VAR_Z:
            xb[i] = z[i]
        elif b == VAR_W:
            xb[i] = w[i]
        elif b == VAR_S:
            xb[i] = w[i] - v[i]
        else:
            xb[i] = v[i]


@njit(cache=True)
def start_basis(z, lb, ub, previous, use_previous, basic):
    """path.default_basis into ``basic`` (int8): z basic strictly inside its bounds, the
    slack at a bound unless ``previous`` (when ``use_previous``) had z basic there, the
    free slack of a fixed variable."""
    for i in range(z.shape[0]):
        if lb[i] == ub[i]:
            basic[i] = VAR_S
        elif z[i] <= lb[i] or z[i] >= ub[i]:
            if use_previous and previous[i] == VAR_Z:
                basic[i] = VAR_Z
            elif z[i] <= lb[i]:
                basic[i] = VAR_W
            else:
                basic[i] = VAR_V
        else:
            basic[i] = VAR_Z


@njit(cache=True)
def lemke_start(indptr, indices, data, q, lb, ub, z, w, v, r, basic):
    """PivotalPath._lemke_start into z, w, v, r, basic: z at a finite bound (the lower
    one first; 0 when free), f = M z + q (M in CSC form, scipy's order), every bounded
    variable's slack basic at delta = max(1, |f_i|) (the free slack of a fixed one), and
    the covering vector r = f - delta at lower bounds, f + delta at upper-only ones, f
    on free rows."""
    n = z.shape[0]
    for i in range(n):
        if np.isfinite(lb[i]):
            z[i] = lb[i]
        elif np.isfinite(ub[i]):
            z[i] = ub[i]
        else:
            z[i] = 0.0
    csc_matvec(indptr, indices, data, z, r)
    for i in range(n):
        f = r[i] + q[i]
        has_l = np.isfinite(lb[i])
        has_u = np.isfinite(ub[i]) and not has_l
        b = VAR_W if has_l else (VAR_V if has_u else VAR_Z)
        if lb[i] == ub[i]:
            b = VAR_S
        basic[i] = b
        af = abs(f)
        d = af if (af > 1.0 or af != af) else 1.0  # np.maximum(1.0, |f|)
        r[i] = f - d if has_l else (f + d if has_u else f)
        w[i] = d if b == VAR_W else 0.0
        v[i] = d if b == VAR_V else 0.0
