"""The Result of a point on the user's problem: its residual report, its acceptance verdict
(:mod:`compass_sparse.nms.acceptance`), and the status the solve reports with it -- a
solution reached before a limit fired is reported solved, a flat tail below the tolerance
FLAT_RESIDUAL, and nothing is reported solved that the verdict does not accept.  Shared by
:func:`compass_sparse.solve_mcp` and :func:`compass_sparse.solve_lcp`, with the two other
facts both report: the final basis in the user's index space and the sparse LU's figures.
"""
from __future__ import annotations

import time

import numpy as np

from .exceptions import CompassError
from .merit import fb_phi, residual_report
from .nms.acceptance import judge
from .options import Options
from .path.outcome import WarmBasis
from .path.warm import default_basis
from .problem.mcp import MCP
from .result import Result
from .status import PointStatus, Status

try:
    import resource  # (the peak RSS of Result.lu; a Unix module)
except ImportError:  # pragma: no cover - Windows
    resource = None

__all__ = ["judge_on", "lu_report", "make_result", "postsolve_basis"]

_FLAT_OVERRIDES = (Status.SOLVED, Status.NO_PROGRESS, Status.MAJOR_ITERATION_LIMIT,
                   Status.MINOR_ITERATION_LIMIT, Status.TIME_LIMIT, Status.STATIONARY_POINT)


def judge_on(problem: MCP, z, f, opt: Options, phi=None):
    """The acceptance verdict of z on ``problem`` (J evaluated only when the residuals are
    small; a J that cannot be evaluated there leaves the residual test alone).  ``phi``:
    Phi(z) when known."""
    def jac(y):
        try:
            return problem.evaluator.jac(y)
        except CompassError:
            return None
    return judge(z, f, problem.lb, problem.ub, opt.convergence_tolerance, jac=jac, phi=phi,
                 start_f=problem.evaluator.start_values())


def make_result(problem: MCP, status: Status, message: str, z, f, opt: Options, t0, *,
            start_z=None, verdict=None, phi=None, **counts) -> Result:
    """The Result of the point z with F values f on ``problem`` (the user's).  ``verdict``
    and ``phi``: the acceptance verdict and Phi of exactly this (z, f) on this problem,
    when the solver has just computed them (they are not computed again)."""
    if phi is None:
        phi = fb_phi(z, f, problem.lb, problem.ub)
    rep = residual_report(z, f, problem.lb, problem.ub, names=problem.row_label, phi=phi)
    if verdict is None:
        verdict = judge_on(problem, z, f, opt, phi)
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
        tolerance=opt.convergence_tolerance, var_names=problem.var_names,
        eqn_names=problem.eqn_names, **counts,
    )


def postsolve_basis(pre, basis: WarmBasis | None, z, lb, ub) -> WarmBasis | None:
    """The basis of the reduced problem in the original index space: reduced variable k
    is original variable ``cols[k]``; a removed variable gets the status of its
    postsolved value (at a bound: its slack; fixed: the free slack)."""
    if basis is None or pre is None:
        return basis
    full = default_basis(z, lb, ub)
    full[pre.stack.cols] = basis.basic
    return WarmBasis(full)


def lu_report(bm) -> dict:
    """Sparse-LU figures of a solve for ``Result.lu`` (empty for the dense basis)."""
    st = getattr(bm, "stats", None)
    if st is None or not hasattr(st, "est_bytes"):
        return {}
    return dict(backend=st.backend, ordering=st.ordering,
                orderings_computed=st.orderings_computed, time_ordering=st.time_ordering,
                time_factor=st.time_factor, est_nnz_lu=st.est_nnz_lu, est_flops=st.est_flops,
                est_bytes=st.est_bytes, max_nnz_lu=st.max_nnz_lu,
                pivot_lu_entries=st.pivot_lu_entries, reuses=st.reuses,
                reuse_steps=st.reuse_steps, reuse_fallbacks=st.reuse_fallbacks,
                peak_rss_bytes=(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
                                if resource is not None else 0))
