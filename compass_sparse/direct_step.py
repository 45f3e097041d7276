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

import threading

import numpy as np
import scipy.sparse as sp

from ._csc import trusted_csc
from ._eval_kernels import csc_same_pattern, free_block
from ._jit import njit
from ._merit_kernels import csc_is_canonical, max_abs_kernel, newton_linearization
from ._path_kernels import VAR_S, VAR_V, VAR_W, VAR_Z
from ._slot_kernels import components, start_basis
from .basis.types import BasisOptions
from .evaluation import all_finite
from .box import float_vector, max_abs

__all__ = ["DIRECT_MAX_DENSITY", "DIRECT_MAX_N", "DIRECT_MIN_N", "KLU_FILL_LIMIT",
           "automatic_lu", "klu_available",
           "REUSE_BEATS_REFACTOR_NNZ", "DirectFactors", "direct_step", "direct_step_applies",
           "reduced_system"]

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


def automatic_lu(backend="auto", ordering="auto") -> bool:
    """Whether the sparse LU is left to the solver: the options ``lu_backend`` and
    ``lu_ordering`` are "auto" and the environment does not choose them either
    (``COMPASS_SPARSE_LU``).  Only then do the direct step and the crash pick KLU."""
    if backend != "auto" or ordering != "auto":
        return False
    import os

    from .basis.backends import _ENV

    return not os.environ.get(_ENV)


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
    compiled call: :func:`~compass_sparse._merit_kernels.newton_linearization` (M's
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
    PivotalPath.run's own start and :func:`direct_step` (``test_direct_step.py``)."""
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


def reduced_system(M, free, z, q):
    """(M_FF as CSC, -(q + M_FN z_N)_F) for the indices F where ``free`` is True (M: CSC,
    sorted indices give sorted indices), in one compiled pass without scipy's slicing."""
    if not (sp.issparse(M) and M.format == "csc"):
        M = sp.csc_matrix(M)
    z = np.asarray(z, dtype=float)
    q = np.asarray(q, dtype=float)
    # positions, arrays and the pass in one compiled call
    Kp, Ki, Kx, rhs, k = free_block(M.indptr, M.indices, M.data,
                                    np.asarray(free, dtype=np.bool_), z, q)
    nf = rhs.shape[0]
    return trusted_csc(Kx[:k], Ki[:k], Kp, (nf, nf)), rhs


class DirectFactors:
    """The sparse LUs of one solve's direct steps.

    KLU (SuiteSparse, through kvxopt: block triangular form, AMD, a diagonal preference,
    no supernodes) factors the blocks while they fill little: on such blocks it is 3-5x
    faster than SuperLU, whose set-up dominates there (0.13 against 0.40 ms at n = 362,
    0.33 against 0.83 ms at n = 992 on the Ramsey model's M_FF), and its symbolic analysis
    of a block pattern is kept across solves (:data:`_KLU_CACHE`).  On blocks that fill,
    SuperLU with COLAMD is the faster (2x on the static CGE model's, 1.3e5 entries from
    8e3), so a KLU factorization holding more than ``KLU_FILL_LIMIT`` times its block's
    entries returns the rest of the solve to SuperLU: a block that fills costs one slow
    factorization at most.  (SuperLU used to factor the first block, to learn its fill
    before KLU was tried: KLU first takes 6% off a Ramsey solve at n = 363 and 13% at
    n = 993, measured in one process, with the same major iterations.)
    Without kvxopt, or with ``klu=False``, SuperLU factors every block.  ``lu_nnz`` is
    the size of the last LU (L + U, and KLU's off-diagonal blocks); ``method`` its
    (backend, ordering)."""

    def __init__(self, klu: bool = True, dense: bool = False, rank_tolerance: float = 1e-9):
        #: small problems (order below ``DIRECT_MIN_N``): M_FF is solved densely in one
        #: compiled pass with the end point (:func:`_dense_direct`), no sparse LU; a block
        #: singular to the compiled engine's ``rank_tolerance`` is left to the path
        self.dense = dense
        self.rank_tolerance = float(rank_tolerance)
        self.klu = klu and not dense and klu_available()
        self.lu_nnz = 0
        self.method = ("", "")
        self._held = None  # (indptr, indices, kvxopt matrix, KLU symbolic) of the last block

    def dense_done(self, nf: int) -> int:
        """Record a dense direct step on a block of order ``nf``; returns its LU's entries."""
        self.method = ("dense", "partial pivoting")
        self.lu_nnz = nf * nf
        return self.lu_nnz

    def solve(self, K, rhs):
        """x with K x = rhs, or None when K is singular (as the factorization finds)."""
        if self.klu:
            return self._klu_solve(K, rhs)
        self.method = ("superlu", "colamd")
        try:
            lu = _superlu_colamd(K)
        except RuntimeError:  # exactly singular
            self.lu_nnz = 0
            return None
        self.lu_nnz = int(lu.nnz)
        return lu.solve(rhs)

    def _klu_solve(self, K, rhs):
        klu = _klu_module()
        from kvxopt import matrix

        self.method = ("klu", "btf+amd")
        h = self._held
        # (kvxopt keeps each column's entries sorted by row: new values can be copied in
        # only when K's are in that order too)
        if (h is not None and csc_same_pattern(K.indptr, K.indices, h[0], h[1])
                and csc_is_canonical(K.indptr, K.indices, K.shape[0], K.indptr[-1])):
            # the block of the last step (the active set did not move): KLU's symbolic
            # analysis (BTF, AMD) depends on the pattern only, so it is kept; only the
            # values change (~40% of a factorization at n = 362 saved)
            A, Fs, info = h[2], h[3], h[4]
            A.V = matrix(K.data[:K.indptr[-1]])
        else:
            A, Fs, info = _klu_analysis(K)
            if Fs is not None:
                self._held = (K.indptr.copy(), K.indices[:K.indptr[-1]].copy(), A, Fs, info)
                A.V = matrix(K.data[:K.indptr[-1]])
        try:
            if Fs is None:  # a block that is not canonical: analysed for itself
                Fs = klu.symbolic(A)
            Fn = klu.numeric(A, Fs)
        except ArithmeticError:  # singular
            self.lu_nnz = 0
            return None
        self.lu_nnz = _klu_lu_nnz(A, Fs, Fn, info)
        if self.lu_nnz > KLU_FILL_LIMIT * max(K.nnz, 1):
            self.klu = False  # SuperLU for the rest of the solve
        b = matrix(np.ascontiguousarray(rhs, dtype=np.float64))
        klu.solve(A, Fs, Fn, b)
        return np.array(b, dtype=np.float64).ravel()


def _superlu_colamd(K):
    """``splu(K, permc_spec="COLAMD")``.  For the direct step's blocks (float64 data,
    int32 canonical index arrays: nothing for splu to sum, cast or sort) the factorization
    routine is called with splu's own arguments directly, without its wrapper's checks and
    conversions (~15 us of a 0.15 ms factorization at n = 100): the same call, so the same
    factors.  Anything else, or a scipy without that routine, goes through splu."""
    from scipy.sparse.linalg import splu

    gstrf = _superlu_gstrf()
    n = K.shape[0]
    if (gstrf is None or K.shape[1] != n or K.data.dtype != np.float64
            or K.indices.dtype != np.int32 or K.indptr.dtype != np.int32
            or not csc_is_canonical(K.indptr, K.indices, n, K.indptr[-1])):
        return splu(K, permc_spec="COLAMD")
    nnz = int(K.indptr[-1])
    return gstrf(n, nnz, K.data[:nnz], K.indices[:nnz], K.indptr,
                 csc_construct_func=_superlu_gstrf.csc_array, ilu=False,
                 options=dict(DiagPivotThresh=None, ColPerm="COLAMD", PanelSize=None,
                              Relax=None))


def _superlu_gstrf():
    """scipy's SuperLU factorization routine when its splu passes exactly the arguments
    :func:`_superlu_colamd` passes (checked once from splu's signature and source), else
    None."""
    if not hasattr(_superlu_gstrf, "fn"):
        _superlu_gstrf.fn = None
        try:
            import inspect

            from scipy.sparse import csc_array
            from scipy.sparse.linalg._dsolve import _superlu, linsolve

            sig = inspect.signature(linsolve.splu)
            src = inspect.getsource(linsolve.splu)
            defaults = {k: sig.parameters[k].default for k in
                        ("permc_spec", "diag_pivot_thresh", "relax", "panel_size", "options")}
            if (defaults == dict(permc_spec=None, diag_pivot_thresh=None, relax=None,
                                 panel_size=None, options=None)
                    and "_options = dict(DiagPivotThresh=diag_pivot_thresh, "
                        "ColPerm=permc_spec,\n                    PanelSize=panel_size, "
                        "Relax=relax)" in src
                    and "return _superlu.gstrf(N, A.nnz, A.data, indices, indptr,\n"
                        "                          csc_construct_func=csc_construct_func,\n"
                        "                          ilu=False, options=_options)" in src):
                _superlu_gstrf.fn = _superlu.gstrf
                _superlu_gstrf.csc_array = csc_array
        except Exception:  # pragma: no cover - another scipy: splu itself
            _superlu_gstrf.fn = None
    return _superlu_gstrf.fn


_KLU_CACHE: list = []
"""KLU analyses of recent block patterns, newest last: (indptr, indices, kvxopt matrix
holding the pattern, symbolic factorization).  A loop of solves of one model meets the
same M_FF patterns in every solve; the analysis (BTF, AMD, ~0.25 ms at n = 992) and the
kvxopt matrix (~0.1 ms) depend on the pattern alone and are made once.  Entries are
found by exact comparison of the index arrays, never by a hash; the cached matrix is a
template that is never handed out (each solve gets its own copy to write values into) and
the symbolic object is only read by KLU's factorization and solve."""

_KLU_LOCK = threading.Lock()

KLU_CACHE_SIZE = 8
"""Patterns kept in :data:`_KLU_CACHE`."""

KLU_CACHE_MAX_NNZ = 200_000
"""Largest block (stored entries) whose analysis is kept: the cache lives as long as the
process, and eight analyses of blocks this size hold ~30 MB; larger blocks are analysed
for their own solve only (their factorization dwarfs the analysis anyway)."""


def _klu_analysis(K):
    """(kvxopt matrix with K's pattern, KLU symbolic analysis of it, [entries of the
    off-diagonal blocks, once known]) from the cache or made and cached; (matrix, None,
    [None]) for a K that is not canonical (kvxopt sorts the entries it is given: the
    values of such a K could not be copied in later), whose analysis the caller makes
    and does not keep."""
    from kvxopt import matrix, spmatrix

    with _KLU_LOCK:  # (solves in several threads share the cache)
        for i in range(len(_KLU_CACHE) - 1, -1, -1):
            e = _KLU_CACHE[i]
            if csc_same_pattern(K.indptr, K.indices, e[0], e[1]):
                if i != len(_KLU_CACHE) - 1:
                    _KLU_CACHE.append(_KLU_CACHE.pop(i))
                return +e[2], e[3], e[4]  # unary plus: a copy of the template
    n = K.shape[0]
    nnz = int(K.indptr[-1])
    cols = np.repeat(np.arange(n, dtype=np.int64), np.diff(K.indptr))
    A = spmatrix(matrix(K.data[:nnz]), matrix(K.indices[:nnz].astype(np.int64)), matrix(cols),
                 (n, n))
    if not csc_is_canonical(K.indptr, K.indices, n, nnz):
        return A, None, [None]
    Fs = _klu_module().symbolic(A)
    info = [None]
    if nnz > KLU_CACHE_MAX_NNZ:
        return A, Fs, info
    with _KLU_LOCK:
        _KLU_CACHE.append((K.indptr.copy(), K.indices[:nnz].copy(), +A, Fs, info))
        if len(_KLU_CACHE) > KLU_CACHE_SIZE:
            _KLU_CACHE.pop(0)
    return A, Fs, info


def _klu_lu_nnz(A, Fs, Fn, info):
    """nnz(L) + nnz(U) + nnz(off-diagonal blocks) of a KLU factorization.  kvxopt gives
    them only as copies of the factors (get_numeric: ~40 us at n = 992, twice per solve);
    the first two are the leading counts of KLU's numeric object (n, nblocks, lnz, unz:
    its layout since KLU 1.0), read there, the third is fixed by the symbolic analysis
    (the pattern's block triangular form) and kept in ``info`` from the first
    factorization of the pattern.  Every get_numeric made checks the counts read against
    the factors' own; a mismatch (another layout) turns the reading off for good."""
    counts = _klu_counts(Fn) if info[0] is not None else None
    if counts is not None:
        return counts[0] + counts[1] + info[0]
    parts = _klu_module().get_numeric(A, Fs, Fn)  # L, U, P, Q, R, F, r (copies)
    nnz_l, nnz_u, nnz_off = len(parts[0]), len(parts[1]), len(parts[5])
    read = _klu_counts(Fn)
    if read is not None and read != (nnz_l, nnz_u):
        _KLU_COUNTS[:] = [None]  # not the layout assumed
    elif read is not None:
        info[0] = nnz_off
    return nnz_l + nnz_u + nnz_off


_KLU_COUNTS: list = []
"""[PyCapsule_GetPointer] once the counts of KLU's numeric object may be read, [None]
when they may not (empty until first asked)."""


def _klu_counts(Fn):
    """(lnz, unz) of a kvxopt KLU numeric factorization (int64 fields 2 and 3 of the
    struct its capsule holds), or None when they cannot be read."""
    if not _KLU_COUNTS:
        try:
            import ctypes

            get = ctypes.pythonapi.PyCapsule_GetPointer
            get.restype = ctypes.c_void_p
            get.argtypes = [ctypes.py_object, ctypes.c_char_p]
            _KLU_COUNTS[:] = [(get, ctypes.c_int64 * 4)]
        except Exception:  # pragma: no cover - no ctypes: the factors' copies
            _KLU_COUNTS[:] = [None]
    st = _KLU_COUNTS[0]
    if st is None:
        return None
    try:
        ptr = st[0](Fn, b"KLU NUM D FACTOR")
    except Exception:  # another capsule (name): not the object assumed
        return None
    if not ptr:
        return None
    head = st[1].from_address(ptr)
    return int(head[2]), int(head[3])


KLU_FILL_LIMIT = 8.0
"""Largest nnz(LU) / nnz(block) of a KLU factorization before the direct step returns
to SuperLU for the rest of the solve."""


def klu_available() -> bool:
    """Whether KLU (kvxopt) can be used."""
    return _klu_module() is not None


_KLU_MODULE: list = []
"""[kvxopt's klu module, or None without kvxopt] once looked up (an import statement
costs a few microseconds at every factorization)."""


def _klu_module():
    if not _KLU_MODULE:
        try:
            from kvxopt import klu
        except ImportError:  # pragma: no cover - kvxopt is a dependency
            klu = None
        _KLU_MODULE.append(klu)
    return _KLU_MODULE[0]


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
