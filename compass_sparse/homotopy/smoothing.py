"""The smoothed projection p_mu and its derivatives (the smoothed normal map's pieces; see
:mod:`compass_sparse.homotopy`)."""
from __future__ import annotations

import numpy as np

from ..box import float_vectors
from ._kernels import smoothed_projection

__all__ = ["SmoothedNormalMap", "splus"]


# ------------------------------------------------------------------ the smoothed equation
def splus(r, mu):
    """s_mu(r) and its derivatives d/dr, d/dmu.  Written as max(r, 0) + 2 mu^2 / (q + |r|),
    q = sqrt(r^2 + 4 mu^2) (the same value on both signs of r), so it has no cancellation
    for r << 0 and no branch."""
    if mu <= 0.0:
        return np.maximum(r, 0.0), (r > 0).astype(float), np.zeros_like(r)
    # hypot and mu * (2 mu / ...) instead of mu^2: mu^2 underflows below 1e-154 (0/0 at
    # r = 0) and overflows above 1e154, both reachable through homotopy_smoothing.
    q = np.hypot(r, 2.0 * mu)
    val = np.maximum(r, 0.0) + mu * (2.0 * mu / (q + np.abs(r)))
    return val, 0.5 * (1.0 + r / q), 2.0 * mu / q


class SmoothedNormalMap:
    """p_mu(x) and its derivatives for the box [lb, ub] (see the module docstring)."""

    def __init__(self, lb, ub):
        self.lb = np.asarray(lb, dtype=float)
        self.ub = np.asarray(ub, dtype=float)
        self._rows = None  # the array route's row data, made when it first runs

    def _row_data(self):
        """(has_l, has_u, c_l, c_u, l0, u0) of the array route.  One formula for every
        kind of row: p = base + c_l s_mu(x - l) - c_u s_mu(x - u), base = l on rows with a
        lower bound and x elsewhere (then s_mu(-r) = s_mu(r) - r gives the upper-bound-only
        row u - s_mu(u - x) = x - s_mu(x - u))."""
        if self._rows is None:
            has_l, has_u = np.isfinite(self.lb), np.isfinite(self.ub)
            self._rows = (has_l, has_u, has_l.astype(float), has_u.astype(float),
                          np.where(has_l, self.lb, 0.0), np.where(has_u, self.ub, 0.0))
        return self._rows

    def project(self, x, mu):
        """(p, dp/dx, dp/dmu) at x (one compiled pass for a float vector)."""
        n = self.lb.size
        if float_vectors(n, x, self.lb, self.ub):
            p, dx, dmu = np.empty(n), np.empty(n), np.empty(n)
            smoothed_projection(x, float(mu), self.lb, self.ub, p, dx, dmu)
            return p, dx, dmu
        return self.project_arrays(x, mu)

    def project_arrays(self, x, mu):
        """:meth:`project` by array operations (the compiled pass's reference)."""
        has_l, _, cl, cu, l0, u0 = self._row_data()
        sl, dl, ml = splus(x - l0, mu)
        su, du, mu_u = splus(x - u0, mu)
        p = np.where(has_l, l0, x) + cl * sl - cu * su
        dx = (1.0 - cl) + cl * dl - cu * du
        dmu = cl * ml - cu * mu_u
        # The smoothed projection may leave the box by rounding only; clip it.
        return np.clip(p, self.lb, self.ub), dx, dmu
