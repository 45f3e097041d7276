"""The compiled route of the major iterations: a run's bookkeeping in compiled calls
(:func:`compass_sparse.nms._kernels.nms_dense`, which says what it needs next, by reverse
communication); here the evaluations, the paths that the dense direct step does not end,
the acceptance test, the fallback, the limits, the callback, the counts, the history and
the log.  The Python loop's steps (:meth:`compass_sparse.nms.solver.NMSSolver.run`) in its
order: the same points bit for bit, ~50 us faster per major iteration of a small problem
(double_root: 1.28 -> 0.82 ms a solve).

While the kernel runs, it holds copies of two things the solver owns: the best point (rows
W_BZ, W_BF, W_BPHI; the solver's :class:`~compass_sparse.nms.best.BestPoint` is the owner)
and the warm basis (row B_WARM; the solver's :class:`~compass_sparse.nms.newton.NewtonStep`
is the owner).  :class:`_KernelCopies` hands them over and back, so that Python code never
reads a stale one.
"""
from __future__ import annotations

import math
import time

import numpy as np

from .._jit import NO_INDICES, NO_VALUES
from ..linalg.csc import trusted_csc
from ..path.direct_step import FEASIBILITY_TOLERANCE, RESIDUAL_TOLERANCE, failed_direct_start
from ..path.outcome import LinearCode, WarmBasis
from ..status import Status
from . import _kernels as nk
from .state import LOCAL_FACTOR, NMSStop, Point

__all__ = ["CompiledRun"]

_NO_POSITIONS = np.zeros(0, dtype=np.int64)  # (the linearizer's maps before one is made)


class _KernelCopies:
    """The kernel's copies of the solver's best point and warm basis (see the module)."""

    def __init__(self, best, newton, W, sf, si, B):
        self.best, self.newton = best, newton
        self.W, self.sf, self.si, self.B = W, sf, si, B
        self.kernel_owns_best = True  # whether rows W_B* hold the best point now

    def take_best(self):  # the solver's best point goes to the kernel
        b = self.best.point
        W, si = self.W, self.si
        W[nk.W_BZ], W[nk.W_BF], W[nk.W_BPHI] = b.z, b.f, b.phi
        self.sf[nk.S_BPSI] = b.psi
        si[nk.I_BEST_NEW] = 0
        self.kernel_owns_best = True

    def hand_best(self):  # ... and back to the solver, before Python reads it
        W = self.W
        if self.kernel_owns_best and self.si[nk.I_BEST_NEW]:
            self.best.point = Point(W[nk.W_BZ].copy(), W[nk.W_BF].copy(),
                                    W[nk.W_BPHI].copy(), float(self.sf[nk.S_BPSI]))
        self.kernel_owns_best = False

    def take_basis(self):  # the last path's basis (the warm start of the next) ...
        warm = self.newton.warm
        if warm is not None:
            self.B[nk.B_WARM] = warm.basic
        self.si[nk.I_HAS_WARM] = warm is not None
        self.si[nk.I_BASIS_NEW] = 0

    def hand_basis(self):  # ... and back to the solver
        if self.si[nk.I_BASIS_NEW]:
            self.newton.warm = WarmBasis(self.B[nk.B_WARM].copy())
            self.si[nk.I_BASIS_NEW] = 0


class CompiledRun:
    """One run of the major iterations from the state ``st`` of the solver ``solver``
    with options ``opt`` (see the module docstring); :meth:`run` returns why it stopped,
    as the Python loop does."""

    def __init__(self, solver, st, opt, stall_limit, reference_progress):
        self.solver, self.opt = solver, opt
        n = solver.n
        self.W = W = np.empty((nk.W_ROWS, n))
        cur = st.cur
        for row, v in ((nk.W_CZ, cur.z), (nk.W_CF, cur.f), (nk.W_CPHI, cur.phi),
                       (nk.W_CX, st.x), (nk.W_KZ, cur.z), (nk.W_KX, st.x),
                       (nk.W_LB, solver.lb), (nk.W_UB, solver.ub)):
            W[row] = v
        self.mem = np.empty(st.memory_size)
        self.mem[:len(st.memory)] = st.memory
        self.sf = sf = np.zeros(nk.S_SIZE)
        for k, v in ((nk.S_CPSI, cur.psi), (nk.S_KPSI, cur.psi), (nk.S_DELTA, st.delta),
                     (nk.S_EPS, st.eps), (nk.S_BEST_SEEN, st.best_seen),
                     (nk.S_FBN_START, st.fbn_start), (nk.S_SIGMA, opt.nms_sigma),
                     (nk.S_DELTA_SHRINK, opt.nms_delta_shrink_factor),
                     (nk.S_DELTA_MIN, opt.nms_delta_min),
                     (nk.S_PROX_SHRINK, opt.proximal_shrink_factor),
                     (nk.S_PROX_INCREASE, opt.proximal_increase_factor),
                     (nk.S_STEP_MIN, opt.nms_stepsize_minimum),
                     (nk.S_SHRINK, opt.nms_shrink_factor),
                     (nk.S_TOL, solver.acceptance.tol), (nk.S_LOCAL, LOCAL_FACTOR),
                     (nk.S_FEASIBILITY, FEASIBILITY_TOLERANCE),
                     (nk.S_RESIDUAL, RESIDUAL_TOLERANCE)):
            sf[k] = v
        self.si = si = np.zeros(nk.I_SIZE, dtype=np.int64)
        for k, v in ((nk.I_NMEM, len(st.memory)), (nk.I_MEMSIZE, st.memory_size),
                     (nk.I_MONOTONE, not opt.nms), (nk.I_MSTEP_FREQ, opt.nms_mstep_frequency),
                     (nk.I_MAX_WATCHDOGS, opt.nms_maximum_watchdogs),
                     (nk.I_STALL_LIMIT, stall_limit), (nk.I_CUR_IS_CKPT, 1),
                     (nk.I_REFERENCE_RULE, reference_progress),
                     (nk.I_LINE, opt.nms_searchtype == "line")):
            si[k] = v
        self.B = np.zeros((3, n), dtype=np.int8)  # the warm basis, the start basis, its slack
        self.copies = _KernelCopies(solver.best, solver.newton, W, sf, si, self.B)
        # the arguments of the kernel's next call that its request leaves unused
        self.jx = self.mdata = NO_VALUES
        self.ip = self.ix = self.mp = self.mi = NO_INDICES
        self.pj = self.pd = _NO_POSITIONS
        self.cur_J = cur.J  # (only the run's start comes with its J)
        self.f = None  # F at the last point the kernel asked for
        self.code_res = None  # the last linear solve's code and pivots (the log's)
        self.pivots = 0

    def answer(self, arg, ft=NO_VALUES, late=False):
        """The kernel's next call, with the answer ``arg`` to its last request."""
        return nk.nms_dense(self.sf, self.si, self.W, self.mem, self.B, self.mdata, ft,
                            self.ip, self.ix, self.jx, self.pj, self.pd, self.mp, self.mi,
                            arg, late)

    def run(self) -> str:
        solver, copies, si, W = self.solver, self.copies, self.si, self.W
        copies.take_best()
        copies.take_basis()
        try:
            code = self.answer(nk.A_START)
            while True:
                if si[nk.I_LOG]:  # a finished major iteration
                    self._log_step()
                if code == nk.NEED_NEWTON:
                    code = self._newton()
                elif code == nk.NEED_F_CAND or code == nk.NEED_F_TRIAL:
                    if code == nk.NEED_F_TRIAL and solver.best.past_deadline():
                        raise NMSStop(Status.TIME_LIMIT, "time limit reached")
                    f = self.f = solver.ev.f(W[nk.W_RZ] if code == nk.NEED_F_CAND
                                             else W[nk.W_TZ])
                    code = (self.answer(nk.A_F_FAILED) if f is None else
                            self.answer(nk.A_F_GIVEN, f, solver.best.past_deadline()))
                elif code == nk.JUDGE:
                    copies.hand_best()  # (a solution found here becomes the best point)
                    solver.best.judge(W[nk.W_TZ].copy(), self.f, W[nk.W_TPHI].copy(),
                                      float(self.sf[nk.S_TPSI]))
                    copies.kernel_owns_best = True
                    code = self.answer(nk.A_JUDGED, late=solver.best.past_deadline())
                elif code == nk.NEED_FALLBACK:
                    code = self._fallback_step(nk.A_FRESH, self.pivots,
                                               "no descent from the best point")
                elif code == nk.TIME_UP:
                    raise NMSStop(Status.TIME_LIMIT, "time limit reached")
                else:  # STALLED
                    return f"no progress in {int(si[nk.I_STALL])} major iterations"
                if isinstance(code, str):  # the run ends
                    return code
        finally:
            copies.hand_best()
            copies.hand_basis()

    def _current(self) -> Point:
        W = self.W
        return Point(W[nk.W_CZ], W[nk.W_CF], W[nk.W_CPHI], float(self.sf[nk.S_CPSI]))

    def _log_step(self):
        """The history's record and the log line of the major iteration the kernel just
        finished (its step's letter in si[I_LOG]; the iterate it accepted is current)."""
        si, sf = self.si, self.sf
        solver = self.solver
        solver.log.iteration(solver.counts.nit, self.code_res, nk.LETTERS[si[nk.I_LOG]],
                             self._current(), float(sf[nk.S_EPS]), self.pivots,
                             fbn=float(sf[nk.S_LOG_FBN]))
        si[nk.I_LOG] = 0

    def _fallback_step(self, answer, pivots, failed):
        """The fallback from the best point (which it may replace); ``failed``: the run's
        end when it finds no point.  Returns the kernel's next request or the end."""
        solver, copies = self.solver, self.copies
        copies.hand_best()
        fb, letter = solver.fallback(self.opt)
        eps = float(self.sf[nk.S_EPS])
        if fb is None:
            if answer == nk.A_FRESH:
                solver.log.iteration(solver.counts.nit, self.code_res, "G",
                                     solver.best.point, eps, pivots)
            return failed
        copies.take_best()
        W = self.W
        W[nk.W_TZ], W[nk.W_TF], W[nk.W_TPHI] = fb.z, fb.f, fb.phi
        self.sf[nk.S_TPSI] = fb.psi
        solver.log.iteration(solver.counts.nit, self.code_res, letter, fb, eps, pivots)
        return self.answer(answer)

    def _newton(self):
        """The request NEED_NEWTON: the limits, the callback, J and the Newton point of the
        current iterate (by the dense direct step in the kernel, or by a path)."""
        solver, opt, sf, W = self.solver, self.opt, self.sf, self.W
        solver.check_limits(opt)
        if solver.callback is not None:
            solver.call_back(self._current())
        if solver.progress.enabled:
            solver.show_progress(math.sqrt(2.0 * sf[nk.S_CPSI]), math.sqrt(2.0 * sf[nk.S_BPSI]))
        J_given, self.cur_J = self.cur_J, None
        self.code_res = LinearCode.ERROR
        newton = solver.newton
        first = solver.counts.nit == 0
        direct = newton.dense_lane(opt, first) and newton.direct.dense
        J = None
        if direct:
            J = newton.jacobian_at(W[nk.W_CZ], W[nk.W_CF], J_given)
            if J is not None and not (J.data.dtype == np.float64 and J.data.shape[0] == J.nnz):
                direct, J_given = False, J  # (the Python route, with this J)
        if direct and J is not None:
            code = self._direct_step(J)
            if code is not None:
                return code
            res, J = self._failed_direct_path(), J
        elif direct:  # (J could not be evaluated)
            solver.counts.nit += 1
            res = None
        else:
            self.copies.hand_basis()
            cur = Point(W[nk.W_CZ].copy(), W[nk.W_CF].copy(), W[nk.W_CPHI].copy(),
                        float(sf[nk.S_CPSI]), J_given)
            res, J, self.code_res = newton.point(cur, W[nk.W_CX].copy(), float(sf[nk.S_EPS]),
                                                 opt, first)
            solver.counts.nit += 1
            self.copies.take_basis()
        if res is None:  # J could not be evaluated at z_k
            return self._fallback_step(nk.A_FRESH_J, 0,
                                       "evaluation failure and no fallback progress")
        self._path_end(res)
        self.ip, self.ix, self.jx = J.indptr, J.indices, J.data
        return self.answer(nk.A_NEWTON)

    def _direct_step(self, J):
        """The linear MCP and its dense direct step in the kernel (answer A_J): the next
        request when the step ended the path, None when the path must run."""
        newton, si, sf = self.solver.newton, self.si, self.sf
        lin = newton.linearizer
        if self.mdata.shape[0] != lin.M.data.shape[0]:
            self.mdata = np.empty(lin.M.data.shape[0])
        si[nk.I_SCATTER] = lin.pos_J is not None
        self.pj = lin.pos_J if lin.pos_J is not None else lin.pos_D
        self.pd = lin.pos_D
        self.mp, self.mi = lin.M.indptr, lin.M.indices
        self.ip, self.ix, self.jx = J.indptr, J.indices, J.data
        sf[nk.S_RANK] = newton.direct.rank_tolerance
        self._t0 = time.perf_counter()
        code = self.answer(nk.A_J)
        self.solver.counts.nit += 1
        if code != nk.NEED_PATH:
            newton.dense_step_done(si[nk.I_DIRECT], si[nk.I_NF], self._t0)
            self.code_res, self.pivots = LinearCode.SOLVED, 0
            return code
        return None

    def _failed_direct_path(self):
        """The step failed: the path, on the call's linear MCP and from its start
        (dense_direct_path's outcome)."""
        newton, si, W, B = self.solver.newton, self.si, self.W, self.B
        P = newton.linearizer.M
        start = failed_direct_start(
            W[nk.W_LZ].copy(), W[nk.W_LW].copy(), W[nk.W_LV].copy(),
            B[nk.B_BASIC].copy(), B[nk.B_SLACK].copy(), si[nk.I_GUESSED],
            newton.direct.dense_done(int(si[nk.I_NF])))
        self.copies.hand_basis()
        res = newton.solve_linear(
            trusted_csc(self.mdata.copy(), P.indices, P.indptr, P.shape),
            W[nk.W_Q].copy(), W[nk.W_R].copy(), W[nk.W_CX].copy(), False, self.opt, start)
        newton.path_done(res, self._t0, self.opt)
        self.copies.take_basis()
        return res

    def _path_end(self, res):
        """A path's end for the kernel."""
        W, si = self.W, self.si
        W[nk.W_RZ], W[nk.W_RW], W[nk.W_RV] = res.z, res.w, res.v
        solved = res.code is LinearCode.SOLVED
        si[nk.I_USABLE] = solved or (res.t > 1e-8 and bool(np.any(res.z != W[nk.W_CZ])))
        si[nk.I_RES_SOLVED] = solved
        si[nk.I_RES_MOVED] = res.t > 0
        self.code_res, self.pivots = res.code, res.pivots
