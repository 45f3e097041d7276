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

import time

import numpy as np


def _ps(psolve, cols):
    """psolve on a list of vectors: one call on their (n, k) matrix (a sparse LU reads its
    factors once for all k: 2 right-hand sides cost 1.4 of one, measured), one 1-D call
    for a single vector."""
    if len(cols) == 1:
        return psolve(cols[0])[:, None]
    return psolve(np.column_stack(cols))


def preconditioned_gmres(matvec, psolve, b, tol, maxiter, deadline=None):
    """(x, steps, residual): GMRES on ``B x = b`` right-preconditioned by ``psolve``
    (``psolve(v) ~ B^{-1} v``), started from ``psolve(b)``.

    ``b`` may be a matrix (n, k): k systems run in lockstep, each step one ``psolve`` of
    the (n, k') matrix of the still-running ones (psolve must then take matrices), and x,
    the residuals and ``tol`` (a list) are per column; ``steps`` is the number of lockstep
    steps.
    Stops early when the residual's mean rate of decrease so far, doubled, predicts that
    ``maxiter`` steps will not reach ``tol`` (checked from the fourth step on).
    Stops when the 2-norm residual (GMRES's own estimate, exact in exact arithmetic) is at
    most ``tol`` (a number, or a function of ``x0 = psolve(b)`` for targets relative to
    the solution's size) or after ``maxiter`` steps; ``residual`` is that estimate (the caller
    checks the true residual of x).  ``steps`` counts the Krylov steps, each one product
    with B and one preconditioner solve (plus the solve of ``x0`` and of the correction).
    No step is started after ``deadline`` (a ``time.perf_counter()`` value): x is then the
    correction of the steps made.
    """
    b = np.asarray(b, dtype=np.float64)
    single = b.ndim == 1
    Bm = b[:, None] if single else b
    n, k = Bm.shape
    X = _ps(psolve, [Bm[:, c] for c in range(k)])
    tols = tol if isinstance(tol, (list, tuple)) else [tol] * k
    tols = [t(X[:, c]) if callable(t) else t for c, t in enumerate(tols)]
    R = [Bm[:, c] - matvec(X[:, c]) for c in range(k)]
    beta = [float(np.linalg.norm(r)) for r in R]
    res = list(beta)
    active = [c for c in range(k) if np.isfinite(beta[c]) and beta[c] > tols[c]
              and maxiter > 0]
    V = {c: np.empty((maxiter + 1, n)) for c in active}
    H = {c: np.zeros((maxiter + 1, maxiter)) for c in active}
    y = {c: np.zeros(0) for c in active}
    steps = {c: 0 for c in range(k)}
    for c in active:
        V[c][0] = R[c] / beta[c]
    lock = 0
    for j in range(maxiter):
        if not active or (deadline is not None and time.perf_counter() > deadline):
            break
        lock = j + 1
        Z = _ps(psolve, [V[c][j] for c in active])
        still = []
        for col, c in enumerate(active):
            w = matvec(Z[:, col])
            Vc, Hc = V[c], H[c]
            for _ in range(2):  # MGS, then once more for orthogonality
                for i in range(j + 1):
                    h = float(Vc[i] @ w)
                    Hc[i, j] += h
                    w -= h * Vc[i]
            hn = float(np.linalg.norm(w))
            Hc[j + 1, j] = hn
            steps[c] = j + 1
            e1 = np.zeros(j + 2)
            e1[0] = beta[c]
            y[c], *_ = np.linalg.lstsq(Hc[:j + 2, :j + 1], e1, rcond=None)
            res[c] = float(np.linalg.norm(e1 - Hc[:j + 2, :j + 1] @ y[c]))
            if not np.isfinite(res[c]) or res[c] <= tols[c] or hn == 0.0:
                continue
            if j >= 3:
                # Predicted failure: even at twice the mean rate so far the residual
                # would not reach tol in the steps left; stop rather than spend them.
                rate = (res[c] / beta[c]) ** (1.0 / steps[c])
                if res[c] * rate ** (2 * (maxiter - steps[c])) > tols[c]:
                    continue
            Vc[j + 1] = w / hn
            still.append(c)
        active = still
    done = [c for c in V if steps[c] and np.all(np.isfinite(y[c]))]
    if done:
        D = _ps(psolve, [V[c][:steps[c]].T @ y[c] for c in done])
        for col, c in enumerate(done):
            X[:, c] = X[:, c] + D[:, col]
    if single:
        return X[:, 0], lock, res[0]
    return X, lock, res
