"""Products with the basis B of a slot table (the residual checks' arithmetic): slot s holds
``sign * M[:, j]`` (KIND_M), ``sign * e_j`` (KIND_UNIT) or ``sign * r`` (KIND_DENSE), given
as the arrays ``kinds``, ``indices``, ``signs``."""
from __future__ import annotations

import numpy as np

from .types import KIND_DENSE, KIND_M, KIND_UNIT

__all__ = ["backward_error", "matvec", "norm_inf", "rmatvec"]


def matvec(k, i, s, M, r, x):
    """B @ x for x indexed by slot."""
    n = k.shape[0]
    m = k == KIND_M
    y = M @ np.bincount(i[m], weights=s[m] * x[m], minlength=n)
    u = k == KIND_UNIT
    y += np.bincount(i[u], weights=s[u] * x[u], minlength=n)
    for d in np.flatnonzero(k == KIND_DENSE):
        y += r * (s[d] * x[d])
    return y


def rmatvec(k, i, s, M, r, y):
    """B^T @ y (indexed by slot) for y indexed by row."""
    out = np.zeros(k.shape[0])
    m = k == KIND_M
    out[m] = s[m] * (M.T @ y)[i[m]]
    u = k == KIND_UNIT
    out[u] = s[u] * y[i[u]]
    d = k == KIND_DENSE
    if np.any(d):
        out[d] = s[d] * float(r @ y)
    return out


def norm_inf(k, i, s, absM, r):
    """||B||_inf (``absM``: |M|)."""
    n = k.shape[0]
    m = k == KIND_M
    rs = absM @ np.bincount(i[m], weights=np.abs(s[m]), minlength=n)
    u = k == KIND_UNIT
    rs += np.bincount(i[u], weights=np.abs(s[u]), minlength=n)
    for d in np.flatnonzero(k == KIND_DENSE):
        rs += np.abs(r) * abs(s[d])
    return float(rs.max()) if n else 0.0


def backward_error(res, rhs, x, norm_B):
    """||res||_inf / (||rhs||_inf + ||B||_inf ||x||_inf) for the residual res = B x - rhs."""
    den = np.abs(rhs).max() + norm_B * np.abs(x).max()
    num = np.abs(res).max()
    if not np.isfinite(num):
        return np.inf
    return float(num / den) if den > 0 else float(num)
