"""A dense reference basis with the BasisManager interface.

B^{-1} is kept explicitly and updated by the rank-one formula of thesis (4.2.3),
H' = H - (H d) H_{i:} / (1 + H_{i:} d) — O(n^2) per pivot, so only for small problems:
it is the yardstick against which tests check the sparse Forrest–Tomlin manager, and a
fallback that is independent of it.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

KIND_M, KIND_UNIT, KIND_DENSE = 0, 1, 2


@dataclass
class _Stats:
    factorizations: int = 0
    updates: int = 0
    refused_updates: int = 0
    time_factor: float = 0.0
    time_solve: float = 0.0
    time_update: float = 0.0


@dataclass
class _Report:
    ok: bool = True
    replaced: list = field(default_factory=list)
    rank_deficiency: int = 0


class DenseBasis:
    """Same calls as compass_sparse.basis.BasisManager, dense explicit inverse."""

    def __init__(self, M, options=None, pivot_tolerance: float = 1e-11):
        self.M = sp.csc_matrix(M).toarray()
        self.n = self.M.shape[0]
        self.r = np.zeros(self.n)
        self.tol = pivot_tolerance
        self.stats = _Stats()
        self.kinds = np.full(self.n, KIND_UNIT, dtype=np.int64)
        self.indices = np.arange(self.n, dtype=np.int64)
        self.signs = np.ones(self.n, dtype=np.int64)
        self.H = np.eye(self.n)

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
                                for k, i, s in zip(self.kinds, self.indices, self.signs)])

    def factor(self, kinds, indices, signs):
        self.stats.factorizations += 1
        self.kinds = np.array(kinds, dtype=np.int64)
        self.indices = np.array(indices, dtype=np.int64)
        self.signs = np.array(signs, dtype=np.int64)
        rep = _Report()
        # Thesis §4.2.3: start from unit columns, bring the others in while regular.
        want = [(k, self.kinds[k], self.indices[k], self.signs[k]) for k in range(self.n)
                if self.kinds[k] != KIND_UNIT]
        # Unit columns first (they are always kept): rows they cover.
        covered = set(int(self.indices[k]) for k in range(self.n) if self.kinds[k] == KIND_UNIT)
        free_rows = [i for i in range(self.n) if i not in covered]
        # start: put unit columns on free rows into the non-unit slots
        for (k, _, _, _), row in zip(want, free_rows):
            self.kinds[k], self.indices[k], self.signs[k] = KIND_UNIT, row, 1
        B = self.assemble()
        try:
            self.H = np.linalg.inv(B)
        except np.linalg.LinAlgError:
            rep.ok = False
            return rep
        for (k, kind, idx, sign) in want:
            c = self.column(kind, idx, sign)
            d = self.H @ c
            scale = max(1.0, np.abs(c).max())
            if abs(d[k]) > 1e-9 * scale * max(1.0, np.abs(self.H[k]).max()):
                self._rank_one(k, c, d)
                self.kinds[k], self.indices[k], self.signs[k] = kind, idx, sign
            else:
                rep.replaced.append((k, int(kind), int(idx), int(sign), int(self.indices[k])))
        rep.rank_deficiency = len(rep.replaced)
        return rep

    def refactor(self):
        return self.factor(self.kinds.copy(), self.indices.copy(), self.signs.copy())

    def _rank_one(self, k, c, d):
        # B' = B with column k replaced by c; B'^{-1} = E B^{-1} with the eta of d.
        Hk = self.H[k].copy() / d[k]
        self.H -= np.outer(d, Hk)
        self.H[k] = Hk

    def ftran(self, rhs):
        return self.H @ rhs

    def ftran_column(self, kind, index, sign):
        return self.H @ self.column(kind, index, sign)

    def btran(self, c):
        return self.H.T @ c

    def replace(self, slot, kind, index, sign):
        from .basis import UpdateStatus  # same enum as the sparse manager

        c = self.column(kind, index, sign)
        d = self.H @ c
        if abs(d[slot]) <= self.tol * max(1.0, np.abs(d).max()):
            self.stats.refused_updates += 1
            return UpdateStatus.REFUSED
        self._rank_one(slot, c, d)
        self.kinds[slot], self.indices[slot], self.signs[slot] = kind, index, sign
        self.stats.updates += 1
        return UpdateStatus.OK
