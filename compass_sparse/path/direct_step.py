"""The direct Newton step: a pivotal path that needs no pivot, found by one sparse solve.

A path of the linearization ``M z + q - w + v = (1 - t) r`` starts at t = 0 from the
current point in the start basis B (thesis §3.3: z_i basic between its bounds, or where
the warm or inward guess keeps it basic at a bound; the slack w_i, v_i or the free s_i
basic elsewhere).  Its basic values are affine in t.  If they are feasible at t = 0 (they
are: the covering vector r makes the current point the t = 0 point) and at t = 1, they
are feasible on the whole segment, so the ratio test never blocks and the path reaches
t = 1 with no pivot.  Near the solution of a smooth model this is the common case: the
active set has settled and every major iteration is a Newton step (the Ramsey CGE models
at n = 100-1000 solve in 3 major iterations and 0 pivots).

The point at t = 1 needs no basis manager: with F the indices whose z is basic and N the
rest (z_N at its current values),

    M_FF z_F = -(q + M_FN z_N)_F,      s_N = (M z + q)_N = w_N - v_N,

one sparse LU of M_FF (:class:`DirectFactors`: KLU while the blocks do not fill, then
SuperLU) and a product.  It is the path's end point when z_F lies in its box and each slack
has its sign (w basic: s >= 0; v basic: s <= 0; the slack of a fixed variable is free).
Otherwise, or when M_FF is singular or the residual check fails, nothing is returned and
the caller runs the path as always: the answer is then exactly the path's, and the cost
of the attempt is one sparse factorization.

For a sparse M this replaces the compiled engine's dense O(n^3) factorization (n <= 500)
or the basis manager's general factorization with rank repair and update structures
(measured on the Ramsey model at n = 363 and 993: benchmarks/small.md, "Round 4").  Dense
M (the thesis families), tiny n and large n keep the engine or the basis manager: see
:func:`direct_step_applies`; so do solves whose basis reuses large factors (the crash's,
or its own: ``REUSE_BEATS_REFACTOR_NNZ``).

Tolerances: a basic value may lie outside its bound by at most ``FEASIBILITY_TOLERANCE``
(1e-12) relative to max(1, |bound|) and is then put on the bound (the path's own values
carry rounding of that order); the end point must satisfy the linear equations to
``RESIDUAL_TOLERANCE`` (1e-9) relative to 1 + max|M z| + max|q|, the path's own solution
check (:meth:`compass_sparse.path.PivotalPath._verify_solution`).
"""
from __future__ import annotations

import numpy as np

from .._jit import njit
from .._merit_kernels import max_abs_kernel
from ._kernels import VAR_S, VAR_V, VAR_W, VAR_Z, newton_linearization
from ._slot_kernels import components, start_basis
from ..basis.types import BasisOptions
from ..box import float_vector, max_abs
from ..box import all_finite
from ..linalg.csc import reduced_system
from ..linalg.direct import DirectFactors, automatic_lu

__all__ = ["DIRECT_MAX_DENSITY", "DIRECT_MAX_N", "DIRECT_MIN_N", "REUSE_BEATS_REFACTOR_NNZ",
           "dense_direct_path", "direct_step", "direct_step_applies", "direct_step_worth_trying",
           "failed_direct_start"]

DIRECT_MIN_N = 150
"""Below this order the compiled engine's dense factorization costs less than a sparse
LU's set-up and the Python around it.  (Measured in one process, the dense step against
KLU, whole solves: 0.80-0.90 at n = 50-102 -- a thesis family at n = 50, a static CGE model
at n = 91, a Ramsey model at n = 102 -- 0.92 at n = 151; 0.97-1.05 at n = 170-183, and
1.15-1.30 at n = 200-273; the bound was 50.)"""

DIRECT_MAX_N = 2000
"""Above this order the direct step is not tried: the basis manager's own set-up is small
next to its factorization there, and its fill-reducing orderings (AMD or METIS, chosen by
a symbolic estimate) and factor reuse serve large blocks better (the dynamic CGE model at
n = 1e4: 0.3 s per factorization in the manager's ordering, 10 s in KLU's)."""

DIRECT_MAX_DENSITY = 0.05
"""Largest nnz(M) / n^2: denser matrices keep the dense engine (whose factorization then
costs about what a sparse one would)."""

REUSE_BEATS_REFACTOR_NNZ = BasisOptions.reuse_min_nnz
"""A sparse basis (n > 500) solves on held factors of at least this many entries by GMRES
(option ``factor_reuse``), which costs less than a fresh factorization: the solver stops
trying the direct step once its LU is this large, or when the crash's factors are taken."""

FEASIBILITY_TOLERANCE = 1e-12
RESIDUAL_TOLERANCE = 1e-9


def direct_step_applies(M, options) -> bool:
    """Whether the Newton paths of a linearization with matrix M try the direct step:
    a sparse M of moderate order, and no LU backend or ordering forced by the user (the
    direct step factors with KLU, or SuperLU and COLAMD, by its own choice)."""
    n = M.shape[0]
    if not DIRECT_MIN_N <= n <= DIRECT_MAX_N:
        return False
    if not automatic_lu(getattr(options, "lu_backend", "auto"),
                        getattr(options, "lu_ordering", "auto")):
        return False
    return M.nnz <= DIRECT_MAX_DENSITY * float(n) * n


def direct_step_worth_trying(direct, basis, last_pivots) -> bool:
    """Whether the next path tries its direct step (``direct``: the solve's
    :class:`DirectFactors` or None; ``last_pivots``: the pivots of the solve's last path,
    None before the first).  On the sparse engine (``basis.runs_paths``) only after a path
    that made no pivot: a path that pivots starts where a failed direct step left it, so
    the step's factorization is wasted, and a model whose active set still changes from
    one major iteration to the next (pivots) usually changes it in the next one too --
    while a path that needs no pivot costs the engine more than the direct step (its
    basis' ordering, factorization, and solution check).  Measured (one process, medians
    of 9 solves): traffic n = 912 (majors 2-7 pivot), the direct step tried before 3 of
    its 9 paths instead of all 9, 7 ms less a solve (74 against 81 ms on a loaded machine),
    the same 586 pivots; the Ramsey model at n = 993 (no pivot in any major iteration)
    unchanged, 12 ms a solve with the direct step against 22 ms without.  The basis
    manager's paths and the dense engine's always try it."""
    if direct is None:
        return False
    if direct.dense or not getattr(basis, "runs_paths", False):
        return True
    return not last_pivots


@njit(cache=True)
def _end_point(indptr, indices, data, q, lb, ub, basic, z, w, v, tol):
    """w, v of the end point from s = M z + q; z_F put on its bound when outside by at
    most ``tol`` (relative).  Returns the largest |residual| over F (-1.0: infeasible, or
    a non-finite s) and max|M z|."""
    n = z.shape[0]
    for i in range(n):
        if basic[i] == VAR_Z:
            if z[i] < lb[i]:
                if lb[i] - z[i] > tol * max(1.0, abs(lb[i])):
                    return -1.0, 0.0
                z[i] = lb[i]
            elif z[i] > ub[i]:
                if z[i] - ub[i] > tol * max(1.0, abs(ub[i])):
                    return -1.0, 0.0
                z[i] = ub[i]
    s = np.zeros(n)
    for j in range(n):
        zj = z[j]
        for e in range(indptr[j], indptr[j + 1]):
            s[indices[e]] += data[e] * zj
    mz = 0.0
    for i in range(n):
        mz = max(mz, abs(s[i]))
    res = 0.0
    for i in range(n):
        si = s[i] + q[i]
        if not np.isfinite(si):
            return -1.0, 0.0
        w[i] = 0.0
        v[i] = 0.0
        b = basic[i]
        if b == VAR_Z:
            res = max(res, abs(si))
        elif b == VAR_W:
            if si < 0.0:
                return -1.0, 0.0
            w[i] = si
        elif b == VAR_V:
            if si > 0.0:
                return -1.0, 0.0
            v[i] = -si
        elif b == VAR_S:
            if si >= 0.0:
                w[i] = si
            else:
                v[i] = -si
        else:
            return -1.0, 0.0
    return res, mz


@njit(cache=True)
def _dense_direct(indptr, indices, data, q, lb, ub, basic, z, w, v, tol, rank_tol):
    """The direct step of a small problem in one compiled pass: M_FF and
    rhs = -(q + M_FN z_N)_F into a dense block, Gaussian elimination with partial
    pivoting, z_F, then the end point (:func:`_end_point`).  Returns (largest |residual|
    over F, max|M z|, |F|); the residual is -1.0 when a solution is not finite, the end
    point is infeasible, or the block is singular by the compiled engine's own test: a
    pivot of column j at most ``rank_tol * max(1, ||M[:, j]||_inf)`` (there the engine
    repairs the basis with artificials and pivots; a Newton step through a nearly
    singular M_FF would run off along a flat direction instead)."""
    n = z.shape[0]
    pos = np.full(n, -1, dtype=np.int64)
    nf = 0
    for i in range(n):
        if basic[i] == VAR_Z:
            pos[i] = nf
            nf += 1
    A = np.zeros((nf, nf))
    b = np.empty(nf)
    cmax = np.ones(nf)  # max(1, ||M[:, j]||_inf) of the free columns, all rows
    for i in range(n):
        if pos[i] >= 0:
            b[pos[i]] = -q[i]
    for j in range(n):
        pj = pos[j]
        for e in range(indptr[j], indptr[j + 1]):
            if pj >= 0:
                cmax[pj] = max(cmax[pj], abs(data[e]))
            pi = pos[indices[e]]
            if pi < 0:
                continue
            if pj >= 0:
                A[pi, pj] += data[e]
            else:
                b[pi] -= data[e] * z[j]
    for k in range(nf):
        p = k
        big = abs(A[k, k])
        for i in range(k + 1, nf):
            if abs(A[i, k]) > big:
                big = abs(A[i, k])
                p = i
        if big <= rank_tol * cmax[k]:  # singular: the path's rank repair decides
            return -1.0, 0.0, nf
        if p != k:
            for j in range(k, nf):
                A[k, j], A[p, j] = A[p, j], A[k, j]
            b[k], b[p] = b[p], b[k]
        piv = A[k, k]
        for i in range(k + 1, nf):
            m = A[i, k] / piv
            if m != 0.0:
                for j in range(k + 1, nf):
                    A[i, j] -= m * A[k, j]
                b[i] -= m * b[k]
    for k in range(nf - 1, -1, -1):
        s = b[k]
        for j in range(k + 1, nf):
            s -= A[k, j] * b[j]
        b[k] = s / A[k, k]
        if not np.isfinite(b[k]):
            return -1.0, 0.0, nf
    for i in range(n):
        if pos[i] >= 0:
            z[i] = b[pos[i]]
    res, mz = _end_point(indptr, indices, data, q, lb, ub, basic, z, w, v, tol)
    return res, mz, nf


@njit(cache=True)
def _dense_direct_from(indptr, indices, data, q, lb, ub, x, r, previous, use_previous,
                       z, w, v, basic, slack, zt, wt, vt, tol, rank_tol):
    """The start of a pivotal path from x and its direct step, in one compiled call (what
    PivotalPath.run does before its first factorization, for a dense direct step):
    (z, w, v) = the components of x, ``basic`` = the start basis (path.default_basis,
    with the inward guess when there is no warm basis ``previous``), then the end point
    (zt, wt, vt) of :func:`_dense_direct`; ``slack`` = the start basis before the inward
    guess (the path's fallback when the guess makes the basis singular).  Returns (code,
    residual, max|M z|, |F|, whether the guess changed the basis): code 0 when r = 0 (the
    start solves the linear problem), 1 after a direct step."""
    n = x.shape[0]
    components(x, lb, ub, z, w, v)
    start_basis(z, lb, ub, previous, use_previous, basic)
    guessed = False
    if not use_previous:
        # the inward guess of PivotalPath._run: z basic at a bound with no slack value
        # where the residual pushes it inwards
        for i in range(n):
            slack[i] = basic[i]
            if lb[i] < ub[i] and ((z[i] <= lb[i] and w[i] == 0.0 and r[i] < 0.0)
                                  or (z[i] >= ub[i] and v[i] == 0.0 and r[i] > 0.0)):
                basic[i] = VAR_Z
                guessed = True
    solved = True
    for i in range(n):
        if r[i] != 0.0:  # (NaN too: the path meets it)
            solved = False
            break
    if solved:
        return 0, 0.0, 0.0, 0, guessed
    for i in range(n):
        zt[i] = z[i]
    res, mz, nf = _dense_direct(indptr, indices, data, q, lb, ub, basic.astype(np.int64), zt,
                                wt, vt, tol, rank_tol)
    return 1, res, mz, nf, guessed


@njit(cache=True)
def dense_newton_direct(jdata, pos_j, scatter, pos_d, eps, indptr, indices, zk, fk, x, lb,
                        ub, previous, use_previous, mdata, q, r, z, w, v, basic, slack, zt,
                        wt, vt, tol, rank_tol, res_tol):
    """A major iteration's linear MCP and its path's start and dense direct step, in one
    compiled call: :func:`~compass_sparse.path._kernels.newton_linearization` (M's
    entries into ``mdata``, q, r at z_k = ``zk``, F(z_k) = ``fk``), then
    :func:`_dense_direct_from` on that M, then the test of :func:`_accepted`.  Returns
    (code, |F|, accepted, guessed): code 0 when r = 0, 1 after a direct step, which
    ``accepted`` says ends the path; ``guessed``: the inward guess changed the start basis
    (``slack`` holds the one before it).  The same bits as the three steps called one by
    one."""
    newton_linearization(jdata, pos_j, scatter, pos_d, eps, indptr, indices, zk, fk, x, mdata,
                         q, r)
    code, res, mz, nf, guessed = _dense_direct_from(
        indptr, indices, mdata, q, lb, ub, x, r, previous, use_previous, z, w, v, basic,
        slack, zt, wt, vt, tol, rank_tol)
    accepted = False
    if code == 1 and res >= 0.0:
        qmax = max_abs_kernel(q, q, False)
        accepted = res <= res_tol * (1.0 + mz + qmax)  # (NaN fails, as in _accepted)
    return code, nf, accepted, guessed


def dense_direct_path(M, q, lb, ub, x, r, previous, factors: DirectFactors):
    """The outcome of a pivotal path from x (covering vector r, warm basis ``previous`` or
    None) when its dense direct step decides it, computed in one compiled call:
    ``("start", (z, w, v), basic, 0)`` when r = 0, ``("direct", (z, w, v), basic, nnz of
    the LU)`` for the direct step's end point, ``("path", (z, w, v, basic, slack basis or
    None), basic, nnz)`` when the path must run (the step failed: the path's start, for
    ``PivotalPath.run(start=)``), or None when the arguments are not the compiled call's
    (the path then does everything itself).  The same values, bit for bit, as
    PivotalPath.run's own start and :func:`direct_step` (``tests/path/test_direct_step.py``)."""
    if not (factors.dense and float_vector(x) and M.data.dtype == np.float64):
        return None
    n = x.shape[0]
    for a in (q, lb, ub, r):
        if not (float_vector(a) and a.shape[0] == n):
            return None
    if previous is not None and previous.basic.shape != (n,):
        return None  # (the path raises its ShapeError)
    z, w, v, zt, wt, vt = np.empty((6, n))  # one allocation; its rows are C vectors
    basic, slack = np.empty((2, n), dtype=np.int8)
    use_previous = previous is not None
    code, res, mz, nf, guessed = _dense_direct_from(
        M.indptr, M.indices, M.data, q, lb, ub, x, r,
        previous.basic if use_previous else basic, use_previous, z, w, v, basic, slack, zt,
        wt, vt, FEASIBILITY_TOLERANCE, factors.rank_tolerance)
    if code == 0:
        return "start", (z, w, v), basic, 0
    nnz_lu = factors.dense_done(nf)
    end, _ = _accepted(res, mz, q, zt, wt, vt, nnz_lu)
    if end is None:
        return failed_direct_start(z, w, v, basic, slack, guessed, nnz_lu)
    return "direct", end, basic, nnz_lu


def failed_direct_start(z, w, v, basic, slack, guessed, nnz_lu):
    """:func:`dense_direct_path`'s outcome when its direct step failed: the path's start
    (z, w, v), its basis, the basis before the inward guess (when ``guessed``) and the
    step's LU entries."""
    return "path", (z, w, v, basic, slack if guessed else None), basic, nnz_lu


def direct_step(M, q, lb, ub, z, basic, factors: DirectFactors | None = None):
    """(z, w, v, nnz of the LU) of the end point at t = 1 of the path from ``z`` in the
    start basis ``basic`` (per index: VAR_Z, VAR_W, VAR_V or VAR_S) when that path makes
    no pivot, else (None, nnz of the LU).  ``M``: CSC (n x n); ``z``: the current z, at
    its bounds off F; ``factors``: the solve's :class:`DirectFactors` (default: a new one)."""
    factors = DirectFactors() if factors is None else factors
    n = z.shape[0]
    zt = np.array(z, dtype=float)
    w = np.empty(n)
    v = np.empty(n)
    if factors.dense:
        res, mz, nf = _dense_direct(M.indptr, M.indices, M.data, q, lb, ub,
                                    basic.astype(np.int64), zt, w, v, FEASIBILITY_TOLERANCE,
                                    factors.rank_tolerance)
        return _accepted(res, mz, q, zt, w, v, factors.dense_done(nf))
    free = basic == VAR_Z
    nnz_lu = 0
    if free.any():
        K, rhs = reduced_system(M, free, zt, q)
        zf = factors.solve(K, rhs)
        nnz_lu = factors.lu_nnz
        if zf is None:  # exactly singular: the path's rank repair decides
            return None, nnz_lu
        if not all_finite(zf):
            return None, nnz_lu
        zt[free] = zf
    res, mz = _end_point(M.indptr, M.indices, M.data, q, lb, ub, basic.astype(np.int64), zt,
                         w, v, FEASIBILITY_TOLERANCE)
    return _accepted(res, mz, q, zt, w, v, nnz_lu)


def _accepted(res, mz, q, z, w, v, nnz_lu):
    """The direct step's answer from its end point's (residual, max|M z|): the point when
    it is feasible and solves the linear equations to ``RESIDUAL_TOLERANCE``."""
    if res < 0.0:
        return None, nnz_lu
    qmax = max_abs(q)
    if not res <= RESIDUAL_TOLERANCE * (1.0 + mz + qmax):  # (NaN fails too)
        return None, nnz_lu
    return (z, w, v), nnz_lu
