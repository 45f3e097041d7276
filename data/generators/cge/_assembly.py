"""Fixed-pattern sparse Jacobian assembly and CES helpers shared by the CGE generators."""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp


class PatternAssembler:
    """Assemble J from a fixed list of (row, col) index arrays, one array per term.

    Terms are registered once (``add``) and ``finalize`` computes the CSC pattern and the map
    from every registered entry to its CSC slot.  At evaluation, ``assemble(values)`` takes
    the value arrays in registration order and sums duplicates with one ``bincount``; the
    structural pattern never changes and explicit zeros stay stored.
    """

    def __init__(self, n: int):
        self.n = int(n)
        self.names: list[str] = []
        self._rows: list[np.ndarray] = []
        self._cols: list[np.ndarray] = []
        self._const: list[bool] = []
        self.sizes: list[int] = []

    def add(self, name: str, rows, cols, *, const: bool = False):
        rows = np.asarray(rows, dtype=np.int64).ravel()
        cols = np.asarray(cols, dtype=np.int64).ravel()
        if rows.shape != cols.shape:
            rows, cols = np.broadcast_arrays(rows, cols)
            rows, cols = rows.ravel().copy(), cols.ravel().copy()
        self.names.append(name)
        self._rows.append(rows)
        self._cols.append(cols)
        self._const.append(bool(const))
        self.sizes.append(rows.size)

    def finalize(self):
        rows = np.concatenate(self._rows) if self._rows else np.zeros(0, np.int64)
        cols = np.concatenate(self._cols) if self._cols else np.zeros(0, np.int64)
        n = self.n
        keys = cols * n + rows  # column-major = CSC order
        ukeys, inv = np.unique(keys, return_inverse=True)
        self.inv = inv.astype(np.int64)
        self.nnz = int(ukeys.size)
        self.indices = (ukeys % n).astype(np.int32)
        ucols = ukeys // n
        self.indptr = np.zeros(n + 1, dtype=np.int32)
        np.cumsum(np.bincount(ucols, minlength=n), out=self.indptr[1:])
        # an entry is constant when every contribution to it is declared constant
        flags = np.concatenate([np.full(s, c) for s, c in zip(self.sizes, self._const)]) \
            if self.sizes else np.zeros(0, bool)
        nonconst = np.bincount(self.inv, (~flags).astype(float), minlength=self.nnz)
        self.const_mask = nonconst == 0
        self.ncoo = int(rows.size)
        del self._rows, self._cols
        return self

    def assemble(self, values: list[np.ndarray]) -> sp.csc_matrix:
        v = np.concatenate([np.broadcast_to(np.asarray(x, dtype=float), (s,))
                            for x, s in zip(values, self.sizes)])
        data = np.bincount(self.inv, v, minlength=self.nnz)
        return sp.csc_matrix((data, self.indices.copy(), self.indptr.copy()),
                             shape=(self.n, self.n))

    def constant_pattern(self) -> sp.csc_matrix:
        """The constant entries as a sparse matrix (values 1)."""
        data = self.const_mask.astype(float)
        C = sp.csc_matrix((data, self.indices.copy(), self.indptr.copy()), shape=(self.n, self.n))
        C.eliminate_zeros()
        return C


class CESGroups:
    """Calibrated CES / Cobb-Douglas / Leontief unit functions over groups of elements.

    Group g has elements e with share theta_e (summing to 1 per group) and elasticity
    sigma_g.  With relative prices x_e:

        sigma = 1:  c_g = prod_e x_e^theta_e
        otherwise:  c_g = (sum_e theta_e x_e^(1 - sigma_g))^(1 / (1 - sigma_g))

    and dc_g/dx_e = theta_e (c_g / x_e)^sigma_g in every case.  For a CET revenue function
    pass sigma = -eta.
    """

    def __init__(self, grp, theta, sigma_grp, ngrp: int):
        self.grp = np.asarray(grp, dtype=np.int64)
        self.theta = np.asarray(theta, dtype=float)
        self.ngrp = int(ngrp)
        self.sigma_grp = np.broadcast_to(np.asarray(sigma_grp, dtype=float), (self.ngrp,)).copy()
        self.sig_e = self.sigma_grp[self.grp]
        self.cd_grp = self.sigma_grp == 1.0
        self.cd_e = self.cd_grp[self.grp]
        self.leo_e = self.sig_e == 0.0
        self.gen_e = ~self.cd_e & ~self.leo_e
        self.any_cd = bool(self.cd_e.any())
        self.any_gen = bool(self.gen_e.any())
        self.any_leo = bool(self.leo_e.any())
        self.expo_gen = 1.0 - self.sig_e[self.gen_e]
        den = 1.0 - self.sigma_grp
        self.inv_gen = 1.0 / np.where(self.cd_grp, 1.0, den)

    def value(self, x):
        """c (per group)."""
        c = np.zeros(self.ngrp)
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            S = np.zeros(self.ngrp)
            if self.any_leo:
                S += np.bincount(self.grp[self.leo_e], self.theta[self.leo_e] * x[self.leo_e],
                                 minlength=self.ngrp)
            if self.any_gen:
                S += np.bincount(self.grp[self.gen_e],
                                 self.theta[self.gen_e] * np.power(x[self.gen_e], self.expo_gen),
                                 minlength=self.ngrp)
            c = np.power(S, self.inv_gen)
            if self.any_cd:
                L = np.bincount(self.grp[self.cd_e], self.theta[self.cd_e] * np.log(x[self.cd_e]),
                                minlength=self.ngrp)
                c[self.cd_grp] = np.exp(L[self.cd_grp])
        return c

    def ratio_pow(self, c, x):
        """(c_g / x_e)^sigma_g per element (1 for Leontief groups)."""
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            r = np.power(c[self.grp] / x, self.sig_e)
        if self.any_leo:
            r[self.leo_e] = 1.0
        return r

    def grad(self, c, x):
        """dc_g/dx_e per element."""
        return self.theta * self.ratio_pow(c, x)


def group_pairs(grp: np.ndarray, ngrp: int):
    """All ordered pairs (e1, e2) of elements in the same group (for dense within-group
    second-order blocks such as cross-price factor demands)."""
    order = np.argsort(grp, kind="stable")
    counts = np.bincount(grp, minlength=ngrp)
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    sz = counts[grp[order]]
    # for each element e1 (in sorted order), pair with every element of its group
    e1 = np.repeat(order, sz)
    base = np.repeat(starts[grp[order]], sz)
    within = np.arange(e1.size) - np.repeat(np.cumsum(sz) - sz, sz)
    e2 = order[base + within]
    return e1, e2
