"""A dense basis: the explicit inverse with rank-one updates (the :class:`Basis` protocol).

B^{-1} = H is kept explicitly and a column replacement at slot k with FTRAN column
d = H c updates it by the rank-one formula of thesis (4.2.3),

    H' = H - (H d) H_{k:} / (1 + H_{k:} d),   written as   H'_{k:} = H_{k:} / d_k,
    H'_{i:} = H_{i:} - d_i H'_{k:}  (i != k),

O(n^2) per pivot and O(n^3) per factorization.  For small problems (n up to a few
hundred) this beats the sparse LU with Forrest-Tomlin updates, whose per-pivot overhead
does not pay off at that size, so the solver uses it there; tests also check the sparse
manager against it.

Factorization (thesis §4.2.3): start from the identity of unit columns (those of the
slot table plus unit columns on the rows no unit column covers), then bring the other
columns in one at a time while the pivot ``|d_k|`` stays above ``rank_tolerance`` (1e-9)
relative to ``max(1, ||c||_inf) max(1, ||H_{k:}||_inf)``; a column that fails keeps the
unit column of its row and is reported in ``FactorReport.replaced`` (the repair).
A replacement is REFUSED when ``|d_k| <= pivot_tolerance * max(1, ||d||_inf)``
(``pivot_tolerance`` 1e-11, as the sparse manager's).
"""
from __future__ import annotations

import time

import numpy as np
import scipy.sparse as sp

from ..exceptions import SingularBasisError
from .types import KIND_M, KIND_UNIT, BasisStats, FactorReport, UpdateStatus

__all__ = ["DenseBasis"]

RANK_TOLERANCE = 1e-9
"""Relative pivot size below which a column is dependent in a fresh factorization."""


class DenseBasis:
    """The :class:`~compass_sparse.basis.protocol.Basis` protocol on a dense inverse."""

    def __init__(self, M, options=None, pivot_tolerance: float = 1e-11):
        self.M = sp.csc_matrix(M).toarray()
        self.n = self.M.shape[0]
        self.r = np.zeros(self.n)
        self.tol = pivot_tolerance
        self.stats = BasisStats()
        self.last_report = FactorReport()
        self._kinds = np.full(self.n, KIND_UNIT, dtype=np.int64)
        self._indices = np.arange(self.n, dtype=np.int64)
        self._signs = np.ones(self.n, dtype=np.int64)
        self.H = np.eye(self.n)

    @property
    def kinds(self):
        return self._kinds

    @property
    def indices(self):
        return self._indices

    @property
    def signs(self):
        return self._signs

    def set_matrix(self, M):
        self.M = sp.csc_matrix(M).toarray()

    def set_dense_column(self, r):
        self.r = np.asarray(r, dtype=float).copy()

    def column(self, kind, index, sign):
        if kind == KIND_M:
            return sign * self.M[:, index]
        if kind == KIND_UNIT:
            c = np.zeros(self.n)
            c[index] = sign
            return c
        return sign * self.r

    def assemble(self):
        return np.column_stack([self.column(k, i, s)
                                for k, i, s in zip(self._kinds, self._indices, self._signs)])

    def factor(self, kinds, indices, signs) -> FactorReport:
        t0 = time.perf_counter()
        self.stats.factorizations += 1
        self._kinds = np.array(kinds, dtype=np.int64)
        self._indices = np.array(indices, dtype=np.int64)
        self._signs = np.array(signs, dtype=np.int64)
        rep = FactorReport()
        want = [(k, self._kinds[k], self._indices[k], self._signs[k]) for k in range(self.n)
                if self._kinds[k] != KIND_UNIT]
        # Unit columns are always kept; the other slots start as units on the free rows.
        covered = set(int(self._indices[k]) for k in range(self.n)
                      if self._kinds[k] == KIND_UNIT)
        free_rows = [i for i in range(self.n) if i not in covered]
        for (k, _, _, _), row in zip(want, free_rows):
            self._kinds[k], self._indices[k], self._signs[k] = KIND_UNIT, row, 1
        try:
            self.H = np.linalg.inv(self.assemble())
        except np.linalg.LinAlgError:  # duplicated unit columns
            raise SingularBasisError("the unit columns of the basis are dependent") from None
        for (k, kind, idx, sign) in want:
            c = self.column(kind, idx, sign)
            d = self.H @ c
            scale = max(1.0, np.abs(c).max())
            if abs(d[k]) > RANK_TOLERANCE * scale * max(1.0, np.abs(self.H[k]).max()):
                self._rank_one(k, d)
                self._kinds[k], self._indices[k], self._signs[k] = kind, idx, sign
            else:
                rep.replaced.append((k, int(kind), int(idx), int(sign), int(self._indices[k])))
        rep.rank_deficiency = len(rep.replaced)
        self.last_report = rep
        self.stats.time_factor += time.perf_counter() - t0
        return rep

    def refactor(self) -> FactorReport:
        return self.factor(self._kinds.copy(), self._indices.copy(), self._signs.copy())

    def _rank_one(self, k, d):
        # B' = B with column k replaced: B'^{-1} = E B^{-1} with the eta of d = B^{-1} c.
        Hk = self.H[k].copy() / d[k]
        self.H -= np.outer(d, Hk)
        self.H[k] = Hk

    def ftran(self, rhs):
        self.stats.ftran_calls += 1
        return self.H @ rhs

    def ftran_column(self, kind, index, sign=1.0):
        self.stats.ftran_calls += 1
        return self.H @ self.column(kind, index, sign)

    def btran(self, c):
        self.stats.btran_calls += 1
        return self.H.T @ c

    def replace(self, slot, kind, index, sign=1.0) -> UpdateStatus:
        t0 = time.perf_counter()
        d = self.H @ self.column(kind, index, sign)
        if abs(d[slot]) <= self.tol * max(1.0, np.abs(d).max()):
            self.stats.refused_updates += 1
            return UpdateStatus.REFUSED
        self._rank_one(slot, d)
        self._kinds[slot], self._indices[slot], self._signs[slot] = kind, index, sign
        self.stats.updates += 1
        self.stats.time_update += time.perf_counter() - t0
        return UpdateStatus.OK
