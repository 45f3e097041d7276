"""The Python route of the crash: the projected Newton loop of
:mod:`compass_sparse.crash` step by step.  Problems whose blocks are all dense take the
compiled route (:mod:`compass_sparse.crash.compiled`) when the solve's routes say so; this
loop is their reference, and the route of every larger problem."""
from __future__ import annotations

import logging
import time

import numpy as np
import scipy.sparse as sp

from ..basis.backends import DENSE_SOLVE_MAX_N
from ..box import dot_norm, max_abs, project, solver_vectors
from ..linalg._csc_kernels import csc_diagonal
from ..linalg.csc import reduced_system
from ..merit import fb_phi, normal_map_at
from ._kernels import NO_BASIS_CHANGE, crash_active_set, dense_crash_step
from .outcome import (CRASH_MEMORY, CRASH_START_FACTOR, CRASH_STEP_LIMIT, EPS_SCALE,
                      PERTURB_ATTEMPTS, RAISED, CrashResult, offer_point)
from . import reduced
from .reduced import reuse_solve, solve_reduced

__all__ = ["crash_python"]

logger = logging.getLogger("compass_sparse.crash")

_NO_PREVIOUS = np.zeros(0, dtype=np.bool_)  # (dense_crash_step's prev_free at the first step)

class _Steps:
    """What the steps of one Python crash share: the last active set, the factors a next
    step may reuse, and the counts."""

    def __init__(self, evalr, lb, ub, opt, deadline, on_point, stats):
        self.evalr, self.lb, self.ub, self.opt = evalr, lb, ub, opt
        self.deadline, self.on_point, self.stats = deadline, on_point, stats
        self.prev_free = None
        self.factors = None  # (labels, HeldLU) of the last factored J_II
        self.aged = False  # the held factors converged slowly: factor at the next step
        self.nfact = 0
        self.reused = 0

    def _factored(self, nf):
        self.nfact += nf
        if self.stats is not None:
            self.stats.factorizations += nf

    def direction(self, it, z, f, J, nm_norm):
        """(d, changes, |I|, None) of step ``it`` at z, or (..., the stop reason).

        Active set of the minimum map: indices whose normal-map point z - F(z) lies
        beyond a bound.  (The thesis' rule (2.5.2) only fixes indices already at a bound
        with F of the right sign; on grid problems it releases one front of the contact
        set per iteration -- 31 iterations on a 300 x 300 obstacle problem -- where this
        rule, a semismooth Newton step on the minimum map, moves the whole front at
        once.)  Rows are scaled by |J_ii| so that F and z are compared in the same units
        (the minimum map of the row-scaled problem has the same solutions)."""
        lb, ub, opt, deadline = self.lb, self.ub, self.opt, self.deadline
        if (z.size <= DENSE_SOLVE_MAX_N and sp.issparse(J) and J.format == "csc"
                and J.shape[0] == z.size and solver_vectors(z, f, lb, ub)
                and (deadline is None or time.perf_counter() <= deadline)):
            # Every block of this problem is factored densely: the direction in one
            # compiled call of the kernels below, in their order on the same arrays (the
            # same bits; a Python step made a dozen calls: see dense_crash_step).  Past the
            # deadline the general route stops the crash as it does.
            prev = self.prev_free
            code, free, d, changes, ninact, eps, nf, found = dense_crash_step(
                J.indptr, J.indices, J.data, z, f, lb, ub,
                _NO_PREVIOUS if prev is None else prev, prev is not None,
                opt.crash_nbchange_limit, bool(opt.crash_perturb),
                float(EPS_SCALE * max(1.0, nm_norm)), PERTURB_ATTEMPTS,
                float(CRASH_STEP_LIMIT * (1.0 + max_abs(z))))
            if code == NO_BASIS_CHANGE:
                return None, 0, 0, "no basis change"
            self.prev_free = free
            self._factored(nf)
            if not found:
                return None, 0, 0, "singular reduced Jacobian"
            return d, changes, ninact, None
        return self._general_direction(it, z, f, J, nm_norm)

    def _general_direction(self, it, z, f, J, nm_norm):
        lb, ub, opt = self.lb, self.ub, self.opt
        if sp.issparse(J) and J.format == "csc" and J.shape[0] == z.size:
            dg = np.empty(z.size)
            csc_diagonal(J.indptr, J.indices, J.data, dg)
        else:
            dg = np.asarray(J.diagonal(), dtype=float)
        # Newton target: active indices go to their bound (d = z - bound); the inactive
        # ones solve F_I(z) + J_II d_I + J_IA d_A = 0 for the step d = z - z_new.
        free = np.empty(z.size, dtype=np.bool_)
        d = np.empty(z.size)
        if solver_vectors(z, f, lb, ub):  # (every crash of the solver: no conversions)
            crash_active_set(z, f, lb, ub, dg, free, d)
        else:
            crash_active_set(*(np.ascontiguousarray(a, dtype=float) for a in (z, f, lb, ub)),
                             dg, free, d)
        prev = self.prev_free
        changes = z.size if prev is None else int(np.count_nonzero(free != prev))
        if prev is not None and changes < opt.crash_nbchange_limit:
            return None, 0, 0, "no basis change"
        self.prev_free = free
        inact = free.nonzero()[0]
        if inact.size:
            # J_II and f_I - J_IA d_A (d is 0 on I), in one compiled pass
            Jii, rhs = reduced_system(J, free, d, -f)
            di, why = self._reduced_step(it, z, J, Jii, rhs, inact, nm_norm)
            if di is None:
                return None, 0, 0, why
            d[inact] = di
        return d, changes, inact.size, None

    def _reduced_step(self, it, z, J, Jii, rhs, inact, nm_norm):
        """(d_I, None) or (None, the stop reason): on the held factors when the inactive
        set moved little and they are fresh, else by a factorization."""
        opt = self.opt
        di = None
        factors = self.factors
        if (factors is not None and not self.aged
                and _moved(factors[0], inact, z.size) <= reduced.REUSE_MAX_CHANGES):
            di, steps = reuse_solve(J, inact, rhs, factors, nm_norm, deadline=self.deadline)
            logger.debug("crash step %d on the previous factors: %d GMRES steps, %s",
                         it, steps, "converged" if di is not None else "factoring")
            self.reused += di is not None
            # a slow convergence says the factors have aged: factor at the next step
            self.aged = di is None or steps > reduced.REUSE_ITERATIONS // 2
        if di is None:
            di, eps, nf, why, held = solve_reduced(
                Jii, rhs, opt.crash_perturb, EPS_SCALE * max(1.0, nm_norm),
                self.deadline, labels=inact, lu=(opt.lu_backend, opt.lu_ordering),
                step_limit=CRASH_STEP_LIMIT * (1.0 + max_abs(z)))
            self._factored(nf)
            if di is None:
                return None, why
            self.factors = (inact, held) if held is not None else None
            self.aged = False
        return di, None

    def search(self, z, d, reference):
        """Search on ||F_B|| along the projected path (arc) or the segment to its end
        (line): (z, F, x, ||F_B||, alpha) of the accepted point, or None."""
        lb, ub, opt, deadline = self.lb, self.ub, self.opt, self.deadline
        alpha = 1.0
        seg = project(z - d, lb, ub) - z if opt.crash_searchtype == "line" else None
        while alpha >= opt.crash_stepsize_minimum:
            if deadline is not None and time.perf_counter() > deadline:
                break
            zt = project(z - alpha * d if seg is None else z + alpha * seg, lb, ub)
            ft = self.evalr.f(zt)
            if ft is not None:
                offer_point(self.on_point, self.stats, zt, ft)
                xt, nmt = normal_map_at(zt, ft, lb, ub)
                nmt_norm = dot_norm(nmt)
                if nmt_norm <= (1.0 - opt.crash_sigma * alpha) * reference:
                    return zt, ft, xt, nmt_norm, alpha
            alpha *= 0.5
        return None


def _moved(old, new, n) -> int:
    """Indices in one of the increasing index sets ``old`` and ``new`` (of 0..n-1) but not
    in both: by masks, O(n) (``np.setxor1d`` hashed both sets: 0.9 s at n = 1e6, in every
    crash step)."""
    mask = np.zeros(n, dtype=np.bool_)
    mask[old] = True
    inside = int(np.count_nonzero(mask[new]))
    return old.size + new.size - 2 * inside


def crash_python(evalr, z, f0, J0, lb, ub, opt, tol, deadline, log, on_point, stats,
                 t0) -> CrashResult:
    """:func:`compass_sparse.crash.crash` by the Python loop (``z`` a float array)."""
    f = evalr.f(z) if f0 is None else f0
    if f is None:
        return CrashResult(z, np.full(z.size, np.nan), z, 0, np.inf, "domain error at start",
                           time.perf_counter() - t0, 0, [])
    x, nm = normal_map_at(z, f, lb, ub)
    nm_norm = dot_norm(nm)
    steps = _Steps(evalr, lb, ub, opt, deadline, on_point, stats)
    rows = []
    reason = "iteration limit"
    J = J0
    it = 0
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
            if deadline is not None and time.perf_counter() > deadline:
                # (the limit passed while J was evaluated: no direction is computed from
                # it, whose reduced system and ordering cost as much again at n = 1e6)
                reason = "time limit"
                it -= 1
                break
        d, changes, ninact, why = steps.direction(it, z, f, J, nm_norm)
        if why is not None:
            reason = why
            it -= 1
            break
        step = steps.search(z, d, max(recent))
        if step is None:
            reason = "no progress"
            it -= 1
            break
        if dot_norm(fb_phi(step[0], step[1], lb, ub)) > fb_start:
            # The step would raise the solver's merit above the start's (see RAISED).
            reason = RAISED
            it -= 1
            break
        z, f, x, nm_norm, alpha = step
        rows.append((it, changes, ninact, nm_norm, alpha))
        if stats is not None:
            stats.iterations += 1
        if log is not None:
            log(f"{it:5d} {changes:8d} {ninact:9d} {nm_norm:12.4e} {alpha:9.2e}")
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
    return CrashResult(z, f, x, max(it, 0), fb, reason, time.perf_counter() - t0,
                       steps.nfact, rows, steps.factors, steps.reused)
