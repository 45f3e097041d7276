"""Basis manager of the pivotal path: sparse LU of B with Forrest-Tomlin updates.

``B = P^T S^{-1} L U Q^T`` with unit columns ordered first (they cost nothing), a sparse LU
(SuperLU, or UMFPACK when available) of the remaining block, Forrest-Tomlin column
replacement with a row-eta file, refactorization triggers (update count, fill, stability,
periodic residual check) and rank repair of singular bases. See
:mod:`compass_sparse.basis.manager` for the mathematics and
:class:`~compass_sparse.basis.types.BasisOptions` for the tolerances and their defaults.
"""

from .manager import BasisManager
from .types import (KIND_DENSE, KIND_M, KIND_UNIT, BasisOptions, BasisStats, FactorReport,
                    UpdateStatus)

__all__ = ["BasisManager", "BasisOptions", "BasisStats", "UpdateStatus", "FactorReport",
           "KIND_M", "KIND_UNIT", "KIND_DENSE"]
