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

Reused factors (``reuse_factors``).  Successive Newton steps factor bases with the same
slot table whose M columns have moved a little.  After :meth:`set_matrix` with an unchanged
pattern, :meth:`factor` with the slot table of the held factors keeps them: they are the
LU of an older basis P, and each solve with the new B runs GMRES preconditioned by P
(:mod:`compass_sparse.basis.krylov`).  A solve is accepted only when its true backward
error is at most ``reuse_tolerance``; otherwise, and before any column replacement or
BTRAN, the basis is factored afresh.  Should that fresh factorization find B singular (a
rank repair changes the slot table the caller knows), :class:`FactorReuseFailed` is
raised: the caller starts again with :meth:`factor`, which then factors afresh.  The same
holds when a residual check's fresh factorization finds the basis singular
(:class:`SolveRepairedBasis`, a subclass).
"""

from __future__ import annotations

import logging
import time

import numpy as np
import scipy.sparse as sp

from ..linalg.blas import single_threaded_blas
from ..exceptions import CompassError, ProblemError, ShapeError, SingularBasisError
from . import _kernels as kern
from .backends import BYTES_PER_ENTRY, FactorBudget, make_backend
from .repair import select_regular_block
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
            mem = 0.8 * avail if avail is not None else None
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
        self._held = None       # (kinds, indices, signs) of the basis of the held factors
        self._reuse_aged = False
        self._offered = None    # (labels, HeldLU) of a principal block of M, e.g. the crash's
        self._psolve = self._solve_quiet   # the preconditioner of the solves when reusing
        self._prefetch = None   # (version, B^{-1} r) solved with an FTRAN on reused factors
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
                self._held = None   # another pattern: the held factors are no preconditioner
            self._Mc, self._absMc = M, abs(M)
        return self._Mc

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
            self._held = (self._kinds.copy(), self._indices.copy(), self._signs.copy())
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
    def num_updates(self) -> int:
        """Forrest-Tomlin updates since the last factorization."""
        return self._k if self._factored else 0

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
        if self._can_reuse() or self._offer_fits():
            self._rebuild_maps()
            self._factored = True
            self._reusing = True
            self._cache = None
            self._version += 1
            self.stats.reuses += 1
            self.last_report = FactorReport()
            return self.last_report
        return self._factorize()

    def _can_reuse(self):
        h = self._held
        ok = (self.options.reuse_factors and h is not None and not self._reuse_aged
              and self._nnz_base >= self.options.reuse_min_nnz
              and np.array_equal(h[0], self._kinds) and np.array_equal(h[1], self._indices)
              and np.array_equal(h[2], self._signs))
        if ok:
            self._psolve = self._solve_quiet
        return ok

    @property
    def holds_offer(self) -> bool:
        """Whether offered factors (:meth:`offer_factors`) wait for the next factor()."""
        return self._offered is not None

    def offer_factors(self, labels, held):
        """Offer the LU ``held`` (a :class:`~compass_sparse.basis.backends.HeldLU`) of a
        matrix close to the principal block ``M[labels, labels]`` (increasing labels), e.g.
        the crash's last reduced Jacobian: a later :meth:`factor` of a basis whose M
        columns are exactly ``labels`` and whose unit columns cover the other rows solves
        on it by GMRES instead of factoring (``reuse_factors``; the same fallbacks)."""
        labels = np.asarray(labels, dtype=_I)
        if not (self.options.reuse_factors and held is not None and held.n == labels.size
                and labels.size and np.all(np.diff(labels) > 0) and labels[-1] < self.n):
            return
        est, nnz = held.ordering.nnz_lu, int(getattr(held.lu, "nnz", 0))
        if nnz < self.options.reuse_min_nnz:
            return      # a fresh factorization is cheaper than GMRES on these
        if est > 0 and nnz > est:
            # Pivoting left the diagonal the ordering counted on (the crash's points are
            # far from the solution): each solve with these factors costs more than with
            # a fresh factorization of the basis (2x fill measured on the static CGE model
            # at n = 3e4, tax abolition; the solve took 16 s with them, 13 s without).
            return
        self._offered = (labels, held)

    def _offer_fits(self):
        if self._offered is None or self._reuse_aged or not self.options.reuse_factors:
            return False
        labels = self._offered[0]
        k, i = self._kinds, self._indices
        km, ku = k == KIND_M, k == KIND_UNIT
        if not np.all(km | ku) or km.sum() != labels.size:
            return False
        if not np.array_equal(np.sort(i[km]), labels):
            return False
        cov = np.zeros(self.n, dtype=bool)
        cov[i[ku]] = True
        if cov.sum() != ku.sum() or cov[labels].any():
            return False
        self._psolve = self._offered_solve
        # the factors in use are the offered ones: report their figures
        held, st = self._offered[1], self.stats
        o = held.ordering
        st.backend, st.ordering = "superlu", o.method
        st.est_nnz_lu = max(st.est_nnz_lu, o.nnz_lu)
        st.est_flops = max(st.est_flops, o.flops)
        if o.nnz_lu >= 0:
            st.est_bytes = max(st.est_bytes, BYTES_PER_ENTRY * o.nnz_lu)
        st.max_nnz_lu = max(st.max_nnz_lu, int(getattr(held.lu, "nnz", 0)))
        return True

    def _offered_solve(self, v):
        """P^{-1} v for P the current basis with its M block on ``labels`` replaced by the
        offered matrix: the M columns on the labelled rows first, then the unit columns
        (they cover the other rows)."""
        labels, held = self._offered
        k, i, g = self._kinds, self._indices, self._signs
        g = g if v.ndim == 1 else g[:, None]      # (v may hold several right-hand sides)
        y = held.solve(v[labels])                 # (M_LL) y = v_L, y by label
        x = np.empty(v.shape)
        km = np.flatnonzero(k == KIND_M)
        x[km] = y[np.searchsorted(labels, i[km])] / g[km]
        ku = np.flatnonzero(k == KIND_UNIT)
        if ku.size:
            yfull = np.zeros(v.shape)
            yfull[labels] = y
            t = self._M @ yfull
            x[ku] = (v[i[ku]] - t[i[ku]]) / g[ku]
        return x

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

    def _reuse_solve(self, rhs, more=()):
        """x with B x = rhs by GMRES on the held factors, or None when it does not reach
        ``reuse_tolerance`` (backward error) within ``reuse_iterations`` steps.  With
        ``more`` (other right-hand sides), the list of the solutions of all, solved in
        lockstep (one preconditioner solve of all per step)."""
        from .krylov import preconditioned_gmres

        o = self.options
        nb = self._norm_inf_B()
        cols = [rhs, *more]
        bns = [float(np.abs(c).max()) if self.n else 0.0 for c in cols]

        # GMRES's 2-norm target is a guide (||x|| is estimated by ||x0||, x0 = P^{-1} rhs;
        # the 2-norm bounds the inf-norm); the check below decides.  Its vector operations
        # are level-1 BLAS: threads only slow them (10x measured at n = 3e4, busy machine).
        def target(bn):
            return lambda x0: 0.5 * o.reuse_tolerance * (bn + nb * float(np.abs(x0).max()))

        def berr(x, c):
            if not np.all(np.isfinite(x)):
                return np.inf, np.inf
            res = float(np.abs(self.matvec(x) - cols[c]).max()) if self.n else 0.0
            den = bns[c] + nb * (float(np.abs(x).max()) if self.n else 0.0)
            return (res / den if den > 0 else res), den

        st = self.stats
        st.reuse_solves += len(cols)
        with single_threaded_blas():
            X, steps, _ = preconditioned_gmres(
                self.matvec, self._psolve, cols[0] if not more else np.column_stack(cols),
                target(bns[0]) if not more else [target(b) for b in bns],
                o.reuse_iterations)
            X = [X] if not more else [X[:, c] for c in range(len(cols))]
            out = []
            for c, x in enumerate(X):
                err, den = berr(x, c)
                if o.reuse_tolerance < err <= 1e3 * o.reuse_tolerance \
                        and steps < o.reuse_iterations:
                    # One restart: GMRES's own residual estimate may end just short of
                    # the true backward error (2.9e-12 for 1e-12 measured at n = 1e5);
                    # when it is that close, a correction continues from x with the
                    # steps left instead of factoring afresh.
                    dx, k, _ = preconditioned_gmres(self.matvec, self._psolve,
                                                    cols[c] - self.matvec(x),
                                                    0.1 * o.reuse_tolerance * den,
                                                    o.reuse_iterations - steps)
                    st.reuse_steps += k
                    x = x + dx
                    err, _ = berr(x, c)
                log.debug("solve on reused factors: %d GMRES steps, backward error %.1e",
                          steps, err)
                out.append(x if err <= o.reuse_tolerance else None)
        st.reuse_steps += steps
        if steps > o.reuse_iterations // 2:
            self._reuse_aged = True    # the next factor() call factors afresh
        return out if more else out[0]

    def refactor(self) -> FactorReport:
        """Factorize the current slot table again (afresh, also when reusing)."""
        return self._factorize()

    def _nonunit_columns(self, slots):
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
        BS = self._nonunit_columns(S2)                       # n x |S2|
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
        cap_cols = n + o.update_limit + 2
        self._Lp, self._Li, self._Lx = Lp, Li, Lx
        nnzu = int(Up[n])
        cap = max(2 * nnzu + 4 * n, 1024)
        self._Ui = np.zeros(cap, dtype=_I)
        self._Ux = np.zeros(cap)
        self._Ui[:nnzu] = Ui
        self._Ux[:nnzu] = Ux
        self._Us = np.zeros(cap_cols, dtype=_I)
        self._Ue = np.zeros(cap_cols, dtype=_I)
        self._Us[:n] = Up[:-1]
        self._Ue[:n] = Up[1:]
        self._Us[n:] = nnzu
        self._Ue[n:] = nnzu
        self._Ufree = nnzu
        # Row forms of L and U (for BTRAN and the update's U^{-T} e_p) are built on first
        # use: a path without pivots never needs them (0.4 s each at n = 1e5).
        self._row_forms = None
        self._LU0 = (Lx, Li, Lp, Ux, Ui, Up)
        self._dead = np.zeros(cap_cols, dtype=np.bool_)
        self._Ud = np.ones(cap_cols)
        self._Ud[:n] = Ud
        rcap = max(4 * n, 1024)
        self._Rs = np.zeros(cap_cols + 1, dtype=_I)
        self._Ri = np.zeros(rcap, dtype=_I)
        self._Rx = np.zeros(rcap)
        self._Rpos = np.zeros(cap_cols, dtype=_I)
        self._Rq = np.zeros(cap_cols, dtype=_I)
        self._k = 0
        self._m1 = m1
        self._rowpos = rowpos
        self._rscale = rscale
        self._slot_at = np.concatenate((slot_at, np.full(cap_cols - n, -1, dtype=_I)))
        self._pos_of_slot = np.empty(n, dtype=_I)
        self._pos_of_slot[slot_at] = np.arange(n, dtype=_I)
        self._nnzL = int(Lp[n])
        self._nnzU = int(nnzu) + n
        self._nnzR = 0
        self._nnz_base = self._nnzL + self._nnzU
        self._rebuild_maps()
        self._factored = True
        self._reusing = False
        self._held = None
        self._offered = None
        self._psolve = self._solve_quiet
        self._reuse_aged = False
        self._threshold_pivoting = bool(mk) and self._backend.last.ordering in ("amd", "metis")
        self._residual_refactored = False
        self._cache = None
        self._version += 1
        st = self.stats
        st.factorizations += 1
        st.nnz_L, st.nnz_U, st.nnz_eta = self._nnzL, self._nnzU, 0
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
    def _require(self):
        if not self._factored:
            raise CompassError("basis is not factorized: call factor() or refactor() "
                               "(after set_matrix/set_dense_column)")

    def _work(self):
        return np.zeros(self.n + self._k + 1)

    def _scatter_rhs(self, w, rows, vals):
        if self._rscale is not None:
            vals = vals * self._rscale[rows]
        w[self._rowpos[rows]] = vals

    def _ftran_work(self, w, keep_spike):
        """w holds S P a; returns (x over slots, spike or None)."""
        kern.lsolve(self._Lp, self._Li, self._Lx, w, self._m1)
        kern.apply_etas(self._Rs, self._Ri, self._Rx, self._Rpos, self._Rq, self._k, w)
        N = self.n + self._k
        spike = w[:N].copy() if keep_spike else None
        kern.usolve(self._Us, self._Ue, self._Ui, self._Ux, self._Ud, w, N)
        return w[self._pos_of_slot], spike

    def _rows(self):
        """(Lrp, Lri, Lrx, Urp, Urj, Urx): CSR arrays of L and of U as factored (built once
        per factorization, on first use)."""
        if self._row_forms is None:
            n = self.n
            Lx, Li, Lp, Ux, Ui, Up = self._LU0
            out = []
            for (x, i, p) in ((Lx, Li, Lp), (Ux, Ui, Up)):
                R = sp.csc_matrix((x, i, p), shape=(n, n)).tocsr()
                out += [R.indptr.astype(_I, copy=False), R.indices.astype(_I, copy=False),
                        R.data]
            self._row_forms = tuple(out)
        return self._row_forms

    def _utsolve(self, w, start, N):
        _, _, _, Urp, Urj, Urx = self._rows()
        kern.utsolve(Urp, Urj, Urx, self._dead, self.n, self._Us,
                     self._Ue, self._Ui, self._Ux, self._Ud, w, start, N)

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
                x, d = self._reuse_solve(rhs, (self._r,))
                self._prefetch = (self._version, d)
            else:
                x = self._reuse_solve(rhs)
            self.stats.time_solve += time.perf_counter() - t0
            self.stats.ftran_calls += 1
            if x is not None:
                return x
            self._leave_reuse()
            t0 = time.perf_counter()
        w = self._work()
        self._scatter_rhs(w, np.arange(self.n), rhs)
        x, _ = self._ftran_work(w, False)
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
            d = self._reuse_solve(rhs)
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
        w = self._work()
        self._scatter_rhs(w, rows, vals)
        d, spike = self._ftran_work(w, True)
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
        y = self._btran_work(c)
        f = self.options.residual_check_frequency
        self.stats.btran_calls += 1
        if f and self.stats.btran_calls % f == 0 and self._threshold_pivoting:
            # the transposed counterpart of the FTRAN check: refine once when the
            # backward error is above machine level (threshold pivoting only)
            self.stats.residual_checks += 1
            err = self._backward_error_t(y, c)
            if np.isfinite(err) and err > _REFINE_ABOVE:
                y2 = y + self._btran_work(c - self.rmatvec(y))
                if np.all(np.isfinite(y2)) and self._backward_error_t(y2, c) < err:
                    y = y2
        self.stats.time_solve += time.perf_counter() - t0
        return y

    def _btran_work(self, c):
        N = self.n + self._k
        w = self._work()
        w[self._pos_of_slot] = c
        self._utsolve(w, 0, N)
        kern.apply_etas_t(self._Rs, self._Ri, self._Rx, self._Rpos, self._Rq, self._k, w)
        Lrp, Lri, Lrx = self._rows()[:3]
        kern.ltsolve(Lrp, Lri, Lrx, w, self._m1)
        y = w[self._rowpos]
        if self._rscale is not None:
            y = y * self._rscale
        return y

    def rmatvec(self, y):
        """B^T @ y (indexed by slot) for y indexed by row."""
        k, i, s = self._kinds, self._indices, self._signs
        out = np.zeros(self.n)
        m = k == KIND_M
        out[m] = s[m] * (self._M.T @ y)[i[m]]
        u = k == KIND_UNIT
        out[u] = s[u] * y[i[u]]
        d = k == KIND_DENSE
        if np.any(d):
            out[d] = s[d] * float(self._r @ y)
        return out

    def _backward_error_t(self, y, c):
        res = np.abs(self.rmatvec(y) - c).max()
        den = np.abs(c).max() + self._norm_inf_B() * np.abs(y).max()
        return float(res / den) if den > 0 else float(res)

    # ---------------------------------------------------------- residual check
    def matvec(self, x):
        """B @ x for x indexed by slot (uses the current slot table)."""
        n = self.n
        k, i, s = self._kinds, self._indices, self._signs
        m = k == KIND_M
        y = self._M @ np.bincount(i[m], weights=s[m] * x[m], minlength=n)
        u = k == KIND_UNIT
        y += np.bincount(i[u], weights=s[u] * x[u], minlength=n)
        for d in np.flatnonzero(k == KIND_DENSE):
            y += self._r * (s[d] * x[d])
        return y

    def _norm_inf_B(self):
        n = self.n
        k, i, s = self._kinds, self._indices, self._signs
        m = k == KIND_M
        rs = self._absM @ np.bincount(i[m], weights=np.abs(s[m]), minlength=n)
        u = k == KIND_UNIT
        rs += np.bincount(i[u], weights=np.abs(s[u]), minlength=n)
        for d in np.flatnonzero(k == KIND_DENSE):
            rs += np.abs(self._r) * abs(s[d])
        return float(rs.max()) if n else 0.0

    def backward_error(self, x, rhs):
        """||B x - rhs||_inf / (||rhs||_inf + ||B||_inf ||x||_inf)."""
        res = self.matvec(x) - rhs
        den = np.abs(rhs).max() + self._norm_inf_B() * np.abs(x).max()
        num = np.abs(res).max()
        if not np.isfinite(num):
            return np.inf
        return float(num / den) if den > 0 else float(num)

    def _maybe_check(self, x, rhs, col):
        f = self.options.residual_check_frequency
        self._n_ftran += 1
        if not np.all(np.isfinite(x)) and self._k > 0:
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
        w = self._work()
        self._scatter_rhs(w, np.arange(self.n), rhs - self.matvec(x))
        dx, _ = self._ftran_work(w, False)
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
        if self._k > 0 or not self._residual_refactored:
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
            w = self._work()
            self._scatter_rhs(w, np.arange(self.n), rhs)
            x, _ = self._ftran_work(w, False)
        # one step of iterative refinement
        r = rhs - self.matvec(x)
        w = self._work()
        self._scatter_rhs(w, np.arange(self.n), r)
        dx, _ = self._ftran_work(w, False)
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
        if self._k >= o.update_limit:
            self.stats.refactor_by_count += 1
            return self._replace_by_refactor(slot, kind, index, sign)
        n, k = self.n, self._k
        N = n + k
        p = int(self._pos_of_slot[slot])
        s = c.spike
        d = c.d
        alpha = d[slot]
        upp = self._Ud[p]
        d1 = alpha * upp
        snorm = np.abs(s).max() if s.size else 0.0
        dnorm = np.abs(d).max()
        ptol = o.pivot_tolerance
        if (not np.isfinite(d1) or not np.isfinite(dnorm) or abs(d1) <= ptol * snorm
                or abs(alpha) <= ptol * dnorm or d1 == 0.0):
            self.stats.refused_updates += 1
            return UpdateStatus.REFUSED
        y = np.zeros(N)
        y[p] = 1.0
        self._utsolve(y, p, N)
        d2 = upp * kern.dot_from(y, s, p)
        if not np.isfinite(d2) or abs(d1 - d2) > o.stability_tolerance * abs(d1):
            self.stats.refactor_by_stability += 1
            return self._replace_by_refactor(slot, kind, index, sign)
        if abs(d2) <= ptol * snorm:
            self.stats.refused_updates += 1
            return UpdateStatus.REFUSED
        eta_i = (p + 1 + np.flatnonzero(y[p + 1:])).astype(_I)
        eta_x = -upp * y[eta_i]
        col_i = np.flatnonzero(s).astype(_I)
        col_i = col_i[col_i != p]
        col_x = s[col_i]
        old_len = int(self._Ue[p] - self._Us[p])
        new_total = (self._nnzL + self._nnzU - old_len + col_i.size + self._nnzR
                     + eta_i.size)
        if new_total > o.fill_factor * self._nnz_base:
            self.stats.refactor_by_fill += 1
            return self._replace_by_refactor(slot, kind, index, sign)
        # ---- commit: append the spike as column q, kill column p, store the eta
        q = N
        need = self._Ufree + col_i.size
        if need > self._Ui.size:
            newcap = max(2 * self._Ui.size, need + 1024)
            self._Ui = np.concatenate((self._Ui, np.zeros(newcap - self._Ui.size, _I)))
            self._Ux = np.concatenate((self._Ux, np.zeros(newcap - self._Ux.size)))
        f = self._Ufree
        self._Ui[f:f + col_i.size] = col_i
        self._Ux[f:f + col_i.size] = col_x
        self._Us[q], self._Ue[q] = f, f + col_i.size
        self._Ufree = f + col_i.size
        self._Ud[q] = d2
        self._Ue[p] = self._Us[p]
        self._Ud[p] = 1.0
        self._dead[p] = True
        r0 = self._Rs[k]
        need = r0 + eta_i.size
        if need > self._Ri.size:
            newcap = max(2 * self._Ri.size, need + 1024)
            self._Ri = np.concatenate((self._Ri, np.zeros(newcap - self._Ri.size, _I)))
            self._Rx = np.concatenate((self._Rx, np.zeros(newcap - self._Rx.size)))
        self._Ri[r0:need] = eta_i
        self._Rx[r0:need] = eta_x
        self._Rs[k + 1] = need
        self._Rpos[k] = p
        self._Rq[k] = q
        self._k = k + 1
        self._slot_at[p] = -1
        self._slot_at[q] = slot
        self._pos_of_slot[slot] = q
        self._nnzU += col_i.size - old_len
        self._nnzR += eta_i.size
        self._set_slot(slot, kind, index, sign)
        self._cache = None
        self._version += 1
        st = self.stats
        st.updates += 1
        st.nnz_U, st.nnz_eta = self._nnzU, self._nnzR
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
        """Estimate of the 1-norm condition number of B (``scipy`` onenormest on B^{-1})."""
        from scipy.sparse.linalg import LinearOperator, onenormest

        self._require()
        if self._reusing:
            self._leave_reuse()
        n = self.n
        Binv = LinearOperator((n, n), matvec=lambda v: self._solve_quiet(v),
                              rmatvec=lambda v: self._solve_quiet_t(v), dtype=float)
        cols = np.abs(self._nonunit_columns(np.arange(n, dtype=_I))).sum(axis=0)
        cols = np.asarray(cols).ravel()
        cols[self._kinds == KIND_UNIT] = np.abs(self._signs[self._kinds == KIND_UNIT])
        return float(cols.max() * onenormest(Binv)) if n else 0.0

    def condest_check(self, limit=1e12):
        """True when the condition estimate is below ``limit``."""
        return self.condest() < limit

    def _solve_quiet(self, v):
        if v.ndim == 2:   # several right-hand sides (lockstep GMRES): one at a time here
            return np.column_stack([self._solve_quiet(v[:, c]) for c in range(v.shape[1])])
        w = self._work()
        self._scatter_rhs(w, np.arange(self.n), np.asarray(v, float).ravel())
        return self._ftran_work(w, False)[0]

    def _solve_quiet_t(self, v):
        st = self.stats.btran_calls, self.stats.time_solve
        y = self.btran(np.asarray(v, float).ravel())
        self.stats.btran_calls, self.stats.time_solve = st
        return y

    def dense_basis(self):
        """The explicit dense B of the current slot table (tests and debugging only)."""
        n = self.n
        B = self._nonunit_columns(np.arange(n, dtype=_I)).toarray()
        u = np.flatnonzero(self._kinds == KIND_UNIT)
        B[:, u] = 0.0
        B[self._indices[u], u] = self._signs[u]
        return B
