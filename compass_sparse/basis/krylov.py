"""Right-preconditioned GMRES: solves with a basis whose LU factors belong to an older basis.

Mathematics
-----------
Let B be the current basis and P ~ B a matrix whose LU factors we hold (the factors of an
earlier basis with the same slot table, e.g. the previous Newton step's Jacobian
columns).  From ``x0 = P^{-1} b`` GMRES minimizes the true residual over

    x = x0 + P^{-1} V_m y,    V_m an orthonormal basis of K_m(B P^{-1}, r0),

so after m steps ``||b - B x||_2 = min_y ||beta e_1 - H_m y||_2`` (the Arnoldi relation
``B P^{-1} V_m = V_{m+1} H_m``).  When ``E = I - B P^{-1}`` is small (the Jacobian moved
little) the residual falls like ``||E||^m``: a handful of solves with the old factors
replace one factorization.  When B is singular or far from P the residual stalls, which
the caller detects and answers with a fresh factorization.

Orthogonalization is modified Gram-Schmidt with one reorthogonalization pass (the
vectors of an ill-conditioned B lose orthogonality otherwise); the small least-squares
problem is re-solved every step (m is at most a few dozen).
"""
from __future__ import annotations

import numpy as np


def preconditioned_gmres(matvec, psolve, b, tol, maxiter):
    """(x, steps, residual): GMRES on ``B x = b`` right-preconditioned by ``psolve``
    (``psolve(v) ~ B^{-1} v``), started from ``psolve(b)``.

    Stops early when the residual's mean rate of decrease so far, doubled, predicts that
    ``maxiter`` steps will not reach ``tol`` (checked from the fourth step on).
    Stops when the 2-norm residual (GMRES's own estimate, exact in exact arithmetic) is at
    most ``tol`` (a number, or a function of ``x0 = psolve(b)`` for targets relative to
    the solution's size) or after ``maxiter`` steps; ``residual`` is that estimate (the caller
    checks the true residual of x).  ``steps`` counts the Krylov steps, each one product
    with B and one preconditioner solve (plus the solve of ``x0`` and of the correction).
    """
    b = np.asarray(b, dtype=np.float64)
    x = psolve(b)
    if callable(tol):
        tol = tol(x)
    r = b - matvec(x)
    beta = float(np.linalg.norm(r))
    if not np.isfinite(beta) or beta <= tol or maxiter <= 0:
        return x, 0, beta
    n = b.size
    V = np.empty((maxiter + 1, n))
    H = np.zeros((maxiter + 1, maxiter))
    V[0] = r / beta
    y = np.zeros(0)
    res = beta
    steps = 0
    for j in range(maxiter):
        w = matvec(psolve(V[j]))
        for _ in range(2):  # MGS, then once more for orthogonality
            for i in range(j + 1):
                h = float(V[i] @ w)
                H[i, j] += h
                w -= h * V[i]
        hn = float(np.linalg.norm(w))
        H[j + 1, j] = hn
        steps = j + 1
        e1 = np.zeros(j + 2)
        e1[0] = beta
        y, *_ = np.linalg.lstsq(H[:j + 2, :j + 1], e1, rcond=None)
        res = float(np.linalg.norm(e1 - H[:j + 2, :j + 1] @ y))
        if not np.isfinite(res) or res <= tol or hn == 0.0:
            break
        if j >= 3 and res > tol:
            # Predicted failure: even at twice the mean rate so far the residual would
            # not reach tol in the steps left; stop rather than spend them.
            rate = (res / beta) ** (1.0 / steps)
            if res * rate ** (2 * (maxiter - steps)) > tol:
                break
        V[j + 1] = w / hn
    if steps and np.all(np.isfinite(y)):
        x = x + psolve(V[:steps].T @ y)
    return x, steps, res
