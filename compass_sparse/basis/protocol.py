"""The basis interface of the pivotal path.

The path (:mod:`compass_sparse.path`) keeps a *slot table*: slot s of the basis B holds
the column ``sign * M[:, index]`` (``KIND_M``), ``sign * e_index`` (``KIND_UNIT``: the
slacks w (sign -1) and v (sign +1), artificials) or ``sign * r`` (``KIND_DENSE``: the
covering vector).  Everything the path needs from the owner of B's factors is written
down here as :class:`Basis`; two implementations exist:

* :class:`~compass_sparse.basis.BasisManager` -- sparse LU with Forrest-Tomlin updates,
  for large problems;
* :class:`~compass_sparse.basis.dense.DenseBasis` -- an explicit inverse with rank-one
  updates, O(n^2) per pivot, the faster choice for small problems.

Contract
--------
``set_matrix(M)`` / ``set_dense_column(r)``
    Load M (n x n, sparse) and the covering vector r.  Factors become stale.
``factor(kinds, indices, signs) -> FactorReport``
    Set the whole slot table and factorize B.  A singular B is *repaired*: every slot
    whose column is dependent gets the unit column ``+e_row`` of an uncovered row, and
    the report lists ``(slot, old_kind, old_index, old_sign, new_row)`` for each.  A basis
    that cannot be repaired raises :class:`~compass_sparse.exceptions.SingularBasisError`.
``refactor() -> FactorReport``
    Factorize the current slot table again (same repair rules).
``ftran(rhs)``, ``ftran_column(kind, index, sign)``, ``btran(c)``
    Solve ``B x = rhs``, ``B x = column`` and ``B^T y = c``.
``replace(slot, kind, index, sign) -> UpdateStatus``
    Replace the column in ``slot``.  ``OK``: updated; ``REFACTORED``: done by a fresh
    factorization of the new slot table, nothing repaired (the caller's table and the
    basis agree; only values should be recomputed from the fresh factors); ``REFUSED``:
    the new pivot is relatively tiny, the basis is unchanged; ``REPAIRED``: not done, and
    the old basis had to be repaired (``last_report.replaced``).  After ``REFUSED`` or
    ``REPAIRED`` the caller factorizes its own table with :meth:`factor`.
``last_report``
    The :class:`FactorReport` of the last factorization.
``kinds``, ``indices``, ``signs``
    The current slot table (read-only views).
``stats``
    A :class:`BasisStats`; at least ``factorizations``, ``updates``, ``refused_updates``
    and the ``time_*`` fields are kept by every implementation.
"""
from __future__ import annotations

from typing import Protocol, runtime_checkable

import numpy as np

from .types import BasisStats, FactorReport, UpdateStatus

__all__ = ["Basis"]


@runtime_checkable
class Basis(Protocol):
    """The owner of the factors of the pivotal path's basis (see the module docstring)."""

    n: int
    stats: BasisStats
    last_report: FactorReport

    @property
    def kinds(self) -> np.ndarray: ...

    @property
    def indices(self) -> np.ndarray: ...

    @property
    def signs(self) -> np.ndarray: ...

    def set_matrix(self, M) -> None: ...

    def set_dense_column(self, r) -> None: ...

    def factor(self, kinds, indices, signs) -> FactorReport: ...

    def refactor(self) -> FactorReport: ...

    def ftran(self, rhs) -> np.ndarray: ...

    def ftran_column(self, kind, index, sign=1.0) -> np.ndarray: ...

    def btran(self, c) -> np.ndarray: ...

    def replace(self, slot, kind, index, sign=1.0) -> UpdateStatus: ...
