"""Status and result types.

Status has two axes (as HiGHS and Pyomo do):

* :class:`Status` — why the solve stopped.  An append-only IntEnum whose codes 1..10
  coincide with PATH's ``MCP_Termination`` codes (1 Solved, 2 NoProgress,
  3 MajorIterationLimit, 4 MinorIterationLimit, 5 TimeLimit, 6 UserInterrupt,
  7 BoundError, 8 DomainError, 9 Infeasible, 10 Error); codes from 100 on are ours and
  map to the PATH code given by :meth:`Status.path_code`.
* :class:`PointStatus` — what the returned point is.

:class:`Result` uses scipy.optimize's field names (``x, fun, success, status, message,
nit, nfev, njev``) and adds the residual report, counters and per-pass statistics.  It
recomputes its own residual from F on request (:meth:`Result.check`), so a caller never
has to trust the solver's bookkeeping.
"""
from __future__ import annotations

import enum
from dataclasses import dataclass, field

import numpy as np

from .merit import ResidualReport, natural_residual, residual_report

__all__ = ["Status", "PointStatus", "PassStats", "Result", "IntermediateResult", "Iteration"]


class Status(enum.IntEnum):
    """Why the solve stopped.  Append-only: codes never change meaning."""

    SOLVED = 1  #: both residuals <= convergence_tolerance (see compass_sparse.acceptance)
    NO_PROGRESS = 2  #: restarts exhausted without reaching the tolerance
    MAJOR_ITERATION_LIMIT = 3  #: major_iteration_limit reached (0: start point evaluated)
    MINOR_ITERATION_LIMIT = 4  #: cumulative pivot limit reached
    TIME_LIMIT = 5  #: time_limit reached
    USER_INTERRUPT = 6  #: KeyboardInterrupt (Ctrl-C)
    BOUND_ERROR = 7  #: inconsistent bounds (normally raised as BoundsError before solving)
    DOMAIN_ERROR = 8  #: F/J undefined (NaN/Inf or exception) and no progress was possible
    INFEASIBLE = 9  #: a linear problem proved to have no solution (ray termination)
    ERROR = 10  #: internal failure (singular basis that could not be repaired, ...)
    CALLBACK_STOP = 100  #: the user's callback asked to stop (PATH code 6)
    #: the residual is below the tolerance only because F is flat there (PATH code 2)
    FLAT_RESIDUAL = 101
    #: the iterates converged to a stationary point of the merit function that is not a
    #: solution; the message names the rows that keep the merit up (PATH code 2)
    STATIONARY_POINT = 102

    def path_code(self) -> int:
        """The PATH ``MCP_Termination`` code with the same meaning."""
        return _PATH_CODE.get(self, int(self))

    @property
    def description(self) -> str:
        return _STATUS_TEXT[self]


_STATUS_TEXT = {
    Status.SOLVED: "solution found",
    Status.NO_PROGRESS: "no progress: restarts exhausted without reaching the tolerance",
    Status.MAJOR_ITERATION_LIMIT: "major iteration limit reached",
    Status.MINOR_ITERATION_LIMIT: "cumulative pivot (minor iteration) limit reached",
    Status.TIME_LIMIT: "time limit reached",
    Status.USER_INTERRUPT: "interrupted by the user",
    Status.BOUND_ERROR: "inconsistent bounds",
    Status.DOMAIN_ERROR: "F or J could not be evaluated near the iterates",
    Status.INFEASIBLE: "the linear problem has no solution (ray termination)",
    Status.ERROR: "internal error",
    Status.CALLBACK_STOP: "stopped by the callback",
    Status.FLAT_RESIDUAL: "residual small only because F is flat (not a solution)",
    Status.STATIONARY_POINT: "stationary point of the merit function (not a solution)",
}

_PATH_CODE = {Status.CALLBACK_STOP: 6, Status.FLAT_RESIDUAL: 2, Status.STATIONARY_POINT: 2}


class PointStatus(enum.IntEnum):
    """What the returned point x is."""

    SOLUTION = 1  #: meets the convergence tolerance
    BEST_POINT = 2  #: the best point (lowest merit) found; not a solution
    START_POINT = 3  #: the (projected) start point; nothing better was found
    CERTIFICATE = 4  #: an LCP's ray (x is the ray's base; see Result.ray)


@dataclass
class IntermediateResult:
    """What a callback receives after each major iteration (return True or raise
    StopIteration to stop the solve)."""

    x: np.ndarray
    fun: np.ndarray
    residual: float
    nit: int
    minor_iterations: int


@dataclass(frozen=True)
class Iteration:
    """One major iteration as the log prints it (``Result.history`` keeps them all).

    ``residual`` is ||Phi_FB||_2 of the iterate accepted in this major iteration, measured
    on the problem the Newton method works on (after the preprocessor); ``step`` is the
    log's two-letter type (the path's code and the step: e.g. ``SD``, ``SM``, ``RW``).
    Iteration 0 is the start point (after the preprocessor, before the crash); a last
    record with an empty type is the returned point when the solve stopped inside a major
    iteration (a solution found during a search).  ``pivots`` are this iteration's,
    ``prox`` the proximal perturbation for the next path, and ``time`` counts seconds from
    the start of the stabilized Newton method (after the preprocessor).
    """

    nit: int
    residual: float
    step: str
    pivots: int
    prox: float
    time: float


@dataclass
class PassStats:
    """What one pass cost.  ``ran`` is False when the pass decided it was not needed."""

    ran: bool = False
    reason: str = ""
    time: float = 0.0
    iterations: int = 0
    nfev: int = 0
    njev: int = 0
    pivots: int = 0
    factorizations: int = 0


@dataclass
class Result:
    """The outcome of a solve.  Always holds a point: the solution or the best one found."""

    x: np.ndarray
    fun: np.ndarray
    success: bool
    status: Status
    point_status: PointStatus
    message: str
    nit: int = 0  #: major iterations
    nfev: int = 0
    njev: int = 0
    residual: ResidualReport | None = None
    minor_iterations: int = 0  #: pivots over all paths
    crash_iterations: int = 0
    restarts: int = 0
    gradient_steps: int = 0
    lm_steps: int = 0
    factorizations: int = 0
    basis_updates: int = 0
    domain_errors: int = 0  #: rejected trial points where F/J failed
    time: float = 0.0
    passes: dict = field(default_factory=dict)
    basis: object | None = None  #: final basis (user's index space), for warm starts
    ray: np.ndarray | None = None  #: INFEASIBLE by a Lemke ray: its direction; x its base
    lb: np.ndarray | None = None
    ub: np.ndarray | None = None
    tolerance: float = 1e-6
    #: every major iteration (:class:`Iteration`), when the stabilized Newton method ran;
    #: ``compass_sparse.plot.convergence`` draws it
    history: list | None = None

    @property
    def worst_rows(self):
        return self.residual.worst if self.residual is not None else []

    def check(self, F, lb=None, ub=None, names=None) -> ResidualReport:
        """Recompute the residuals of ``x`` from F (a callable or an MCP) — independent of
        the solver's bookkeeping."""
        from .problem import MCP

        if isinstance(F, MCP):
            f = F.F_uncounted(self.x)
            lb = F.lb if lb is None else lb
            ub = F.ub if ub is None else ub
            names = names or F.row_label
        else:
            from .problem import as_real

            f = as_real(F(np.array(self.x, copy=True)), "F(x)")
            if f.size != self.x.size:
                from .exceptions import ShapeError

                raise ShapeError(f"F(x) returned {f.size} values at the result's point, "
                                 f"which has {self.x.size} variables")
            f = f.reshape(self.x.shape)
        lb = self.lb if lb is None else np.broadcast_to(np.asarray(lb, float), self.x.shape)
        ub = self.ub if ub is None else np.broadcast_to(np.asarray(ub, float), self.x.shape)
        return residual_report(self.x, f, lb, ub, names=names)

    def natural_residual(self, F, lb=None, ub=None) -> float:
        rep = self.check(F, lb, ub)
        return rep.natural

    def sensitivity(self, problem, dF_dp, **kwargs):
        """dx/dp at this solution of ``problem`` (an MCP) for the parameter derivative
        ``dF_dp`` (n,) or (n, k): see :func:`compass_sparse.sensitivity.sensitivity`."""
        from .sensitivity import sensitivity

        return sensitivity(problem, self.x, dF_dp, **kwargs)

    def summary(self) -> str:
        lines = [
            f"status        {self.status.name} ({self.status.path_code()}): {self.message}",
            f"point         {self.point_status.name}",
        ]
        if self.residual is not None:
            r = self.residual
            lines += [
                f"residual      ||Phi||_2 {r.fb_norm:.4e}   ||Phi||_inf {r.fb_inf:.4e}   "
                f"natural {r.natural:.4e}",
            ]
            if r.worst:
                lines.append(f"worst row     {r.worst[0][0]} (|Phi| {r.worst[0][1]:.3e})")
        lines += [
            f"major its     {self.nit}   minor its {self.minor_iterations}   crash its "
            f"{self.crash_iterations}   restarts {self.restarts}",
            f"evaluations   F {self.nfev}   J {self.njev}   domain errors {self.domain_errors}",
            f"basis         factorizations {self.factorizations}   updates {self.basis_updates}",
            f"time          {self.time:.4f} s",
        ]
        ran = [f"{k} {v.time:.3f}s" for k, v in self.passes.items() if v.ran]
        if ran:
            lines.append("passes        " + ", ".join(ran))
        return "\n".join(lines)

    def __repr__(self):
        r = self.residual.fb_norm if self.residual is not None else float("nan")
        return (f"Result(status={self.status.name}, success={self.success}, n={self.x.size}, "
                f"residual={r:.3e}, nit={self.nit}, minor={self.minor_iterations})")


def natural_residual_of(F, x, lb, ub) -> float:
    """Natural residual of x for callable F (helper for tests and benchmarks)."""
    return natural_residual(x, np.asarray(F(np.array(x, copy=True)), float), lb, ub)
