"""The public entry point of the solver, :func:`solve_mcp` (and :class:`MCPSolver` for
repeated solves), and the pass pipeline behind it:

    problem -> presolve -> scaling -> crash -> NMS (major iterations on the pivotal path)
            -> [homotopy] -> postsolve -> Result

Thin functions that validate, normalize and dispatch to the passes.  Every pass decides
cheaply whether it applies and the Result says which ran and what each cost
(``Result.passes``); which implementation of each ran is chosen once per solve by
:mod:`compass_sparse.routes` (``Result.routes``).  Failures are statuses, never exceptions;
bad input raises an exception of :mod:`compass_sparse.exceptions` before any work is done.
Linear problems have their own entry point, :func:`compass_sparse.solve_lcp`
(:mod:`compass_sparse.lcp`), which hands over to this pipeline when its path fails.
"""
from __future__ import annotations

import contextlib
import dataclasses
import functools
import logging
import math
import time

import numpy as np

from ._jit import stop_compiling
from .box import float_vector
from .diagnostics import MISMATCH, directional_mismatch
from .exceptions import ProblemError, ShapeError
from .feasibility import STALLED, infeasible_result
from .linalg._csc_kernels import csc_scaled_all_finite
from .linalg.blas import BLAS_LIMIT_MIN_N, single_threaded_blas
from .merit import fb_phi, fb_psi
from .nms.acceptance import Acceptance
from .nms.solver import NMSSolver
from .nms.state import Point
from ._options_base import suggest
from .options import ALIASES, Options
from .path.outcome import WarmBasis
from .problem._kernels import any_equal
from .problem.isolated import isolated_pairs, solved_exactly
from .problem.mcp import MCP
from .report import judge_on, lu_report, make_result, postsolve_basis
from .result import Result
from .routes import DENSE_BASIS_MAX_N, basis_factory, choose_routes, kernel_route
from .scaling import SPREAD_TRIGGER, equilibrate, scale_problem, spread
from .status import PassStats, Status, WorkCounts

logger = logging.getLogger("compass_sparse")

__all__ = ["MCPSolver", "check_basis", "solve_mcp"]

WORK_COUNTS = tuple(f.name for f in dataclasses.fields(WorkCounts))
"""Result fields that count work done (summed over a solve and its hand-over)."""


def blas_threads(n: int):
    """Single-threaded BLAS for small problems (their dense kernels are tiny; see
    :mod:`compass_sparse.linalg.blas`)."""
    if n > DENSE_BASIS_MAX_N or n < BLAS_LIMIT_MIN_N:
        return contextlib.nullcontext()
    return single_threaded_blas()


def loggers(opt: Options):
    """(major-iteration log, minor log) callables for verbosity >= 2 and >= 3, or None.

    The library only emits records (at INFO) on the ``compass_sparse`` logger; showing
    them is the application's choice (``logging.basicConfig(level=logging.INFO)``; the
    command-line tool does so).  The log never changes which arithmetic runs."""
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
    unknown = sorted(set(kwargs) - set(_PROBLEM_KEYWORDS))
    option_names = {f.name for f in dataclasses.fields(Options)}
    hints = []
    for u in unknown:
        if u in option_names:
            hints.append(f"{u!r} (an option: pass options={{{u!r}: ...}})")
            continue
        close = suggest(u, set(_PROBLEM_KEYWORDS) | option_names, ALIASES)
        if close in option_names:
            hints.append(f"{u!r} (did you mean the option {close!r}? pass "
                         f"options={{{close!r}: ...}})")
        else:
            hints.append(f"{u!r}" + (f" (did you mean {close!r}?)" if close else ""))
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
    t0 = time.perf_counter()  # (the time limit counts from the call)
    opt = Options.coerce(options)
    if isinstance(F, MCP):
        # Built earlier: the data its functions read may have changed since the start
        # point was checked, so the values remembered then are not trusted.  Its counts
        # start again: a Result counts the calls of its own solve (they included the
        # construction's start check and every earlier solve of the object).
        F.evaluator.forget()
        F.evaluator.counters.reset()
    problem, check = _as_problem(F, jac, lb, ub, x0, problem_kwargs)
    return solve_problem(problem, opt, callback=callback, basis=basis, check=check, t0=t0)


FINISH_SECONDS_PER_VARIABLE = 2.0e-7
"""Seconds per variable the passes leave of the time limit for what follows them: the
best point's diagnosis, the history, the Result's residual report and verdict (0.1-0.15 s
at n = 1e6, measured: benchmarks/time_limit.md), so that a solve stopped by its limit
returns within it."""


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
    if linear_rows == 0 and not has_fixed and not _isolated_pair_solved(problem, f0, cache):
        st.reason = "no linear rows (all entries declared constant) and no fixed variables"
        return None, st
    # (lazy: the preprocessor's 17 modules are a third of the package's import time, 10 ms
    # of 30 with bytecode caches, measured; most small problems never run it)
    from .presolve import presolve as run_presolve

    t0 = time.perf_counter()
    pre = run_presolve(problem, f0=f0, J0=J0,
                       leave_simple_to_solver=problem.n <= LEAVE_SIMPLE_MAX_N)
    st.ran = True
    st.time = time.perf_counter() - t0
    return pre, st


def _isolated_pair_solved(problem, f0, cache) -> bool:
    """Whether the declared pattern has an isolated pair (a variable and its row that
    nothing else touches, :mod:`compass_sparse.problem.isolated`) that the start point
    solves exactly: the preprocessor keeps it there (a free variable with F = 0 and a
    zero row and column of J made every Newton system singular)."""
    if not problem.pattern_declared:
        return False
    if cache.isolated_pairs is None:
        P = problem.evaluator.pattern_ref
        cache.isolated_pairs = isolated_pairs(P.indptr, P.indices, problem.n)
    idx = cache.isolated_pairs
    if idx.size == 0:
        return False
    lb, ub = problem.lb[idx], problem.ub[idx]
    return bool(solved_exactly(problem.x0[idx], f0[idx], lb, ub)[lb < ub].any())


def _affine_data(problem: MCP, x):
    """(M, q) with F(z) = M z + q when every Jacobian entry is declared constant (and a
    row without entries is one of a declared pattern), checked once more at x (relative
    1e-8); else None.  Evaluated on a fresh evaluator: outside the solve's counts."""
    mask = problem.constant_mask
    P = problem.evaluator.pattern_ref
    if mask is None or P is None or not mask.all():
        return None
    if not problem.pattern_declared and (np.bincount(P.indices, minlength=problem.n) == 0).any():
        return None
    ev = problem.evaluator.fresh()
    try:
        f0, M = ev.FJ(problem.x0)
        f1 = ev.F(x)
    except Exception:  # (the user's F failed: no verdict rests on it)
        return None
    q = f0 - M @ problem.x0
    pred = M @ x + q
    size = np.abs(f1) + abs(M) @ np.abs(x) + np.abs(q) + 1.0
    if not np.all(np.abs(f1 - pred) <= 1e-8 * size):
        return None
    return M, q


def _infeasible_if_affine(problem: MCP, res: Result, opt: Options, t0) -> Result:
    """A stalled solve of an MCP whose F is affine (every Jacobian entry declared
    constant) is an LCP: its sign conditions are decided by an LP, and an INFEASIBLE
    Result with a checked Farkas certificate replaces it when no point of the box meets
    them (:mod:`compass_sparse.feasibility`)."""
    data = _affine_data(problem, res.x)
    if data is None:
        return res
    deadline = t0 + opt.time_limit if math.isfinite(opt.time_limit) else None
    out = infeasible_result(problem, *data, opt, t0, passes=res.passes, deadline=deadline,
                            failed=res)
    if out is None:
        return res
    out.message += " (F is affine: every Jacobian entry is declared constant)"
    return out


_JACOBIAN_SUSPECT = (Status.NO_PROGRESS, Status.STATIONARY_POINT, Status.MAJOR_ITERATION_LIMIT,
                     Status.MINOR_ITERATION_LIMIT, Status.FLAT_RESIDUAL, Status.ERROR)
"""The failed solves whose message says when J disagrees with F (a wrong Jacobian ends in
these; a limit of time, an interrupt or a domain error say nothing about J)."""


def jacobian_hint(problem: MCP, res: Result):
    """Append to a failed solve's message that J disagrees with F near its point, when it
    does (:func:`compass_sparse.diagnostics.directional_mismatch`: two evaluations of F
    and one of J, outside the counts), naming check_jacobian."""
    if res.status not in _JACOBIAN_SUSPECT:
        return
    mismatch = directional_mismatch(problem, res.x, problem.x0)
    if mismatch > MISMATCH:
        res.message += (f"; the Jacobian disagrees with F near the returned point (J d and "
                        f"the difference quotient of F along d differ by {mismatch:.1e}, "
                        "relative): compare them entry by entry with "
                        "compass_sparse.check_jacobian(F, J, res.x)")


def solve_problem(problem: MCP, opt: Options, *, callback=None, basis=None,
                  check=False, top=True, t0=None) -> Result:
    """The pass pipeline on a built problem (``check``: its start point is still to be
    checked), inside the solve's kernel route (:func:`compass_sparse.routes.kernel_route`).
    ``top``: the user's solve, not a hand-over inside one; it alone checks a failed
    solve's Jacobian and logs the summary (once, at verbosity >= 1).  ``t0``: when the
    solve began (``time.perf_counter()``; default now): its time and limit count from it,
    the start point's check included (0.3 s at n = 1e6)."""
    t0 = time.perf_counter() if t0 is None else t0
    basis = check_basis(basis, problem.n)  # (bad input: before any evaluation)
    with kernel_route(problem.n) as kernels:
        try:
            if check:
                problem.check_start()
            res = _solve_evaluated(problem, opt, kernels, callback=callback, basis=basis,
                                   t0=t0)
        except KeyboardInterrupt:
            # Ctrl-C outside the major iterations (the start point, the preprocessor): the
            # start point is the best point known.  Its Result compiles nothing (numba may
            # have been loading: compass_sparse._jit).
            stop_compiling()
            res = make_result(problem, Status.USER_INTERRUPT,
                              "interrupted by the user (Ctrl-C)", problem.x0,
                              np.full(problem.n, np.nan), opt, t0, start_z=problem.x0)
        finally:
            # The user's functions may read data that changes before the next solve.
            problem.evaluator.forget()
    if not res.routes:  # no pass ran that has a route
        res.routes = {"kernels": kernels}
    if top and res.status in STALLED:
        res = _infeasible_if_affine(problem, res, opt, t0)
    if top:
        jacobian_hint(problem, res)
        if opt.verbosity >= 1:
            logger.info(res.summary())
    return res


_SOLVE_PASSES = ("crash", "path", "fallback", "homotopy")


def _solve_evaluated(problem: MCP, opt: Options, kernels: str, *, callback=None,
                     basis=None, t0=None) -> Result:
    t0 = time.perf_counter() if t0 is None else t0
    passes = {}
    # F and J at the start point: one evaluation each (kept from the problem's start check
    # when it ran), handed down to the preprocessor, the crash and the first iteration.
    f0, J0 = problem.evaluator.fj(problem.x0)
    problem.evaluator.pin(problem.x0)
    if f0 is None:
        return make_result(problem, Status.DOMAIN_ERROR, "F or J failed at the start point: "
                           f"{problem.evaluator.last_error}", problem.x0,
                           np.full(problem.n, np.nan), opt, t0, start_z=problem.x0,
                           passes=passes)
    # The start point is judged on the user's problem before any pass runs: a warm start
    # at a solution (a scenario that changed nothing, a re-solve) costs one verdict, not a
    # preprocessor run (4.6 ms against 0.8 ms on a static CGE model at n = 247, measured).
    phi_user = fb_phi(problem.x0, f0, problem.lb, problem.ub)
    verdict_user = judge_on(problem, problem.x0, f0, opt, phi_user)
    if verdict_user.solved:
        _not_run(passes, ("presolve",) + _SOLVE_PASSES, "start point already solved")
        return make_result(problem, Status.SOLVED, "the start point is a solution",
                           problem.x0, f0, opt, t0, start_z=problem.x0, verdict=verdict_user,
                           phi=phi_user, passes=passes, basis=basis)
    pre, st = _presolve_pass(problem, opt, f0, J0)
    passes["presolve"] = st
    if pre is not None:
        st.reason = pre.summary_line()
        if opt.verbosity >= 2:
            logger.info(f"preprocessor: {st.reason}")
        if pre.infeasible is None and pre.reduced is problem:
            pre = None  # nothing removed: no postsolve needed
    if pre is None:
        return _from_start(problem, None, problem, f0, J0, phi_user, verdict_user, opt, t0,
                           passes, kernels, callback, basis)
    return _presolved(problem, pre, f0, opt, t0, passes, kernels, callback, basis)


def _presolved(problem, pre, f0, opt, t0, passes, kernels, callback, basis) -> Result:
    """The solve after a preprocessor run ``pre`` that removed something: its verdicts,
    or the reduced problem's solve."""
    if pre.infeasible is not None:
        return make_result(problem, Status.INFEASIBLE, f"preprocessor: {pre.infeasible}",
                           problem.x0, f0, opt, t0, passes=passes)
    if pre.reduced is None:
        z = pre.postsolve(np.zeros(0))
        f = problem.F(z)
        verdict = judge_on(problem, z, f, opt)
        if not verdict.solved:
            # The postsolve's arithmetic missed the tolerance on the user's problem
            # (e.g. a free variable of 1e17 recovered from a row with coefficients of
            # 1e-3 and 1e0: its F is exact only to ~0.1): not a solution to report.
            return solve_without_preprocessor(problem, z, f, opt, t0, passes)
        return make_result(problem, Status.SOLVED, "solved by the preprocessor", z, f, opt,
                           t0, passes=passes, verdict=verdict)
    work = pre.reduced
    if basis is not None:  # the warm basis, restricted through the index map
        basis = WarmBasis(basis.basic[pre.stack.cols])
    z0 = work.x0
    f0, J0 = work.evaluator.fj(z0)
    work.evaluator.pin(z0)
    if f0 is None:
        return _finish(problem, pre, Status.DOMAIN_ERROR, "F or J failed at the start "
                       f"point: {work.evaluator.last_error}", z0, opt, t0, passes)
    phi0 = fb_phi(z0, f0, work.lb, work.ub)
    verdict0 = judge_on(work, z0, f0, opt, phi0)
    return _from_start(problem, pre, work, f0, J0, phi0, verdict0, opt, t0, passes, kernels,
                       callback, basis)


def _from_start(problem, pre, work, f0, J0, phi0, verdict0, opt, t0, passes, kernels,
                callback, basis) -> Result:
    """The solve of ``work`` (the user's problem, or the preprocessor's reduced one) from
    its evaluated start point, whose verdict is ``verdict0``."""
    z0 = work.x0
    if verdict0.solved or opt.major_iteration_limit == 0:
        status = Status.SOLVED if verdict0.solved else Status.MAJOR_ITERATION_LIMIT
        msg = ("the start point is a solution" if status is Status.SOLVED
               else "major_iteration_limit = 0: start point evaluated")
        _not_run(passes, _SOLVE_PASSES, "start point already solved"
                 if status is Status.SOLVED else "major_iteration_limit = 0")
        return _finish(problem, pre, status, msg, z0, opt, t0, passes,
                       f_reduced=f0, start_z=problem.x0, basis=basis)
    sc, passes["scaling"] = _scaling_pass(J0, opt)
    if sc is not None and opt.verbosity >= 2:
        logger.info(f"scaling: {passes['scaling'].reason}")
    inner = work
    user_jac = None
    if sc is not None:  # the solver works in the scaled units
        inner = scale_problem(work, sc)
        user_jac = _UserJacobian(work.evaluator, inner.evaluator, sc)
    acceptance = Acceptance(work.lb, work.ub, opt.convergence_tolerance,
                            *((sc.row, sc.col) if sc is not None else ()), user_jac=user_jac,
                            start_f=f0)
    if sc is not None:
        z0, f0, J0 = z0 / sc.col, sc.row * f0, sc.scale_jacobian(J0)
        phi0 = fb_phi(z0, f0, inner.lb, inner.ub)
    # (the passes stop early enough for the Result to be built within the limit)
    deadline = (t0 + opt.time_limit - FINISH_SECONDS_PER_VARIABLE * work.n
                if math.isfinite(opt.time_limit) else None)
    routes = choose_routes(inner.n, opt, kernels=kernels, scaled=sc is not None,
                           nnz=J0.nnz)
    log_major, log_minor = loggers(opt)
    solver = NMSSolver(inner, opt, make_basis=basis_factory(routes.path, opt, deadline),
                       routes=routes, callback=callback, deadline=deadline,
                       log_major=log_major, log_minor=log_minor, acceptance=acceptance,
                       warm_basis=basis,
                       # the solver's start Point is (z0, f0) of `work`, judged above
                       start_verdict=verdict0 if sc is None else None)
    tn = time.perf_counter()
    with blas_threads(work.n):
        out = solver.solve(Point(z0, f0, phi0, fb_psi(phi0), J0))
    passes.update(out.passes)
    passes["nms"] = PassStats(ran=True, iterations=out.counts.nit, time=time.perf_counter() - tn)
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
                  f_reduced=fb, **dataclasses.asdict(out.counts), basis=out.basis,
                  history=out.history, lu=lu_report(solver.newton.basis),
                  routes=routes.as_dict())
    return res


def check_basis(basis, n: int) -> WarmBasis | None:
    """A warm-start basis (a :class:`WarmBasis` or its array) of a problem of n variables,
    or a ShapeError naming both sizes (the basis of another problem is never used
    silently: its indices would pair with other variables)."""
    if basis is None:
        return None
    b = np.asarray(basis.basic if isinstance(basis, WarmBasis) else basis)
    integral = b.dtype.kind in "iub" or (b.dtype.kind == "f"
                                         and bool(np.all(b == np.round(b))))
    if b.ndim != 1 or not integral:
        raise ShapeError(f"the warm-start basis is an array of shape {b.shape} and dtype "
                         f"{b.dtype}: pass the Result.basis of a solve of this problem")
    if b.shape != (n,):
        raise ShapeError(f"the warm-start basis is of a problem of {b.size} variables but "
                         f"this problem has {n}: pass the Result.basis of a solve of this "
                         "problem")
    return WarmBasis(b.astype(np.int8))


def _not_run(passes, names, reason):
    """Record the passes ``names`` as not run, for ``reason``."""
    for k in names:
        passes[k] = PassStats(reason=reason)


def solve_without_preprocessor(problem, z, f, opt, t0, passes, presolve_missed=True) -> Result:
    """The whole problem solved again from z without the preprocessor, in what is left of
    the time limit (the clock does not restart): the preprocessor's point z (F values f)
    missed the tolerance on the user's problem (``presolve_missed``, said in its report),
    or the pass that ran before could not finish.  The Result keeps the earlier passes'
    reports and counts the evaluations of both."""
    left = opt.time_limit - (time.perf_counter() - t0)
    if left <= 0:
        return make_result(problem, Status.TIME_LIMIT, "time limit reached", z, f, opt, t0,
                       start_z=problem.x0, passes=passes)
    if presolve_missed:
        st = passes.get("presolve")
        if st is not None:
            st.reason += ("; its point missed the tolerance on the original problem "
                          "(the postsolve's rounding): solved again without it")
    c = problem.counters  # the evaluations so far (the new solve counts its own)
    general = solve_problem(problem.with_start(z), opt.replace(presolve=False, time_limit=left),
                            top=False)
    general.passes = {**passes, **{k: v for k, v in general.passes.items() if k != "presolve"}}
    general.nfev += c.nfev
    general.njev += c.njev
    general.domain_errors += c.domain_errors
    general.time = time.perf_counter() - t0
    return general


class _UserJacobian:
    """The user's J at a user's point z = C y, for the verdicts of a scaled solve
    (:class:`~compass_sparse.nms.acceptance.Acceptance`): evaluated, counted and rejected
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
        counts["basis"] = postsolve_basis(pre, counts["basis"], z, problem.lb, problem.ub)
    res = make_result(problem, status, message, z, f, opt, t0, start_z=start_z, passes=passes,
                  **counts)
    if pre is not None and status is Status.SOLVED and not res.success:
        # solved on the reduced problem, but the postsolved point misses the tolerance on
        # the user's problem (see the preprocessor-only case in _presolved); the
        # work of both solves is counted
        general = solve_without_preprocessor(problem, res.x, res.fun, opt, t0, passes)
        for k in WORK_COUNTS:
            setattr(general, k, getattr(general, k) + getattr(res, k))
        return general
    return res


# ---------------------------------------------------------------------------- object API
class MCPSolver:
    """Set up once, solve repeatedly (scenario loops), warm-started from the last basis.

    >>> solver = MCPSolver(problem, options={"convergence_tolerance": 1e-8})
    >>> r1 = solver.solve()
    >>> r2 = solver.solve(x0=r1.x)          # e.g. after changing data the closure reads
    """

    def __init__(self, problem: MCP, options=None, callback=None):
        if not isinstance(problem, MCP):
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
        res = solve_problem(prob, self.options, callback=self.callback, basis=basis)
        self.last = res
        return res
