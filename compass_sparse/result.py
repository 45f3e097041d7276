"""The outcome of a solve: :class:`Result`.

:class:`Result` uses scipy.optimize's field names (``x, fun, success, status, message,
nit, nfev, njev``) and adds the residual report, counters and per-pass statistics.  It
recomputes its own residual from F on request (:meth:`Result.check`), so a caller never
has to trust the solver's bookkeeping.  Its two status axes, :class:`~compass_sparse.Status`
and :class:`~compass_sparse.PointStatus`, are defined in :mod:`compass_sparse.status`.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from . import sensitivity as _sensitivity
from .exceptions import ShapeError
from .merit import ResidualReport, natural_residual, residual_report
from .problem.mcp import MCP, as_real, row_label, var_label
from .status import PointStatus, Status

__all__ = ["NESTED_IN_NMS", "Result"]

NESTED_IN_NMS = ("crash", "path", "fallback", "homotopy")
"""Passes that run inside the stabilized Newton method: their times are part of its."""


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
    #: INFEASIBLE by the sign conditions of a linear problem: the Farkas multipliers y, one
    #: per row, checked from the data (:mod:`compass_sparse.feasibility`); x is the point
    #: of the box that misses the conditions least
    certificate: np.ndarray | None = None
    lb: np.ndarray | None = None
    ub: np.ndarray | None = None
    tolerance: float = 1e-6
    #: every major iteration (:class:`Iteration`), when the stabilized Newton method ran;
    #: ``compass_sparse.plot.convergence`` draws it
    history: list | None = None
    #: sparse LU of the basis: backend, ordering, symbolic estimates (est_nnz_lu, est_flops,
    #: est_bytes: the largest met), max_nnz_lu, pivot_lu_entries (the sparse engine's
    #: factor entries held at each of its pivots, summed), times, and the process's peak
    #: RSS in bytes
    lu: dict = field(default_factory=dict)
    #: which implementation of each pass ran (:mod:`compass_sparse.routes`): "kernels"
    #: (compiled or interpreted), "path" (dense engine, dense basis or sparse basis),
    #: "nms", "crash", "homotopy" (compiled or python), chosen once for the solve
    routes: dict = field(default_factory=dict)
    #: the problem's names of the variables and of the rows of F (None: unnamed), which
    #: :meth:`check`, :meth:`solution` and :meth:`at_bound` speak in
    var_names: list | None = None
    eqn_names: list | None = None

    @property
    def worst_rows(self):
        return self.residual.worst if self.residual is not None else []

    def var_label(self, i: int) -> str:
        """The name of variable i (``x[i]`` when the problem has no names)."""
        return var_label(self.var_names, i)

    def row_label(self, i: int) -> str:
        """The name of row i of F, as the problem names it (:meth:`MCP.row_label`)."""
        return row_label(self.var_names, self.eqn_names, i)

    def solution(self, as_series: bool | None = None):
        """The point by name: a pandas Series indexed by the variables' names when pandas
        can be imported (``as_series=None``; True requires it), else a dict name -> value
        in the variables' order."""
        names = [self.var_label(i) for i in range(self.x.size)]
        if as_series is not False:
            try:
                import pandas as pd  # (optional: the Series form when it is there)
            except ImportError:
                if as_series:
                    raise
            else:
                return pd.Series(self.x.copy(), index=names, name="x")
        return dict(zip(names, self.x.tolist()))

    def at_bound(self, tol: float = 0.0) -> dict:
        """The variables at a bound: name -> "lower", "upper" or "fixed" (lb = ub), in the
        variables' order; ``tol``: how far from the bound still counts as at it."""
        lb = np.broadcast_to(np.asarray(self.lb if self.lb is not None else -np.inf, float),
                             self.x.shape)
        ub = np.broadcast_to(np.asarray(self.ub if self.ub is not None else np.inf, float),
                             self.x.shape)
        at_lb = self.x <= lb + tol
        at_ub = self.x >= ub - tol
        out = {}
        for i in np.flatnonzero(at_lb | at_ub).tolist():
            out[self.var_label(i)] = ("fixed" if lb[i] == ub[i] else
                                      "lower" if at_lb[i] else "upper")
        return out

    def check(self, F, lb=None, ub=None, names=None) -> ResidualReport:
        """Recompute the residuals of ``x`` from F (a callable or an MCP) — independent of
        the solver's bookkeeping.  The worst rows are named as the problem names them
        (``names``: other names, a sequence or a callable i -> str)."""
        if isinstance(F, MCP):
            f = F.F_uncounted(self.x)
            lb = F.lb if lb is None else lb
            ub = F.ub if ub is None else ub
            names = names or F.row_label
        else:
            names = names or self.row_label
            f = as_real(F(np.array(self.x, copy=True)), "F(x)")
            if f.size != self.x.size:
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
        return _sensitivity.sensitivity(problem, self.x, dF_dp, **kwargs)

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
        passes = self.passes_line()
        if passes:
            lines.append("passes        " + passes)
        return "\n".join(lines)

    def passes_line(self) -> str:
        """The passes that ran and their seconds, those that run inside the stabilized
        Newton method (the crash, the paths, the fallbacks, the homotopy) within its
        time: ``presolve 0.1 s, nms 27.5 s (crash 10.5 s, path 13.3 s within)``."""
        ran = {k: v for k, v in self.passes.items() if v.ran}
        inner = [k for k in ran if k in NESTED_IN_NMS] if "nms" in ran else []
        out = []
        for k, v in ran.items():
            if k in inner:
                continue
            text = f"{k} {v.time:.3f} s"
            if k == "nms" and inner:
                text += (" (" + ", ".join(f"{j} {ran[j].time:.3f} s" for j in inner)
                         + " within)")
            out.append(text)
        return ", ".join(out)

    def __repr__(self):
        r = self.residual.fb_norm if self.residual is not None else float("nan")
        return (f"Result(status={self.status.name}, success={self.success}, n={self.x.size}, "
                f"residual={r:.3e}, nit={self.nit}, minor={self.minor_iterations})")


def natural_residual_of(F, x, lb, ub) -> float:
    """Natural residual of x for callable F (helper for tests and benchmarks)."""
    return natural_residual(x, np.asarray(F(np.array(x, copy=True)), float), lb, ub)
