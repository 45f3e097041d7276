"""A small reference MCP solver for the presolve tests ONLY.

Semismooth Newton on the Fischer–Burmeister function Phi (dense, n <= a few hundred):
H = diag(da) + diag(db) J, Newton step H d = -Phi, Armijo backtracking on
Psi = 0.5 ||Phi||^2, with a steepest-descent fallback when the Newton direction is not a
descent direction.  Good enough for the P-matrix / strongly monotone instances built by
the tests; it is not the package's solver.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from compass_sparse.merit import fb_jacobian_diagonals, fb_phi, natural_residual


@dataclass
class RefResult:
    x: np.ndarray
    nit: int
    success: bool
    fb_norm: float
    natural: float


def ref_solve(problem, x0=None, tol=1e-12, max_iter=200) -> RefResult:
    lb, ub = problem.lb, problem.ub
    x = np.clip(problem.x0 if x0 is None else np.asarray(x0, float), lb, ub)
    n = x.size
    f, J = problem.FJ(x)
    phi = fb_phi(x, f, lb, ub)
    psi = 0.5 * phi @ phi
    nit = 0
    while np.sqrt(2 * psi) > tol and nit < max_iter:
        da, db = fb_jacobian_diagonals(x, f, lb, ub)
        H = np.diag(da) + db[:, None] * J.toarray()
        grad = H.T @ phi
        try:
            d = np.linalg.solve(H + 1e-14 * np.eye(n), -phi)
            if not np.all(np.isfinite(d)) or grad @ d > -1e-12 * np.linalg.norm(d) ** 2:
                d = -grad
        except np.linalg.LinAlgError:
            d = -grad
        t = 1.0
        while True:
            xt = x + t * d
            ft = problem.F(xt)
            pt = fb_phi(xt, ft, lb, ub)
            psit = 0.5 * pt @ pt
            if psit <= psi + 1e-4 * t * (grad @ d) or t < 1e-12:
                break
            t *= 0.5
        x = xt
        f, J = problem.FJ(x)
        phi = fb_phi(x, f, lb, ub)
        psi = 0.5 * phi @ phi
        nit += 1
    fbn = float(np.sqrt(2 * psi))
    return RefResult(x=x, nit=nit, success=fbn <= tol * 10, fb_norm=fbn,
                     natural=natural_residual(x, f, lb, ub))
