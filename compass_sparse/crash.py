"""Crash pass: projected Newton to guess the active set (thesis §2.5; Dirkse & Ferris 1997).

At z_k in the box, the *fixed* indices are those at a bound whose F has the sign that keeps
them there,

    A = {i : (z_i = l_i and F_i >= 0) or (z_i = u_i and F_i <= 0)},   I = complement,

and the direction solves the reduced Newton system J_II d_I = F_I (d_A = 0), perturbed to
J_II + eps I when J_II is singular (Billups).  The search is along the projected path
z(alpha) = pi(z_k - alpha d) (``crash_searchtype = "arc"``; "line" searches the segment
z_k + alpha (pi(z_k - d) - z_k) instead), alpha = 1, 1/2, 1/4, ..., accepting the first
alpha with

    ||F_B(x(alpha))|| <= (1 - sigma alpha) ||F_B(x(0))||,

where x(alpha) is the point with pi(x) = z(alpha) of least normal-map norm: the normal cone
at z(alpha) absorbs the part of F that points out of the box (thesis (2.5.5)-(2.5.9)).
The crash stops when the active set stops changing (``crash_nbchange_limit``), the
decrease is below sigma, alpha < ``crash_stepsize_minimum``, a step would raise ||Phi||
above its start's (:data:`RAISED`), or after
``crash_iteration_limit`` steps; it is skipped below ``crash_minimum_dimension``.
One factorization of J_II and one Jacobian per iteration: it is a Newton method on the
current face, which is why it finds the active set of well-behaved large problems in a
few steps.  When the inactive set moved by at most ``REUSE_MAX_CHANGES`` indices, the step
is first sought by GMRES preconditioned with the previous step's factors (an inexact
Newton step; see :func:`_reuse_solve`) and J_II is factored only when that fails: on the
large CGE models a factorization costs as much as tens of solves with old factors.
"""
from __future__ import annotations

import logging
import time
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from . import _crash_kernels as ck
from ._crash_kernels import (NO_BASIS_CHANGE, dense_crash_step, dense_perturbed_solve,
                             initial_shift)
from ._merit_kernels import crash_active_set, csc_diagonal, csc_to_dense
from ._blas import BLAS_LIMIT_MIN_N, single_threaded_blas
from ._jit import NO_INDICES, NO_VALUES
from ._csc import float_csc
from .basis.backends import DENSE_SOLVE_MAX_N, SingularFactorError, solve_sparse
from .direct_step import (DIRECT_MAX_N, KLU_FILL_LIMIT, REUSE_BEATS_REFACTOR_NNZ,
                          DirectFactors, automatic_lu, klu_available, reduced_system)
from .evaluation import all_finite
from .exceptions import FactorBudgetError
from .merit import _solver_vectors, dot_norm, fb_phi, max_abs, normal_map_at, project

__all__ = ["CrashResult", "crash"]

logger = logging.getLogger(__name__)

CRASH_MEMORY = 4
_NO_PREVIOUS = np.zeros(0, dtype=np.bool_)  # (dense_crash_step's prev_free at the first step)
CRASH_START_FACTOR = 2.0


@dataclass
class CrashResult:
    z: np.ndarray
    f: np.ndarray
    x: np.ndarray  # normal-map point with pi(x) = z of least ||F_B||
    iterations: int
    fb_norm: float
    stop_reason: str
    time: float
    factorizations: int
    log: list
    #: (labels, HeldLU): the factors of the last reduced Jacobian J[labels, labels]
    #: (None if not kept), for the first Newton step's basis (a preconditioner)
    factors: tuple | None = None
    reused: int = 0  #: steps solved on the previous step's factors (no factorization)


CRASH_STEP_LIMIT = 10.0
"""Largest ||d||_inf / (1 + ||z||_inf) of a crash step solved on a PERTURBED J_II + eps I.
On a singular J_II a tiny eps leaves the matrix nearly singular, and the step has length
~1/eps along the null space: at the start x0 = 0 of kojshin (J_II has a zero column)
eps = 1e-7 gave ||d|| ~ 1e7, and the search spent 13 F evaluations to reject it.  A longer
step is refused as a singular matrix would be, and eps grows tenfold (eps ~ 1 gave a crash
step to a third of the start residual there)."""

PERTURB_ATTEMPTS = 8
"""Factorizations of J_II (+ eps I) per crash step: eps = 0 (when J_II is structurally
regular), then eps0 = 1e-8 max(1, ||F_B||) growing tenfold, so up to eps0 * 1e6 or 1e7.
(Jumping straight to the eps that brings a runaway step to the limit, ~eps ||d|| / limit,
was tried: at kojshin's start it stopped at eps ~ 0.1, whose step the search rejects, where
tenfold growth passes on to eps ~ 1.)"""


COMPILED_CRASH = True
"""A problem whose crash blocks are all dense (n <= ``DENSE_SOLVE_MAX_N``) runs its crash in
compiled calls between two evaluations (:func:`_crash_dense`, the same points bit for
bit); False keeps the Python route, the reference of the tests."""

RAISED = "raised the merit"
"""The stop reason of a crash whose next step would raise the solver's merit, the
Fischer-Burmeister norm ||Phi||, above its value at the crash's start: a point the
watchdog, searching from that start as its checkpoint, would not accept.  The crash's
own search measures the normal map (and accepts rises up to twice the start's at first),
which can fall while ||Phi|| climbs: on the static CGE model with a 50% output tax
(n = 2024) the crash went 181 -> 184 -> 145 -> 255 -> ... and handed on a point
(||Phi|| 175) whose linearizations the paths then walked for 1500-4000 pivots each (17705
pivots in all, 60 s), where Newton from the start solves it in 5 major iterations without
a pivot; on the traffic equilibrium (n = 912) it climbed 21.1 -> 36.8 over 6 steps for
37 of the solve's 76 factorizations and then handed on its start.  The step is not taken;
the crash hands on its best point so far."""

_REASONS = ("iteration limit", "converged", "domain error in J", "no basis change",
            "singular reduced Jacobian", "no progress", "time limit",
            RAISED)  # (ck.R_* order)


def _klu_suits(Jii, lu) -> bool:
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


def _solve_reduced(Jii, rhs, perturb, eps0, deadline=None, labels=None, lu=("auto", "auto"),
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
        # (the same LAPACK routines, so the same steps; see compass_sparse._crash_kernels).
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
    klu = _klu_suits(Jii, lu)
    for attempt in range(PERTURB_ATTEMPTS):
        if deadline is not None and time.perf_counter() > deadline:
            return None, eps, nf, "time limit", None
        A = Jii if eps == 0.0 else Jii + eps * sp.identity(n, format="csc")
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


REUSE_MAX_CHANGES = 64
"""The last factors of J_II precondition the next crash step when the inactive set moved
by at most this many indices (each changed index adds about one GMRES step)."""

REUSE_ITERATIONS = 40
"""GMRES steps allowed on reused factors before the crash factors afresh."""


def _reuse_solve(J, inact, rhs, prev, nm_norm):
    """d with J_II d = rhs by GMRES preconditioned with the held factors of the previous
    crash step's J_I'I' (I' the previous inactive set), or None when it does not converge.

    The system is posed on U = I u I': rows and columns of I' - I are identity (those d
    are 0), so that it differs from the factored matrix by the moved Jacobian values and
    a border whose rank is at most twice the number of indices that moved; GMRES absorbs
    both in a few steps when z moved little.  The target is an inexact-Newton forcing
    term, ||J_II d - rhs|| <= eta ||rhs|| with eta = min(1e-4, ||nm||) (bounded below by
    1e-10): superlinear convergence is kept."""
    from .basis.krylov import preconditioned_gmres

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
                                           REUSE_ITERATIONS)
    if not np.all(np.isfinite(x)) or np.linalg.norm(B @ x - b) > eta * bn:
        return None, steps
    return x[in_new], steps


def crash(evalr, z0, lb, ub, options, *, f0=None, J0=None, tol=None, deadline=None,
          log=None, on_point=None, stats=None) -> CrashResult:
    """Projected-Newton crash from z0, a point of the box.  ``evalr`` is the problem's
    :class:`~compass_sparse.evaluation.Evaluator`; ``f0``, ``J0``: F and J at z0 when known.
    ``on_point(z, f)`` sees every trial point where F was evaluated (the caller's best point
    may be among them, and it may stop the crash by raising).  ``stats`` (a
    :class:`~compass_sparse.result.PassStats`) counts the accepted steps and the
    factorizations as they happen, so that they are reported when ``on_point`` stops the
    crash at a solution."""
    kw = dict(f0=f0, J0=J0, tol=tol, deadline=deadline, log=log, on_point=on_point,
              stats=stats)
    if BLAS_LIMIT_MIN_N <= np.size(z0) <= DENSE_SOLVE_MAX_N:
        # Its reduced systems are factored densely, each in a single-threaded BLAS block;
        # one block around the whole crash makes those free (see compass_sparse._blas).
        # (Below BLAS_LIMIT_MIN_N OpenBLAS keeps such small kernels on one thread itself.)
        with single_threaded_blas():
            return _crash(evalr, z0, lb, ub, options, **kw)
    return _crash(evalr, z0, lb, ub, options, **kw)


def _crash(evalr, z0, lb, ub, options, *, f0, J0, tol, deadline, log, on_point,
           stats) -> CrashResult:
    t0 = time.perf_counter()
    opt = options
    tol = opt.convergence_tolerance if tol is None else tol
    z = np.asarray(z0, dtype=float)
    if (COMPILED_CRASH and f0 is not None and 0 < z.size <= DENSE_SOLVE_MAX_N
            and _solver_vectors(z, f0, lb, ub)):
        return _crash_dense(evalr, z, f0, J0, lb, ub, opt, tol, deadline, log, on_point,
                            stats, t0)
    f = evalr.f(z) if f0 is None else f0
    if f is None:
        return CrashResult(z, np.full(z.size, np.nan), z, 0, np.inf, "domain error at start",
                           time.perf_counter() - t0, 0, [])
    x, nm = normal_map_at(z, f, lb, ub)
    nm_norm = dot_norm(nm)
    rows = []
    nfact = 0
    prev_free = None
    reason = "iteration limit"
    J = J0
    it = 0
    factors = None
    aged = False
    reused = 0
    eps_scale = 1e-8
    # Non-monotone reference: the full projected Newton step is tried against the largest
    # of the last few residuals (x2 at the start), so that the active set can change by
    # many indices at once instead of creeping one front per halved step.
    recent = [CRASH_START_FACTOR * nm_norm]
    best = (nm_norm, z, f, x)
    fb_at = None  # (z, f, ||Phi(z)||) of the last step's start
    for it in range(1, opt.crash_iteration_limit + 1):
        if deadline is not None and time.perf_counter() > deadline:
            reason = "time limit"
            it -= 1
            break
        fb = dot_norm(fb_phi(z, f, lb, ub))
        fb_at = (z, f, fb)
        if it == 1:
            fb_start = fb
        if fb <= tol:
            reason = "converged"
            it -= 1
            break
        if J is None:
            J = evalr.jac(z, f)
            if J is None:
                reason = "domain error in J"
                it -= 1
                break
        # Active set of the minimum map: indices whose normal-map point z - F(z) lies
        # beyond a bound.  (The thesis' rule (2.5.2) only fixes indices already at a
        # bound with F of the right sign; on grid problems it releases one front of
        # the contact set per iteration — 31 iterations on a 300 x 300 obstacle problem
        # — where this rule, a semismooth Newton step on the minimum map, moves the
        # whole front at once.)
        # Rows are scaled by |J_ii| so that F and z are compared in the same units (the
        # minimum map of the row-scaled problem has the same solutions).
        if (z.size <= DENSE_SOLVE_MAX_N and sp.issparse(J) and J.format == "csc"
                and J.shape[0] == z.size and _solver_vectors(z, f, lb, ub)
                and (deadline is None or time.perf_counter() <= deadline)):
            # Every block of this problem is factored densely: the direction in one
            # compiled call of the kernels below, in their order on the same arrays (the
            # same bits; a Python step made a dozen calls: see dense_crash_step).  Past the
            # deadline the general route stops the crash as it does.
            code, free, d, changes, ninact, eps, nf, found = dense_crash_step(
                J.indptr, J.indices, J.data, z, f, lb, ub,
                _NO_PREVIOUS if prev_free is None else prev_free, prev_free is not None,
                opt.crash_nbchange_limit, bool(opt.crash_perturb),
                float(eps_scale * max(1.0, nm_norm)), PERTURB_ATTEMPTS,
                float(CRASH_STEP_LIMIT * (1.0 + max_abs(z))))
            if code == NO_BASIS_CHANGE:
                reason = "no basis change"
                it -= 1
                break
            prev_free = free
            nfact += nf
            if stats is not None:
                stats.factorizations += nf
            if not found:
                reason = "singular reduced Jacobian"
                it -= 1
                break
        else:
            if sp.issparse(J) and J.format == "csc" and J.shape[0] == z.size:
                dg = np.empty(z.size)
                csc_diagonal(J.indptr, J.indices, J.data, dg)
            else:
                dg = np.asarray(J.diagonal(), dtype=float)
            # Newton target: active indices go to their bound (d = z - bound); the inactive
            # ones solve F_I(z) + J_II d_I + J_IA d_A = 0 for the step d = z - z_new.
            free = np.empty(z.size, dtype=np.bool_)
            d = np.empty(z.size)
            if _solver_vectors(z, f, lb, ub):  # (every crash of the solver: no conversions)
                crash_active_set(z, f, lb, ub, dg, free, d)
            else:
                crash_active_set(*(np.ascontiguousarray(a, dtype=float) for a in (z, f, lb, ub)),
                                 dg, free, d)
            changes = z.size if prev_free is None else int(np.count_nonzero(free != prev_free))
            if prev_free is not None and changes < opt.crash_nbchange_limit:
                reason = "no basis change"
                it -= 1
                break
            prev_free = free
            inact = free.nonzero()[0]
            ninact = inact.size
            if inact.size:
                # J_II and f_I - J_IA d_A (d is 0 on I), in one compiled pass
                Jii, rhs = reduced_system(J, free, d, -f)
                di = None
                if (factors is not None and not aged
                        and np.setxor1d(factors[0], inact).size <= REUSE_MAX_CHANGES):
                    di, steps = _reuse_solve(J, inact, rhs, factors, nm_norm)
                    logger.debug("crash step %d on the previous factors: %d GMRES steps, %s",
                                 it, steps, "converged" if di is not None else "factoring")
                    reused += di is not None
                    # a slow convergence says the factors have aged: factor at the next step
                    aged = di is None or steps > REUSE_ITERATIONS // 2
                if di is None:
                    di, eps, nf, why, held = _solve_reduced(
                        Jii, rhs, opt.crash_perturb, eps_scale * max(1.0, nm_norm),
                        deadline, labels=inact, lu=(opt.lu_backend, opt.lu_ordering),
                        step_limit=CRASH_STEP_LIMIT * (1.0 + max_abs(z)))
                    nfact += nf
                    if stats is not None:
                        stats.factorizations += nf
                    if di is None:
                        reason = why
                        it -= 1
                        break
                    factors = (inact, held) if held is not None else None
                    aged = False
                d[inact] = di
        # Search on ||F_B||: along the projected path (arc) or the segment to its end (line).
        alpha = 1.0
        accepted = False
        seg = project(z - d, lb, ub) - z if opt.crash_searchtype == "line" else None
        while alpha >= opt.crash_stepsize_minimum:
            if deadline is not None and time.perf_counter() > deadline:
                break
            zt = project(z - alpha * d if seg is None else z + alpha * seg, lb, ub)
            ft = evalr.f(zt)
            if ft is not None:
                _offer(on_point, stats, zt, ft)
                xt, nmt = normal_map_at(zt, ft, lb, ub)
                nmt_norm = dot_norm(nmt)
                if nmt_norm <= (1.0 - opt.crash_sigma * alpha) * max(recent):
                    accepted = True
                    break
            alpha *= 0.5
        if not accepted:
            reason = "no progress"
            it -= 1
            break
        if dot_norm(fb_phi(zt, ft, lb, ub)) > fb_start:
            # The step would raise the solver's merit above the start's (see RAISED).
            reason = RAISED
            it -= 1
            break
        rows.append((it, changes, ninact, nmt_norm, alpha))
        if stats is not None:
            stats.iterations += 1
        if log is not None:
            log(f"{it:5d} {changes:8d} {ninact:9d} {nmt_norm:12.4e} {alpha:9.2e}")
        z, f, x, nm_norm = zt, ft, xt, nmt_norm
        recent = (recent + [nm_norm])[-CRASH_MEMORY:]
        if nm_norm < best[0]:
            best = (nm_norm, z, f, x)
        J = None
    if best[0] < nm_norm:
        # The non-monotone steps climbed from a better iterate (measured: 0.43 after the
        # first step, 5.8 after the fourth, on the dynamic CGE model at n = 2.4e4): hand
        # the best one on.
        nm_norm, z, f, x = best
    if fb_at is not None and fb_at[0] is z and fb_at[1] is f:
        fb = fb_at[2]  # the loop stopped at the start of a step: ||Phi|| of this point
    else:
        fb = dot_norm(fb_phi(z, f, lb, ub))
    return CrashResult(z, f, x, max(it, 0), fb, reason, time.perf_counter() - t0, nfact, rows,
                       factors, reused)


def _offer(on_point, stats, zt, ft):
    """A trial point where F was evaluated, offered to the caller (who may stop the crash
    by raising: the step that reached the point is counted then)."""
    if on_point is not None:
        try:
            on_point(zt, ft)
        except BaseException:
            if stats is not None:
                stats.iterations += 1
            raise


_SETTINGS: dict = {}  # id(options) -> (options, tol, sf, si): see _dense_settings


def _dense_settings(opt, tol):
    """Fresh copies of the compiled crash's settings arrays (sf, si) for options ``opt``
    and tolerance ``tol``, made from arrays kept per options object: a loop of solves
    with the same options sets them up once (a dozen item assignments, ~3 us a solve).
    The entry holds the options object itself, so its id is not reused while kept."""
    hit = _SETTINGS.get(id(opt))
    if hit is None or hit[0] is not opt or hit[1] != tol:
        sf = np.zeros(ck.CF_SIZE)
        sf[ck.CF_SIGMA] = opt.crash_sigma
        sf[ck.CF_MIN_STEP] = opt.crash_stepsize_minimum
        sf[ck.CF_TOL] = tol
        sf[ck.CF_EPS_SCALE] = 1e-8  # (the Python route's eps_scale)
        sf[ck.CF_STEP_LIMIT] = CRASH_STEP_LIMIT
        sf[ck.CF_START_FACTOR] = CRASH_START_FACTOR
        si = np.zeros(ck.CI_SIZE, dtype=np.int64)
        si[ck.CI_LIMIT] = opt.crash_iteration_limit
        si[ck.CI_NBCHANGE] = opt.crash_nbchange_limit
        si[ck.CI_PERTURB] = bool(opt.crash_perturb)
        si[ck.CI_ATTEMPTS] = PERTURB_ATTEMPTS
        si[ck.CI_LINE] = opt.crash_searchtype == "line"
        if len(_SETTINGS) >= 32:
            _SETTINGS.clear()
        hit = _SETTINGS[id(opt)] = (opt, tol, sf, si)
    return hit[2].copy(), hit[3].copy()


def _crash_dense(evalr, z, f0, J0, lb, ub, opt, tol, deadline, log, on_point, stats, t0):
    """:func:`crash` of a problem whose blocks are all dense: everything between two
    evaluations of the user's F or J in one compiled call (``_crash_kernels.crash_dense``,
    which says what it needs next); here only the evaluations, the trial points offered
    to ``on_point``, the time limit, the counts and the log.  The Python route's steps in
    its order: the same points bit for bit."""
    n = z.size
    W = np.empty((ck.CW_ROWS, n))
    W[ck.CW_Z] = z
    W[ck.CW_F] = f0
    W[ck.CW_LB] = lb
    W[ck.CW_UB] = ub
    prev_free = np.zeros(n, dtype=np.bool_)
    sf, si = _dense_settings(opt, tol)
    rows = []
    seen = [0, 0]  # accepted steps and factorizations already counted in stats

    def late():
        return deadline is not None and time.perf_counter() > deadline

    step = ck.crash_dense
    none, no_index = NO_VALUES, NO_INDICES
    if late():
        code = step(sf, si, W, prev_free, none, no_index, no_index, none, ck.STOP)
    elif J0 is not None:
        J = float_csc(J0)
        code = step(sf, si, W, prev_free, none, J.indptr, J.indices, J.data, ck.J_GIVEN)
    else:
        code = step(sf, si, W, prev_free, none, no_index, no_index, none, ck.NOTHING)
    while True:
        # what the call did: factorizations made, a step accepted (counted as they happen,
        # so that a stop raised by on_point reports them)
        if stats is not None and si[ck.CI_NFACT] != seen[1]:
            stats.factorizations += int(si[ck.CI_NFACT]) - seen[1]
            seen[1] = int(si[ck.CI_NFACT])
        if si[ck.CI_ACCEPTED] != seen[0]:
            seen[0] = int(si[ck.CI_ACCEPTED])
            row = (int(si[ck.CI_ROW_IT]), int(si[ck.CI_CHANGES]), int(si[ck.CI_NINACT]),
                   float(sf[ck.CF_NMT]), float(sf[ck.CF_ALPHA]))
            rows.append(row)
            if stats is not None:
                stats.iterations += 1
            if log is not None:
                log(f"{row[0]:5d} {row[1]:8d} {row[2]:9d} {row[3]:12.4e} {row[4]:9.2e}")
        if code == ck.DONE:
            break
        if late():
            code = step(sf, si, W, prev_free, none, no_index, no_index, none, ck.STOP)
        elif code == ck.NEED_J:
            J = evalr.jac(W[ck.CW_Z], W[ck.CW_F])
            if J is None:
                code = step(sf, si, W, prev_free, none, no_index, no_index, none,
                            ck.J_FAILED)
            else:
                J = float_csc(J)
                code = step(sf, si, W, prev_free, none, J.indptr, J.indices, J.data,
                            ck.J_GIVEN)
        else:  # NEED_F at the trial point
            zt = W[ck.CW_ZT].copy()
            ft = evalr.f(zt)
            if ft is None:
                code = step(sf, si, W, prev_free, none, no_index, no_index, none,
                            ck.F_FAILED)
                continue
            _offer(on_point, stats, zt, ft)
            code = step(sf, si, W, prev_free, ft, no_index, no_index, none, ck.F_GIVEN)
    return CrashResult(W[ck.CW_Z].copy(), W[ck.CW_F].copy(), W[ck.CW_X].copy(),
                       max(int(si[ck.CI_IT]), 0), float(sf[ck.CF_FB]),
                       _REASONS[int(si[ck.CI_REASON])], time.perf_counter() - t0,
                       int(si[ck.CI_NFACT]), rows)
