"""Debugging checks of a basis manager, apart from its algorithm (as HiGHS keeps
``HFactorDebug`` apart from ``HFactor``): the condition estimate of B and the explicit
dense B of the slot table.  Neither is used by a solve."""
from __future__ import annotations

import numpy as np

from .types import KIND_UNIT

__all__ = ["condest", "dense_basis"]

_I = np.int64


def condest(bm) -> float:
    """Estimate of the 1-norm condition number of the basis of ``bm`` (a
    :class:`~compass_sparse.basis.manager.BasisManager`): ||B||_1 times scipy's onenormest
    of B^{-1}, on fresh factors."""
    # (lazy: scipy.sparse.linalg adds ~0.15 s to the package's import)
    from scipy.sparse.linalg import LinearOperator, onenormest

    bm.fresh_factors()
    n = bm.n
    Binv = LinearOperator((n, n), matvec=bm.solve_quiet, rmatvec=bm.solve_quiet_t,
                          dtype=float)
    kinds, signs = bm.kinds, bm.signs
    cols = np.abs(bm.nonunit_columns(np.arange(n, dtype=_I))).sum(axis=0)
    cols = np.asarray(cols).ravel()
    cols[kinds == KIND_UNIT] = np.abs(signs[kinds == KIND_UNIT])
    return float(cols.max() * onenormest(Binv)) if n else 0.0


def dense_basis(bm) -> np.ndarray:
    """The explicit dense B of the slot table of ``bm``."""
    n = bm.n
    B = bm.nonunit_columns(np.arange(n, dtype=_I)).toarray()
    kinds, indices, signs = bm.kinds, bm.indices, bm.signs
    u = np.flatnonzero(kinds == KIND_UNIT)
    B[:, u] = 0.0
    B[indices[u], u] = signs[u]
    return B
