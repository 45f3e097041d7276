"""The one-dimensional affine MCP  l <= z <= u  _|_  a z + c.

Solutions: z = l if l is finite and a l + c >= 0; z = u if u is finite and a u + c <= 0;
the root -c/a if it lies strictly inside (l, u); every z in [l, u] when a = c = 0.
For a > 0 the solution is unique, z = clip(-c/a, l, u).  For a < 0 there can be up to three
solutions, or none (e.g. l = -inf, u = +inf never fails, but l finite with a l + c < 0 and
u = +inf has none).
"""
from __future__ import annotations

import numpy as np

__all__ = ["solve_1d", "solve_1d_vector"]


def solve_1d(a: float, c: float, l: float, u: float, prefer: float = 0.0, tol: float = 0.0):
    """Return (status, value): status 'unique', 'multiple' (value = the solution nearest
    ``prefer``) or 'none' (value = nan).  ``tol`` widens the sign tests (absolute)."""
    if a > 0:
        return "unique", float(min(max(-c / a, l), u))
    if a == 0:
        if c > tol:
            return ("unique", float(l)) if np.isfinite(l) else ("none", np.nan)
        if c < -tol:
            return ("unique", float(u)) if np.isfinite(u) else ("none", np.nan)
        if l == u:
            return "unique", float(l)
        return "multiple", float(min(max(prefer, l), u))
    cands = []
    if np.isfinite(l) and a * l + c >= -tol:
        cands.append(float(l))
    if np.isfinite(u) and a * u + c <= tol:
        cands.append(float(u))
    r = -c / a
    if l < r < u:
        cands.append(float(r))
    cands = sorted(set(cands))
    if not cands:
        return "none", np.nan
    if len(cands) == 1:
        return "unique", cands[0]
    best = min(cands, key=lambda v: abs(v - prefer))
    return "multiple", best


def solve_1d_vector(a, c, l, u, prefer):
    """Elementwise :func:`solve_1d` for a > 0 (vectorized) and otherwise one by one; an
    unsolvable entry gets the bound nearest to satisfying it (never happens when a > 0 or
    the box is bounded, which is what the preprocessor guarantees)."""
    a = np.asarray(a, dtype=float)
    c = np.asarray(c, dtype=float)
    out = np.empty_like(c)
    pos = a > 0
    out[pos] = np.clip(-c[pos] / a[pos], l[pos], u[pos])
    for k in np.flatnonzero(~pos):
        status, v = solve_1d(a[k], c[k], l[k], u[k], prefer[k])
        if status == "none":
            v = l[k] if np.isfinite(l[k]) else u[k]
        out[k] = v
    return out
