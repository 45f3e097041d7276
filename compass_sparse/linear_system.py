"""An LCP whose variables are all free is the linear system M z + q = 0.

Pivoting on it is pointless, and when M is singular and q is not in its range the general
method searches for a long time for a solution that does not exist (a Neumann Laplacian
with q = -1 took 107 s at n = 1000).  Here:

* a least-squares solution z of min ||M z + q|| is computed (dense SVD-based ``lstsq``
  up to ``DENSE_MAX_N``; LSMR above);
* if ||M z + q||_2 <= tol, z solves the LCP (Phi_FB = -(M z + q) for free rows);
* otherwise y = M z + q is a certificate of inconsistency when M^T y vanishes:
  ||M^T y||_2 <= CERTIFICATE_RTOL * ||M||_F * ||y||_2 while y^T q = ||y||^2 > 0, so no z
  has M z + q = 0 (y^T (M z + q) = (M^T y)^T z + y^T q would be 0);
* anything else (LSMR not converged, no clean certificate) is left to the general method.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from .status import Status
from .linalg.blas import single_threaded_blas

__all__ = ["solve_free_lcp", "FreeSystemOutcome", "CERTIFICATE_RTOL", "DENSE_MAX_N"]

DENSE_MAX_N = 2000
"""Up to this n the least-squares problem is solved densely."""

CERTIFICATE_RTOL = 1e-9
"""||M^T y|| / (||M||_F ||y||) below which y certifies that M z + q = 0 is inconsistent."""


@dataclass
class FreeSystemOutcome:
    status: Status
    message: str
    z: np.ndarray | None


def solve_free_lcp(M: sp.csc_matrix, q: np.ndarray, tol: float) -> FreeSystemOutcome | None:
    n = q.size
    if n <= DENSE_MAX_N:
        # single-threaded (see compass_sparse.linalg.blas): 25 s against 0.8 s at n = 1000
        with single_threaded_blas():
            z = np.linalg.lstsq(M.toarray(), -q, rcond=None)[0]
    else:
        # (lazy: scipy's linalg adds ~0.15 s to the package's import)
        from scipy.sparse.linalg import lsmr

        z = lsmr(M, -q, atol=1e-14, btol=1e-14, maxiter=20 * n)[0]
    y = M @ z + q
    ny = float(np.linalg.norm(y))
    if ny <= tol:
        return FreeSystemOutcome(Status.SOLVED, "solution of the linear system M z + q = 0", z)
    normM = float(sp.linalg.norm(M)) if M.nnz else 0.0
    resid = float(np.linalg.norm(M.T @ y))
    if resid <= CERTIFICATE_RTOL * max(normM, 1e-300) * ny and float(y @ q) > 0:
        return FreeSystemOutcome(
            Status.INFEASIBLE,
            "every variable is free, so the LCP is the linear system M z + q = 0, which has "
            f"no solution: M is singular and q is not in its range (y = M z + q at the "
            f"least-squares point has M^T y = {resid:.2e} relative to ||M|| ||y|| = "
            f"{normM * ny:.2e}, while y^T q = {float(y @ q):.3e} > 0)", z)
    return None
