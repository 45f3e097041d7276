"""The public entry point of linear problems: :func:`solve_lcp`.

A box-constrained LCP, lb <= z <= ub _|_ M z + q, is solved by one pivotal path (thesis
§3.3; after a projected-Newton crash for n >= ``crash_minimum_dimension``), with a Lemke ray
start as the fallback; ray termination from the Lemke start proves infeasibility when M is
copositive-plus (here: positive semidefinite).  An LCP whose variables are all free is the
linear system M z + q = 0 (:mod:`compass_sparse.linear_system`).  A path that fails
otherwise (a ray for a general M, a cycle, a limit) first has the rows' sign conditions
decided by an LP (:mod:`compass_sparse.feasibility`): when no point of the box meets them
the problem is INFEASIBLE, with a Farkas certificate; else the general stabilized Newton
method (:func:`compass_sparse.solve_mcp`'s pipeline) takes over.
"""
from __future__ import annotations

import logging
import math
import time

import numpy as np
import scipy.sparse as sp

from .box import dot_norm
from .crash.driver import crash
from .exceptions import ProblemError, ShapeError
from .feasibility import infeasible_result
from .linear_system import solve_free_lcp
from .merit import fb_phi, normal_map_at
from .nms.log import SectionLog
from .options import Options
from .path.linear_mcp import solve_handing_over
from .path.outcome import LinearCode
from .progress import Progress, pass_line
from .problem.mcp import MCP, as_real
from .report import judge_on, lu_report, make_result
from .result import Result
from .routes import basis_factory, choose_routes, kernel_route
from .solve import blas_threads, check_basis, loggers, solve_without_preprocessor
from .status import PassStats, PointStatus, Status

logger = logging.getLogger("compass_sparse")

__all__ = ["solve_lcp"]


# ---------------------------------------------------------------------------- LCP
def solve_lcp(M, q, lb=0.0, ub=np.inf, x0=None, *, options=None, var_names=None,
              basis=None) -> Result:
    """Solve the (box-constrained) linear complementarity problem

        lb <= z <= ub  _|_  M z + q

    by one pivotal path (after a projected-Newton crash for n >= crash_minimum_dimension),
    with a Lemke ray start as the fallback.  Ray termination from the Lemke start is
    reported as ``Status.INFEASIBLE`` (a proof of infeasibility when M is copositive-plus);
    so is an LCP none of whose box points meets the rows' sign conditions, decided by an
    LP when the path fails, with the Farkas certificate in ``Result.certificate``.  A path
    that fails otherwise hands over to the general stabilized Newton method.
    ``basis``: the ``Result.basis`` of an earlier solve of an LCP of the same size, to
    warm-start the path (a basis of another size raises ShapeError).
    """
    t0 = time.perf_counter()
    opt = Options.coerce(options)
    M, q = _lcp_data(M, q)
    basis = check_basis(basis, q.size)
    with kernel_route(q.size) as kernels:
        routes = choose_routes(q.size, opt, kernels=kernels, nnz=M.nnz)
        res = _solve_lcp(M, q, lb, ub, x0, opt, var_names, routes, t0, basis)
    if not res.routes:
        res.routes = routes.as_dict()
    if opt.verbosity >= 1:  # (a hand-over to the general method logs nothing of its own)
        logger.info(res.summary())
    return res


def _solve_lcp(M, q, lb, ub, x0, opt, var_names, routes, t0, basis) -> Result:
    n = q.size

    def F(z):
        return M @ z + q

    problem = MCP(F, lambda z: M, lb, ub, x0, n=n, var_names=var_names, constant_jac=M)
    passes = {"presolve": PassStats(reason="linear problems go straight to the path")}
    lb, ub = problem.lb, problem.ub
    if np.all(np.isneginf(lb)) and np.all(np.isposinf(ub)):
        # Every variable free: the LCP is the linear system M z + q = 0.
        out = solve_free_lcp(M, q, opt.convergence_tolerance)
        if out is not None:
            passes["path"] = PassStats(reason="all variables free: a linear system")
            zs = out.z if out.z is not None else problem.x0
            return make_result(problem, out.status, out.message, zs, problem.F(zs), opt, t0,
                               passes=passes)
    z = problem.x0
    f = problem.F(z)  # kept from the start check
    at_solution = judge_on(problem, z, f, opt).solved
    if at_solution or opt.major_iteration_limit == 0:
        status = Status.SOLVED if at_solution else Status.MAJOR_ITERATION_LIMIT
        return make_result(problem, status, "start point evaluated", z, f, opt, t0,
                           start_z=problem.x0, passes=passes)
    crash_its = 0
    x = normal_map_at(z, f, lb, ub)[0]
    st = PassStats()
    deadline = t0 + opt.time_limit if math.isfinite(opt.time_limit) else None
    log_major, log_minor = loggers(opt)
    try:
        if opt.crash_method == "pnewton" and n >= opt.crash_minimum_dimension:
            tc = time.perf_counter()
            shown = _crash_progress(opt, problem)
            cr = crash(problem.evaluator, z, lb, ub, opt, f0=f, J0=M,
                       log=SectionLog(log_major).writer("crash"), deadline=deadline,
                       on_point=shown, compiled=routes.crash == "compiled")
            if shown is not None:
                shown(None, None, final=True)  # (the line ends: the path logs below it)
            st = PassStats(ran=True, time=time.perf_counter() - tc, iterations=cr.iterations,
                           factorizations=cr.factorizations, reason=cr.stop_reason)
            crash_its = cr.iterations
            if np.all(np.isfinite(cr.f)):
                z, f, x = cr.z, cr.f, cr.x
        else:
            st.reason = f"n < crash_minimum_dimension ({opt.crash_minimum_dimension})"
        passes["crash"] = st
        return _lcp_path(problem, M, q, z, f, x, opt, t0, passes, st, crash_its, log_minor,
                         routes, basis)
    except KeyboardInterrupt:
        return make_result(problem, Status.USER_INTERRUPT, "interrupted by the user (Ctrl-C)",
                           z, f, opt, t0, start_z=problem.x0, passes=passes,
                           crash_iterations=crash_its)


def _crash_progress(opt, problem):
    """The crash's ``on_point``: the progress line (Options.progress) during the crash,
    with the best residual of its trial points (None when nothing is shown)."""
    progress = Progress(opt.progress)
    if not progress.enabled:
        return None
    best = [np.inf]

    def on_point(z, f, final=False):
        if progress.due(final):
            if z is not None:
                best[0] = min(best[0], dot_norm(fb_phi(z, f, problem.lb, problem.ub)))
            progress.show(pass_line("crash", problem.counters.nfev, best[0],
                                    progress.elapsed), final=final)
    return on_point


def _lcp_path(problem, M, q, z, f, x, opt, t0, passes, st, crash_its, log_minor, routes,
              warm):
    """The pivotal path(s) of :func:`solve_lcp` from the (crashed) point z, x = pi^-1(z)."""
    n = q.size
    lb, ub = problem.lb, problem.ub
    if judge_on(problem, z, f, opt).solved:
        passes["path"] = PassStats(reason="crash solved the problem")
        return make_result(problem, Status.SOLVED, "solved by the crash", z, f, opt, t0,
                           passes=passes, crash_iterations=crash_its,
                           factorizations=st.factorizations, routes=routes.as_dict())
    deadline = t0 + opt.time_limit if math.isfinite(opt.time_limit) else None
    make = basis_factory(routes.path, opt, deadline)
    bm = make(M)
    tp = time.perf_counter()
    # One path solves a linear problem: give it room (a Lemke path may need ~n pivots).
    limit = opt.minor_iteration_limit or max(10 * n, 1000)
    with blas_threads(n):
        res, bm = solve_handing_over(make.hand_over, M, q, lb, ub, bm, opt, x, warm=warm,
                                     ray_start=opt.lemke_start in ("always", "first"),
                                     keep_ray=True, minor_limit=limit, deadline=deadline,
                                     log=log_minor)
    pivots = res.pivots
    passes["path"] = PassStats(ran=True, time=time.perf_counter() - tp, iterations=1,
                               pivots=pivots, factorizations=bm.stats.factorizations)
    counts = {"nit": 1, "minor_iterations": pivots, "crash_iterations": crash_its,
              "factorizations": bm.stats.factorizations + st.factorizations,
              "basis_updates": bm.stats.updates, "passes": passes,
              "routes": routes.as_dict(), "lu": lu_report(bm)}
    if res.code is LinearCode.SOLVED:
        zs = res.z
        fs = problem.F(zs)
        out = make_result(problem, Status.SOLVED, "solution found", zs, fs, opt, t0,
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
        out = make_result(problem, Status.INFEASIBLE,
                          "ray termination from a Lemke start on a positive semidefinite M: "
                          "the problem has no solution", zs, problem.F(zs), opt, t0,
                          ray=res.ray.copy(), **counts)
        out.point_status = PointStatus.CERTIFICATE
        return out
    if not bounded:
        # The path ended in a ray, which proves nothing for a general M, or failed
        # otherwise: an empty set of points that meet the rows' sign conditions proves
        # infeasibility.  One LP, decided before the general method, which would stall on
        # such a problem (2-4 s at n = 60-150 where the LP takes 0.02 s, measured).
        out = infeasible_result(problem, M, q, opt, t0, passes=passes, deadline=deadline,
                                counts=counts)
        if out is not None:
            return out
    # The path cycled, hit a limit or lost accuracy: the stabilized Newton method takes over,
    # within what is left of the time limit (the clock does not restart).
    if opt.time_limit - (time.perf_counter() - t0) <= 0:
        return make_result(problem, Status.TIME_LIMIT, "time limit reached in the pivotal path",
                           z, f, opt, t0, start_z=problem.x0, **counts)
    general = solve_without_preprocessor(problem, z, f, opt, t0, passes, presolve_missed=False)
    general.minor_iterations += pivots
    general.crash_iterations += crash_its
    return general


def _lcp_data(M, q):
    """Validated copies of the LCP data (the user's M is never modified): q real of shape
    (n,) (a column (n, 1) is accepted), M real n x n, both finite, named in errors."""
    q = as_real(q, "q")
    if q.ndim > 1 and q.size == max(q.shape):
        q = q.reshape(-1)
    if q.ndim != 1:
        raise ShapeError(f"q has shape {q.shape}, expected (n,) or (n, 1)")
    n = q.size
    if sp.issparse(M):
        if M.dtype.kind == "c":  # (the dtype: a dok matrix has no data array)
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
            # (lazy: scipy.sparse.linalg adds ~0.15 s to the package's import)
            from scipy.sparse.linalg import eigsh

            lam = float(eigsh(S, k=1, which="SA", return_eigenvectors=False, tol=1e-8,
                              maxiter=5000)[0])
    except Exception:
        return False
    return lam >= -tol * scale
