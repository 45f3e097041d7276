"""Basis manager of the pivotal path: sparse LU of B with Forrest-Tomlin updates.

``B = P^T S^{-1} L U Q^T`` with unit columns ordered first (they cost nothing), a sparse LU
of the remaining block (SuperLU in a fill-reducing ordering chosen once per pattern, or
SuiteSparse UMFPACK: :mod:`~compass_sparse.basis.backends`,
:mod:`~compass_sparse.basis.ordering`), Forrest-Tomlin column
replacement with a row-eta file, refactorization triggers (update count, fill, stability,
periodic residual check) and rank repair of singular bases. See
:mod:`compass_sparse.basis.manager` for the mathematics and
:class:`~compass_sparse.basis.types.BasisOptions` for the tolerances and their defaults.

The interface the pivotal path uses is the :class:`~compass_sparse.basis.protocol.Basis`
protocol; :class:`~compass_sparse.basis.dense.DenseBasis` implements it on an explicit
inverse for small problems.
"""

from .dense import DenseBasis
from .manager import BasisManager, FactorReuseFailed, SolveRepairedBasis
from .protocol import Basis
from .types import (KIND_DENSE, KIND_M, KIND_UNIT, BasisOptions, BasisStats, FactorReport,
                    UpdateStatus)

__all__ = ["Basis", "BasisManager", "FactorReuseFailed", "SolveRepairedBasis", "DenseBasis",
           "BasisOptions", "BasisStats",
           "UpdateStatus", "FactorReport", "KIND_M", "KIND_UNIT", "KIND_DENSE"]
