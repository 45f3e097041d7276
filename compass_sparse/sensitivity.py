"""Sensitivity of an MCP solution to parameters, by the implicit function theorem.

Let z(p) solve  l <= z <= u  _|_  F(z, p)  and write J = dF/dz, G = dF/dp at (z, p).
Split the indices at the solution (tolerance ``active_tol``, below):

* inactive   I: l_i < z_i < u_i, so F_i = 0;
* strongly active A: z_i at a bound with F_i strictly of the complementary sign
  (z_i = l_i, F_i > 0 or z_i = u_i, F_i < 0), or l_i = u_i (fixed);
* degenerate (weakly active) D: z_i at a bound and F_i = 0.

Without degenerate indices the active set does not change for small parameter moves, F_I = 0
holds along z(p) and z_A stays at its bound, so (implicit function theorem)

    J_II dz_I/dp = -G_I,      dz_A/dp = 0,

one sparse LU of J_II for every parameter.  It exists when J_II is nonsingular (then z(p) is
locally unique and differentiable).

At a degenerate point z(p) is in general only directionally differentiable.  Under strong
regularity (Robinson 1980) the directional derivative d = z'(p; e) is the unique solution of
the linearized MCP on the critical cone

    d_A = 0,   J_I. d + G_I e = 0,
    0 <= d_i  _|_  (J d + G e)_i >= 0   for i in D at a lower bound (<= 0, <= 0 at an upper one),

which is a small box-constrained LCP that we solve by one pivotal path (the path of
:func:`compass_sparse.solve_lcp`, :mod:`compass_sparse.path`).
:func:`sensitivity` returns the one-sided derivatives d+ = z'(p; +e) and d- = -z'(p; -e) for
each parameter and says whether they agree (then z is differentiable in that parameter even
though the point is degenerate).  If the linearized MCP has no solution (no strong
regularity) the derivative is reported as NaN with the reason; it is never made up.

Tolerance: z_i is at a bound when its distance to it is at most
``active_tol * max(1, |bound|)``, and F_i counts as zero when
``|F_i| <= active_tol * max(1, max_j |J_ij|)``.  An index that meets both is degenerate.
Classifying a nearly degenerate index as degenerate is safe (the linearized MCP decides its
side); the opposite error gives a wrong one-sided derivative, so the default (1e-7) is loose
compared with the residuals of converged solves (1e-10 and below on smooth problems).  The
sets are read from the point and F, not from ``Result.basis``: at a degenerate index the
final basis only tells on which linear piece the path stopped, and after the preprocessor
the basis is indexed by the reduced problem.

:func:`tangent_predictor` is the same step used as a predictor along a scenario path: from a
solution x of the problem at p, with F(x, p') known, the first-order prediction of z(p') on
x's active set is x + d with J_II d_I = -F_I(x, p') (to first order F(x, p') = G (p' - p)
on I), projected onto the bounds.
"""
from __future__ import annotations

import logging
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from .exceptions import CompassError, ProblemError, ShapeError
from .options import Options
from .path.linear_mcp import solve_handing_over
from .path.outcome import LinearCode
from .problem.mcp import MCP
from .routes import basis_factory, path_route

logger = logging.getLogger("compass_sparse")

__all__ = [
    "ACTIVE_TOL",
    "Sensitivity",
    "SingularSensitivityError",
    "classify",
    "sensitivity",
    "tangent_predictor",
]

ACTIVE_TOL = 1e-7
"""Default tolerance of the active-set identification (see the module docstring)."""

LINEAR_TOLERANCE = 1e-13
"""Tolerance of the linearized MCP of a degenerate point (its right-hand side scaled to
unit size)."""


class SingularSensitivityError(CompassError):
    """J restricted to the inactive indices is singular at the point: the solution is not
    locally unique there, so it has no derivative with respect to the parameters."""


@dataclass
class Sensitivity:
    """Derivatives of a solution with respect to k parameters.

    ``dx`` (n, k) is the derivative where it exists; at a degenerate point it is the right
    derivative d+ and ``dx_minus`` the left one d-.  ``differentiable[j]`` says whether
    d+ = d- for parameter j (always True without degenerate indices)."""

    dx: np.ndarray
    dx_minus: np.ndarray
    inactive: np.ndarray  #: indices with F_i = 0 held along the path (z_i moves)
    active: np.ndarray  #: indices held at their bound
    degenerate: np.ndarray  #: indices at a bound with F_i = 0
    differentiable: np.ndarray  #: (k,) bool
    messages: list = field(default_factory=list)

    @property
    def is_degenerate(self) -> bool:
        return self.degenerate.size > 0


def _at_bounds(x, lb, ub, tol):
    """Masks of x within tol * max(1, |bound|) of its (finite) lower and upper bounds."""
    with np.errstate(invalid="ignore"):
        at_l = np.isfinite(lb) & (x - lb <= tol * np.maximum(1.0, np.abs(lb)))
        at_u = np.isfinite(ub) & (ub - x <= tol * np.maximum(1.0, np.abs(ub)))
    return at_l, at_u


def classify(x, f, lb, ub, J, active_tol: float = ACTIVE_TOL):
    """(inactive, active, degenerate, side) index sets at a point; ``side`` is +1 for a
    degenerate index at its lower bound and -1 at its upper bound (see the module docstring
    for the tolerances)."""
    x, f = np.asarray(x, float), np.asarray(f, float)
    rowscale = np.maximum(1.0, abs(sp.csr_matrix(J)).max(axis=1).toarray().ravel())
    ftol = active_tol * rowscale
    at_l, at_u = _at_bounds(x, lb, ub, active_tol)
    fixed = lb == ub
    zero_f = np.abs(f) <= ftol
    deg_l = at_l & zero_f & ~fixed
    deg_u = at_u & zero_f & ~fixed & ~at_l
    degenerate = deg_l | deg_u
    at_bound = at_l | at_u | fixed
    active = at_bound & ~degenerate
    inactive = ~at_bound
    side = np.where(deg_l, 1, np.where(deg_u, -1, 0))
    return (np.flatnonzero(inactive), np.flatnonzero(active), np.flatnonzero(degenerate),
            side)


def _as_columns(dF_dp, n: int) -> np.ndarray:
    try:
        G = dF_dp.toarray() if sp.issparse(dF_dp) else np.asarray(dF_dp, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ProblemError(f"dF_dp must be an array of shape ({n},) or ({n}, k) of "
                           f"numbers: {exc}") from None
    if dF_dp is None:
        raise ProblemError(f"dF_dp is None: give the derivative of F with respect to the "
                           f"parameters, of shape ({n},) or ({n}, k)")
    if G.ndim == 1:
        G = G[:, None]
    if G.ndim != 2 or G.shape[0] != n:
        raise ShapeError(f"dF_dp has shape {np.shape(dF_dp)}, expected ({n},) or ({n}, k)")
    return G


def _solve_inactive(J, idx, rhs):
    """Solve J[idx, idx] d = rhs (rows idx) by sparse LU; SingularSensitivityError if
    singular."""
    if idx.size == 0:
        return np.zeros((0,) + rhs.shape[1:])
    A = sp.csc_matrix(J)[idx][:, idx].tocsc()
    try:
        # (lazy: scipy.sparse.linalg adds ~0.15 s to the package's import)
        from scipy.sparse.linalg import splu

        lu = splu(A)
    except RuntimeError as exc:  # "Factor is exactly singular"
        raise SingularSensitivityError(
            f"the Jacobian on the {idx.size} inactive indices is singular ({exc}); "
            "the solution is not locally unique, so it has no derivative") from None
    d = lu.solve(np.asarray(rhs, float))
    if not np.all(np.isfinite(d)):
        raise SingularSensitivityError("the Jacobian on the inactive indices is numerically "
                                       "singular: the derivative is not finite")
    return d


def _problem_parts(problem, x):
    if not isinstance(problem, MCP):
        raise ProblemError("a sensitivity needs the problem the point solves, as a "
                           f"compass_sparse.MCP; got {type(problem).__name__}")
    x = np.asarray(x, dtype=float)
    if x.shape != (problem.n,):
        raise ShapeError(f"the point has shape {x.shape} but the problem has {problem.n} "
                         "variables: pass the MCP this point solves")
    f, J = _values(problem).FJ(x)
    return x, f, J


def _values(problem):
    """An evaluator of the problem's F and J that leaves the problem's own counters and
    memo untouched (a sensitivity is a look at a solved problem, not part of a solve)."""
    return problem.evaluator.fresh()


def sensitivity(problem, x, dF_dp, *, active_tol: float = ACTIVE_TOL) -> Sensitivity:
    """Derivative of the solution ``x`` of ``problem`` with respect to parameters.

    ``dF_dp`` is the (n,) or (n, k) derivative of F with respect to the k parameters at x
    (dense or sparse).  See the module docstring for the method and its degenerate case.
    Raises :class:`SingularSensitivityError` when J on the inactive set is singular.
    """
    x, f, J = _problem_parts(problem, x)
    n = x.size
    G = _as_columns(dF_dp, n)
    k = G.shape[1]
    inactive, active, degenerate, side = classify(x, f, problem.lb, problem.ub, J, active_tol)
    dx = np.zeros((n, k))
    messages = []
    if degenerate.size == 0:
        dx[inactive] = -_solve_inactive(J, inactive, G[inactive])
        return Sensitivity(dx, dx.copy(), inactive, active, degenerate,
                           np.ones(k, dtype=bool), messages)
    dminus = np.zeros((n, k))
    diff = np.zeros(k, dtype=bool)
    for j in range(k):
        dplus_j, m1 = _directional(J, G[:, j], inactive, degenerate, side, +1.0)
        dminus_j, m2 = _directional(J, G[:, j], inactive, degenerate, side, -1.0)
        dx[:, j], dminus[:, j] = dplus_j, -dminus_j
        messages += [m for m in (m1, m2) if m]
        scale = max(1.0, float(np.max(np.abs(dx[:, j]))) if np.all(np.isfinite(dx[:, j]))
                    else 1.0)
        diff[j] = bool(np.all(np.abs(dx[:, j] - dminus[:, j]) <= 1e-8 * scale))
    logger.info("sensitivity at a degenerate point: %d degenerate indices; one-sided "
                "derivatives %s", degenerate.size,
                "agree" if diff.all() else f"differ for {int((~diff).sum())} parameter(s)")
    return Sensitivity(dx, dminus, inactive, active, degenerate, diff, messages)


def _directional(J, g, inactive, degenerate, side, sign):
    """z'(p; sign * e): the linearized MCP of the module docstring on I u D, by one pivotal
    path (the right-hand side scaled to unit size so that the path's tolerances are
    relative)."""
    n = g.size
    free = np.concatenate([inactive, degenerate])
    order = np.argsort(free)
    free = free[order]
    lo = np.full(free.size, -np.inf)
    hi = np.full(free.size, np.inf)
    s = side[free]
    lo[s > 0] = 0.0
    hi[s < 0] = 0.0
    q = sign * g[free]
    scale = float(np.max(np.abs(q))) if q.size else 0.0
    d = np.zeros(n)
    if scale == 0.0:
        return d, ""
    M = sp.csc_matrix(J)[free][:, free]
    res = _linear_mcp(M, q / scale, lo, hi)
    if res.code is not LinearCode.SOLVED:
        d[:] = np.nan
        return d, (f"the linearized MCP in direction {'+' if sign > 0 else '-'}e has no "
                   f"solution found ({res.code.name}): no directional derivative")
    d[free] = res.z * scale
    return d, ""


def _linear_mcp(M, q, lo, hi):
    """The pivotal path of lo <= d <= hi _|_ M d + q from d = pi(0) (thesis §3.3), with
    the Lemke ray start as its fallback, on the basis the routes give a problem of its
    order: the method of :func:`compass_sparse.solve_lcp` without its crash and its
    hand-over to the stabilized Newton method.  Under strong regularity the linearized
    MCP has one solution, which the path reaches."""
    opt = Options(convergence_tolerance=LINEAR_TOLERANCE)
    n = q.size
    make = basis_factory(path_route(n, opt, M.nnz), opt)
    return solve_handing_over(make.hand_over, M, q, lo, hi, make(M), opt, np.zeros(n),
                              keep_ray=True, minor_limit=max(10 * n, 1000))[0]


def tangent_predictor(problem, x, *, f=None, active_tol: float = ACTIVE_TOL):
    """First-order prediction of the solution of ``problem`` from a solution ``x`` of a
    neighbouring problem (see the module docstring): x + d projected on the bounds, with
    J_II d_I = -F_I(x) on x's inactive set.  Returns None when J_II is singular."""
    x = np.asarray(x, dtype=float)
    if f is None:
        f, J = _values(problem).FJ(x)
    else:
        J = _values(problem).J(x, f)
    lb, ub = problem.lb, problem.ub
    at_l, at_u = _at_bounds(x, lb, ub, active_tol)
    at_bound = at_l | at_u | (lb == ub)
    inactive = np.flatnonzero(~at_bound)
    try:
        d = _solve_inactive(J, inactive, -np.asarray(f, float)[inactive])
    except SingularSensitivityError:
        return None
    out = x.copy()
    out[inactive] += d
    return np.clip(out, lb, ub)
