"""The basis manager: sparse LU of the pivotal-path basis with Forrest-Tomlin updates.

Mathematics
-----------
B is n x n; slot s holds ``sign * M[:, j]`` (KIND_M), ``sign * e_j`` (KIND_UNIT) or
``sign * r`` (KIND_DENSE). Ordering the unit slots first,

    P B Q = [[D, C], [0, K']],       D = diag(signs of the unit slots),

where P puts the rows covered by unit columns first and K' = P_K K Q_K is the non-unit
block on the uncovered rows, permuted by the sparse LU backend (``S P_K K Q_K = L_K U_K``,
S an optional row scaling, identity for SuperLU). Hence

    S P B Q = L U,   L = diag(I, L_K),   U = [[D, C], [0, U_K]],   i.e.  B = P^T S^{-1} L U Q^T,

an LU of B in which unit columns cost nothing (an all-unit basis costs O(n)). Indices of
the permuted system are called *positions*.

Forrest-Tomlin update (after k updates U_k = R_k ... R_1 L^{-1} S P B_k Q_k). Replacing
the column at position p by a column a:

* spike  ``s = R_k ... R_1 L^{-1} S P a`` (kept from the FTRAN of a);
* ``y = U^{-T} e_p``; the row eta ``R_{k+1}`` maps ``w_q = w_p - sum_{i>p} c_i w_i`` with
  ``c_i = -u_pp y_i`` and sets ``w_p = 0``; q = n + k is a new position at the end;
* the new diagonal is computed twice: ``d1 = d_p u_pp`` (d = B^{-1} a, the FTRAN column)
  and ``d2 = s_p - c^T s = u_pp y^T s``; the update is REFUSED when the pivot is relatively
  tiny and triggers a refactorization when d1 and d2 disagree (see the tolerances);
* column p of U becomes an empty "dead" column with unit diagonal, s (without entry p)
  is appended as column q with diagonal d2. Index order stays a triangular order.

Solves (vectors over positions, length n + k):

* FTRAN  ``B x = a``:   w = S P a;  w = L^{-1} w;  w = R_k...R_1 w;  w = U^{-1} w;  x = Q^T w;
* BTRAN  ``B^T y = c``: w = Q^T c;  w = U^{-T} w;  w = R_1^T...R_k^T w;  w = L^{-T} w;
  y = P^T S w.

The solves are dense-vector solves of cost O(n + k + nnz(L) + nnz(U) + nnz(R)); the
column-oriented ones (L in FTRAN, U in FTRAN, L^T in BTRAN) skip zeros so that a sparse
right-hand side only pays O(n) index checks on top of its own fill.

Tolerances and triggers (defaults in :class:`~compass_sparse.basis.types.BasisOptions`):
``update_limit`` 50 updates, ``fill_factor`` 2.0, ``pivot_tolerance`` 1e-11 (refusal),
``stability_tolerance`` 1e-8 (|d1 - d2| / |d1|), a residual check every
``residual_check_frequency`` = 20 FTRANs against ``residual_tolerance`` 1e-10, and
``rank_tolerance`` 1e-11 for the rank repair of a fresh factorization (see
:mod:`compass_sparse.basis.repair`).

Reused factors (``reuse_factors``): a basis may solve on the LU of an older one by GMRES
(:mod:`compass_sparse.basis.reuse`).  Should the fresh factorization that a failed reused
solve asks for find B singular (a rank repair changes the slot table the caller knows),
:class:`FactorReuseFailed` is raised: the caller starts again with :meth:`factor`, which
then factors afresh.  The same holds when a residual check's fresh factorization finds
the basis singular (:class:`SolveRepairedBasis`, a subclass).  The factors themselves --
L, U, the row etas and their solves -- are :mod:`compass_sparse.basis.factors`; the
condition estimate and the explicit B are :mod:`compass_sparse.basis.debug`.
"""

from __future__ import annotations

import logging
import time

import numpy as np
import scipy.sparse as sp

from ..exceptions import CompassError, ProblemError, ShapeError, SingularBasisError
from . import _kernels as kern
from . import debug, products
from .backends import MEMORY_SHARE, FactorBudget, make_backend
from .factors import UpdatedFactors
from .repair import select_regular_block
from .reuse import FactorReuse
from .types import (KIND_DENSE, KIND_M, KIND_UNIT, BasisOptions, BasisStats,
                    FactorReport, UpdateStatus)

_I = np.int64

log = logging.getLogger(__name__)

_REFINE_ABOVE = 1e-14
"""A residual check that finds a backward error above this (and below the residual
tolerance) refines the solution once (:meth:`BasisManager._refine`)."""


class FactorReuseFailed(CompassError):
    """A basis solved on reused factors turned out singular when factored afresh: its rank
    repair changed the slot table, so the caller must call :meth:`BasisManager.factor`
    again (it factors afresh)."""


class SolveRepairedBasis(FactorReuseFailed):
    """A residual check found a solve inaccurate, the basis was factored afresh, and that
    factorization found it singular: its rank repair changed the slot table, so the
    solution asked for is not of the caller's basis.  As for :class:`FactorReuseFailed`,
    the caller starts again with :meth:`BasisManager.factor` (before, the change went
    unreported and a caller's slot table no longer matched the factors)."""


def _readonly(a):
    v = a.view()
    v.flags.writeable = False
    return v


class _SpikeCache:
    __slots__ = ("key", "version", "spike", "d")

    def __init__(self, key, version, spike, d):
        self.key, self.version, self.spike, self.d = key, version, spike, d


class BasisManager:
    """Owner of the LU factors of the basis B (see the module docstring).

    Parameters
    ----------
    M : scipy.sparse matrix (n x n), any format; converted to CSC once.
    options : BasisOptions, optional.
    """

    def __init__(self, M, options: BasisOptions | None = None):
        self.options = options if options is not None else BasisOptions()
        o = self.options
        mem = o.memory_limit
        if mem is None:
            avail = FactorBudget.available_memory()
            mem = MEMORY_SHARE * avail if avail is not None else None
        self.budget = FactorBudget(o.deadline, None if mem == np.inf else mem)
        self._backend = make_backend(o.backend, o.ordering, o.diag_pivot_thresh, self.budget)
        self._Mc = self._absMc = None
        self._check_matrix(M, first=True)
        n = self.n
        self._r = None
        self._kinds = np.full(n, KIND_UNIT, dtype=_I)
        self._indices = np.arange(n, dtype=_I)
        self._signs = np.ones(n)
        self._unit_slot = np.full(n, -1, dtype=_I)
        self._m_slot = np.full(n, -1, dtype=_I)
        self._dense_slot = -1
        self._factored = False
        self._version = 0
        self._cache = None
        self._n_ftran = 0
        self._reusing = False   # the held factors belong to an older basis (GMRES solves)
        self.reuse = FactorReuse(self)  # the factors solved on when reusing
        self._prefetch = None   # (version, B^{-1} r) solved with an FTRAN on reused factors
        self._lu = None         # the factors (UpdatedFactors), made by the first factor()
        self.stats = BasisStats()
        self.last_report = FactorReport()
        kern.warmup()

    # ------------------------------------------------------------------ input
    def _check_matrix(self, M, first=False):
        """Validate M now; its canonical copy is made when first needed (:attr:`_M`): a
        Newton path that ends by the direct step never factors, so never needs it."""
        if not sp.issparse(M):
            raise ShapeError("M must be a scipy.sparse matrix")
        if M.shape[0] != M.shape[1]:
            raise ShapeError(f"M must be square, got {M.shape}")
        if not first and M.shape[0] != self.n:
            raise ShapeError(f"M must be {self.n} x {self.n}, got {M.shape}")
        data = getattr(M, "data", None)
        if isinstance(data, np.ndarray) and data.size and not np.all(np.isfinite(data)):
            raise ProblemError("M contains NaN or Inf")
        self._pending = M
        self.n = M.shape[0]

    @property
    def _M(self):
        """M as canonical CSC (float64, summed duplicates, sorted indices; a copy)."""
        if self._pending is not None:
            M = sp.csc_matrix(self._pending, dtype=np.float64, copy=True)
            self._pending = None
            if M.nnz and not np.all(np.isfinite(M.data)):
                raise ProblemError("M contains NaN or Inf")
            M.sum_duplicates()
            M.sort_indices()
            old = self._Mc
            if old is not None and not (
                    M.indptr.size == old.indptr.size and M.indices.size == old.indices.size
                    and np.array_equal(M.indptr, old.indptr)
                    and np.array_equal(M.indices, old.indices)):
                self.reuse.held = None   # another pattern: held factors are no preconditioner
            self._Mc, self._absMc = M, abs(M)
        return self._Mc

    @property
    def matrix(self):
        """M as canonical CSC (read only)."""
        return self._M

    @property
    def _absM(self):
        """|M| (of the canonical copy)."""
        self._M  # noqa: B018 - loads a pending matrix
        return self._absMc

    def set_matrix(self, M):
        """Replace M (same order; the pattern may change). The factors become stale:
        call :meth:`factor` or :meth:`refactor` before the next solve (with
        ``reuse_factors`` and an unchanged pattern, :meth:`factor` may keep them as the
        preconditioner of the new basis)."""
        self._check_matrix(M)
        self._invalidate()

    def set_dense_column(self, r):
        """Set the dense column (covering vector) r, float64 of length n. If a slot holds
        it, the factors become stale (refactor before solving)."""
        r = np.array(r, dtype=np.float64).ravel()
        if r.shape != (self.n,):
            raise ShapeError(f"dense column must have length {self.n}, got {r.shape}")
        if not np.all(np.isfinite(r)):
            raise ProblemError("dense column contains NaN or Inf")
        self._r = r
        if self._dense_slot >= 0 or np.any(self._kinds == KIND_DENSE):
            self._invalidate()

    def _invalidate(self):
        self._prefetch = None
        if self._factored and not self._reusing and self.options.reuse_factors:
            # the factors stay valid for the basis they were computed for: keep what it was
            self.reuse.held = (self._kinds.copy(), self._indices.copy(), self._signs.copy())
        self._factored = False
        self._cache = None
        self._version += 1

    # -------------------------------------------------------------- slot table
    @property
    def kinds(self):
        return _readonly(self._kinds)

    @property
    def indices(self):
        return _readonly(self._indices)

    @property
    def signs(self):
        return _readonly(self._signs)

    @property
    def is_factored(self) -> bool:
        return self._factored

    @property
    def factors(self):
        """The :class:`~compass_sparse.basis.factors.UpdatedFactors` of the last
        factorization (None before the first)."""
        return self._lu

    @property
    def num_updates(self) -> int:
        """Forrest-Tomlin updates since the last factorization."""
        return self._lu.k if self._factored else 0

    def slot_of_unit(self, row) -> int:
        return int(self._unit_slot[row])

    def slot_of_m(self, j) -> int:
        return int(self._m_slot[j])

    def slot_of_dense(self) -> int:
        return int(self._dense_slot)

    def _rebuild_maps(self):
        n = self.n
        self._unit_slot = np.full(n, -1, dtype=_I)
        self._m_slot = np.full(n, -1, dtype=_I)
        u = np.flatnonzero(self._kinds == KIND_UNIT)
        self._unit_slot[self._indices[u]] = u
        m = np.flatnonzero(self._kinds == KIND_M)
        self._m_slot[self._indices[m]] = m
        d = np.flatnonzero(self._kinds == KIND_DENSE)
        self._dense_slot = int(d[0]) if d.size else -1

    def _check_column(self, kind, index, sign):
        kind = int(kind)
        sign = float(sign)
        if kind not in (KIND_M, KIND_UNIT, KIND_DENSE):
            raise ProblemError(f"unknown column kind {kind}")
        if not np.isfinite(sign) or sign == 0.0:
            raise ProblemError(f"column sign must be finite and nonzero, got {sign}")
        if kind == KIND_DENSE:
            if self._r is None:
                raise ProblemError("KIND_DENSE used before set_dense_column()")
            index = 0
        else:
            index = int(index)
            if not 0 <= index < self.n:
                raise ProblemError(f"column index {index} out of range [0, {self.n})")
        return kind, index, sign

    # ---------------------------------------------------------- factorization
    def factor(self, kinds, indices, signs) -> FactorReport:
        """Set the slot table and factorize B from scratch (with rank repair)."""
        self._M  # noqa: B018 - a pending matrix decides whether held factors still fit
        n = self.n
        kinds = np.asarray(kinds).astype(_I).ravel()
        indices = np.asarray(indices).astype(_I).ravel()
        signs = np.asarray(signs, dtype=np.float64).ravel()
        if kinds.shape != (n,) or indices.shape != (n,) or signs.shape != (n,):
            raise ShapeError(f"kinds, indices and signs must have length {n}")
        if np.any((kinds < 0) | (kinds > 2)):
            raise ProblemError("kinds must be KIND_M, KIND_UNIT or KIND_DENSE")
        if np.any(~np.isfinite(signs) | (signs == 0.0)):
            raise ProblemError("signs must be finite and nonzero")
        nd = kinds != KIND_DENSE
        if np.any((indices[nd] < 0) | (indices[nd] >= n)):
            raise ProblemError("column index out of range")
        if np.any(~nd) and self._r is None:
            raise ProblemError("KIND_DENSE used before set_dense_column()")
        indices = indices.copy()
        indices[~nd] = 0
        self._kinds, self._indices, self._signs = kinds.copy(), indices, signs.copy()
        self._prefetch = None
        if self.reuse.can_reuse(self._lu) or self.reuse.offer_fits():
            self._rebuild_maps()
            self._factored = True
            self._reusing = True
            self._cache = None
            self._version += 1
            self.stats.reuses += 1
            self.last_report = FactorReport()
            return self.last_report
        return self._factorize()

    @property
    def holds_offer(self) -> bool:
        """Whether offered factors (:meth:`offer_factors`) wait for the next factor()."""
        return self.reuse.offered is not None

    def offer_factors(self, labels, held):
        """Offer the LU ``held`` of a matrix close to the principal block ``M[labels,
        labels]`` (see :meth:`compass_sparse.basis.reuse.FactorReuse.offer`)."""
        self.reuse.offer(labels, held)

    @property
    def reusing(self) -> bool:
        """True while solves run on the factors of an older basis (GMRES)."""
        return self._factored and self._reusing

    def _leave_reuse(self):
        """Factor the current slot table afresh; raise :class:`FactorReuseFailed` when the
        basis turns out singular (its repair changed the slot table)."""
        self.stats.reuse_fallbacks += 1
        rep = self._factorize()
        if rep.rank_deficiency:
            raise FactorReuseFailed("the basis solved on reused factors is singular")

    def refactor(self) -> FactorReport:
        """Factorize the current slot table again (afresh, also when reusing)."""
        return self._factorize()

    def nonunit_columns(self, slots):
        """CSC matrix (n x len(slots)) of the non-unit columns of ``slots``."""
        n = self.n
        kinds, idx, sg = self._kinds[slots], self._indices[slots], self._signs[slots]
        parts_p, parts_i, parts_x = [], [], []
        M = self._M
        counts = np.zeros(slots.size, dtype=_I)
        is_m = kinds == KIND_M
        if np.any(is_m):
            js = idx[is_m]
            starts, ends = M.indptr[js], M.indptr[js + 1]
            cnt = ends - starts
            counts[is_m] = cnt
            tot = int(cnt.sum())
            # gather the columns' entries without a Python loop
            offs = np.repeat(starts - np.concatenate(([0], np.cumsum(cnt)[:-1])), cnt)
            take = np.arange(tot, dtype=_I) + offs
            parts_i.append(M.indices[take].astype(_I))
            parts_x.append(M.data[take] * np.repeat(sg[is_m], cnt))
            parts_p.append(np.repeat(np.flatnonzero(is_m), cnt))
        dn = np.flatnonzero(kinds == KIND_DENSE)
        if dn.size:
            rnz = np.flatnonzero(self._r)
            for c in dn:
                counts[c] = rnz.size
                parts_i.append(rnz.astype(_I))
                parts_x.append(self._r[rnz] * sg[c])
                parts_p.append(np.full(rnz.size, c, dtype=_I))
        if not parts_i:
            return sp.csc_matrix((n, slots.size))
        ii = np.concatenate(parts_i)
        xx = np.concatenate(parts_x)
        cc = np.concatenate(parts_p)
        order = np.argsort(cc, kind="stable")
        indptr = np.concatenate(([0], np.cumsum(counts))).astype(_I)
        return sp.csc_matrix((xx[order], ii[order], indptr), shape=(n, slots.size))

    def _factorize(self) -> FactorReport:
        t0 = time.perf_counter()
        o = self.options
        n = self.n
        kinds, idx = self._kinds, self._indices
        report = FactorReport()

        is_unit = kinds == KIND_UNIT
        us = np.flatnonzero(is_unit)
        _, first = np.unique(idx[us], return_index=True)
        good_units = us[first]
        dup_units = np.setdiff1d(us, good_units)
        covered = np.zeros(n, bool)
        covered[idx[good_units]] = True
        R2 = np.flatnonzero(~covered)
        S2 = np.flatnonzero(~is_unit)
        BS = self.nonunit_columns(S2)                       # n x |S2|
        K = sp.csc_matrix(BS[R2, :]) if S2.size else sp.csc_matrix((R2.size, 0))
        if S2.size:
            rows_k, cols_k, fac = select_regular_block(K, self._backend, o.rank_tolerance,
                                                       o.dense_rank_limit)
        else:
            rows_k, cols_k, fac = np.zeros(0, _I), np.zeros(0, _I), None

        # --- repair: left-out slots get unit columns on rows without a pivot
        drop_cols = np.setdiff1d(np.arange(S2.size), cols_k)
        deficient = np.concatenate((dup_units, S2[drop_cols])).astype(_I)
        free_rows = np.setdiff1d(R2, R2[rows_k])
        if deficient.size != free_rows.size:  # pragma: no cover - invariant
            raise SingularBasisError("internal error in rank repair")
        for s, row in zip(deficient.tolist(), free_rows.tolist()):
            report.replaced.append((s, int(kinds[s]), int(idx[s]), float(self._signs[s]),
                                    int(row)))
            self._kinds[s] = KIND_UNIT
            self._indices[s] = row
            self._signs[s] = 1.0
        report.rank_deficiency = len(report.replaced)
        if report.rank_deficiency:
            self.stats.rank_repairs += 1

        # --- positions: unit slots first, then the LU order of K
        units = np.flatnonzero(self._kinds == KIND_UNIT)
        m1 = units.size
        mk = cols_k.size
        assert m1 + mk == n
        rowpos = np.empty(n, dtype=_I)
        rowpos[self._indices[units]] = np.arange(m1, dtype=_I)
        slot_at = np.empty(n, dtype=_I)
        slot_at[:m1] = units
        Ud = np.ones(n)
        Ud[:m1] = self._signs[units]
        rscale = None
        # L and U of B as CSC arrays over positions (compiled assembly, no sort)
        if mk:
            krows = R2[rows_k][fac.row_order]          # global row at K position t
            kcols = cols_k[fac.col_order]              # BS column at K position t
            rowpos[krows] = m1 + np.arange(mk, dtype=_I)
            slot_at[m1:] = S2[kcols]
            if fac.row_scale is not None:
                rscale = np.ones(n)
                rscale[R2[rows_k]] = fac.row_scale
            Lk, Uk = sp.csc_matrix(fac.L), sp.csc_matrix(fac.U)
            C = BS[:, kcols]       # its entries in unit-covered rows form the C block
            Ud[m1:] = Uk.diagonal()
            # SuperLU's factors come with int32 indices: the kernel takes them as they
            # are (widening them cost 0.6 s per factorization at n = 1e5)
            it = np.int32 if max(Lk.nnz, Uk.nnz, C.nnz) < 2**31 - 1 else _I
            parts = [(F.indptr.astype(it, copy=False), F.indices.astype(it, copy=False),
                      F.data) for F in (Lk, Uk, C)]
        else:
            e = (np.zeros(1, _I), np.zeros(0, _I), np.zeros(0))
            parts = [e, e, e]
        # (the kernel's int64 arrays are kept as they are: a scipy matrix of them would
        # narrow the indices to int32, and widening them back cost ~1 s per factorization
        # at n = 1e5)
        Lx, Li, Lp = kern.assemble_triangle(n, m1, *parts[0], True, *parts[2], rowpos)
        Ux, Ui, Up = kern.assemble_triangle(n, m1, *parts[1], False, *parts[2], rowpos)
        self._lu = UpdatedFactors(n, m1, rowpos, slot_at, Ud, rscale, (Lx, Li, Lp),
                                  (Ux, Ui, Up), o.update_limit)
        self._rebuild_maps()
        self._factored = True
        self._reusing = False
        self.reuse.reset()
        self._threshold_pivoting = bool(mk) and self._backend.last.ordering in ("amd", "metis")
        self._residual_refactored = False
        self._cache = None
        self._version += 1
        st = self.stats
        st.factorizations += 1
        st.nnz_L, st.nnz_U, st.nnz_eta = self._lu.nnzL, self._lu.nnzU, 0
        if mk:
            self._record_lu(self._backend.last)
        st.time_factor += time.perf_counter() - t0
        report.ok = True
        self.last_report = report
        return report

    def _record_lu(self, info):
        st = self.stats
        st.backend, st.ordering = info.backend, info.ordering
        if not info.ordering_reused:
            st.orderings_computed += 1
            st.time_ordering += info.time_ordering
        st.est_nnz_lu = max(st.est_nnz_lu, info.est_nnz_lu)
        st.est_flops = max(st.est_flops, info.est_flops)
        st.est_bytes = max(st.est_bytes, info.est_bytes)
        st.max_nnz_lu = max(st.max_nnz_lu, info.nnz_lu)

    # ------------------------------------------------------------------ solves
    def fresh_factors(self):
        """Factors of the current slot table itself (not reused ones of an older basis)."""
        self._require()
        if self._reusing:
            self._leave_reuse()

    def _require(self):
        if not self._factored:
            raise CompassError("basis is not factorized: call factor() or refactor() "
                               "(after set_matrix/set_dense_column)")

    def _column(self, kind, index, sign):
        if kind == KIND_M:
            a, b = self._M.indptr[index], self._M.indptr[index + 1]
            return self._M.indices[a:b].astype(_I), self._M.data[a:b] * sign
        if kind == KIND_UNIT:
            return np.array([index], dtype=_I), np.array([sign])
        nz = np.flatnonzero(self._r)
        return nz, self._r[nz] * sign

    def ftran(self, rhs):
        """Solve B x = rhs (dense rhs of length n); returns x indexed by slot."""
        self._require()
        t0 = time.perf_counter()
        rhs = np.asarray(rhs, dtype=np.float64).ravel()
        if rhs.shape != (self.n,):
            raise ShapeError(f"rhs must have length {self.n}")
        if self._reusing:
            if self._r is not None and self._prefetch is None:
                # The path solves with its covering vector next (t enters): both in
                # lockstep, sharing the preconditioner solves.
                x, d = self.reuse.solve(rhs, (self._r,))
                self._prefetch = (self._version, d)
            else:
                x = self.reuse.solve(rhs)
            self.stats.time_solve += time.perf_counter() - t0
            self.stats.ftran_calls += 1
            if x is not None:
                return x
            self._leave_reuse()
            t0 = time.perf_counter()
        w = self._lu.work()
        self._lu.scatter_rhs(w, np.arange(self.n), rhs)
        x, _ = self._lu.ftran_work(w, False)
        self.stats.time_solve += time.perf_counter() - t0
        self.stats.ftran_calls += 1
        x = self._maybe_check(x, rhs, None)
        return x

    def ftran_column(self, kind, index, sign=1.0):
        """Solve B d = column(kind, index, sign); caches the spike for :meth:`replace`."""
        self._require()
        kind, index, sign = self._check_column(kind, index, sign)
        t0 = time.perf_counter()
        if self._reusing:
            pf = self._prefetch
            if kind == KIND_DENSE and pf is not None and pf[0] == self._version \
                    and pf[1] is not None:
                self.stats.ftran_calls += 1
                return pf[1] * sign
            rhs = np.zeros(self.n)
            rows, vals = self._column(kind, index, sign)
            np.add.at(rhs, rows, vals)
            d = self.reuse.solve(rhs)
            if d is not None:  # (no spike: a replacement factors afresh first)
                self.stats.time_solve += time.perf_counter() - t0
                self.stats.ftran_calls += 1
                return d
            self._leave_reuse()
        d = self._ftran_column(kind, index, sign)
        self.stats.time_solve += time.perf_counter() - t0
        self.stats.ftran_calls += 1
        return self._maybe_check(d, None, (kind, index, sign))

    def _ftran_column(self, kind, index, sign):
        rows, vals = self._column(kind, index, sign)
        w = self._lu.work()
        self._lu.scatter_rhs(w, rows, vals)
        d, spike = self._lu.ftran_work(w, True)
        self._cache = _SpikeCache((kind, index, sign), self._version, spike, d)
        return d

    def btran(self, c):
        """Solve B^T y = c (c indexed by slot); returns y indexed by row."""
        self._require()
        t0 = time.perf_counter()
        c = np.asarray(c, dtype=np.float64).ravel()
        if c.shape != (self.n,):
            raise ShapeError(f"c must have length {self.n}")
        if self._reusing:
            self._leave_reuse()
        y = self._lu.btran_work(c)
        f = self.options.residual_check_frequency
        self.stats.btran_calls += 1
        if f and self.stats.btran_calls % f == 0 and self._threshold_pivoting:
            # the transposed counterpart of the FTRAN check: refine once when the
            # backward error is above machine level (threshold pivoting only)
            self.stats.residual_checks += 1
            err = self._backward_error_t(y, c)
            if np.isfinite(err) and err > _REFINE_ABOVE:
                y2 = y + self._lu.btran_work(c - self.rmatvec(y))
                if np.all(np.isfinite(y2)) and self._backward_error_t(y2, c) < err:
                    y = y2
        self.stats.time_solve += time.perf_counter() - t0
        return y

    def rmatvec(self, y):
        """B^T @ y (indexed by slot) for y indexed by row."""
        return products.rmatvec(self._kinds, self._indices, self._signs, self._M, self._r, y)

    def _backward_error_t(self, y, c):
        res = np.abs(self.rmatvec(y) - c).max()
        den = np.abs(c).max() + self.norm_inf_B() * np.abs(y).max()
        return float(res / den) if den > 0 else float(res)

    # ---------------------------------------------------------- residual check
    def matvec(self, x):
        """B @ x for x indexed by slot (uses the current slot table)."""
        return products.matvec(self._kinds, self._indices, self._signs, self._M, self._r, x)

    def norm_inf_B(self):
        """||B||_inf of the current slot table."""
        return products.norm_inf(self._kinds, self._indices, self._signs, self._absM,
                                 self._r)

    def backward_error(self, x, rhs):
        """||B x - rhs||_inf / (||rhs||_inf + ||B||_inf ||x||_inf)."""
        return products.backward_error(self.matvec(x) - rhs, rhs, x, self.norm_inf_B())

    def _maybe_check(self, x, rhs, col):
        f = self.options.residual_check_frequency
        self._n_ftran += 1
        if not np.all(np.isfinite(x)) and self._lu.k > 0:
            # a non-finite solution after updates: never hand it out
            return self._recover(x, rhs, col)
        if f == 0 or self._n_ftran % f:
            return x
        if rhs is None:
            rhs = np.zeros(self.n)
            rows, vals = self._column(*col)
            np.add.at(rhs, rows, vals)
        self.stats.residual_checks += 1
        err = self.backward_error(x, rhs)
        if err <= self.options.residual_tolerance:
            if err > _REFINE_ABOVE:
                x = self._refine(x, rhs, err, col)
            return x
        return self._recover(x, rhs, col)

    def _refine(self, x, rhs, err, col):
        """One step of iterative refinement, kept when it lowers the backward error.
        Threshold pivoting (symmetric orderings) may leave a backward error well above
        machine precision though below the residual tolerance; the check that measured
        it makes the correction cheap (one more solve)."""
        w = self._lu.work()
        self._lu.scatter_rhs(w, np.arange(self.n), rhs - self.matvec(x))
        dx, _ = self._lu.ftran_work(w, False)
        x2 = x + dx
        if np.all(np.isfinite(x2)) and self.backward_error(x2, rhs) < err:
            x = x2
            if col is not None and self._cache is not None:
                self._cache.d = x
        return x

    def _recover(self, x, rhs, col):
        if rhs is None:
            rhs = np.zeros(self.n)
            rows, vals = self._column(*col)
            np.add.at(rhs, rows, vals)
        if self._lu.k > 0 or not self._residual_refactored:
            # (a fresh factorization is retried once: it may have been damaged)
            self.stats.refactor_by_residual += 1
            rep = self._factorize()
            self._residual_refactored = True
            if rep.rank_deficiency:
                raise SolveRepairedBasis("a solve was inaccurate and the basis, factored "
                                         "afresh, is singular: its repair changed the "
                                         "slot table")
        if col is not None:
            x = self._ftran_column(*col)
        else:
            w = self._lu.work()
            self._lu.scatter_rhs(w, np.arange(self.n), rhs)
            x, _ = self._lu.ftran_work(w, False)
        # one step of iterative refinement
        r = rhs - self.matvec(x)
        w = self._lu.work()
        self._lu.scatter_rhs(w, np.arange(self.n), r)
        dx, _ = self._lu.ftran_work(w, False)
        x2 = x + dx
        if np.all(np.isfinite(x2)) and self.backward_error(x2, rhs) < self.backward_error(x, rhs):
            x = x2
        if col is not None and self._cache is not None:
            self._cache.d = x
        return x

    # ----------------------------------------------------------------- update
    def replace(self, slot, kind, index, sign=1.0) -> UpdateStatus:
        """Replace the column in ``slot`` by column (kind, index, sign).

        Uses the spike of the last :meth:`ftran_column` call when it was for this
        column; otherwise computes it. Returns an :class:`UpdateStatus`.
        """
        self._require()
        slot = int(slot)
        if not 0 <= slot < self.n:
            raise ProblemError(f"slot {slot} out of range")
        kind, index, sign = self._check_column(kind, index, sign)
        t0 = time.perf_counter()
        if self._reusing:
            self._leave_reuse()
        try:
            return self._replace(slot, kind, index, sign)
        finally:
            self.stats.time_update += time.perf_counter() - t0

    def _replace(self, slot, kind, index, sign):
        o = self.options
        key = (kind, index, sign)
        c = self._cache
        if c is None or c.key != key or c.version != self._version:
            self._ftran_column(kind, index, sign)
            c = self._cache
        if self._lu.k >= o.update_limit:
            self.stats.refactor_by_count += 1
            return self._replace_by_refactor(slot, kind, index, sign)
        outcome = self._lu.update(slot, c.spike, c.d, o.pivot_tolerance,
                                  o.stability_tolerance, o.fill_factor)
        if outcome == "refused":
            self.stats.refused_updates += 1
            return UpdateStatus.REFUSED
        if outcome == "unstable":
            self.stats.refactor_by_stability += 1
            return self._replace_by_refactor(slot, kind, index, sign)
        if outcome == "fill":
            self.stats.refactor_by_fill += 1
            return self._replace_by_refactor(slot, kind, index, sign)
        self._set_slot(slot, kind, index, sign)
        self._cache = None
        self._version += 1
        st = self.stats
        st.updates += 1
        st.nnz_U, st.nnz_eta = self._lu.nnzU, self._lu.nnzR
        return UpdateStatus.OK

    def _set_slot(self, slot, kind, index, sign):
        ok, oi = self._kinds[slot], self._indices[slot]
        if ok == KIND_UNIT and self._unit_slot[oi] == slot:
            self._unit_slot[oi] = -1
        elif ok == KIND_M and self._m_slot[oi] == slot:
            self._m_slot[oi] = -1
        elif ok == KIND_DENSE and self._dense_slot == slot:
            self._dense_slot = -1
        self._kinds[slot], self._indices[slot], self._signs[slot] = kind, index, sign
        if kind == KIND_UNIT:
            self._unit_slot[index] = slot
        elif kind == KIND_M:
            self._m_slot[index] = slot
        else:
            self._dense_slot = slot

    def _replace_by_refactor(self, slot, kind, index, sign):
        old = (int(self._kinds[slot]), int(self._indices[slot]), float(self._signs[slot]))
        self._kinds[slot], self._indices[slot], self._signs[slot] = kind, index, sign
        rep = self._factorize()
        if rep.rank_deficiency == 0:
            return UpdateStatus.REFACTORED
        # the new basis is singular: restore the old one (regular) and refuse
        for (s, ok, oi, osg, _row) in rep.replaced:
            self._kinds[s], self._indices[s], self._signs[s] = ok, oi, osg
        self._kinds[slot], self._indices[slot], self._signs[slot] = old
        rep2 = self._factorize()
        if rep2.rank_deficiency:
            return UpdateStatus.REPAIRED  # the old basis, repaired: see last_report
        self.stats.refused_updates += 1
        return UpdateStatus.REFUSED

    # ----------------------------------------------------------- diagnostics
    def condest(self):
        """Estimate of the 1-norm condition number of B (:mod:`compass_sparse.basis.debug`)."""
        return debug.condest(self)

    def condest_check(self, limit=1e12):
        """True when the condition estimate is below ``limit``."""
        return self.condest() < limit

    def dense_basis(self):
        """The explicit dense B of the current slot table (tests and debugging only)."""
        return debug.dense_basis(self)

    def solve_quiet(self, v):
        """B^{-1} v with the current factors, without counts or checks."""
        return self._lu.solve(v)

    def solve_quiet_t(self, v):
        """B^{-T} v, without counts."""
        st = self.stats.btran_calls, self.stats.time_solve
        y = self.btran(np.asarray(v, float).ravel())
        self.stats.btran_calls, self.stats.time_solve = st
        return y

