"""Compiled parts of the crash's reduced solve (see :func:`compass_sparse.crash._solve_reduced`).

A crash step on a small problem solves (J_II + eps I) d = rhs for a block of order <= 200
in up to eight attempts of growing eps.  Each attempt in Python -- a copy, the diagonal
shift, LAPACK's getrf and getrs through their wrappers, a finiteness test and a max norm --
cost ~20 us, and the structural test that decides whether eps = 0 is tried at all built a
scipy copy of the block without its stored zeros (~60 us): on kojshin's start, a third of a
solve.  Here the attempts run in one compiled call.

The factorization is numpy's ``linalg.solve`` as numba compiles it: LAPACK's gesv, which
is getrf followed by getrs on scipy's library, so the bits of scipy's lu_factor + lu_solve
(checked by the tests on orders 1 ... 200).  Its singular-matrix error is raised exactly
when getrf reports a zero pivot (info > 0).  :func:`dense_solve_or_none` is also the dense
solve of :func:`compass_sparse.basis.backends.solve_sparse`: one dense LU in the package.
"""
from __future__ import annotations

import numpy as np

from ._eval_kernels import free_block
from ._jit import njit
from ._matching import _augmenting_matching
from ._merit_kernels import crash_active_set, csc_diagonal, csc_to_dense

__all__ = ["dense_crash_step", "dense_perturbed_solve", "dense_solve_or_none",
           "initial_shift", "structurally_singular"]


@njit(cache=True)
def structurally_singular(indptr, indices, data, n):
    """Whether the n x n CSC block has no zero-free diagonal in any row and column order
    (a maximum matching of its NONZERO entries -- stored zeros do not count -- leaves a
    column unmatched): then no value of its entries makes it regular."""
    if n == 0:
        return False
    ptr = np.empty(n + 1, np.int64)
    idx = np.empty(indptr[n], np.int64)
    k = 0
    for j in range(n):
        ptr[j] = k
        for e in range(indptr[j], indptr[j + 1]):
            if data[e] != 0.0:
                idx[k] = indices[e]
                k += 1
    ptr[n] = k
    row_of, _ = _augmenting_matching(n, n, ptr, idx[:k])
    for j in range(n):
        if row_of[j] < 0:
            return True
    return False


@njit(cache=True)
def initial_shift(indptr, indices, data, n, perturb, eps0):
    """The first eps of a crash step's attempts on the n x n CSC block: eps0 when
    ``perturb`` and the block is structurally singular (no value of its entries makes it
    regular, so an unperturbed factorization can only fail -- and without a zero-free
    diagonal a sparse one runs in the slow fallback ordering: 40 s at n = 3e4 on the
    dynamic CGE model), else 0.  A full block without a zero entry needs no matching."""
    if not perturb or n == 0:
        return 0.0
    k = indptr[n]
    if k == n * n:
        full = True
        for e in range(k):
            if data[e] == 0.0:
                full = False
                break
        if full:
            return 0.0
    return eps0 if structurally_singular(indptr, indices, data, n) else 0.0


@njit(cache=True)
def dense_solve_or_none(A, b):
    """(x, True) with A x = b, or (b, False) when LAPACK finds A exactly singular."""
    try:
        return np.linalg.solve(A, b), True
    except Exception:  # numba's LinAlgError: getrf's info > 0, a zero pivot
        return b, False


@njit(cache=True)
def dense_perturbed_solve(dense, rhs, eps, eps0, perturb, attempts, step_limit):
    """The attempts of :func:`compass_sparse.crash._solve_reduced` on a dense block.

    ``dense``: the block (Fortran order); ``eps``: the first shift (0, or eps0 for a
    structurally singular block).  Attempt k solves (dense + eps I) d = rhs; a solution is
    taken when it is finite and, on a shifted matrix, ``max|d| <= step_limit``; otherwise
    eps becomes eps0 (after 0) or grows tenfold -- when ``perturb`` -- up to ``attempts``
    factorizations.  Returns (d, eps of the last attempt, factorizations, found)."""
    n = dense.shape[0]
    A = np.empty((0, 0), dtype=np.float64).T  # the shifted matrix, made when needed
    nf = 0
    for _ in range(attempts):
        nf += 1
        if eps == 0.0:
            d, ok = dense_solve_or_none(dense, rhs)  # (solve factors a copy: dense stays)
        else:
            if A.shape[0] != n:
                A = np.empty((n, n), dtype=np.float64).T  # Fortran order, as LAPACK's
            A[:, :] = dense
            for i in range(n):
                A[i, i] += eps
            d, ok = dense_solve_or_none(A, rhs)
        if ok:
            finite = True
            big = 0.0
            for i in range(n):
                v = d[i]
                if not np.isfinite(v):
                    finite = False
                    break
                big = max(big, abs(v))
            if finite and not (eps > 0.0 and big > step_limit):
                return d, eps, nf, True
        if not perturb:
            break
        eps = eps0 if eps == 0.0 else eps * 10.0
    return rhs, eps, nf, False


NO_BASIS_CHANGE = 1
"""Code of :func:`dense_crash_step`: the active set moved by fewer indices than the limit."""


@njit(cache=True)
def dense_crash_step(indptr, indices, data, z, f, lb, ub, prev_free, has_prev,
                     nbchange_limit, perturb, eps0, attempts, step_limit):
    """One crash step's direction on a problem of order <= 200 (its reduced blocks are
    dense), in one call: the kernels the Python step called one by one, in its order and
    on its arrays -- the diagonal of J, the active set and Newton target
    (``crash_active_set``), the count of changes against ``prev_free`` (a stop when fewer
    than ``nbchange_limit`` and ``has_prev``), the reduced system (``free_block`` with
    q = -F), the test that tries eps = 0 only on a block that may be regular, and the
    perturbed dense attempts (``dense_perturbed_solve``).  So the same bits.

    Returns (code, free, d, changes, inactive count, eps, factorizations, found): code
    ``NO_BASIS_CHANGE`` or 0; ``d`` is the full step (its inactive entries solved when
    ``found``)."""
    n = z.shape[0]
    dg = np.empty(n)
    csc_diagonal(indptr, indices, data, dg)
    free = np.empty(n, dtype=np.bool_)
    d = np.empty(n)
    crash_active_set(z, f, lb, ub, dg, free, d)
    changes = n
    if has_prev:
        changes = 0
        for i in range(n):
            if free[i] != prev_free[i]:
                changes += 1
        if changes < nbchange_limit:
            return NO_BASIS_CHANGE, free, d, changes, 0, 0.0, 0, False
    q = np.empty(n)
    for i in range(n):
        q[i] = -f[i]
    Kp, Ki, Kx, rhs, k = free_block(indptr, indices, data, free, d, q)
    m = rhs.shape[0]
    if m == 0:
        return 0, free, d, changes, 0, 0.0, 0, True
    eps = initial_shift(Kp, Ki[:k], Kx[:k], m, perturb, eps0)
    dense = np.empty((m, m), dtype=np.float64).T  # Fortran order, as LAPACK's
    csc_to_dense(Kp, Ki, Kx, dense)
    di, eps, nf, found = dense_perturbed_solve(dense, rhs, eps, eps0, perturb, attempts,
                                               step_limit)
    if found:
        p = 0
        for i in range(n):
            if free[i]:
                d[i] = di[p]
                p += 1
    return 0, free, d, changes, m, eps, nf, found
