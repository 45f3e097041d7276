"""The stabilized Newton method's driver: runs of crash + major iterations, restarts, the
homotopy fallback and the diagnosis of a failed solve (see :mod:`compass_sparse.nms` for
the method).

:class:`NMSSolver` owns the counts of the solve (:class:`~compass_sparse.status.WorkCounts`)
and the pass records; it delegates the best point to :class:`~compass_sparse.nms.best.BestPoint`,
the Newton points to :class:`~compass_sparse.nms.newton.NewtonStep` and the history and
log to :class:`~compass_sparse.nms.log.MajorLog`.  The major iterations run in the Python
loop here (:meth:`NMSSolver.run`) or in compiled calls
(:class:`~compass_sparse.nms.compiled.CompiledRun`), as the solve's routes chose.
"""
from __future__ import annotations

import time

import numpy as np

from .._jit import stop_compiling
from ..basis.backends import factor_seconds
from ..box import all_finite, max_abs_diff, near_point, project, random_point
from ..crash.driver import crash
from ..exceptions import FactorBudgetError
from ..homotopy.outcome import HomotopyStatus
from ..homotopy.paths import homotopy_pass
from ..merit import fb_directional, fb_phi, fb_psi, normal_map_at
from ..path.outcome import LinearCode, WarmBasis
from ..progress import Progress, pass_line, solve_line
from ..routes import Routes
from ..status import IntermediateResult, PassStats, Status, WorkCounts
from .acceptance import Acceptance
from .best import BestPoint
from .compiled import CompiledRun
from .fallback import gradient_steps, lm_step
from .log import MajorLog
from .newton import NewtonStep
from .restarts import FROM_RANDOM, FROM_START, RestartSchedule
from .state import (REFERENCE_PROGRESS, NMSState, NMSStop, Outcome, Point, below_reference,
                    classify_step, reference_value, stall_update)
from .stationarity import Stationarity, stationarity, worst_rows

__all__ = ["NMSSolver"]

_DIAGNOSED = (Status.NO_PROGRESS, Status.MAJOR_ITERATION_LIMIT, Status.MINOR_ITERATION_LIMIT,
              Status.TIME_LIMIT)


class NMSSolver:
    """The stabilized Newton method on one MCP (after presolve).

    ``routes``: the solve's :class:`~compass_sparse.routes.Routes` (the major iterations',
    crash's and tracker's routes); ``make_basis(M)``: the basis of the pivotal paths (the
    solve's :func:`~compass_sparse.routes.basis_factory`); ``warm_basis``: a warm start of
    the first path; ``start_verdict``: the caller's acceptance verdict of the start Point
    handed to :meth:`solve`, when the solver works on the user's problem unscaled (the
    first run does not judge that point again)."""

    def __init__(self, problem, options, *, make_basis, routes: Routes | None = None,
                 callback=None, deadline=None, log_major=None, log_minor=None,
                 acceptance=None, warm_basis: WarmBasis | None = None, start_verdict=None):
        self.p = problem
        self.acceptance = acceptance or Acceptance(problem.lb, problem.ub,
                                                   options.convergence_tolerance)
        self.ev = problem.evaluator
        self.opt0 = options
        self.lb, self.ub = problem.lb, problem.ub
        self.n = problem.n
        self.routes = routes if routes is not None else Routes()
        self.callback = callback
        self.deadline = deadline
        self.tol = options.convergence_tolerance
        self.counts = WorkCounts()
        self.passes = {"crash": PassStats(), "path": PassStats(), "fallback": PassStats()}
        self.best = BestPoint(self.acceptance, self.ev, self.lb, self.ub, deadline,
                              problem.row_label)
        self.log = MajorLog(log_major, problem.counters, problem.row_label)
        self.newton = NewtonStep(self.ev, self.lb, self.ub, make_basis=make_basis,
                                 stats=self.passes["path"], counts=self.counts,
                                 deadline=deadline, log=self.log.minor(log_minor),
                                 warm=warm_basis)
        self.progress = Progress(options.progress)
        self._rng = None
        self._start_verdict = start_verdict
        self._start0 = None  # the start Point of solve()

    @property
    def rng(self):
        """The random generator of the restarts from new points (made when first needed:
        most solves never restart, and making one costs ~20 us)."""
        if self._rng is None:
            self._rng = np.random.default_rng(self.opt0.seed)
        return self._rng

    # ------------------------------------------------------------------ bookkeeping
    def point(self, z, f=None, J=None):
        """The evaluated Point at z (F evaluated when not given; None where it fails)."""
        if f is None:
            f = self.ev.f(z)
            if f is None:
                return None
        phi = fb_phi(z, f, self.lb, self.ub)
        return Point(z, f, phi, fb_psi(phi), J)

    def check_limits(self, opt):
        """Stop before a major iteration past a limit, or when the factorization it makes
        (of order n: :func:`~compass_sparse.basis.backends.factor_seconds`, its work per
        column alone) cannot finish in the time left -- twice that for the first, which
        also orders the pattern (a column order costs about a factorization's work per
        column: the sparse engine's first path at n = 1e6 took 1.8 s, 0.9 s of them
        ordering)."""
        if self.deadline is not None:
            left = self.deadline - time.perf_counter()
            if left < 0.0:
                raise NMSStop(Status.TIME_LIMIT, "time limit reached")
            need = factor_seconds(self.n, -1.0) * (2.0 if self.newton.basis is None else 1.0)
            if need > left:
                raise NMSStop(Status.TIME_LIMIT, "time limit reached: a major iteration "
                              f"factors a matrix of order {self.n} (~{need:.2g} s) and "
                              f"{left:.2g} s are left")
        if self.counts.nit >= opt.major_iteration_limit:
            raise NMSStop(Status.MAJOR_ITERATION_LIMIT,
                          f"major iteration limit ({opt.major_iteration_limit}) reached")
        if self.counts.minor_iterations >= opt.cumulative_limit(self.n):
            raise NMSStop(Status.MINOR_ITERATION_LIMIT,
                          f"cumulative pivot limit ({opt.cumulative_limit(self.n)}) reached")

    def _progress(self, cur: Point, final=False):
        self.show_progress(cur.fbn, self.best.point.fbn, final)

    def show_progress(self, fbn, best_fbn, final=False):
        """The progress line (Options.progress) at an iterate and the best point."""
        p = self.progress
        if p.enabled and p.due(final):
            c = self.counts
            p.show(solve_line(c.nit, c.minor_iterations, fbn, best_fbn, c.restarts,
                              p.elapsed), final=final)

    def watched(self, phase, on_point):
        """``on_point`` of a pass (the crash, the homotopy) that also redraws the progress
        line, which otherwise moves only between major iterations."""
        p = self.progress
        if not p.enabled:
            return on_point

        def watch(*point):
            out = on_point(*point)
            best = self.best.point
            if p.due() and best is not None:
                p.show(pass_line(phase, self.ev.counters.nfev, best.fbn, p.elapsed))
            return out
        return watch

    def call_back(self, cur: Point):
        """The user's callback at the current iterate (its return or StopIteration ends
        the solve; an exception of its own too, with the best point)."""
        if self.callback is None:
            return
        z, f = self.acceptance.user_point(cur.z, cur.f)  # the user's units
        a = self.acceptance
        info = IntermediateResult(x=np.array(z, copy=True), fun=np.array(f, copy=True),
                                  residual=float(np.linalg.norm(fb_phi(z, f, a.lb, a.ub))),
                                  nit=self.counts.nit,
                                  minor_iterations=self.counts.minor_iterations)
        try:
            stop = self.callback(info)
        except StopIteration:
            stop = True
        except Exception as exc:  # the user's callback failed: stop, keep the best point
            raise NMSStop(Status.CALLBACK_STOP, f"the callback raised {exc!r}") from exc
        if stop:
            raise NMSStop(Status.CALLBACK_STOP, "stopped by the callback")

    def fallback(self, opt):
        """LM step and projected-gradient steps from the best point: (the new point or
        None, its log letter 'L' or 'G')."""
        t0 = time.perf_counter()
        b = self.best.point
        out, letter = None, "G"
        if opt.lm_fallback:
            lm = lm_step(self.ev, b.z, b.f, None, self.lb, self.ub, opt, deadline=self.deadline,
                         on_point=self.best.consider)
            if lm is not None:
                self.counts.lm_steps += 1
                out, letter = Point(lm[0], lm[1], lm[2], lm[3]), "L"
        if out is None:
            g = gradient_steps(self.ev, b.z, b.f, None, self.lb, self.ub, opt,
                               deadline=self.deadline, on_point=self.best.consider)
            if g is not None:
                self.counts.gradient_steps += g[4]
                out = Point(g[0], g[1], g[2], g[3])
        st = self.passes["fallback"]
        st.ran = True
        st.time += time.perf_counter() - t0
        st.iterations += 1
        return out, letter

    # ------------------------------------------------------------------ driver
    def solve(self, start: Point) -> Outcome:
        """Run from ``start``, the evaluated start point (in the box, with F and J)."""
        self.log.t_start = time.perf_counter()
        self._start0 = start
        status, message = Status.NO_PROGRESS, ""
        try:
            self._restarts(start)
        except NMSStop as stop:
            status, message = stop.status, stop.message
        except FactorBudgetError as exc:
            status = Status.TIME_LIMIT if exc.kind == "time" else Status.MEMORY_LIMIT
            message = f"factorization not started: {exc}"
        except KeyboardInterrupt:
            # The Result is built without compiling (numba may have been compiling a
            # kernel: compass_sparse._jit), the compiled kernels run as they are.
            stop_compiling()
            status, message = Status.USER_INTERRUPT, "interrupted by the user (Ctrl-C)"
        status, message = self._diagnose(status, message)
        best = self.best.point
        if best is not None:
            self._progress(best, final=True)
        basis = self.newton.basis
        c = self.counts
        c.factorizations = ((basis.stats.factorizations if basis is not None else 0)
                            + self.passes["crash"].factorizations
                            + self.passes.get("homotopy", PassStats()).factorizations)
        c.basis_updates = basis.stats.updates if basis is not None else 0
        return Outcome(status, message, best, counts=c, basis=self.newton.warm,
                       passes=self.passes, history=self.log.full_history(start.phi, c.nit, best),
                       verdict=self.best.verdict if status is Status.SOLVED else None)

    def _restarts(self, start: Point):
        """Runs from ``start`` and the restarts' points, the homotopy among them, until a
        stop ends the solve (a solution stops it from inside) or the restarts run out."""
        opt, opt0 = self.opt0, self.opt0
        start0, z0 = start, start.z
        schedule = RestartSchedule(opt0)
        pattern = start.J if start.J is not None else self.ev.pattern_ref
        homotopy_after = opt0.restarts_before_homotopy(
            self.n, pattern.nnz if pattern is not None else self.n * self.n)
        if opt0.homotopy == "only":
            self.best.consider(start.z, start.f, start.phi, start.psi)
            raise NMSStop(Status.NO_PROGRESS, self._homotopy(z0))
        c = self.counts
        while True:
            homotopy_next = (opt0.homotopy == "auto" and "homotopy" not in self.passes
                             and c.restarts >= min(homotopy_after, opt0.restart_limit))
            why = self.run(start, opt, stall_limit=opt0.homotopy_stationary_limit
                           if homotopy_next else None)
            if homotopy_next:
                why = self._homotopy(z0)
            if c.restarts >= opt0.restart_limit:
                raise NMSStop(Status.NO_PROGRESS, f"{why}; restart limit reached")
            c.restarts += 1
            self.log.note(f"restart {c.restarts}: {why}")
            opt, where = schedule.plan(c.restarts - 1, self.best.point.fbn)
            if where == FROM_START:
                start = start0
            elif where == FROM_RANDOM:
                start = random_point(self.rng, z0, self.lb, self.ub)
            else:
                start = near_point(self.rng, self.best.point.z, self.lb, self.ub)
            self.newton.warm = None

    def _homotopy(self, start):
        """The homotopy pass (a solution stops the solve from inside): its first path from
        ``start`` (the user's start point), or with homotopy_start = 'best' after a stall
        from the best point; later paths from random points around ``start``."""
        opt0 = self.opt0
        polish = None if opt0.homotopy == "only" else (lambda z: self.run(z, opt0))
        first = start
        if opt0.homotopy == "auto" and opt0.homotopy_start == "best":
            first = self.best.point.z
        self.counts.nit += 1  # the pass is one major iteration of the log and the history
        try:
            out = homotopy_pass(self.ev, self.lb, self.ub, first, opt0,
                                stats=self.passes.setdefault("homotopy", PassStats()),
                                on_point=self.watched("homotopy", self.best.consider),
                                rng=lambda: self.rng, deadline=self.deadline, tol=self.tol,
                                polish=polish, center=start, log=self.log.writer("homotopy"),
                                compiled=self.routes.homotopy == "compiled")
        finally:
            self.log.homotopy(self.counts.nit, self.best.point.fbn)
        if out.status is HomotopyStatus.TIME_LIMIT:
            raise NMSStop(Status.TIME_LIMIT, "time limit reached on the homotopy path")
        return f"homotopy {out.status.value} ({out.message})"

    def _diagnose(self, status, message):
        """A failed solve names the rows that keep the merit up; one that converged to a
        stationary point of the merit function says so (see
        :mod:`compass_sparse.nms.stationarity`; not tested after a time limit)."""
        best = self.best.point
        if status not in _DIAGNOSED or best is None:
            return status, message
        J = None
        if status is not Status.TIME_LIMIT:
            # (a solve the clock stopped names its rows only: past its limit it evaluates
            # no J -- with the products of the test, 0.3 s at n = 1e6 -- and a run cut
            # short has not converged anywhere)
            try:
                J = self.ev.jac(best.z, best.f)
            except KeyboardInterrupt:
                return status, message
        st = (Stationarity(False, np.inf, worst_rows(best.phi)) if J is None
              else stationarity(best.z, best.f, J, self.lb, self.ub))
        a = self.acceptance
        if a.row is not None:
            # The verdict is the scaled problem's (better conditioned); the rows are named
            # with the user's |Phi_i| at the user's point (the Result's residual report
            # reads the same values), not the scaled ones.
            zu, fu = a.user_point(best.z, best.f)
            st.rows = worst_rows(fb_phi(zu, fu, a.lb, a.ub))
        text = st.message(self.p.row_label)
        if status is Status.NO_PROGRESS and st.stationary:
            return Status.STATIONARY_POINT, text
        return status, f"{message}; {text}"

    # ------------------------------------------------------------------ one run
    def run(self, start, opt, stall_limit=None):
        """Crash + NMS from ``start`` (a point of the box, or an evaluated Point) with
        options opt.  Returns when stuck (for a restart or the homotopy): when the best
        merit has not improved in ``stall_limit`` major iterations, or, for a restart
        (stall_limit None: opt.restart_stationary_limit), when in that many the best merit
        has not improved and no checkpoint has beaten its reference value
        (REFERENCE_PROGRESS)."""
        # The restart rule also counts checkpoints below their reference value as progress
        # (below_reference); the hand-over to the homotopy (its own stall_limit) watches
        # the best merit only: see REFERENCE_PROGRESS.
        reference_progress = stall_limit is None and REFERENCE_PROGRESS
        if stall_limit is None:
            stall_limit = opt.restart_stationary_limit
        cur = start if isinstance(start, Point) else self.point(start)
        if cur is None:
            # only a restart's drawn point arrives unevaluated (the user's start was evaluated)
            return "F or J undefined at the last restart's point (not at the start point)"
        # the caller's verdict holds for the start Point itself, in the first run only
        v0 = self._start_verdict if start is self._start0 else None
        self._start_verdict = None
        self.best.consider(cur.z, cur.f, cur.phi, cur.psi, v0)
        x, _ = normal_map_at(cur.z, cur.f, self.lb, self.ub)
        cur, x = self._crash(cur, x, opt)
        # nms = False: a monotone line search -- no d-steps, and the reference value is
        # the merit of the current point (a memory of one checkpoint, no initial slack).
        monotone = not opt.nms
        st = NMSState(
            cur=cur, x=x, memory_size=1 if monotone else opt.nms_memory_size,
            memory=[cur.psi if monotone else opt.nms_initial_reference_factor * cur.psi],
            ckpt=(cur, x),
            delta=10.0 * max(1.0, float(np.max(np.abs(cur.z))) if cur.z.size else 1.0),
            eps=opt.proximal_perturbation, best_seen=self.best.point.psi, fbn_start=cur.fbn)
        if self.routes.nms == "compiled":
            return CompiledRun(self, st, opt, stall_limit, reference_progress).run()
        return self._python_run(st, opt, stall_limit, reference_progress)

    def _crash(self, cur, x, opt):
        """The crash from the run's start ``cur`` (x its normal-map point): (the point the
        major iterations start from, its x)."""
        crash_st = self.passes["crash"]
        if not (opt.crash_method == "pnewton" and self.n >= opt.crash_minimum_dimension
                and opt.crash_iteration_limit > 0):
            if not crash_st.ran and crash_st.reason == "":
                crash_st.reason = (
                    "crash_method none" if opt.crash_method == "none"
                    else f"n < crash_minimum_dimension ({opt.crash_minimum_dimension})")
            return cur, x
        t0 = time.perf_counter()
        counters = self.p.counters
        nf0, nj0 = counters.nfev, counters.njev
        crash_st.ran = True
        it0 = crash_st.iterations
        try:  # (a solution found by the crash stops the solve from inside it)
            cr = crash(self.ev, cur.z, self.lb, self.ub, opt, f0=cur.f, J0=cur.J, tol=self.tol,
                       deadline=self.deadline,
                       log=self.log.writer("crash"),
                       on_point=self.watched("crash", self.best.consider_trial), stats=crash_st,
                       compiled=self.routes.crash == "compiled")
        finally:
            crash_st.time += time.perf_counter() - t0
            crash_st.nfev += counters.nfev - nf0
            crash_st.njev += counters.njev - nj0
            self.counts.crash_iterations += crash_st.iterations - it0
        crash_st.reason = cr.stop_reason  # (of the last run's crash; a skip's is stale)
        self.log.note(f"crash: {cr.iterations} step{'' if cr.iterations == 1 else 's'}, "
                      f"{cr.stop_reason}")
        if cr.iterations > 0 and all_finite(cr.f):
            pt = self.point(cr.z, cr.f)
            self.best.consider(pt.z, pt.f, pt.phi, pt.psi)
            if pt.psi <= opt.nms_initial_reference_factor * cur.psi:
                self.newton.crash_factors = cr.factors
                return pt, cr.x
        return cur, x

    def _python_run(self, st, opt, stall_limit, reference_progress):
        """The major iterations of :meth:`run` in Python (the compiled route's reference)."""
        c = self.counts
        while True:
            self.check_limits(opt)
            self.call_back(st.cur)
            self._progress(st.cur)
            res, J, code = self.newton.point(st.cur, st.x, st.eps, opt, c.nit == 0)
            c.nit += 1
            st.progress = False
            if res is None:  # J could not be evaluated at z_k
                fb, letter = self.fallback(opt)
                if fb is None:
                    return "evaluation failure and no fallback progress"
                st.fresh_checkpoint(fb, normal_map_at(fb.z, fb.f, self.lb, self.ub)[0])
                self.log.iteration(c.nit, code, letter, st.cur, st.eps, 0)
                continue
            if not self._major_step(st, res, opt):
                return "no descent from the best point"
            # Stationarity: restart when neither the best merit nor (for a while after
            # the best merit's last improvement) the reference value has been beaten.
            stall_update(st, self.best.point.psi, reference_progress)
            if st.stall >= stall_limit:
                return f"no progress in {st.stall} major iterations"

    def _major_step(self, st, res, opt) -> bool:
        """The NMS test of the Newton point ``res`` of the current iterate: a d-, m- or
        watchdog step or the fallback; False when the fallback finds no point."""
        lb, ub = self.lb, self.ub
        cur = st.cur
        if cur is st.ckpt[0]:
            st.ckpt_newton = res
        # A failed path that did not move (t ~ 0) offers no candidate point.
        usable = res.code is LinearCode.SOLVED or (
            res.t > 1e-8 and bool(np.any(res.z != cur.z)))
        step = None
        cand = self.point(res.z) if usable else None
        if cand is not None:
            self.best.consider(cand.z, cand.f, cand.phi, cand.psi)
            R, large = reference_value(st.memory, cur.psi, cur.fbn, st.fbn_start)
            dist = max_abs_diff(cand.z, cur.z)
            step = classify_step(
                cand.psi, R, large, dist, st.delta,
                opt.nms and st.n_d < opt.nms_mstep_frequency, opt.nms_sigma,
                lambda: self._descent_ok(cur, cand, R, opt))
            if step in ("D", "O"):
                st.n_d += 1
                st.delta = max(st.delta * opt.nms_delta_shrink_factor, opt.nms_delta_min)
            elif step == "M":
                st.n_d = 0
        if step is None:
            return self._watchdog(st, res, cur, usable, opt)
        xN = res.x if cand.z is res.z else normal_map_at(cand.z, cand.f, lb, ub)[0]
        st.cur, st.x = cand, xN
        if step in ("M", "O") or cand.psi < min(st.memory):
            st.progress = below_reference(cand.psi, R)
            st.checkpoint(cand, xN)
            st.watchdogs = 0
        st.eps *= opt.proximal_shrink_factor
        self.log.iteration(self.counts.nit, res.code, step, st.cur, st.eps, res.pivots)
        return True

    def _watchdog(self, st, res, cur, usable, opt) -> bool:
        """No step from the Newton point: back to the checkpoint and search towards its
        Newton point, else the fallback from the best point (False: it found nothing)."""
        if usable and st.eps == 0.0 and res.code is not LinearCode.SOLVED:
            st.eps = 0.01 * min(1.0, cur.fbn)
        elif not usable:
            st.eps = max(st.eps * opt.proximal_increase_factor, 1e-6 * min(1.0, cur.fbn))
        st.watchdogs += 1
        found = None
        newton = st.ckpt_newton
        if st.watchdogs <= opt.nms_maximum_watchdogs and newton is not None and (
                newton.code is LinearCode.SOLVED or newton.t > 0):
            c = st.ckpt[0]
            R = reference_value(st.memory, c.psi, c.fbn, st.fbn_start)[0]
            found = self._watchdog_search(st.ckpt, newton, R, opt)
        nit = self.counts.nit
        if found is not None:
            st.progress = below_reference(found[0].psi, R)
            st.checkpoint(*found)
            st.n_d = 0
            self.log.iteration(nit, res.code, "W", st.cur, st.eps, res.pivots)
            return True
        fb, letter = self.fallback(opt)
        if fb is None:
            self.log.iteration(nit, res.code, "G", self.best.point, st.eps, res.pivots)
            return False
        st.fresh_checkpoint(fb, normal_map_at(fb.z, fb.f, self.lb, self.ub)[0])
        st.n_d = 0
        st.watchdogs = 0
        self.log.iteration(nit, res.code, letter, st.cur, st.eps, res.pivots)
        return True

    def _descent_ok(self, cur, cand, R, opt):
        # The directional derivative of Psi at z_k uses the Jacobian of this major iteration.
        J = self.newton.last_J
        if J is not None:
            dd = fb_directional(cur.z, cur.f, J, self.lb, self.ub, cur.phi, cand.z)
            if dd < 0:
                return cand.psi <= R + opt.nms_sigma * dd
        return cand.psi <= (1.0 - opt.nms_sigma) * R

    def _watchdog_search(self, ckpt, newton, R, opt):
        c, xc = ckpt
        lb, ub = self.lb, self.ub
        zN = newton.z
        xN = newton.x
        alpha = 1.0
        while alpha >= opt.nms_stepsize_minimum:
            if self.best.past_deadline():
                raise NMSStop(Status.TIME_LIMIT, "time limit reached")
            if opt.nms_searchtype == "line":
                # (projected: the combination of two points at one bound can round to a
                # unit in the last place beyond it, and a returned point must lie in the box)
                zt = project((1.0 - alpha) * c.z + alpha * zN, lb, ub)
            else:
                zt = project((1.0 - alpha) * xc + alpha * xN, lb, ub)
            pt = self.point(zt)
            if pt is not None:
                self.best.consider(pt.z, pt.f, pt.phi, pt.psi)
                if pt.psi <= (1.0 - opt.nms_sigma * alpha) * min(R, max(c.psi, 1e-300) * 1e300) \
                        and pt.psi < R:
                    if opt.nms_searchtype == "line":
                        x, _ = normal_map_at(pt.z, pt.f, lb, ub)
                    else:
                        x = (1.0 - alpha) * xc + alpha * xN
                    return pt, x
            alpha *= opt.nms_shrink_factor
        return None
