"""Fallback steps on the merit function Psi = 0.5 ||Phi_FB||^2 (thesis §3.4; Ferris, Kanzow
& Munson 1999).

* Projected gradient step from the best point: z(alpha) = pi(z - alpha grad Psi) (arc) or
  z + alpha (pi(z - grad Psi) - z) (line), accepting the first alpha (shrinking by
  ``gradient_shrink_factor``) with Psi(z(alpha)) <= Psi(z) - sigma grad Psi^T (z - z(alpha)).
  Monotone and always possible at a non-stationary point, but slow.
* Levenberg–Marquardt step: with H = diag(da) + diag(db) J an element of the generalized
  Jacobian of Phi, solve the symmetric positive definite system

      (H^T H + mu I) d = -H^T Phi = -grad Psi

  and search along pi(z + alpha d).  For mu -> 0 this is a Gauss–Newton step on Phi, for
  large mu a short gradient step, so it bridges Newton and gradient behaviour where the
  pivotal path fails (singular or indefinite J).  Up to order ``DENSE_SOLVE_MAX_N`` the
  system is solved densely (LAPACK's LU); above it by CHOLMOD (a
  sparse Cholesky of the SPD matrix, SuiteSparse from the ``kvxopt`` wheels, AMD-ordered
  by CHOLMOD itself); SuperLU when CHOLMOD reports the matrix not positive definite
  (round-off on a nearly singular H^T H with tiny mu) or kvxopt is missing.
"""
from __future__ import annotations

import time

import numpy as np
import scipy.sparse as sp

from ..basis.backends import DENSE_SOLVE_MAX_N
from ..box import project
from ..merit import fb_jacobian_diagonals, fb_phi, fb_psi

__all__ = ["gradient_steps", "lm_step", "spd_solve", "cholmod_available"]


def cholmod_available() -> bool:
    try:
        # (lazy: kvxopt loads SuiteSparse's libraries; imported where they are used)
        import kvxopt.cholmod  # noqa: F401
    except Exception:
        return False
    return True


def spd_solve(A, b):
    """Solve A x = b for sparse SPD A: CHOLMOD when available, else SuperLU."""
    A = sp.csc_matrix(A)
    b = np.asarray(b, dtype=np.float64).ravel()
    try:
        # (lazy: kvxopt loads SuiteSparse's libraries; imported where they are used)
        from kvxopt import cholmod, matrix, spmatrix
    except ImportError:
        cholmod = None
    if cholmod is not None and A.shape[0] > 0:
        L = sp.tril(A, format="csc")      # CHOLMOD reads the lower triangle ('L')
        cols = np.repeat(np.arange(L.shape[1], dtype=np.int64), np.diff(L.indptr))
        Ak = spmatrix(matrix(L.data.astype(np.float64)), matrix(L.indices.astype(np.int64)),
                      matrix(cols), L.shape)
        B = matrix(b.copy())
        try:
            cholmod.linsolve(Ak, B, uplo="L")
            return np.asarray(B).ravel()
        except ArithmeticError:           # not positive definite in floating point
            pass
    import scipy.sparse.linalg as spla  # (lazy: its import costs ~0.15 s)

    return spla.splu(A, permc_spec="MMD_AT_PLUS_A").solve(b)


def _armijo(evalr, z, psi, g, trial, lb, ub, sigma, shrink, alpha_min, alpha0=1.0,
            on_point=None, deadline=None):
    """The first alpha = alpha0 shrink^k >= alpha_min whose trial point ``trial(alpha)``
    (always of the form proj(z + alpha v)) decreases Psi enough: (z, f, phi, psi, alpha),
    or None.

    A trial that rounds to z itself ends the search: in each component, rounding and the
    projection are monotone in alpha, so every shorter step rounds to z as well and cannot
    decrease Psi.  At a stationary point of Psi on the box, where -grad Psi points out of
    the box at its bounds, this is the first trial (billups: ~100 trials of z per
    fallback before, each a memo hit and an acceptance test)."""
    alpha = alpha0
    while alpha >= alpha_min:
        if deadline is not None and time.perf_counter() > deadline:
            return None  # the caller's limit check reports the time limit
        zt = trial(alpha)
        if np.array_equal(zt, z):
            return None
        ft = evalr.f(zt)
        if ft is not None:
            phit = fb_phi(zt, ft, lb, ub)
            psit = fb_psi(phit)
            if on_point is not None:
                on_point(zt, ft, phit, psit)
            dec = float(g @ (z - zt))
            if psit <= psi - sigma * max(dec, 0.0) and psit < psi:
                return zt, ft, phit, psit, alpha
        alpha *= shrink
    return None


def gradient_steps(evalr, z, f, J, lb, ub, opt, *, on_point=None, deadline=None):
    """Up to ``gradient_step_limit`` projected-gradient steps from z.  Returns the last
    accepted (z, f, phi, psi, steps) or None when no step decreased Psi."""
    phi = fb_phi(z, f, lb, ub)
    psi = fb_psi(phi)
    out = None
    steps = 0
    for _ in range(max(1, opt.gradient_step_limit)):
        if J is None:
            J = evalr.jac(z, f)
            if J is None:
                break
        da, db = fb_jacobian_diagonals(z, f, lb, ub)
        g = da * phi + J.T @ (db * phi)
        gn = float(g @ g)
        if gn == 0.0:
            break
        # First trial: the Cauchy-like step length psi / ||g||^2, capped at 1.
        a0 = min(1.0, max(psi / gn, 1e-12))
        if opt.gradient_searchtype == "arc":
            trial = lambda a, z=z, g=g: project(z - a * g, lb, ub)  # noqa: E731
        else:
            pz = project(z - g, lb, ub) - z
            # (projected: z + a pz can round to a unit in the last place beyond a bound)
            trial = lambda a, z=z, pz=pz: project(z + a * pz, lb, ub)  # noqa: E731
            a0 = 1.0
        acc = _armijo(evalr, z, psi, g, trial, lb, ub, opt.gradient_sigma,
                      opt.gradient_shrink_factor, max(opt.gradient_stepsize_minimum, 1e-20),
                      alpha0=a0, on_point=on_point, deadline=deadline)
        if acc is None:
            break
        z, f, phi, psi, _ = acc
        J = None
        steps += 1
        out = (z, f, phi, psi, steps)
    return out


def lm_step(evalr, z, f, J, lb, ub, opt, *, mu=None, on_point=None, deadline=None):
    """One projected Levenberg–Marquardt step.  Returns (z, f, phi, psi, mu) or None."""
    if J is None:
        J = evalr.jac(z, f)
        if J is None:
            return None
    phi = fb_phi(z, f, lb, ub)
    psi = fb_psi(phi)
    da, db = fb_jacobian_diagonals(z, f, lb, ub)
    n = z.size
    dense = n <= DENSE_SOLVE_MAX_N
    if dense:
        # Small systems are solved densely (LAPACK's LU of the SPD matrix): building and
        # factoring sparse matrices cost ~0.7 ms per mu at n = 1 (billups), more than
        # the dense arithmetic up to this order.
        J = J.toarray() if sp.issparse(J) else np.asarray(J, dtype=np.float64)
        H = db[:, None] * J
        H[np.diag_indices(n)] += da
    else:
        H = sp.csc_matrix(sp.diags(db) @ J + sp.diags(da))
    g = H.T @ phi
    gnorm = float(np.linalg.norm(g))
    if gnorm == 0.0:
        return None
    if mu is None:
        mu = opt.lm_initial_mu * gnorm
    HtH = H.T @ H if dense else (H.T @ H).tocsc()
    for _ in range(4):
        if deadline is not None and time.perf_counter() > deadline:
            # Each Cholesky factorization is atomic (12 s of H^T H at n = 3e4 on the
            # dynamic CGE model): none is started after the limit.
            return None
        try:
            if dense:
                A = HtH.copy()
                A[np.diag_indices(n)] += mu
                d = np.linalg.solve(A, -g)
            else:
                d = spd_solve(HtH + mu * sp.identity(n, format="csc"), -g)
        except (RuntimeError, np.linalg.LinAlgError):
            mu *= 10.0
            continue
        if not np.all(np.isfinite(d)):
            mu *= 10.0
            continue
        acc = _armijo(evalr, z, psi, g, lambda a: project(z + a * d, lb, ub), lb, ub,
                      opt.nms_sigma, 0.5, 1e-6, on_point=on_point, deadline=deadline)
        if acc is not None:
            zt, ft, phit, psit, alpha = acc
            return zt, ft, phit, psit, (mu * 0.3 if alpha == 1.0 else mu)
        mu *= 10.0
    return None
