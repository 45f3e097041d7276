"""Sparse LU backends for the non-unit block K of the basis.

A backend factors a square sparse matrix K (CSC) as

    diag(s[row_order]) K[row_order, :][:, col_order] = L U

with L unit lower triangular and U upper triangular (``s`` an optional row scaling, None
for SuperLU). ``row_order[t]`` is the row of K pivoted at position t, ``col_order[t]`` its
column. A backend raises :class:`SingularFactorError` when the matrix is exactly singular.

* :class:`SuperLUBackend` (``scipy.sparse.linalg.splu``, always available) factors K in the
  fill-reducing ordering of :mod:`compass_sparse.basis.ordering`: with ``colamd`` SuperLU
  orders the columns itself and pivots rows partially (threshold ``diag_pivot_thresh``,
  default 1.0); with a symmetric ordering (``amd``, ``metis``: rows matched to a zero-free
  diagonal, then permuted symmetrically) it keeps the column order and pivots rows with
  the threshold ``diag_pivot_thresh`` (default :data:`SYMMETRIC_PIVOT_THRESH` = 0.1),
  preferring the diagonal the ordering was computed for.
* :class:`UmfpackBackend` (SuiteSparse UMFPACK from the ``kvxopt`` wheels) chooses its own
  ordering and strategy.  UMFPACK computes ``P R K Q = L U`` with R a diagonal row scaling
  (kvxopt returns P, Q and R as sparse matrices; ``R`` multiplies), i.e.
  ``row_order[t]`` = the column of P's nonzero in row t, ``col_order[t]`` = the row of
  Q's nonzero in column t and ``s = diag(R)``, pinned by a test against a dense solve.
  The symbolic analysis is kept per pattern: a refactorization of the same pattern
  (Newton steps, crash steps, refactorization after updates) is numeric only.
  UMFPACK pivots by a relative threshold (0.001 on the diagonal under its symmetric
  strategy) that kvxopt does not let us raise; on some bases it grew U to 1e19 for a
  matrix of condition 1e3.  Every UMFPACK factorization is therefore checked by the
  backward error of ``L U v`` against ``P R K Q v`` for one fixed vector v; above
  :data:`UMFPACK_CHECK_TOL` the block is factored by SuperLU with partial pivoting.

The ordering (and the symbolic analysis) is computed once per sparsity pattern and reused;
``last`` on a backend describes the latest factorization (:class:`FactorInfo`).

Budget: before a factorization the backend compares the symbolic estimate of the ordering
(flops, bytes of L + U) with the limits of a :class:`FactorBudget` and raises
:class:`FactorBudgetError` instead of starting a factorization that cannot finish in the
time left or would not fit in memory.  Its seconds are predicted as
``n FACTOR_SECONDS_PER_COLUMN + flops / FLOP_RATE`` (:func:`factor_seconds`): SuperLU's
work per column bounds a factorization that fills little (0.74 s for a tridiagonal block
of order 7e5, whose 3.5e6 flops take 2 ms), its flops one that fills.  The ordering is
computed under the same deadline (:mod:`compass_sparse.basis.ordering`: none is started
past it, METIS and AMD only where they and the factorization fit in the time left).
"""

from __future__ import annotations

import hashlib
import logging
import os
import time
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from ..exceptions import FactorBudgetError, OptionError
from ..linalg._dense_kernels import dense_solve_or_none
from ..linalg.blas import single_threaded_blas
from ..linalg.direct import LU_ENVIRONMENT
from .ordering import Ordering, OrderingCache

log = logging.getLogger(__name__)

_I = np.int64

FLOP_RATE = 2.0e9
"""Flops per second assumed by the time check (a fast single core on the supernodal
kernels: the check must never stop a factorization that would have finished).  Measured
rates on the CGE Jacobians were 0.5-2e9 (SuperLU with nested dissection, one core)."""

FACTOR_SECONDS_PER_COLUMN = 6.0e-7
"""Seconds per column of a SuperLU factorization that fills little (symbolic work, the
column's panel and its solves).  Measured 0.6-1.05e-6 on tridiagonal blocks of order 1e5
and 7e5 under AMD, METIS and COLAMD (one core of a shared two-core machine): the low end,
so that the check stops no factorization that would have finished."""


def factor_seconds(n: int, flops: float) -> float:
    """Predicted seconds of a factorization of order n whose symbolic estimate is
    ``flops`` (negative: none, e.g. COLAMD: the work per column alone)."""
    return n * FACTOR_SECONDS_PER_COLUMN + max(flops, 0.0) / FLOP_RATE


BYTES_PER_ENTRY = 16.0
"""Bytes per stored entry of L + U (value + index), plus the manager's copies: x 2."""

SYMMETRIC_PIVOT_THRESH = 0.1
"""Row-pivoting threshold of SuperLU under a symmetric ordering: the diagonal is kept while
``|a_jj| >= 0.1 max_i |a_ij|``.  Measured on the CGE Jacobians against 0.5 and 1.0:
fill 2.0e6 / 2.2e6 / 4.2e6 (static n = 1e4) and 1.6e6 / 1.9e6 / 2.0e6 (dynamic).  The
accuracy threshold pivoting gives up on ill-conditioned bases (forward errors 30x above
partial pivoting at cond 1e9) is won back by the refinement step of the periodic residual
checks (:meth:`BasisManager._refine`, and the BTRAN check)."""

UMFPACK_CHECK_TOL = 1e-9
"""Relative backward error ``||P R K Q v - L U v|| / (||R K|| ||v||)`` (inf-norms) above
which a UMFPACK factorization is rejected for SuperLU with partial pivoting.  A stable
factorization scores 1e-16..1e-13 (random and CGE blocks); the rejected ones (element
growth) scored 1e-3 and more.  1e-9 leaves the residual checks of the basis manager
(1e-10 on solves, with refinement) room."""

AUTO_SYMMETRIC_MIN_N = 400
"""``backend="auto"``: blocks of at least this order are factored by SuperLU in a
symmetric fill-reducing ordering (AMD / nested dissection); smaller ones by SuperLU with
COLAMD, whose set-up costs least (every choice takes about a millisecond there).
Crossovers measured on CGE Jacobian blocks: ``benchmarks/bench_basis_lu.py``,
``benchmarks/basis.md``."""



class SingularFactorError(Exception):
    """The backend found an exactly zero pivot."""


@dataclass
class FactorBudget:
    """Limits a factorization is checked against (None = no limit).

    ``deadline`` is a ``time.perf_counter()`` value, ``memory_bytes`` the bytes L + U may
    take (default: 80% of the memory the system reports available when the budget is
    created)."""

    deadline: float | None = None
    memory_bytes: float | None = None

    @staticmethod
    def available_memory() -> float | None:
        """Bytes the system reports available, read at most every ``MEMINFO_MAX_AGE``
        seconds (a small solve creates several budgets; each read cost ~40 us)."""
        now = time.monotonic()
        if _MEMINFO and now - _MEMINFO[0] <= MEMINFO_MAX_AGE:
            return _MEMINFO[1]
        value = None
        try:
            with open("/proc/meminfo") as fh:
                for line in fh:
                    if line.startswith("MemAvailable:"):
                        value = float(line.split()[1]) * 1024.0
                        break
        except OSError:
            pass
        _MEMINFO[:] = [now, value]
        return value


MEMORY_SHARE = 0.8
"""The share of the memory the system reports available that a basis' factors may take
(a factorization, or the sparse engine's storage, that would need more is not started:
MEMORY_LIMIT)."""

MEMINFO_MAX_AGE = 0.5
"""Seconds a reading of the available memory is reused (memory budgets of
factorizations: a factorization that may take 80% of it is refused)."""

_MEMINFO: list = []  # [time.monotonic() of the reading, bytes or None]


@dataclass
class LUFactors:
    L: sp.csc_matrix          # unit lower triangular (diagonal may or may not be stored)
    U: sp.csc_matrix          # upper triangular with diagonal
    row_order: np.ndarray     # position -> row of K
    col_order: np.ndarray     # position -> column of K
    row_scale: np.ndarray | None = None   # indexed by row of K; None = no scaling


@dataclass
class FactorInfo:
    """The latest factorization of a backend: ``backend`` and ``ordering`` used, the
    symbolic estimates (-1 when none), the fill obtained, the seconds spent ordering
    (0 when reused) and factoring."""

    backend: str = ""
    ordering: str = ""
    order: int = 0
    nnz: int = 0
    est_nnz_lu: int = -1
    est_flops: float = -1.0
    nnz_lu: int = 0
    time_ordering: float = 0.0
    time_factor: float = 0.0
    ordering_reused: bool = False

    @property
    def est_bytes(self) -> float:
        return BYTES_PER_ENTRY * self.est_nnz_lu if self.est_nnz_lu >= 0 else -1.0


def umfpack_available() -> bool:
    try:
        # (lazy: kvxopt loads SuiteSparse's libraries; imported where they are used)
        import kvxopt.umfpack  # noqa: F401
    except Exception:
        return False
    return True


def metis_available() -> bool:
    try:
        # (lazy: ~0.07 s of import, for large problems' orderings only)
        import pymetis  # noqa: F401
    except Exception:
        return False
    return True


def _check_budget(info: FactorInfo, budget: FactorBudget | None):
    if budget is None:
        return
    if budget.memory_bytes is not None and info.est_nnz_lu >= 0 \
            and info.est_bytes > budget.memory_bytes:
        raise FactorBudgetError(
            "memory", f"a {info.order} x {info.order} factorization would need about "
            f"{info.est_bytes / 2**30:.1f} GiB for L + U (ordering {info.ordering}, "
            f"{info.est_nnz_lu:.3g} entries); {budget.memory_bytes / 2**30:.1f} GiB allowed")
    if budget.deadline is not None and time.perf_counter() > budget.deadline:
        # Past the deadline nothing is started, with or without an estimate (COLAMD has
        # none: rank repairs and path refactorizations in it ran on past the limit).
        raise FactorBudgetError(
            "time", f"a {info.order} x {info.order} factorization (ordering "
            f"{info.ordering}) after the time limit")
    if budget.deadline is not None:
        left = budget.deadline - time.perf_counter()
        need = factor_seconds(info.order, info.est_flops)
        if need > left:
            flops = f"{info.est_flops:.3g} flops, " if info.est_flops >= 0 else ""
            raise FactorBudgetError(
                "time", f"a {info.order} x {info.order} factorization needs about "
                f"{need:.2g} s ({flops}ordering {info.ordering}); "
                f"{max(left, 0.0):.2g} s left")


def _inverse(p):
    inv = np.empty_like(p)
    inv[p] = np.arange(p.size, dtype=p.dtype)
    return inv


def _permute(K, rows, cols):
    """``K[rows, :][:, cols]`` for CSC K, without the row-indexing copy of scipy."""
    Kc = K[:, cols]
    Kp = sp.csc_matrix((Kc.data, _inverse(rows)[Kc.indices], Kc.indptr), shape=Kc.shape)
    Kp.has_sorted_indices = False
    Kp.sort_indices()
    return Kp


class SuperLUBackend:
    """SuperLU in the ordering of an :class:`~compass_sparse.basis.ordering.OrderingCache`."""

    name = "superlu"

    def __init__(self, ordering="auto", diag_pivot_thresh=None, budget=None):
        self.orderings = OrderingCache(ordering, factor_seconds=factor_seconds)
        self.diag_pivot_thresh = diag_pivot_thresh
        self.budget = budget
        self.last = FactorInfo(backend=self.name)

    def splu(self, K, strict=False, labels=None):
        """(SuperLU object of the ordered K, ordering): ``lu`` factors
        ``K[o.rows][:, o.cols]`` under a symmetric ordering, K itself under COLAMD.
        ``strict`` = COLAMD and partial pivoting, for rank detection.  ``labels``: see
        :meth:`~compass_sparse.basis.ordering.OrderingCache.get`."""
        # (lazy: scipy's linalg adds ~0.15 s to the package's import)
        from scipy.sparse.linalg import splu

        K = sp.csc_matrix(K)
        n = K.shape[0]
        before = self.orderings.computed
        # rank detection keeps to COLAMD with partial pivoting: with a symmetric ordering
        # (fixed column order) the tiny pivots of a singular block marked more columns
        # than its rank deficiency (measured on the rank-repair tests)
        deadline = None if self.budget is None else self.budget.deadline
        o = (Ordering("colamd") if strict
             else self.orderings.get(K, labels=labels, deadline=deadline))
        fresh = self.orderings.computed > before
        info = FactorInfo(self.name, o.method, n, int(K.nnz), o.nnz_lu, o.flops,
                          time_ordering=o.time if fresh else 0.0, ordering_reused=not fresh)
        self.last = info
        _check_budget(info, self.budget)
        t0 = time.perf_counter()
        if o.method == "colamd":
            A, spec, thresh, symm = K, "COLAMD", 1.0, False
        else:
            A, spec, thresh, symm = _permute(K, o.rows, o.cols), "NATURAL", SYMMETRIC_PIVOT_THRESH, True
        if self.diag_pivot_thresh is not None:
            thresh = self.diag_pivot_thresh
        if strict:
            thresh = 1.0
        try:
            lu = splu(A, permc_spec=spec, diag_pivot_thresh=thresh,
                      options=dict(SymmetricMode=symm))
        except RuntimeError as exc:  # "Factor is exactly singular"
            raise SingularFactorError(str(exc)) from exc
        info.time_factor = time.perf_counter() - t0
        return lu, o

    def factor(self, K, strict=False) -> LUFactors:
        """LU of K; ``strict`` asks for COLAMD with partial pivoting, whose tiny pivots
        mark dependent columns reliably (rank repair)."""
        t0 = time.perf_counter()
        lu, o = self.splu(K, strict)
        # Pr A Pc = L U: row i of A sits at position perm_r[i], column j at perm_c[j].
        row_order = _inverse(lu.perm_r.astype(_I))
        col_order = _inverse(lu.perm_c.astype(_I))
        if o.method != "colamd":
            row_order = o.rows[row_order]
            col_order = o.cols[col_order]
        L, U = lu.L, lu.U
        self.last.nnz_lu = int(L.nnz + U.nnz)
        self.last.time_factor = time.perf_counter() - t0
        return LUFactors(L, U, row_order, col_order)

    def solve(self, K, b, labels=None, keep=False):
        """x with K x = b, from one factorization (no factors extracted); with ``keep``
        also the :class:`HeldLU` of K."""
        lu, o = self.splu(K, labels=labels)
        held = HeldLU(lu, o, K.shape[0])
        x = held.solve(b)
        return (x, held) if keep else x


class HeldLU:
    """A SuperLU factorization of a square K kept for later solves with K (e.g. as the
    preconditioner of a nearby matrix): ``solve(b)`` = K^{-1} b."""

    def __init__(self, lu, ordering, n):
        self.lu, self.ordering, self.n = lu, ordering, n

    def solve(self, b):
        b = np.asarray(b, dtype=np.float64)
        if self.ordering.method == "colamd":
            return self.lu.solve(b)
        x = np.empty_like(b)
        x[self.ordering.cols] = self.lu.solve(b[self.ordering.rows])
        return x


def _structure_key(K) -> bytes:
    """Hash of the stored structure of a CSC matrix, stored zeros included: UMFPACK's
    symbolic analysis belongs to the exact structure (the ordering key,
    :func:`~compass_sparse.basis.ordering.pattern_key`, ignores stored zeros)."""
    h = hashlib.blake2b(digest_size=16)
    h.update(np.asarray(K.shape, dtype=_I).tobytes())
    h.update(np.ascontiguousarray(K.indptr, dtype=_I).tobytes())
    h.update(np.ascontiguousarray(K.indices, dtype=_I).tobytes())
    return h.digest()


def _kvx_matrix(K):
    # (lazy: kvxopt loads SuiteSparse's libraries; imported where they are used)
    from kvxopt import matrix, spmatrix

    cols = np.repeat(np.arange(K.shape[1], dtype=_I), np.diff(K.indptr))
    return spmatrix(matrix(np.ascontiguousarray(K.data, dtype=np.float64)),
                    matrix(K.indices.astype(_I)), matrix(cols), K.shape)


def _from_kvx(M):
    cp, ri, v = M.CCS
    return sp.csc_matrix((np.asarray(v).ravel(), np.asarray(ri, dtype=_I).ravel(),
                          np.asarray(cp, dtype=_I).ravel()), shape=M.size)


class UmfpackBackend:
    """UMFPACK (kvxopt); symbolic analysis kept per pattern, numeric factorization each
    time.  UMFPACK orders by itself, so the ordering option must be "auto"."""

    name = "umfpack"

    def __init__(self, budget=None, cache_size=4):
        self.budget = budget
        self._fallback = SuperLUBackend("colamd", budget=budget)
        self.unstable = 0
        self._symbolic = {}
        self._cache_size = cache_size
        self.last = FactorInfo(backend=self.name)
        self.symbolic_reused = 0

    def factor(self, K, strict=False) -> LUFactors:
        # (lazy: kvxopt loads SuiteSparse's libraries; imported where they are used)
        from kvxopt import umfpack

        del strict   # kvxopt exposes no pivot tolerance: UMFPACK's defaults apply

        K = sp.csc_matrix(K)
        K.sort_indices()
        n = K.shape[0]
        key = _structure_key(K)
        A = _kvx_matrix(K)
        t0 = time.perf_counter()
        Fs = self._symbolic.pop(key, None)
        reused = Fs is not None
        if reused:
            self.symbolic_reused += 1
        else:
            try:
                Fs = umfpack.symbolic(A)
            except (ArithmeticError, ValueError) as exc:
                raise SingularFactorError(f"UMFPACK symbolic: {exc}") from exc
        self._symbolic[key] = Fs                  # most recent last
        while len(self._symbolic) > self._cache_size:
            self._symbolic.pop(next(iter(self._symbolic)))
        info = FactorInfo(self.name, "umfpack", n, int(K.nnz),
                          time_ordering=0.0 if reused else time.perf_counter() - t0,
                          ordering_reused=reused)
        self.last = info
        _check_budget(info, self.budget)
        t1 = time.perf_counter()
        try:
            Fn = umfpack.numeric(A, Fs)
        except (ArithmeticError, ValueError) as exc:
            raise SingularFactorError(f"UMFPACK: {exc}") from exc
        Lk, Uk, Pk, Qk, Rk = umfpack.get_numeric(A, Fn)
        L, U = _from_kvx(Lk), _from_kvx(Uk)
        # P: one entry per column; row t of P selects row_order[t] of K
        Ps, Qs, Rs = _from_kvx(Pk), _from_kvx(Qk), _from_kvx(Rk)
        row_order = np.empty(n, dtype=_I)
        row_order[Ps.indices] = np.repeat(np.arange(n, dtype=_I), np.diff(Ps.indptr))
        col_order = Qs.indices.astype(_I)
        s = Rs.diagonal().copy()
        d = U.diagonal()
        if n and (np.any(d == 0.0) or not np.all(np.isfinite(d))):
            raise SingularFactorError("UMFPACK: zero pivot")
        info.nnz_lu = int(L.nnz + U.nnz)
        info.time_factor = time.perf_counter() - t1
        fac = LUFactors(L, U, row_order, col_order, s)
        if n and factor_backward_error(K, fac) > UMFPACK_CHECK_TOL:
            self.unstable += 1
            log.debug("UMFPACK factorization of a %d x %d block unstable; SuperLU instead", n, n)
            try:
                return self._fallback.factor(K, strict=True)
            finally:
                self._fallback.last.time_factor += info.time_factor
                self.last = self._fallback.last
        return fac


def factor_backward_error(K, fac) -> float:
    """``||P S K Q v - L U v||_inf / (||S K||_inf ||v||_inf)`` for one fixed vector v of
    entries in [1, 2) with alternating signs (S the row scaling, P and Q the orders of
    ``fac``): one product with K, L and U, a cheap check that the factors are sound."""
    n = K.shape[0]
    v = (1.0 + (np.arange(n) % 7) / 7.0) * np.where(np.arange(n) % 2, -1.0, 1.0)
    x = np.empty(n)
    x[fac.col_order] = v                      # Q v, in K's column numbering
    Kx = K @ x
    SK_norm = np.asarray(abs(K).sum(axis=1)).ravel()
    if fac.row_scale is not None:
        Kx = Kx * fac.row_scale
        SK_norm = SK_norm * fac.row_scale
    lhs = Kx[fac.row_order]
    Uv = fac.U @ v
    d = fac.L.diagonal()
    Lv = fac.L @ Uv + (1.0 - d) * Uv     # L is unit triangular, its diagonal stored or not
    den = float(SK_norm.max()) * float(np.abs(v).max())
    res = float(np.abs(lhs - Lv).max())
    if not np.isfinite(res):
        return float("inf")
    return res / den if den > 0 else res



def resolve(backend="auto", ordering="auto"):
    """The (backend, ordering) pair an ``auto`` choice stands for: the environment
    variable ``COMPASS_SPARSE_LU`` first (applies only to the ``auto`` fields), then the
    defaults.  ``ordering`` "auto" under SuperLU is chosen per block by the ordering
    cache (see :mod:`compass_sparse.basis.ordering`)."""
    env = os.environ.get(LU_ENVIRONMENT, "").strip()
    if env:
        b, _, o = env.partition(":")
        if backend == "auto" and b and not (b == "umfpack" and ordering != "auto"):
            backend = b           # (an explicit ordering keeps SuperLU, which takes it)
        if ordering == "auto" and o and backend != "umfpack":
            ordering = o
    if backend == "auto":
        backend = "superlu"
    return backend, ordering


class AutoBackend:
    """SuperLU, with COLAMD on blocks below :data:`AUTO_SYMMETRIC_MIN_N` and the ordering
    cache's choice (AMD or nested dissection) above."""

    name = "auto"

    def __init__(self, ordering="auto", diag_pivot_thresh=None, budget=None):
        self.small = SuperLUBackend("colamd", diag_pivot_thresh, budget)
        self.large = SuperLUBackend(ordering, diag_pivot_thresh, budget)
        self.last = self.small.last

    def factor(self, K, strict=False) -> LUFactors:
        b = self.small if K.shape[0] < AUTO_SYMMETRIC_MIN_N else self.large
        try:
            return b.factor(K, strict)
        finally:
            self.last = b.last


DENSE_SOLVE_MAX_N = 200
"""Up to this order :func:`solve_sparse` factors densely (LAPACK getrf): cheaper than a
sparse LU there, and SuperLU's dense supernode kernels were seen to call BLAS with an
illegal leading dimension on small finite blocks (the "DTRSV parameter number 6" message,
with a suspect solve)."""


def _dense_solve(A, b):
    """x with A x = b by LAPACK's LU (getrf + getrs, in one compiled call: the
    package's one dense solve); raises :class:`SingularFactorError` on an exactly
    zero pivot."""
    # Fortran order, as LAPACK factors it
    D = A.toarray(order="F") if sp.issparse(A) else np.array(A, dtype=np.float64, order="F")
    rhs = np.array(b, dtype=np.float64)
    if D.shape[0] == 0:
        return rhs
    with single_threaded_blas():
        x, ok = dense_solve_or_none(D, rhs)
    if not ok:
        raise SingularFactorError("exactly singular (a zero pivot in the dense LU)")
    return x


def solve_sparse(A, b, deadline=None, labels=None, keep=False, backend="auto",
                 ordering="auto"):
    """Solve A x = b (A square sparse) by one LU in the automatic ordering (or the
    environment's choice, as for the basis); raises :class:`SingularFactorError` when A is
    exactly singular, and :class:`FactorBudgetError` when the factorization's estimate does
    not fit in the time left before ``deadline`` (a ``time.perf_counter()`` value) or in 80%
    of the available memory.  For the crash, whose reduced Jacobians are large CGE blocks
    too: ``labels``, the increasing indices of the principal submatrix A, let the ordering
    of a neighbouring index set be carried over (:mod:`compass_sparse.basis.ordering`).
    ``keep``: return ``(x, held)`` with held a :class:`HeldLU` of A, or None when the
    factors were not kept (the dense and UMFPACK routes).  ``backend``, ``ordering``: as
    for :func:`make_backend` (the options ``lu_backend``, ``lu_ordering``)."""
    if A.shape[0] <= DENSE_SOLVE_MAX_N:
        x = _dense_solve(A, b)
        return (x, None) if keep else x
    # the memory check of the basis manager applies here too (80% of what is available):
    # the crash factors blocks as large as the basis'
    avail = FactorBudget.available_memory()
    b_ = make_backend(backend, ordering,
                      budget=FactorBudget(deadline=deadline,
                                          memory_bytes=MEMORY_SHARE * avail if avail else None))
    if isinstance(b_, AutoBackend):
        b_ = b_.small if A.shape[0] < AUTO_SYMMETRIC_MIN_N else b_.large
    if isinstance(b_, SuperLUBackend):
        return b_.solve(A, b, labels=labels, keep=keep)
    f = b_.factor(sp.csc_matrix(A))     # UMFPACK: solve with its factors
    # (lazy: scipy's linalg adds ~0.15 s to the package's import)
    from scipy.sparse.linalg import spsolve_triangular

    w = (f.row_scale * np.asarray(b, dtype=np.float64))[f.row_order]
    L = sp.csr_matrix(f.L)
    y = spsolve_triangular(L, w, lower=True, unit_diagonal=True)
    y = spsolve_triangular(sp.csr_matrix(f.U), y, lower=False)
    x = np.empty_like(y)
    x[f.col_order] = y
    return (x, None) if keep else x


def make_backend(name="auto", ordering="auto", diag_pivot_thresh=None, budget=None):
    """A backend for ``BasisOptions.backend`` / ``ordering`` (validated there)."""
    forced = name != "auto"
    name, ordering = resolve(name, ordering)
    if name == "umfpack":
        if not umfpack_available():
            raise OptionError("backend='umfpack' needs the package kvxopt (SuiteSparse "
                              "wheels): pip install kvxopt")
        if ordering != "auto":
            raise OptionError(f"backend='umfpack' orders by itself; ordering={ordering!r} "
                              "needs backend='superlu'")
        return UmfpackBackend(budget)
    if name != "superlu":
        raise OptionError(f"unknown LU backend {name!r} (from {LU_ENVIRONMENT}?)")
    if ordering == "metis" and not metis_available():
        raise OptionError("ordering='metis' needs the package pymetis")
    if not forced and ordering == "auto":
        return AutoBackend(ordering, diag_pivot_thresh, budget)
    return SuperLUBackend(ordering, diag_pivot_thresh, budget)
