"""Public entry points: :func:`solve_mcp`, :func:`solve_lcp` and :class:`MCPSolver`.

Thin functions that validate, normalize and dispatch to the passes:

    problem -> presolve -> crash -> NMS (major iterations on the pivotal path) -> postsolve

Every pass decides cheaply whether it applies and the Result says which ran and what each
cost (``Result.passes``).  Failures are statuses, never exceptions; bad input raises an
exception of :mod:`compass_sparse.exceptions` before any work is done.
"""
from __future__ import annotations

import functools
import logging
import math
import time

import numpy as np
import scipy.sparse as sp

from .acceptance import Acceptance, judge
from .crash.driver import crash
from .exceptions import CompassError
from .box import dot_norm, float_vector
from .merit import fb_phi, fb_psi, normal_map_at, residual_report
from .nms import NMSSolver, Point
from .options import Options
from .exceptions import ShapeError
from .path.outcome import LinearCode, WarmBasis
from .path.warm import default_basis
from .path.linear_mcp import solve_linear_mcp
from .problem.mcp import MCP
from .result import Result
from .status import Iteration, PassStats, PointStatus, Status
from .linalg.blas import BLAS_LIMIT_MIN_N, single_threaded_blas
from .problem._kernels import any_equal
from .linalg._csc_kernels import csc_scaled_all_finite
from .scaling import SPREAD_TRIGGER, equilibrate, scale_problem, spread

logger = logging.getLogger("compass_sparse")

__all__ = ["solve_mcp", "solve_lcp", "MCPSolver"]

DENSE_BASIS_MAX_N = 300
"""Up to this dimension the dense basis is used (0: always the sparse manager)."""

UPDATE_LIMIT_FLOOR = 50
"""factorization_update_limit is capped at max(n, this) (the bases preallocate the updates)."""


def _manager_factory(opt: Options, deadline=None):
    """Bases for the pivotal paths; the sparse manager gets the solve's deadline, so that a
    factorization that cannot finish in time is not started (TIME_LIMIT)."""
    def make(M):
        n = M.shape[0]
        from .path import dense_engine as dense_path

        # Both bases preallocate room for their updates; past max(n, 50) updates applying
        # them costs more than a fresh factorization, so a larger limit is capped there.
        limit = min(opt.factorization_update_limit, max(n, UPDATE_LIMIT_FLOOR))
        # The compiled engine writes no per-pivot log: verbosity >= 3 keeps the Python loop.
        if n <= dense_path.DENSE_ENGINE_MAX_N and opt.verbosity < 3:
            return dense_path.DensePathEngine(M, opt, update_limit=limit)
        if n <= DENSE_BASIS_MAX_N:
            from .basis.dense import DenseBasis

            return DenseBasis(M)
        from .basis import BasisManager, BasisOptions

        return BasisManager(M, options=BasisOptions(update_limit=limit, deadline=deadline,
                                                    backend=opt.lu_backend,
                                                    ordering=opt.lu_ordering,
                                                    reuse_factors=opt.factor_reuse))

    return make


def _blas_threads(n: int):
    """Single-threaded BLAS for small problems (their dense kernels are tiny; see
    :mod:`compass_sparse.linalg.blas`)."""
    import contextlib

    if n > DENSE_BASIS_MAX_N or n < BLAS_LIMIT_MIN_N:
        return contextlib.nullcontext()
    return single_threaded_blas()


def _loggers(opt: Options):
    """(major-iteration log, minor log) callables for verbosity >= 2 and >= 3, or None.

    The library only emits records (at INFO) on the ``compass_sparse`` logger; showing
    them is the application's choice (``logging.basicConfig(level=logging.INFO)``; the
    command-line tool does so)."""
    major = logger.info if opt.verbosity >= 2 else None
    minor = logger.info if opt.verbosity >= 3 else None
    return major, minor


_PROBLEM_KEYWORDS = ("n", "jac_sparsity", "var_names", "eqn_names", "constant_jac", "fd_step",
                     "check")


def _check_keywords(kwargs):
    """Unknown keywords of solve_mcp: a ProblemError with a hint (an option given as a
    keyword belongs in ``options=``)."""
    if not kwargs or set(kwargs).issubset(_PROBLEM_KEYWORDS):
        return
    import dataclasses
    import difflib

    from .exceptions import ProblemError

    unknown = sorted(set(kwargs) - set(_PROBLEM_KEYWORDS))
    option_names = {f.name for f in dataclasses.fields(Options)}
    hints = []
    for u in unknown:
        if u in option_names:
            hints.append(f"{u!r} (an option: pass options={{{u!r}: ...}})")
            continue
        close = difflib.get_close_matches(u, list(_PROBLEM_KEYWORDS) + sorted(option_names), 1)
        hints.append(f"{u!r}" + (f" (did you mean {close[0]!r}?)" if close else ""))
    raise ProblemError("solve_mcp got unknown keyword(s): " + ", ".join(hints))


def _as_problem(F, jac, lb, ub, x0, kwargs) -> tuple[MCP, bool]:
    """The problem, and whether its start point is still to be checked."""
    _check_keywords(kwargs)
    if isinstance(F, MCP):
        if x0 is not None:
            return F.with_start(x0), False
        return F, False
    # The start point is checked by the solve, where a Ctrl-C in the user's first F or J
    # call still ends in a Result (a bad start still raises EvaluationError there).
    kwargs = dict(kwargs)
    check = bool(kwargs.pop("check", True))
    return MCP(F, jac, lb, ub, x0, **kwargs, check=False), check


def _judge_on(problem: MCP, z, f, opt: Options, phi=None):
    """The acceptance verdict of z on ``problem`` (J evaluated only when the residuals are
    small; a J that cannot be evaluated there leaves the residual test alone).  ``phi``:
    Phi(z) when known."""
    def jac(y):
        try:
            return problem.evaluator.jac(y)
        except CompassError:
            return None
    return judge(z, f, problem.lb, problem.ub, opt.convergence_tolerance, jac=jac, phi=phi)


_FLAT_OVERRIDES = (Status.SOLVED, Status.NO_PROGRESS, Status.MAJOR_ITERATION_LIMIT,
                   Status.MINOR_ITERATION_LIMIT, Status.TIME_LIMIT, Status.STATIONARY_POINT)


def _result(problem: MCP, status: Status, message: str, z, f, opt: Options, t0, *,
            start_z=None, verdict=None, phi=None, **counts) -> Result:
    """The Result of the point z with F values f on ``problem`` (the user's).  ``verdict``
    and ``phi``: the acceptance verdict and Phi of exactly this (z, f) on this problem,
    when the solver has just computed them (they are not computed again)."""
    if phi is None:
        phi = fb_phi(z, f, problem.lb, problem.ub)
    rep = residual_report(z, f, problem.lb, problem.ub, names=problem.row_label, phi=phi)
    if verdict is None:
        verdict = _judge_on(problem, z, f, opt, phi)
    solved = verdict.solved
    if solved and status not in (Status.SOLVED,):
        # A limit fired after the solution was reached: report the solution.
        status, message = Status.SOLVED, "solution found"
    if not solved and verdict.small_residual and status in _FLAT_OVERRIDES:
        status, message = Status.FLAT_RESIDUAL, verdict.flat_message(problem.row_label)
    if status is Status.SOLVED and not solved:
        status, message = Status.ERROR, "internal error: a non-solution was marked solved"
    if solved:
        pstat = PointStatus.SOLUTION
    elif start_z is not None and np.array_equal(z, start_z):
        pstat = PointStatus.START_POINT
    else:
        pstat = PointStatus.BEST_POINT
    c = problem.counters
    return Result(
        x=np.asarray(z, dtype=float).copy(), fun=np.asarray(f, dtype=float).copy(),
        success=status is Status.SOLVED, status=status, point_status=pstat, message=message,
        nfev=c.nfev, njev=c.njev, residual=rep, time=time.perf_counter() - t0,
        domain_errors=c.domain_errors, lb=problem.lb, ub=problem.ub,
        tolerance=opt.convergence_tolerance, **counts,
    )


def solve_mcp(F, jac=None, lb=0.0, ub=np.inf, x0=None, *, options=None, callback=None,
              basis: WarmBasis | None = None, **problem_kwargs) -> Result:
    """Solve the mixed complementarity problem  lb <= x <= ub  _|_  F(x).

    Parameters
    ----------
    F : callable or MCP
        ``F(x) -> (n,)`` array (or ``(f, J)`` with ``jac=True``), or an already built
        :class:`~compass_sparse.MCP` (then jac, lb, ub are ignored).
    jac : callable, True or None
        Sparse Jacobian with a fixed pattern; None with ``jac_sparsity=`` for sparse
        finite differences.
    lb, ub : scalar or array
        Bounds (+-inf allowed).  Default NCP bounds [0, inf).
    x0 : array, optional
        Start point (projected onto the box).
    options : Options or dict, optional
        See :class:`~compass_sparse.Options` (``Options.describe()`` lists all).
    callback : callable(IntermediateResult) -> bool, optional
        Called after every major iteration; return True or raise StopIteration to stop.
    basis : WarmBasis, optional
        A basis from a previous Result (``result.basis``) to warm-start the first path.
    **problem_kwargs
        Passed to :class:`~compass_sparse.MCP` (``jac_sparsity``, ``var_names``,
        ``eqn_names``, ``constant_jac``).

    Returns
    -------
    Result
        Always holds a point: the solution, or the best point found with the reason.
    """
    opt = Options.coerce(options)
    if isinstance(F, MCP):
        # Built earlier: the data its functions read may have changed since the start
        # point was checked, so the values remembered then are not trusted.  Its counts
        # start again: a Result counts the calls of its own solve (they included the
        # construction's start check and every earlier solve of the object).
        F.evaluator.forget()
        F.evaluator.counters.reset()
    problem, check = _as_problem(F, jac, lb, ub, x0, problem_kwargs)
    return _solve_problem(problem, opt, callback=callback, basis=basis, check=check)


LEAVE_SIMPLE_MAX_N = 2000
"""Up to this order, when every reduction the preprocessor finds is one the solver does as
well on the whole problem (l = u variables kept fixed, diagonal column singletons), no
reduced problem is built: its set-up (~1 ms) and its restricted evaluations cost a small
model more than they save (a static CGE model at n = 91: 7.9 -> 3.5 ms per solve).  Above
it that cost is negligible, and the reduced problem is kept (a different but valid
trajectory: on the dynamic CGE model at n = 1e4 the crash no longer ended the solve, 1.7
-> 3.7 s)."""


def _presolve_pass(problem, opt, f0, J0):
    """Run the preprocessor when the problem declares linear structure."""
    st = PassStats()
    if not opt.presolve:
        st.reason = "presolve off"
        return None, st
    # Every reduction but fixing l = u needs a row whose entries are all declared
    # constant; without one the pass would only cost time (17 s at n = 1e6, measured).
    lb, ub = problem.lb, problem.ub
    has_fixed = (any_equal(lb, ub) if float_vector(lb) and float_vector(ub)
                 else bool((lb == ub).any()))

    def count_linear_rows():
        P = J0 if J0 is not None else problem.pattern  # J0 is stored on the pattern
        mask = problem.constant_mask
        if mask is None and P.indices.shape[0] == problem.n * problem.n:
            return 0  # a full pattern with nothing declared constant (a dense J)
        nonconst_rows = P.indices if mask is None else P.indices[~mask]
        return int(np.count_nonzero(np.bincount(nonconst_rows, minlength=problem.n) == 0))

    # A fact of the pattern and of the constant entries declared on it: counted once per
    # pattern (a loop of solves of one problem counted it in every solve).
    cache = problem.evaluator.pattern_cache
    if cache.linear_rows is None:
        cache.linear_rows = count_linear_rows()
    linear_rows = cache.linear_rows
    if linear_rows == 0 and not has_fixed:
        st.reason = "no linear rows (all entries declared constant) and no fixed variables"
        return None, st
    try:
        from .presolve import presolve as run_presolve
    except ImportError:  # pragma: no cover - the package ships it
        st.reason = "preprocessor unavailable"
        return None, st
    t0 = time.perf_counter()
    pre = run_presolve(problem, f0=f0, J0=J0,
                       leave_simple_to_solver=problem.n <= LEAVE_SIMPLE_MAX_N)
    st.ran = True
    st.time = time.perf_counter() - t0
    return pre, st


def _solve_problem(problem: MCP, opt: Options, *, callback=None, basis=None,
                   check=False) -> Result:
    t0 = time.perf_counter()
    try:
        if check:
            problem.check_start()
        return _solve_evaluated(problem, opt, callback=callback, basis=basis)
    except KeyboardInterrupt:
        # Ctrl-C outside the major iterations (the start point, the preprocessor): the
        # start point is the best point known.
        return _result(problem, Status.USER_INTERRUPT, "interrupted by the user (Ctrl-C)",
                       problem.x0, np.full(problem.n, np.nan), opt, t0, start_z=problem.x0)
    finally:
        # The user's functions may read data that changes before the next solve.
        problem.evaluator.forget()


def _check_basis(basis, n: int) -> WarmBasis | None:
    """A warm-start basis of the user's problem, or an error naming the mismatch."""
    if basis is None:
        return None
    b = np.asarray(basis.basic if isinstance(basis, WarmBasis) else basis)
    if b.shape != (n,):
        raise ShapeError(f"the warm-start basis has shape {b.shape} but the problem has {n} "
                         "variables: pass the Result.basis of a solve of this problem")
    return WarmBasis(b.astype(np.int8))


def _postsolve_basis(pre, basis: WarmBasis | None, z, lb, ub) -> WarmBasis | None:
    """The basis of the reduced problem in the original index space: reduced variable k
    is original variable ``cols[k]``; a removed variable gets the status of its
    postsolved value (at a bound: its slack; fixed: the free slack)."""
    if basis is None or pre is None:
        return basis
    full = default_basis(z, lb, ub)
    full[pre.stack.cols] = basis.basic
    return WarmBasis(full)


_SOLVE_PASSES = ("crash", "path", "fallback", "homotopy")


def _not_run(passes, names, reason):
    """Record the passes ``names`` as not run, for ``reason``."""
    for k in names:
        passes[k] = PassStats(reason=reason)


def _solve_evaluated(problem: MCP, opt: Options, *, callback=None, basis=None) -> Result:
    basis = _check_basis(basis, problem.n)
    t0 = time.perf_counter()
    log_major, log_minor = _loggers(opt)
    deadline = t0 + opt.time_limit if math.isfinite(opt.time_limit) else None
    passes = {}
    # F and J at the start point: one evaluation each (kept from the problem's start check
    # when it ran), handed down to the preprocessor, the crash and the first iteration.
    f0, J0 = problem.evaluator.fj(problem.x0)
    problem.evaluator.pin(problem.x0)
    if f0 is None:
        return _result(problem, Status.DOMAIN_ERROR, "F or J failed at the start point: "
                       f"{problem.evaluator.last_error}", problem.x0,
                       np.full(problem.n, np.nan), opt, t0, start_z=problem.x0,
                       passes=passes)
    # The start point is judged on the user's problem before any pass runs: a warm start
    # at a solution (a scenario that changed nothing, a re-solve) costs one verdict, not a
    # preprocessor run (4.6 ms against 0.8 ms on a static CGE model at n = 247, measured).
    phi_user = fb_phi(problem.x0, f0, problem.lb, problem.ub)
    verdict_user = _judge_on(problem, problem.x0, f0, opt, phi_user)
    if verdict_user.solved:
        _not_run(passes, ("presolve",) + _SOLVE_PASSES, "start point already solved")
        return _result(problem, Status.SOLVED, "the start point is a solution", problem.x0,
                       f0, opt, t0, start_z=problem.x0, verdict=verdict_user, phi=phi_user,
                       passes=passes, basis=basis)
    pre, st = _presolve_pass(problem, opt, f0, J0)
    passes["presolve"] = st
    work = problem
    if pre is not None:
        st.reason = pre.summary_line()
        if pre.infeasible is not None:
            return _result(problem, Status.INFEASIBLE, f"preprocessor: {pre.infeasible}",
                           problem.x0, f0, opt, t0, passes=passes)
        if pre.reduced is None:
            z = pre.postsolve(np.zeros(0))
            f = problem.F(z)
            verdict = _judge_on(problem, z, f, opt)
            if not verdict.solved:
                # The postsolve's arithmetic missed the tolerance on the user's problem
                # (e.g. a free variable of 1e17 recovered from a row with coefficients of
                # 1e-3 and 1e0: its F is exact only to ~0.1): not a solution to report.
                return _without_preprocessor(problem, z, f, opt, t0, passes)
            return _result(problem, Status.SOLVED, "solved by the preprocessor", z, f, opt,
                           t0, passes=passes, verdict=verdict)
        if pre.reduced is problem:
            pre = None  # nothing removed: no postsolve needed
        else:
            work = pre.reduced
            if basis is not None:  # the warm basis, restricted through the index map
                basis = WarmBasis(basis.basic[pre.stack.cols])
    z0 = work.x0
    if work is not problem:
        f0, J0 = work.evaluator.fj(z0)
        work.evaluator.pin(z0)
        if f0 is None:
            return _finish(problem, pre, Status.DOMAIN_ERROR, "F or J failed at the start "
                           f"point: {work.evaluator.last_error}", z0, opt, t0, passes)
    if work is problem:
        phi0, verdict0 = phi_user, verdict_user
    else:
        phi0 = fb_phi(z0, f0, work.lb, work.ub)
        verdict0 = _judge_on(work, z0, f0, opt, phi0)
    at_solution = verdict0.solved
    if at_solution or opt.major_iteration_limit == 0:
        status = Status.SOLVED if at_solution else Status.MAJOR_ITERATION_LIMIT
        msg = ("the start point is a solution" if status is Status.SOLVED
               else "major_iteration_limit = 0: start point evaluated")
        _not_run(passes, _SOLVE_PASSES, "start point already solved"
                 if status is Status.SOLVED else "major_iteration_limit = 0")
        return _finish(problem, pre, status, msg, z0, opt, t0, passes,
                       f_reduced=f0, start_z=problem.x0, basis=basis)
    sc, passes["scaling"] = _scaling_pass(J0, opt)
    inner = work
    user_jac = None
    if sc is not None:  # the solver works in the scaled units
        inner = scale_problem(work, sc)
        user_jac = _UserJacobian(work.evaluator, inner.evaluator, sc)
    acceptance = Acceptance(work.lb, work.ub, opt.convergence_tolerance,
                            *((sc.row, sc.col) if sc is not None else ()), user_jac=user_jac)
    if sc is not None:
        z0, f0, J0 = z0 / sc.col, sc.row * f0, sc.scale_jacobian(J0)
        phi0 = fb_phi(z0, f0, inner.lb, inner.ub)
    solver = NMSSolver(inner, opt, manager_factory=_manager_factory(opt, deadline),
                       callback=callback, deadline=deadline, log_major=log_major,
                       log_minor=log_minor, acceptance=acceptance)
    solver.basis = basis
    if sc is None:  # the solver's start Point is (z0, f0) of `work`, judged above
        solver.start_verdict = verdict0
    if log_major is not None:
        log_major(f"{'major':>5} {'minor':>7} {'func':>6} {'grad':>5} {'residual':>12} "
                  f"type {'prox':>9} {'inorm':>10} (label)")
    tn = time.perf_counter()
    with _blas_threads(work.n):
        out = solver.solve(Point(z0, f0, phi0, fb_psi(phi0), J0))
    passes.update(out.passes)
    passes["nms"] = PassStats(ran=True, iterations=out.nit, time=time.perf_counter() - tn)
    passes.setdefault("homotopy", PassStats(
        reason="homotopy off" if opt.homotopy == "off" else "NMS did not stall"
        if out.status is Status.SOLVED else f"not reached ({out.status.name.lower()})"))
    zb, fb = out.best.z, out.best.f
    if sc is not None:  # back to the user's units
        zb, fb = sc.col * zb, fb / sc.row
    # The verdict that stopped the solve was taken on (zb, fb); when neither the
    # preprocessor nor the scaling changed the problem, that is the user's problem and
    # the verdict stands for the Result.
    same = pre is None and sc is None
    verdict = out.verdict if same else None
    if pre is None and sc is not None and out.verdict is not None and out.verdict.reusable:
        # taken on the user's problem at the user's point (zb, fb: the same products as
        # the verdict's) with the user's J: what judging again would find
        verdict = out.verdict
    res = _finish(problem, pre, out.status, out.message, zb, opt, t0, passes,
                  start_z=problem.x0, verdict=verdict, phi=out.best.phi if same else None,
                  f_reduced=fb, nit=out.nit, minor_iterations=out.minor,
                  crash_iterations=out.crash_iterations, restarts=out.restarts,
                  gradient_steps=out.gradient_steps, lm_steps=out.lm_steps,
                  factorizations=out.factorizations, basis_updates=out.updates,
                  basis=out.basis, history=_history(solver, out, phi0),
                  lu=_lu_report(solver.bm))
    if opt.verbosity >= 1:
        logger.info(res.summary())
    return res


def _without_preprocessor(problem, z, f, opt, t0, passes, presolve_missed=True) -> Result:
    """The whole problem solved again from z without the preprocessor, in what is left of
    the time limit (the clock does not restart): the preprocessor's point z (F values f)
    missed the tolerance on the user's problem (``presolve_missed``, said in its report),
    or the pass that ran before could not finish.  The Result keeps the earlier passes'
    reports and counts the evaluations of both."""
    left = opt.time_limit - (time.perf_counter() - t0)
    if left <= 0:
        return _result(problem, Status.TIME_LIMIT, "time limit reached", z, f, opt, t0,
                       start_z=problem.x0, passes=passes)
    if presolve_missed:
        st = passes.get("presolve")
        if st is not None:
            st.reason += ("; its point missed the tolerance on the original problem "
                          "(the postsolve's rounding): solved again without it")
    c = problem.counters  # the evaluations so far (the new solve counts its own)
    general = _solve_problem(problem.with_start(z), opt.replace(presolve=False, time_limit=left))
    general.passes = {**passes, **{k: v for k, v in general.passes.items() if k != "presolve"}}
    general.nfev += c.nfev
    general.njev += c.njev
    general.domain_errors += c.domain_errors
    general.time = time.perf_counter() - t0
    return general


class _UserJacobian:
    """The user's J at a user's point z = C y, for the verdicts of a scaled solve
    (:class:`~compass_sparse.acceptance.Acceptance`): evaluated, counted and rejected
    exactly as the scaled evaluator's guarded ``jac(y)`` would do it -- the parent's J at
    C y (one memo, one count), an exception or a non-finite entry of R J C (tested
    without building it) rejected on the scaled evaluator -- but returned unscaled.
    Applies while the scaled evaluator shares the parent's pattern object (it does not
    check J against a pattern of its own) and J is not taken by differences on the
    scaled problem."""

    __slots__ = ("parent", "scaled", "row", "col")

    def __init__(self, parent, scaled, sc):
        self.parent, self.scaled = parent, scaled
        self.row, self.col = sc.row, sc.col

    def applies(self) -> bool:
        s = self.scaled
        return s.jac_mode is not None and s.pattern_ref is not None and \
            s.pattern_ref is self.parent.pattern_ref

    def __call__(self, zu):
        return self.scaled.guarded(
            lambda: self.parent.J(zu),
            lambda J: csc_scaled_all_finite(J.indptr, J.indices, J.data, self.row, self.col),
            "J")


def _history(solver, out, phi0):
    """The start point, every logged major iteration, and the final point when the solve
    stopped inside a major iteration (a solution found during a search: empty type)."""
    hist = [Iteration(0, dot_norm(phi0), "", 0, 0.0, 0.0)] + solver.history
    if out.best is not None and hist[-1].nit < out.nit:
        hist.append(Iteration(out.nit, out.best.fbn, "", 0, 0.0,
                              time.perf_counter() - solver._t_start))
    return hist


@functools.lru_cache(maxsize=256)
def _spread_reason(s: float) -> str:
    """Why the scaling pass did not run.  (Formatting two floats costs ~2 us, ~1% of a
    small solve; a loop of solves of one model formats the same spread every time.)"""
    return f"row/column max-norm spread {s:.1e} <= {SPREAD_TRIGGER:.0e}"


def _scaling_pass(J0, opt):
    """(Scaling or None, PassStats): equilibrate J(z0) when it is badly scaled."""
    st = PassStats()
    if not opt.scaling:
        st.reason = "scaling off"
        return None, st
    t = time.perf_counter()
    s = spread(J0)
    if s <= SPREAD_TRIGGER:
        st.reason = _spread_reason(s)
        st.time = time.perf_counter() - t
        return None, st
    sc = equilibrate(J0, before=s)  # (the spread just computed)
    st.ran, st.reason, st.time = True, sc.summary(), time.perf_counter() - t
    return sc, st


def _lu_report(bm) -> dict:
    """Sparse-LU figures of a solve for ``Result.lu`` (empty for the dense basis)."""
    st = getattr(bm, "stats", None)
    if st is None or not hasattr(st, "est_bytes"):
        return {}
    import resource
    return dict(backend=st.backend, ordering=st.ordering,
                orderings_computed=st.orderings_computed, time_ordering=st.time_ordering,
                time_factor=st.time_factor, est_nnz_lu=st.est_nnz_lu, est_flops=st.est_flops,
                est_bytes=st.est_bytes, max_nnz_lu=st.max_nnz_lu, reuses=st.reuses,
                reuse_steps=st.reuse_steps, reuse_fallbacks=st.reuse_fallbacks,
                peak_rss_bytes=resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024)


def _finish(problem, pre, status, message, z_red, opt, t0, passes, *, f_reduced=None,
            start_z=None, **counts):
    """Postsolve and build the Result on the ORIGINAL problem."""
    if pre is not None:
        z = pre.postsolve(np.asarray(z_red, dtype=float))
        f = None
    else:
        z = z_red
        f = f_reduced if f_reduced is not None else None
    if f is None:
        f = problem.evaluator.f(z)
        if f is None:  # the point is returned with the failure; F is unknown there
            f = np.full(problem.n, np.nan)
    if "basis" in counts:
        counts["basis"] = _postsolve_basis(pre, counts["basis"], z, problem.lb, problem.ub)
    res = _result(problem, status, message, z, f, opt, t0, start_z=start_z, passes=passes,
                  **counts)
    if pre is not None and status is Status.SOLVED and not res.success:
        # solved on the reduced problem, but the postsolved point misses the tolerance on
        # the user's problem (see the preprocessor-only case in _solve_evaluated); the
        # work of both solves is counted
        general = _without_preprocessor(problem, res.x, res.fun, opt, t0, passes)
        for k in _WORK_COUNTS:
            setattr(general, k, getattr(general, k) + getattr(res, k))
        return general
    return res


_WORK_COUNTS = ("nit", "minor_iterations", "crash_iterations", "restarts", "gradient_steps",
                "lm_steps", "factorizations", "basis_updates")
"""Result fields that count work done (summed over a solve and its hand-over)."""


# ---------------------------------------------------------------------------- LCP
def solve_lcp(M, q, lb=0.0, ub=np.inf, x0=None, *, options=None, var_names=None) -> Result:
    """Solve the (box-constrained) linear complementarity problem

        lb <= z <= ub  _|_  M z + q

    by one pivotal path (after a projected-Newton crash for n >= crash_minimum_dimension),
    with a Lemke ray start as the fallback.  Ray termination from the Lemke start is
    reported as ``Status.INFEASIBLE`` (a proof of infeasibility when M is copositive-plus).
    A path that cycles or stalls hands over to the general stabilized Newton method.
    """
    t0 = time.perf_counter()
    opt = Options.coerce(options)
    M, q = _lcp_data(M, q)
    n = q.size

    def F(z):
        return M @ z + q

    problem = MCP(F, lambda z: M, lb, ub, x0, n=n, var_names=var_names, constant_jac=M)
    log_major, log_minor = _loggers(opt)
    passes = {"presolve": PassStats(reason="linear problems go straight to the path")}
    lb, ub = problem.lb, problem.ub
    if np.all(np.isneginf(lb)) and np.all(np.isposinf(ub)):
        # Every variable free: the LCP is the linear system M z + q = 0.
        from .linear_system import solve_free_lcp

        out = solve_free_lcp(M, q, opt.convergence_tolerance)
        if out is not None:
            passes["path"] = PassStats(reason="all variables free: a linear system")
            zs = out.z if out.z is not None else problem.x0
            return _result(problem, out.status, out.message, zs, problem.F(zs), opt, t0,
                           passes=passes)
    z = problem.x0
    f = problem.F(z)  # kept from the start check
    at_solution = _judge_on(problem, z, f, opt).solved
    if at_solution or opt.major_iteration_limit == 0:
        status = Status.SOLVED if at_solution else Status.MAJOR_ITERATION_LIMIT
        return _result(problem, status, "start point evaluated", z, f, opt, t0,
                       start_z=problem.x0, passes=passes)
    crash_its = 0
    x = normal_map_at(z, f, lb, ub)[0]
    st = PassStats()
    deadline = t0 + opt.time_limit if math.isfinite(opt.time_limit) else None
    try:
        if opt.crash_method == "pnewton" and n >= opt.crash_minimum_dimension:
            tc = time.perf_counter()
            cr = crash(problem.evaluator, z, lb, ub, opt, f0=f, J0=M, log=log_major,
                       deadline=deadline)
            st = PassStats(ran=True, time=time.perf_counter() - tc, iterations=cr.iterations,
                           factorizations=cr.factorizations, reason=cr.stop_reason)
            crash_its = cr.iterations
            if np.all(np.isfinite(cr.f)):
                z, f, x = cr.z, cr.f, cr.x
        else:
            st.reason = f"n < crash_minimum_dimension ({opt.crash_minimum_dimension})"
        passes["crash"] = st
        return _lcp_path(problem, M, q, z, f, x, opt, t0, deadline, passes, st, crash_its,
                         log_minor)
    except KeyboardInterrupt:
        return _result(problem, Status.USER_INTERRUPT, "interrupted by the user (Ctrl-C)", z, f,
                       opt, t0, start_z=problem.x0, passes=passes, crash_iterations=crash_its)


def _lcp_path(problem, M, q, z, f, x, opt, t0, deadline, passes, st, crash_its, log_minor):
    """The pivotal path(s) of :func:`solve_lcp` from the (crashed) point z, x = pi^-1(z)."""
    n = q.size
    lb, ub = problem.lb, problem.ub
    if _judge_on(problem, z, f, opt).solved:
        passes["path"] = PassStats(reason="crash solved the problem")
        return _result(problem, Status.SOLVED, "solved by the crash", z, f, opt, t0,
                       passes=passes, crash_iterations=crash_its,
                       factorizations=st.factorizations)
    deadline = t0 + opt.time_limit if math.isfinite(opt.time_limit) else None
    bm = _manager_factory(opt, deadline)(M)
    tp = time.perf_counter()
    # One path solves a linear problem: give it room (a Lemke path may need ~n pivots).
    limit = opt.minor_iteration_limit or max(10 * n, 1000)
    with _blas_threads(n):
        res = solve_linear_mcp(M, q, lb, ub, bm, opt, x,
                               ray_start=opt.lemke_start in ("always", "first"),
                               keep_ray=True, minor_limit=limit, deadline=deadline,
                               log=log_minor)
    pivots = res.pivots
    passes["path"] = PassStats(ran=True, time=time.perf_counter() - tp, iterations=1,
                               pivots=pivots, factorizations=bm.stats.factorizations)
    counts = dict(nit=1, minor_iterations=pivots, crash_iterations=crash_its,
                  factorizations=bm.stats.factorizations + st.factorizations,
                  basis_updates=bm.stats.updates, passes=passes)
    if res.code is LinearCode.SOLVED:
        zs = res.z
        fs = problem.F(zs)
        out = _result(problem, Status.SOLVED, "solution found", zs, fs, opt, t0,
                      basis=res.basis, **counts)
        if out.success:
            return out
    # Only a genuine ray (the entering variable unbounded) from the Lemke start says
    # something about infeasibility, and a bounded box always has a solution.
    bounded = bool(np.all(np.isfinite(lb)) and np.all(np.isfinite(ub)))
    if (res.code is LinearCode.RAY and res.ray_start and res.unbounded and not bounded
            and _is_monotone(M)):
        # The certificate: x is the ray's base and x + theta * ray (theta >= 0) the ray.
        zs = res.ray_base
        out = _result(problem, Status.INFEASIBLE,
                      "ray termination from a Lemke start on a positive semidefinite M: "
                      "the problem has no solution", zs, problem.F(zs), opt, t0,
                      ray=res.ray.copy(), **counts)
        out.point_status = PointStatus.CERTIFICATE
        return out
    # The path cycled, hit a limit or lost accuracy: the stabilized Newton method takes over,
    # within what is left of the time limit (the clock does not restart).
    if opt.time_limit - (time.perf_counter() - t0) <= 0:
        return _result(problem, Status.TIME_LIMIT, "time limit reached in the pivotal path",
                       z, f, opt, t0, start_z=problem.x0, **counts)
    general = _without_preprocessor(problem, z, f, opt, t0, passes, presolve_missed=False)
    general.minor_iterations += pivots
    general.crash_iterations += crash_its
    return general


def _lcp_data(M, q):
    """Validated copies of the LCP data (the user's M is never modified): q real of shape
    (n,) (a column (n, 1) is accepted), M real n x n, both finite, named in errors."""
    from .exceptions import ProblemError, ShapeError
    from .problem.mcp import as_real

    q = as_real(q, "q")
    if q.ndim > 1 and q.size == max(q.shape):
        q = q.reshape(-1)
    if q.ndim != 1:
        raise ShapeError(f"q has shape {q.shape}, expected (n,) or (n, 1)")
    n = q.size
    if sp.issparse(M):
        if np.iscomplexobj(M.data):
            raise ProblemError("M is complex; compass_sparse solves real problems")
        M = sp.csc_matrix(M, dtype=float, copy=True)
    else:
        M = sp.csc_matrix(as_real(M, "M"))
    if M.shape != (n, n):
        raise ShapeError(f"M has shape {M.shape} but q has {n} entries; M must be {n} x {n}")
    M.sum_duplicates()
    M.sort_indices()
    if not np.all(np.isfinite(M.data)):
        k = int(np.flatnonzero(~np.isfinite(M.data))[0])
        j = int(np.searchsorted(M.indptr, k, side="right") - 1)
        raise ProblemError(f"M[{int(M.indices[k])}, {j}] is {M.data[k]}: M must be finite")
    bad = np.flatnonzero(~np.isfinite(q))
    if bad.size:
        raise ProblemError(f"q[{bad[0]}] is {q[bad[0]]}: q must be finite")
    return M, q


def _is_monotone(M, tol=1e-10) -> bool:
    """True when (M + M^T)/2 is positive semidefinite (then M is copositive-plus and a ray
    from the Lemke start proves infeasibility).  Dense eigenvalues up to n = 3000, the
    smallest eigenvalue by Lanczos above; False when undecided."""
    S = ((M + M.T) * 0.5).tocsc()
    n = S.shape[0]
    scale = max(1.0, float(abs(S).max())) if S.nnz else 1.0
    try:
        if n <= 3000:
            lam = float(np.linalg.eigvalsh(S.toarray())[0])
        else:
            from scipy.sparse.linalg import eigsh

            lam = float(eigsh(S, k=1, which="SA", return_eigenvectors=False, tol=1e-8,
                              maxiter=5000)[0])
    except Exception:
        return False
    return lam >= -tol * scale


# ---------------------------------------------------------------------------- object API
class MCPSolver:
    """Set up once, solve repeatedly (scenario loops), warm-started from the last basis.

    >>> solver = MCPSolver(problem, options={"convergence_tolerance": 1e-8})
    >>> r1 = solver.solve()
    >>> r2 = solver.solve(x0=r1.x)          # e.g. after changing data the closure reads
    """

    def __init__(self, problem: MCP, options=None, callback=None):
        if not isinstance(problem, MCP):
            from .exceptions import ProblemError

            raise ProblemError("MCPSolver takes an MCP, not "
                               f"{type(problem).__name__}; build one with "
                               "compass_sparse.MCP(F, jac, lb, ub, x0)")
        self.problem = problem
        self.options = Options.coerce(options)
        self.callback = callback
        self.last: Result | None = None

    def set_options(self, **changes):
        self.options = self.options.replace(**changes)

    def solve(self, x0=None, *, warm_start: bool = True) -> Result:
        """Solve from x0 (default: the last returned point, else the problem's x0)."""
        if x0 is None and self.last is not None and warm_start:
            x0 = self.last.x
        prob = self.problem.with_start(x0) if x0 is not None else self.problem
        basis = self.last.basis if (warm_start and self.last is not None) else None
        prob.evaluator.forget()  # the data F reads may have changed since the last call
        res = _solve_problem(prob, self.options, callback=self.callback, basis=basis)
        self.last = res
        return res
