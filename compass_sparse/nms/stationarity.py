"""Diagnosis of a failed solve: has it converged to a stationary point of the merit function?

Psi = 0.5 ||Phi||^2 has gradient g = H^T Phi with H = Da + Db J (see :mod:`.merit`).  Every
method here (Newton on the normal map, its watchdog, the gradient and Levenberg–Marquardt
fallbacks) can be attracted to a point where g = 0 but Phi != 0: a local minimum of Psi
that is not a solution (for example F = x^2 + 1, or a CGE model without an equilibrium).
There no local method makes progress, so the solve should say so instead of only reporting
a limit.  After a failed solve the best point z is called stationary when

    ||grad Psi(z)||_2 * max(1, ||z||_inf) <= STATIONARY_RTOL * Psi(z),

i.e. even a step as long as the point itself along the steepest descent direction would,
to first order, lower the merit by less than STATIONARY_RTOL of its value.  (The iterates
only approach such a point: for F = x^2 + 1 the best point after the restarts is x ~ 1e-2,
with ratio ~ 3e-2.)  The rows that keep the merit up are those with the largest |Phi_i|.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from ..merit import fb_jacobian_diagonals, fb_phi

__all__ = ["STATIONARY_RTOL", "Stationarity", "stationarity", "worst_rows"]

STATIONARY_RTOL = 0.1
"""First-order relative decrease of Psi over a step of length max(1, ||z||) below which a
non-solution is called a stationary point."""

ROWS_NAMED = 5
"""How many rows the diagnosis names at most ..."""

ROW_SHARE = 1e-3
"""... and only rows with |Phi_i| at least this fraction of the largest."""


@dataclass
class Stationarity:
    stationary: bool
    ratio: float  #: ||grad Psi|| max(1, ||z||_inf) / Psi
    rows: list = field(default_factory=list)  #: (row index, |Phi_i|), largest first

    def rows_text(self, row_label) -> str:
        names = ", ".join(f"{row_label(i)} (|Phi| {v:.2e})" for i, v in self.rows)
        return f"the rows that keep the merit up: {names}"

    def message(self, row_label) -> str:
        if not self.stationary:
            return self.rows_text(row_label)
        return (f"converged to a stationary point of the merit function that is not a "
                f"solution (||grad Psi|| max(1, ||z||) / Psi = {self.ratio:.1e}); "
                + self.rows_text(row_label))


def worst_rows(phi) -> list:
    """(row index, |Phi_i|) of the rows that keep the merit up: at most ``ROWS_NAMED``,
    largest first, each at least ``ROW_SHARE`` of the largest."""
    k = min(ROWS_NAMED, phi.size)
    a = np.abs(phi)
    if phi.size > 4 * k:
        # the k largest by a partition, then sorted, ties by index (a whole sort took
        # 0.08 s at n = 1e6, twice in a failed solve's diagnosis)
        idx = np.sort(np.argpartition(a, a.size - k)[a.size - k:])
        idx = idx[np.argsort(-a[idx], kind="stable")]
    else:
        idx = np.argsort(-a, kind="stable")[:k]
    big = float(a[idx[0]]) if phi.size else 0.0
    return [(int(i), float(a[i])) for i in idx if a[i] >= ROW_SHARE * big > 0]


def stationarity(z, f, J, lb, ub) -> Stationarity:
    """Whether z is a stationary point of Psi that is not a solution (see module docs)."""
    phi = fb_phi(z, f, lb, ub)
    nphi = float(np.linalg.norm(phi))
    rows = worst_rows(phi)
    if nphi == 0.0 or J is None:
        return Stationarity(False, np.inf, rows)
    da, db = fb_jacobian_diagonals(z, f, lb, ub)
    H = sp.diags(db) @ sp.csr_matrix(J) + sp.diags(da)
    g = H.T @ phi
    psi = 0.5 * nphi ** 2
    zmax = float(np.max(np.abs(z))) if z.size else 0.0
    ratio = float(np.linalg.norm(g)) * max(1.0, zmax) / max(psi, 1e-300)
    return Stationarity(ratio <= STATIONARY_RTOL, ratio, rows)
