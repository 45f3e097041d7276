"""Why a solve stopped, what its point is, and the records of its progress.

Status has two axes (as HiGHS and Pyomo do):

* :class:`Status` — why the solve stopped.  An append-only IntEnum whose codes 1..10
  coincide with PATH's ``MCP_Termination`` codes (1 Solved, 2 NoProgress,
  3 MajorIterationLimit, 4 MinorIterationLimit, 5 TimeLimit, 6 UserInterrupt,
  7 BoundError, 8 DomainError, 9 Infeasible, 10 Error); codes from 100 on are ours and
  map to the PATH code given by :meth:`Status.path_code`.
* :class:`PointStatus` — what the returned point is.

:class:`Iteration` (one major iteration of the log), :class:`IntermediateResult` (what a
callback receives) and :class:`PassStats` (what one pass cost) are the records the passes
fill while they run; :class:`~compass_sparse.result.Result` collects them.  A leaf module:
every pass may import it, and it imports nothing of the package.
"""
from __future__ import annotations

import enum
from dataclasses import dataclass

import numpy as np

__all__ = ["IntermediateResult", "Iteration", "PassStats", "PointStatus", "Status", "WorkCounts"]


class _NamedIntEnum(enum.IntEnum):
    """An IntEnum that prints as its name (``print(res.status)`` gives ``SOLVED``, not
    ``1``) and compares, hashes and converts as its code (``status == 1``,
    ``int(status)``); a number format (``f"{status:d}"``) gives the code."""

    def __str__(self):
        return self.name

    def __format__(self, spec):
        if spec and spec[-1] in "bcdnoxX":
            return format(int(self), spec)
        return format(self.name, spec)


class Status(_NamedIntEnum):
    """Why the solve stopped.  Append-only: codes never change meaning."""

    SOLVED = 1  #: both residuals <= convergence_tolerance (see compass_sparse.nms.acceptance)
    NO_PROGRESS = 2  #: restarts exhausted without reaching the tolerance
    MAJOR_ITERATION_LIMIT = 3  #: major_iteration_limit reached (0: start point evaluated)
    MINOR_ITERATION_LIMIT = 4  #: cumulative pivot limit reached
    TIME_LIMIT = 5  #: time_limit reached
    USER_INTERRUPT = 6  #: KeyboardInterrupt (Ctrl-C)
    BOUND_ERROR = 7  #: inconsistent bounds (normally raised as BoundsError before solving)
    DOMAIN_ERROR = 8  #: F/J undefined (NaN/Inf or exception) and no progress was possible
    #: a linear problem proved to have no solution (a Lemke ray, or a Farkas certificate
    #: that no point of the box meets the sign conditions of its rows)
    INFEASIBLE = 9
    ERROR = 10  #: internal failure (singular basis that could not be repaired, ...)
    MEMORY_LIMIT = 11  #: a factorization was not started: its L + U would exceed the memory
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
    Status.INFEASIBLE: "the linear problem has no solution (ray or Farkas certificate)",
    Status.ERROR: "internal error",
    Status.CALLBACK_STOP: "stopped by the callback",
    Status.FLAT_RESIDUAL: "residual small only because F is flat (not a solution)",
    Status.STATIONARY_POINT: "stationary point of the merit function (not a solution)",
    Status.MEMORY_LIMIT: "memory limit: the next factorization would not fit in memory",
}

_PATH_CODE = {Status.CALLBACK_STOP: 6, Status.FLAT_RESIDUAL: 2, Status.STATIONARY_POINT: 2,
              Status.MEMORY_LIMIT: 10}


class PointStatus(_NamedIntEnum):
    """What the returned point x is."""

    SOLUTION = 1  #: meets the convergence tolerance
    BEST_POINT = 2  #: the best point (lowest merit) found; not a solution
    START_POINT = 3  #: the (projected) start point; nothing better was found
    #: a proof of infeasibility: an LCP's ray (x is the ray's base; see Result.ray), or a
    #: Farkas certificate (Result.certificate; x misses the sign conditions least)
    CERTIFICATE = 4


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
class WorkCounts:
    """The work a solve did, under the names :class:`~compass_sparse.result.Result` reports
    them (one name per count, from the pass that counts to the Result)."""

    nit: int = 0  #: major iterations
    minor_iterations: int = 0  #: pivots over all paths
    crash_iterations: int = 0
    restarts: int = 0
    gradient_steps: int = 0
    lm_steps: int = 0
    factorizations: int = 0
    basis_updates: int = 0
