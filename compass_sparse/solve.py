"""Public entry points: :func:`solve_mcp`, :func:`solve_lcp` and :class:`MCPSolver`.

Thin functions that validate, normalize and dispatch to the passes:

    problem -> presolve -> crash -> NMS (major iterations on the pivotal path) -> postsolve

Every pass decides cheaply whether it applies and the Result says which ran and what each
cost (``Result.passes``).  Failures are statuses, never exceptions; bad input raises an
exception of :mod:`compass_sparse.exceptions` before any work is done.
"""
from __future__ import annotations

import logging
import sys
import time

import numpy as np
import scipy.sparse as sp

from .crash import crash, normal_map_at
from .merit import fb_phi, fb_psi, residual_report
from .nms import NMSSolver
from .options import Options
from .path import LinearCode, PivotalPath, WarmBasis
from .problem import MCP
from .result import PassStats, PointStatus, Result, Status
from ._evaluate import GuardedEvaluator

logger = logging.getLogger("compass_sparse")

__all__ = ["solve_mcp", "solve_lcp", "MCPSolver"]

DENSE_BASIS_MAX_N = 300
"""Below this dimension the dense reference basis is used (0: always the sparse manager)."""


def _manager_factory(opt: Options):
    def make(M):
        n = M.shape[0]
        if n <= DENSE_BASIS_MAX_N:
            from ._dense_basis import DenseBasis

            return DenseBasis(M)
        from .basis import BasisManager, BasisOptions

        return BasisManager(M, options=BasisOptions(update_limit=opt.factorization_update_limit))

    return make


def _blas_threads(n: int):
    """Single-threaded BLAS for small problems: their dense kernels (the dense basis below
    DENSE_BASIS_MAX_N) are tiny, and a multithreaded BLAS on a loaded machine made a
    200 x 200 inverse 100 times slower (0.2 s against 2 ms, measured)."""
    import contextlib

    if n > DENSE_BASIS_MAX_N:
        return contextlib.nullcontext()
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:  # pragma: no cover - a declared dependency
        return contextlib.nullcontext()
    return threadpool_limits(limits=1, user_api="blas")


def _setup_logging(opt: Options):
    if opt.verbosity > 0 and not logger.handlers and not logging.getLogger().handlers:
        h = logging.StreamHandler(sys.stdout)
        h.setFormatter(logging.Formatter("%(message)s"))
        logger.addHandler(h)
        logger.propagate = False
    if opt.verbosity > 0:
        logger.setLevel(logging.INFO if opt.verbosity >= 2 else logging.WARNING)
    return (lambda s: logger.info(s)) if opt.verbosity >= 2 else None


def _as_problem(F, jac, lb, ub, x0, kwargs) -> MCP:
    if isinstance(F, MCP):
        if x0 is not None:
            return F.with_start(x0)
        return F
    return MCP(F, jac, lb, ub, x0, **kwargs)


def _result(problem: MCP, status: Status, message: str, z, f, opt: Options, t0, *,
            start_z=None, **counts) -> Result:
    rep = residual_report(z, f, problem.lb, problem.ub, names=problem.row_label)
    solved = rep.fb_norm <= opt.convergence_tolerance
    if solved and status not in (Status.SOLVED,):
        # A limit fired after the solution was reached: report the solution.
        status, message = Status.SOLVED, "solution found"
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
        lb=problem.lb, ub=problem.ub, tolerance=opt.convergence_tolerance, **counts,
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
    problem = _as_problem(F, jac, lb, ub, x0, problem_kwargs)
    return _solve_problem(problem, opt, callback=callback, basis=basis)


def _presolve_pass(problem, opt):
    """Run the preprocessor when the problem declares linear structure."""
    st = PassStats()
    if not opt.presolve:
        st.reason = "presolve off"
        return None, st
    # Every reduction but fixing l = u needs a row whose entries are all declared
    # constant; without one the pass would only cost time (17 s at n = 1e6, measured).
    has_fixed = bool(np.any(problem.lb == problem.ub))
    P = problem.pattern
    mask = problem.constant_mask
    nonconst_rows = P.indices if mask is None else P.indices[~mask]
    linear_rows = int(np.count_nonzero(np.bincount(nonconst_rows, minlength=problem.n) == 0))
    if linear_rows == 0 and not has_fixed:
        st.reason = "no linear rows (all entries declared constant) and no fixed variables"
        return None, st
    try:
        from .presolve import presolve as run_presolve
    except ImportError:  # pragma: no cover - the package ships it
        st.reason = "preprocessor unavailable"
        return None, st
    t0 = time.perf_counter()
    pre = run_presolve(problem)
    st.ran = True
    st.time = time.perf_counter() - t0
    return pre, st


def _solve_problem(problem: MCP, opt: Options, *, callback=None, basis=None) -> Result:
    t0 = time.perf_counter()
    log_major = _setup_logging(opt)
    deadline = t0 + opt.time_limit if np.isfinite(opt.time_limit) else None
    passes = {}
    pre, st = _presolve_pass(problem, opt)
    passes["presolve"] = st
    work = problem
    if pre is not None:
        st.reason = pre.summary_line()
        if getattr(pre, "infeasible", None):
            f = problem.F(problem.x0)
            return _result(problem, Status.INFEASIBLE, f"preprocessor: {pre.infeasible}",
                           problem.x0, f, opt, t0, passes=passes)
        if pre.reduced is None:
            z = pre.postsolve(np.zeros(0))
            f = problem.F(z)
            return _result(problem, Status.SOLVED, "solved by the preprocessor", z, f, opt,
                           t0, passes=passes)
        if pre.reduced is problem:
            pre = None  # nothing removed: no postsolve needed
        else:
            work = pre.reduced
    evalr = GuardedEvaluator(work)
    z0 = work.x0
    f0 = evalr.f(z0)
    if f0 is None:
        return _finish(problem, pre, Status.DOMAIN_ERROR, f"F failed at the start point: "
                       f"{evalr.last_error}", work.x0, opt, t0, passes, evalr)
    phi0 = fb_phi(z0, f0, work.lb, work.ub)
    if np.sqrt(2 * fb_psi(phi0)) <= opt.convergence_tolerance or opt.major_iteration_limit == 0:
        status = (Status.SOLVED if np.sqrt(2 * fb_psi(phi0)) <= opt.convergence_tolerance
                  else Status.MAJOR_ITERATION_LIMIT)
        msg = ("the start point is a solution" if status is Status.SOLVED
               else "major_iteration_limit = 0: start point evaluated")
        for k in ("crash", "path", "fallback", "homotopy"):
            passes[k] = PassStats(reason="start point already solved"
                                  if status is Status.SOLVED else "major_iteration_limit = 0")
        return _finish(problem, pre, status, msg, z0, opt, t0, passes, evalr,
                       start_z=problem.x0, basis=basis)
    solver = NMSSolver(work, evalr, opt, manager_factory=_manager_factory(opt),
                       callback=callback, deadline=deadline, log_major=log_major)
    solver.basis = basis
    if log_major is not None:
        log_major(f"{'major':>5} {'minor':>7} {'func':>6} {'grad':>5} {'residual':>12} "
                  f"type {'prox':>9} {'inorm':>10} (label)")
    with _blas_threads(work.n):
        out = solver.solve(z0)
    passes.update(out.passes)
    passes["nms"] = PassStats(ran=True, iterations=out.nit)
    passes.setdefault("homotopy", PassStats(
        reason="homotopy off" if opt.homotopy == "off" else "NMS did not stall"))
    res = _finish(problem, pre, out.status, out.message, out.best.z, opt, t0, passes, evalr,
                  f_reduced=out.best.f, nit=out.nit, minor_iterations=out.minor,
                  crash_iterations=out.crash_iterations, restarts=out.restarts,
                  gradient_steps=out.gradient_steps, lm_steps=out.lm_steps,
                  factorizations=out.factorizations, basis_updates=out.updates,
                  basis=out.basis)
    if opt.verbosity >= 1:
        logger.warning(res.summary())
    return res


def _finish(problem, pre, status, message, z_red, opt, t0, passes, evalr, *, f_reduced=None,
            start_z=None, **counts):
    """Postsolve and build the Result on the ORIGINAL problem."""
    if pre is not None:
        z = pre.postsolve(np.asarray(z_red, dtype=float))
        f = problem.F(z)
    else:
        z = z_red
        f = f_reduced if f_reduced is not None else problem.F(z)
    res = _result(problem, status, message, z, f, opt, t0, start_z=start_z,
                  passes=passes, domain_errors=evalr.domain_errors, **counts)
    work = evalr.problem
    if work is not problem:  # the reduced problem counts its own evaluations
        res.nfev += work.counters.nfev
        res.njev += work.counters.njev
    return res


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
    M = sp.csc_matrix(M, dtype=float)
    q = np.asarray(q, dtype=float)
    n = q.size
    if M.shape != (n, n):
        from .exceptions import ShapeError

        raise ShapeError(f"M has shape {M.shape} but q has {n} entries; M must be {n} x {n}")
    M.sort_indices()

    def F(z):
        return M @ z + q

    problem = MCP(F, lambda z: M, lb, ub, x0, n=n, var_names=var_names, constant_jac=M)
    log_major = _setup_logging(opt)
    evalr = GuardedEvaluator(problem)
    passes = {"presolve": PassStats(reason="linear problems go straight to the path")}
    lb, ub = problem.lb, problem.ub
    z = problem.x0
    f = problem.F(z)
    if np.linalg.norm(fb_phi(z, f, lb, ub)) <= opt.convergence_tolerance \
            or opt.major_iteration_limit == 0:
        status = (Status.SOLVED if np.linalg.norm(fb_phi(z, f, lb, ub))
                  <= opt.convergence_tolerance else Status.MAJOR_ITERATION_LIMIT)
        return _result(problem, status, "start point evaluated", z, f, opt, t0,
                       start_z=problem.x0, passes=passes)
    crash_its = 0
    x = normal_map_at(z, f, lb, ub)[0]
    st = PassStats()
    if opt.crash_method == "pnewton" and n >= opt.crash_minimum_dimension:
        tc = time.perf_counter()
        cr = crash(evalr, z, lb, ub, opt, f0=f, J0=M, log=log_major)
        st = PassStats(ran=True, time=time.perf_counter() - tc, iterations=cr.iterations,
                       factorizations=cr.factorizations, reason=cr.stop_reason)
        crash_its = cr.iterations
        if np.all(np.isfinite(cr.f)):
            z, f, x = cr.z, cr.f, cr.x
    else:
        st.reason = f"n < crash_minimum_dimension ({opt.crash_minimum_dimension})"
    passes["crash"] = st
    if np.linalg.norm(fb_phi(z, f, lb, ub)) <= opt.convergence_tolerance:
        passes["path"] = PassStats(reason="crash solved the problem")
        return _result(problem, Status.SOLVED, "solved by the crash", z, f, opt, t0,
                       passes=passes, crash_iterations=crash_its,
                       factorizations=st.factorizations)
    bm = _manager_factory(opt)(M)
    tp = time.perf_counter()
    # One path solves a linear problem: give it room (a Lemke path may need ~n pivots).
    limit = opt.minor_iteration_limit or max(10 * n, 1000)
    deadline = t0 + opt.time_limit if np.isfinite(opt.time_limit) else None
    path = PivotalPath(M, q, lb, ub, bm, opt, minor_limit=limit, deadline=deadline)
    start_ray = opt.lemke_start in ("always", "first")
    with _blas_threads(n):
        res = path.run(x, ray_start=start_ray)
        pivots = res.pivots
        if res.code is not LinearCode.SOLVED and not start_ray:
            res2 = PivotalPath(M, q, lb, ub, bm, opt, minor_limit=limit,
                               deadline=deadline).run(x, ray_start=True)
            pivots += res2.pivots
            if res2.code is LinearCode.SOLVED or res2.code is LinearCode.RAY:
                res = res2
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
        zs = res.z
        fs = problem.F(zs)
        if np.linalg.norm(fb_phi(z, f, lb, ub)) < np.linalg.norm(fb_phi(zs, fs, lb, ub)):
            zs, fs = z, f
        return _result(problem, Status.INFEASIBLE,
                       "ray termination from a Lemke start on a positive semidefinite M: "
                       "the problem has no solution", zs, fs, opt, t0, **counts)
    # The path cycled, hit a limit or lost accuracy: the stabilized Newton method takes over.
    general = _solve_problem(problem.with_start(z), opt.replace(presolve=False))
    general.passes = {**passes, **{k: v for k, v in general.passes.items() if k != "presolve"}}
    general.minor_iterations += pivots
    general.crash_iterations += crash_its
    general.time = time.perf_counter() - t0
    return general


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
            raise TypeError("MCPSolver takes an MCP; build one with compass_sparse.MCP(...)")
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
        res = _solve_problem(prob, self.options, callback=self.callback, basis=basis)
        self.last = res
        return res
