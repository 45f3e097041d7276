"""The sign conditions of a (box) LCP, decided by an LP, and their Farkas certificate.

A solution of the LCP  l <= z <= u  _|_  w = M z + q  meets, row by row, the sign
condition its variable's bounds impose on w (row i is paired with z_i):

    P = {l_i finite, u_i = +inf}:   w_i >= 0     (z_i > l_i forces w_i = 0)
    N = {l_i = -inf, u_i finite}:   w_i <= 0
    E = {both bounds infinite}:     w_i  = 0
    B = {both bounds finite}:       nothing (any sign of w_i has a z_i that fits it)

so if no z in the box meets them all, the LCP has no solution (PATH's Lemke start ends in
a ray there; a path or a Newton method only stalls).  They are decided by the LP (phase
one of the simplex method, with one slack t for all rows)

    t* = min t   over z in [l, u], t >= 0,
         w_i + s_i t >= 0  (i in P, E),   w_i - s_i t <= 0  (i in N, E),

with the row scales s_i = max(|q_i|, max_j |M_ij|) (1 for a zero row): t* is the least
uniform relative violation of the sign conditions over the box, 0 when they can be met.
The LP is solved by HiGHS (``scipy.optimize.linprog(method="highs")``).

Farkas' lemma (the LP's dual) gives the certificate.  A y with y_i >= 0 on P, y_i <= 0 on
N, y_i = 0 on B (free on E) has y^T w >= 0 for every w that meets the sign conditions,
while for every z in the box

    y^T (M z + q) <= beta(y) = y^T q + sum_j max(c_j l_j, c_j u_j),   c = M^T y,

finite when c_j = 0 where both bounds of z_j are infinite, c_j <= 0 where only u_j is and
c_j >= 0 where only l_j is.  beta(y) < 0 proves that no z in the box meets the sign
conditions, and more: with v_i >= 0 the amount by which w_i misses its condition,
sum_i |y_i| v_i >= -beta(y), so ||v||_2 >= -beta(y) / ||y||_2 at every z (Cauchy-Schwarz),
and |Phi_i| >= v_i (Fischer-Burmeister: sqrt(a^2 + w^2) - a - w >= -w for a >= 0): no
point of the box has ||Phi||_2 below that floor.  The LP's dual values normalized to
sum_i |y_i| s_i = 1 give beta(y) = -t*.

Tolerances (each stressed in ``tests/test_feasibility.py``):

* ``FEASIBILITY_TOL`` (1e-9): the LP calls the sign conditions infeasible only when
  t* > FEASIBILITY_TOL, a violation beyond 1e-9 of the rows' scales; HiGHS runs with
  primal and dual feasibility tolerances ``LP_TOL`` (1e-10), below it.
* The certificate is checked again from M, q and the bounds alone (:func:`check_farkas`,
  never the LP's numbers): its signs exactly, the wrong-signed part of c on infinite
  sides at most ``CERTIFICATE_RTOL`` (1e-9) of ||M||_F ||y||_2 -- then y is an exact
  certificate for M + E with ||E||_F <= 1e-9 ||M||_F, as the free LCP's
  (:mod:`compass_sparse.linear_system`) -- and beta(y) below -``CERTIFICATE_MARGIN``
  (1e-10) times the sum of the magnitudes of its terms (so that rounding cannot have made
  it negative).
* INFEASIBLE is claimed (:func:`lcp_feasibility`) only when the checked certificate
  proves a residual floor -beta(y) / ||y||_2 above the solve's convergence tolerance (so
  no point can pass the acceptance test, which asks ||Phi||_2 <= tol) and a relative
  violation -beta(y) / sum |y_i| s_i above FEASIBILITY_TOL; a problem that misses by
  less is left to the solver.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from .report import make_result
from .status import PassStats, PointStatus, Status, WorkCounts

__all__ = ["CERTIFICATE_MARGIN", "CERTIFICATE_RTOL", "FEASIBILITY_TOL", "LP_TOL", "STALLED",
           "FarkasCheck", "Infeasibility", "check_farkas", "infeasible_result",
           "lcp_feasibility", "polish_certificate", "sign_rows"]

FEASIBILITY_TOL = 1e-9
"""The LP's: sign conditions violated by at most this (relative to the rows' scales)
count as met."""

LP_TOL = 1e-10
"""HiGHS's primal and dual feasibility tolerances for the LP (below FEASIBILITY_TOL)."""

CERTIFICATE_RTOL = 1e-9
"""Largest wrong-signed part of M^T y on infinite sides, relative to ||M||_F ||y||_2."""

CERTIFICATE_MARGIN = 1e-10
"""beta(y) must be below -CERTIFICATE_MARGIN times the sum of its terms' magnitudes."""

_P, _N, _E, _B = 0, 1, 2, 3  # row kinds (see the module docstring)


def sign_rows(lb, ub) -> np.ndarray:
    """The kind of each row's sign condition: 0 (P: w >= 0), 1 (N: w <= 0), 2 (E: w = 0),
    3 (B: none)."""
    lo, hi = np.isfinite(lb), np.isfinite(ub)
    kind = np.full(lb.shape, _B, dtype=np.int8)
    kind[lo & ~hi] = _P
    kind[~lo & hi] = _N
    kind[~lo & ~hi] = _E
    return kind


@dataclass
class FarkasCheck:
    """What :func:`check_farkas` found for a candidate y."""

    valid: bool  #: signs right, backward error and margin met: beta(y) < 0 is proved
    beta: float  #: max over the box of y^T (M z + q) (wrong-signed parts of c set to 0)
    backward_error: float  #: ||wrong-signed part of M^T y||_2 / (||M||_F ||y||_2)
    residual_floor: float  #: -beta / ||y||_2: every z has ||Phi||_2 at least this
    violation: float  #: -beta / sum_i |y_i| s_i: the same, relative to the row scales
    why: str = ""  #: why it is not valid


def row_scales(M, q) -> np.ndarray:
    """s_i = max(|q_i|, max_j |M_ij|), 1 where both are 0."""
    A = abs(sp.csr_matrix(M))
    s = np.maximum(np.abs(q), A.max(axis=1).toarray().ravel() if A.nnz else 0.0)
    return np.where(s > 0, s, 1.0)


def check_farkas(M, q, lb, ub, y) -> FarkasCheck:
    """Check y as a Farkas certificate of the sign conditions of the LCP (M, q, [lb, ub])
    from the data alone (see the module docstring for what is checked and why)."""
    M = sp.csc_matrix(M, copy=True)
    q = np.asarray(q, dtype=float)
    lb, ub = (np.broadcast_to(np.asarray(b, dtype=float), q.shape) for b in (lb, ub))
    y = np.asarray(y, dtype=float)
    kind = sign_rows(lb, ub)
    nan = FarkasCheck(False, math.nan, math.inf, 0.0, 0.0)
    if y.shape != q.shape or not np.all(np.isfinite(y)) or not np.any(y):
        nan.why = "y is not a nonzero finite vector of the rows"
        return nan
    wrong = (((kind == _P) & (y < 0)) | ((kind == _N) & (y > 0)) | ((kind == _B) & (y != 0)))
    if wrong.any():
        nan.why = f"y has the wrong sign in row {int(np.flatnonzero(wrong)[0])}"
        return nan
    c = M.T @ y
    lo, hi = np.isfinite(lb), np.isfinite(ub)
    # the part of c that would make its term infinite: c_j of the wrong sign where the
    # bound it would reach is infinite
    bad = np.where(~lo & ~hi, c, np.where(lo & ~hi, np.maximum(c, 0.0),
                                          np.where(~lo & hi, np.minimum(c, 0.0), 0.0)))
    c_ok = c - bad
    M.sum_duplicates()
    normM = float(np.linalg.norm(M.data))  # (Frobenius)
    ny = float(np.linalg.norm(y))
    backward = float(np.linalg.norm(bad)) / max(normM * ny, 1e-300)
    # each term's bound: u_j where c_j > 0, l_j where c_j < 0 (finite there by now)
    b = np.where(c_ok > 0, ub, np.where(c_ok < 0, lb, 0.0))
    terms = np.where(c_ok != 0, c_ok * b, 0.0)
    beta = float(y @ q + terms.sum())
    magnitude = float(np.abs(y) @ np.abs(q)
                      + (abs(M).T @ np.abs(y)) @ np.where(c_ok != 0, np.abs(b), 0.0))
    s = row_scales(M, q)
    out = FarkasCheck(False, beta, backward, -beta / ny, -beta / float(np.abs(y) @ s))
    if backward > CERTIFICATE_RTOL:
        out.why = (f"M^T y has a wrong-signed part of {backward:.1e} (relative) on "
                   f"unbounded variables, above {CERTIFICATE_RTOL:.0e}")
    elif not beta < -CERTIFICATE_MARGIN * magnitude:
        out.why = (f"beta(y) = {beta:.3e} is not below -{CERTIFICATE_MARGIN:.0e} x "
                   f"{magnitude:.3e} (its terms' magnitude)")
    else:
        out.valid = True
    return out


@dataclass
class Infeasibility:
    """An LCP whose sign conditions no point of the box meets, with the checked proof."""

    y: np.ndarray  #: the Farkas certificate (one multiplier per row)
    check: FarkasCheck  #: its independent check
    z: np.ndarray  #: the LP's point of least violation (in the box)
    lp_violation: float  #: the LP's t*
    time: float

    @property
    def message(self) -> str:
        c = self.check
        k = int(np.count_nonzero(self.y))
        return ("no point of the box meets the sign conditions of the rows (w >= 0 at a "
                "finite lower bound only, w <= 0 at a finite upper bound only, w = 0 for a "
                f"free variable): a Farkas certificate y on {k} row(s) has max over the box "
                f"of y^T (M z + q) = {c.beta:.3e} < 0, so every point has ||Phi||_2 >= "
                f"{c.residual_floor:.3e}, more than the convergence tolerance "
                "(Result.certificate holds y)")


def _lp(M, q, lb, ub, kind, s, time_limit):
    """The feasibility LP: (t*, z, y) with y normalized to sum |y_i| s_i = 1, or None."""
    # (lazy: scipy.optimize costs ~0.4 s to import; most solves never decide feasibility)
    from scipy.optimize import linprog

    n = q.size
    Mr = sp.csr_matrix(M)
    lower = np.flatnonzero((kind == _P) | (kind == _E))  # -w_i - s_i t <= 0
    upper = np.flatnonzero((kind == _N) | (kind == _E))  #  w_i - s_i t <= 0
    A = sp.vstack([-Mr[lower], Mr[upper]], format="csr")
    slack = -np.concatenate([s[lower], s[upper]])
    A = sp.hstack([A, sp.csr_matrix(slack[:, None])], format="csr")
    b = np.concatenate([q[lower], -q[upper]])
    cost = np.zeros(n + 1)
    cost[n] = 1.0
    bounds = np.column_stack([np.append(lb, 0.0), np.append(ub, np.inf)])
    options = {"primal_feasibility_tolerance": LP_TOL, "dual_feasibility_tolerance": LP_TOL}
    if math.isfinite(time_limit):
        options["time_limit"] = max(time_limit, 1e-3)
    res = linprog(cost, A_ub=A, b_ub=b, bounds=bounds, method="highs", options=options)
    if res.status != 0 or res.x is None:
        return None
    mu = -np.asarray(res.ineqlin.marginals)  # >= 0: dual values of the rows above
    y = np.zeros(n)
    np.add.at(y, lower, mu[:lower.size])
    np.add.at(y, upper, -mu[lower.size:])
    return float(res.x[n]), np.clip(res.x[:n], lb, ub), y


def _signed(y, kind):
    """y with the signs of a certificate: rows B zero, P nonnegative, N nonpositive."""
    y = y.copy()
    y[kind == _B] = 0.0
    y[(kind == _P) & (y < 0)] = 0.0
    y[(kind == _N) & (y > 0)] = 0.0
    return y


_POLISH_NEAR = 1e-6
"""A one-sided column whose |c_j| is below this (relative to ||M||_F ||y||_2) is held at 0
by the polish."""


def polish_certificate(M, y, lb, ub, kind):
    """y moved by least squares on its support so that M^T y vanishes on the columns
    whose term needs c_j = 0 or of one sign (both bounds infinite, or c_j on its wrong
    side): the LP's dual values meet those only to HiGHS's tolerance (1e-10 scaled)."""
    lo, hi = np.isfinite(lb), np.isfinite(ub)
    c = M.T @ y
    # the columns held at c_j = 0: both bounds infinite, and one-sided ones whose c_j is
    # wrong-signed or so near 0 that the move of y could make it so
    near = np.abs(c) <= _POLISH_NEAR * float(np.linalg.norm(M.data)) * np.linalg.norm(y)
    one_sided = (lo & ~hi & ((c > 0) | near)) | (~lo & hi & ((c < 0) | near))
    cols = np.flatnonzero((~lo & ~hi) | one_sided)
    rows = np.flatnonzero(y)
    if cols.size == 0 or rows.size == 0:
        return y
    A = sp.csc_matrix(M)[rows][:, cols].T.tocsr()  # (cols x rows): A y_rows = c_cols
    r = A @ y[rows]
    if A.shape[0] * A.shape[1] <= 4_000_000:
        d = np.linalg.lstsq(A.toarray(), r, rcond=None)[0]
    else:
        # (lazy: scipy.sparse.linalg adds ~0.15 s to the package's import)
        from scipy.sparse.linalg import lsqr

        d = lsqr(A, r, atol=1e-15, btol=1e-15)[0]
    out = y.copy()
    out[rows] -= d
    return _signed(out, kind)


def lcp_feasibility(M, q, lb, ub, tolerance: float, *, deadline=None) -> Infeasibility | None:
    """Decide the sign conditions of the LCP (M, q, [lb, ub]) by the LP of the module
    docstring: an :class:`Infeasibility` with its checked certificate when no point of the
    box comes within ``tolerance`` (the solve's convergence tolerance) of meeting them,
    else None (feasible, not provably infeasible beyond the tolerances, or the LP did not
    finish by ``deadline``, a ``time.perf_counter()`` value)."""
    t0 = time.perf_counter()
    kind = sign_rows(lb, ub)
    if np.all(kind == _B):
        return None  # a bounded box: every sign condition can be met
    left = math.inf if deadline is None else deadline - t0
    if left <= 0:
        return None
    M = sp.csc_matrix(M)
    s = row_scales(M, q)
    out = _lp(M, q, lb, ub, kind, s, left)
    if out is None or not out[0] > FEASIBILITY_TOL:
        return None
    t_star, z, y = out
    y = _signed(y, kind)
    check = check_farkas(M, q, lb, ub, y)
    if not check.valid and check.backward_error > CERTIFICATE_RTOL:
        y = polish_certificate(M, y, lb, ub, kind)
        check = check_farkas(M, q, lb, ub, y)
    if not (check.valid and check.violation > FEASIBILITY_TOL
            and check.residual_floor > tolerance):
        return None
    return Infeasibility(y=y, check=check, z=z, lp_violation=t_star,
                         time=time.perf_counter() - t0)


STALLED = (Status.NO_PROGRESS, Status.STATIONARY_POINT)
"""The failures after which a linear problem's sign conditions are decided: a stall of
the Newton method (a ray of the path is the other occasion)."""

_CARRIED = tuple(WorkCounts.__dataclass_fields__) + ("history", "routes", "lu")
"""What an INFEASIBLE Result keeps of the failed solve it replaces."""


def infeasible_result(problem, M, q, opt, t0, *, passes, deadline=None, failed=None,
                      counts=None):
    """The INFEASIBLE Result of the linear problem ``problem`` (F = M z + q on its box)
    when :func:`lcp_feasibility` proves its sign conditions infeasible, else None; the
    check is recorded as the pass "feasibility" in ``passes``.  The Result's point is the
    LP's point of least violation, ``Result.certificate`` the checked y.  It keeps the
    work of the ``failed`` Result it replaces, or ``counts`` (make_result's keywords)."""
    tf = time.perf_counter()
    out = lcp_feasibility(M, q, problem.lb, problem.ub, opt.convergence_tolerance,
                          deadline=deadline)
    st = passes["feasibility"] = PassStats(ran=True, time=time.perf_counter() - tf,
                                           iterations=1)
    if out is None:
        st.reason = ("the sign conditions can be met, or are missed by less than the "
                     "tolerances, or the time limit came first")
        return None
    st.reason = f"infeasible: Farkas certificate checked (beta = {out.check.beta:.3e})"
    before = (problem.counters.nfev, problem.counters.njev)
    counts = {k: v for k, v in (counts or {}).items() if k != "passes"}
    res = make_result(problem, Status.INFEASIBLE, out.message, out.z, problem.F(out.z), opt,
                      t0, passes=passes, **counts)
    if failed is not None:
        for k in _CARRIED:
            setattr(res, k, getattr(failed, k))
        res.nfev = failed.nfev + problem.counters.nfev - before[0]
        res.njev = failed.njev + problem.counters.njev - before[1]
    res.point_status = PointStatus.CERTIFICATE
    res.certificate = out.y
    return res
