"""The crash's reduced Newton systems (J_II + eps I) d_I = rhs: dense blocks in one compiled
call, sparse ones by KLU or the LU backends attempt by attempt (each factorization atomic,
the deadline checked between them), eps growing while the matrix is singular or the step
runs away; and the inexact step on the previous step's factors (GMRES) when the inactive
set moved little."""
from __future__ import annotations

import time

import numpy as np
import scipy.sparse as sp

from ..basis.backends import DENSE_SOLVE_MAX_N, SingularFactorError, solve_sparse
from ..basis.krylov import preconditioned_gmres
from ..box import all_finite, max_abs
from ..exceptions import FactorBudgetError
from ..linalg._csc_kernels import csc_to_dense
from ..linalg.blas import single_threaded_blas
from ..linalg.direct import KLU_FILL_LIMIT, DirectFactors, automatic_lu, klu_available
from ..path.direct_step import DIRECT_MAX_N, REUSE_BEATS_REFACTOR_NNZ
from ._kernels import dense_perturbed_solve, initial_shift
from .outcome import PERTURB_ATTEMPTS

__all__ = ["REUSE_ITERATIONS", "REUSE_MAX_CHANGES", "klu_suits", "reuse_solve", "solve_reduced"]


def klu_suits(Jii, lu) -> bool:
    """Whether the crash factors the sparse block J_II (order above
    ``DENSE_SOLVE_MAX_N``) by KLU, as the direct step does, instead of SuperLU: a block of
    the direct step's orders (at most ``DIRECT_MAX_N``), no LU backend or ordering chosen
    by the user, and too few entries for its factors to be worth keeping -- even at KLU's
    fill limit its LU would stay below the size from which the basis reuses factors, so
    they would serve no later solve.  (Ramsey model at n = 363 and 993: 0.07 and 0.17 ms
    per factorization against SuperLU's 0.37 and 0.8 ms, its analysis kept per pattern.)"""
    n = Jii.shape[0]
    return (DENSE_SOLVE_MAX_N < n <= DIRECT_MAX_N and automatic_lu(*lu)
            and Jii.nnz * KLU_FILL_LIMIT < REUSE_BEATS_REFACTOR_NNZ and klu_available())


def solve_reduced(Jii, rhs, perturb, eps0, deadline=None, labels=None, lu=("auto", "auto"),
                   step_limit=np.inf):
    """Solve (J_II + eps I) d = rhs with eps = 0 first (eps0 at once when J_II is
    structurally singular), then growing when singular.

    Returns (d or None, eps, factorizations, why, held): ``why`` is None on success, else
    the crash's stop reason; ``held`` the kept factors of the last matrix (or None).  A step
    on a perturbed matrix longer than ``step_limit`` (max norm) is refused.  A block of
    order <= ``DENSE_SOLVE_MAX_N`` is factored densely, all attempts in one compiled call
    (the deadline is checked before it); a larger one attempt by attempt: each
    factorization is atomic, so the deadline is checked before every attempt and handed to
    the factorization's budget (one whose estimate does not fit in the time left is not
    started)."""
    nf = 0
    held = None
    n = Jii.shape[0]
    eps = initial_shift(Jii.indptr, Jii.indices, Jii.data, n, bool(perturb), float(eps0))
    if 0 < n <= DENSE_SOLVE_MAX_N:
        # A block that solve_sparse factors densely: all attempts in one compiled call
        # (the same LAPACK routines, so the same steps; see compass_sparse.crash._kernels).
        # Eight attempts at this order cost milliseconds at most: the deadline is checked
        # before them, not between them.
        if deadline is not None and time.perf_counter() > deadline:
            return None, eps, nf, "time limit", None
        dense = np.empty((n, n), order="F")  # (LAPACK's order; scipy's toarray ~10 us more)
        csc_to_dense(Jii.indptr, Jii.indices, Jii.data, dense)
        d, eps, nf, found = dense_perturbed_solve(
            dense, np.ascontiguousarray(rhs, dtype=np.float64), eps, float(eps0),
            bool(perturb), PERTURB_ATTEMPTS, float(step_limit))
        if found:
            return d, eps, nf, None, None
        return None, eps, nf, "singular reduced Jacobian", None
    klu = klu_suits(Jii, lu)
    shifted = None
    for attempt in range(PERTURB_ATTEMPTS):
        if deadline is not None and time.perf_counter() > deadline:
            return None, eps, nf, "time limit", None
        if eps == 0.0:
            A = Jii
        else:
            shifted = _ShiftedMatrix(Jii) if shifted is None else shifted
            A = shifted.at(eps)
        try:
            nf += 1
            if klu:
                d = DirectFactors().solve(A, rhs)
                if d is None:
                    raise SingularFactorError("singular (KLU)")
            else:
                d, held = solve_sparse(A, rhs, deadline=deadline, labels=labels, keep=True,
                                       backend=lu[0], ordering=lu[1])
            if all_finite(d) and not (eps > 0.0 and max_abs(d) > step_limit):
                return d, eps, nf, None, held
        except SingularFactorError:  # exactly singular
            pass
        except FactorBudgetError as exc:  # not started: no time or memory for it
            return None, eps, nf - 1, f"{exc.kind} limit", None
        if not perturb:
            break
        eps = eps0 if eps == 0.0 else eps * 10.0
    return None, eps, nf, "singular reduced Jacobian", None


class _ShiftedMatrix:
    """J_II + eps I for the eps of each attempt, on one pattern (J_II's and the diagonal)
    made once: an attempt writes the diagonal's values.  (Each ``J_II + eps * identity``
    through scipy.sparse cost ~0.5 ms on the traffic model's blocks at n = 912, and its
    structurally singular blocks take several attempts per crash step.)  The values are
    those of that sum: J_ii + eps on the diagonal, J_II's elsewhere."""

    def __init__(self, Jii):
        n = Jii.shape[0]
        cols = np.repeat(np.arange(n), np.diff(Jii.indptr))
        idx = np.arange(n)
        # (COO to CSC sums the diagonal into existing entries and keeps the zeros it adds)
        A = sp.csc_matrix((np.r_[Jii.data, np.zeros(n)],
                           (np.r_[Jii.indices, idx], np.r_[cols, idx])), shape=(n, n))
        A.sort_indices()
        self.matrix = A
        rows = A.indices
        self._diag = np.flatnonzero(rows == np.repeat(idx, np.diff(A.indptr)))
        self._base = A.data[self._diag].copy()

    def at(self, eps):
        self.matrix.data[self._diag] = self._base + eps
        return self.matrix


REUSE_MAX_CHANGES = 64
"""The last factors of J_II precondition the next crash step when the inactive set moved
by at most this many indices (each changed index adds about one GMRES step)."""


REUSE_ITERATIONS = 40
"""GMRES steps allowed on reused factors before the crash factors afresh."""


def reuse_solve(J, inact, rhs, prev, nm_norm, deadline=None):
    """d with J_II d = rhs by GMRES preconditioned with the held factors of the previous
    crash step's J_I'I' (I' the previous inactive set), or None when it does not converge
    (or the ``deadline`` passed: no GMRES step is started after it).

    The system is posed on U = I u I': rows and columns of I' - I are identity (those d
    are 0), so that it differs from the factored matrix by the moved Jacobian values and
    a border whose rank is at most twice the number of indices that moved; GMRES absorbs
    both in a few steps when z moved little.  The target is an inexact-Newton forcing
    term, ||J_II d - rhs|| <= eta ||rhs|| with eta = min(1e-4, ||nm||) (bounded below by
    1e-10): superlinear convergence is kept."""
    labels, held = prev
    U = np.union1d(labels, inact)
    in_new = np.isin(U, inact, assume_unique=True)
    in_old = np.isin(U, labels, assume_unique=True)
    B = sp.csc_matrix(J[U][:, U])
    keep = in_new.astype(np.float64)
    B = sp.csc_matrix(sp.diags(keep) @ B @ sp.diags(keep) + sp.diags(1.0 - keep))
    dg = B.diagonal()
    dg = np.where(dg != 0.0, dg, 1.0)
    only_new = ~in_old

    def psolve(v):
        out = np.empty_like(v)
        out[in_old] = held.solve(v[in_old])
        out[only_new] = v[only_new] / dg[only_new]
        return out

    b = np.zeros(U.size)
    b[in_new] = rhs
    bn = float(np.linalg.norm(b))
    eta = max(1e-10, min(1e-4, nm_norm))
    with single_threaded_blas():   # level-1 vector work: threads only slow it
        x, steps, _ = preconditioned_gmres(lambda v: B @ v, psolve, b, 0.5 * eta * bn,
                                           REUSE_ITERATIONS, deadline=deadline)
    if not np.all(np.isfinite(x)) or np.linalg.norm(B @ x - b) > eta * bn:
        return None, steps
    return x[in_new], steps
