"""Sparse LU backends for the non-unit block K of the basis.

A backend factors a square sparse matrix K (CSC) as

    diag(s[row_order]) K[row_order, :][:, col_order] = L U

with L unit lower triangular and U upper triangular (``s`` an optional row scaling, ones
for SuperLU). ``row_order[t]`` is the row of K pivoted at position t, ``col_order[t]`` its
column. A backend raises :class:`SingularFactorError` when the matrix is exactly singular.

SuperLU (``scipy.sparse.linalg.splu``) is always available; UMFPACK is used when
``scikits.umfpack`` is importable (imported lazily here and nowhere else).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp


class SingularFactorError(Exception):
    """The backend found an exactly zero pivot."""


@dataclass
class LUFactors:
    L: sp.csc_matrix          # unit lower triangular (diagonal may or may not be stored)
    U: sp.csc_matrix          # upper triangular with diagonal
    row_order: np.ndarray     # position -> row of K
    col_order: np.ndarray     # position -> column of K
    row_scale: np.ndarray | None = None   # indexed by row of K; None = no scaling


def umfpack_available() -> bool:
    try:
        import scikits.umfpack  # noqa: F401
    except Exception:
        return False
    return True


class SuperLUBackend:
    name = "superlu"

    def __init__(self, permc_spec="COLAMD", diag_pivot_thresh=1.0):
        self.permc_spec = permc_spec
        self.diag_pivot_thresh = diag_pivot_thresh

    def factor(self, K) -> LUFactors:
        from scipy.sparse.linalg import splu

        try:
            lu = splu(K, permc_spec=self.permc_spec,
                      diag_pivot_thresh=self.diag_pivot_thresh,
                      options=dict(SymmetricMode=False))
        except RuntimeError as exc:  # "Factor is exactly singular"
            raise SingularFactorError(str(exc)) from exc
        # Pr K Pc = L U: row i of K sits at position perm_r[i], column j at perm_c[j].
        row_order = np.empty(lu.perm_r.size, dtype=np.int64)
        row_order[lu.perm_r] = np.arange(lu.perm_r.size, dtype=np.int64)
        col_order = np.empty(lu.perm_c.size, dtype=np.int64)
        col_order[lu.perm_c] = np.arange(lu.perm_c.size, dtype=np.int64)
        return LUFactors(sp.csc_matrix(lu.L), sp.csc_matrix(lu.U), row_order, col_order)


class UmfpackBackend:
    name = "umfpack"

    def factor(self, K) -> LUFactors:
        import scikits.umfpack as um

        try:
            lu = um.splu(K)
        except Exception as exc:
            raise SingularFactorError(str(exc)) from exc
        U = sp.csc_matrix(lu.U)
        if U.shape[0] and np.any(U.diagonal() == 0.0):
            raise SingularFactorError("UMFPACK: zero pivot")
        # UMFPACK: P R A Q = L U with a row scaling R (multiplied or divided, depending on
        # the build) -- the conventions of the wrapper are settled by a probe product.
        n = K.shape[0]
        L = sp.csc_matrix(lu.L)
        pr = np.asarray(lu.perm_r, dtype=np.int64)
        pc = np.asarray(lu.perm_c, dtype=np.int64)
        R = np.asarray(getattr(lu, "R", np.ones(n)), dtype=float).ravel()
        x = np.random.default_rng(0).standard_normal(n)
        lux = L @ (U @ x)
        inv = np.empty_like(pr)
        inv[pr] = np.arange(n)
        for ro in (pr, inv):
            for co in (pc, np.argsort(pc)):
                for s in (R, 1.0 / R):
                    y = s[ro] * (K[ro, :][:, co] @ x)
                    if np.linalg.norm(y - lux) <= 1e-8 * (np.linalg.norm(lux) + 1.0):
                        return LUFactors(L, U, ro, co, s)
        raise SingularFactorError("UMFPACK factors could not be interpreted")


def make_backend(name, permc_spec="COLAMD", diag_pivot_thresh=1.0):
    if name == "auto":
        name = "umfpack" if umfpack_available() else "superlu"
    if name == "umfpack":
        if not umfpack_available():
            from ..exceptions import OptionError

            raise OptionError("backend='umfpack' needs the optional package scikits.umfpack")
        return UmfpackBackend()
    return SuperLUBackend(permc_spec, diag_pivot_thresh)
