"""Options, statistics and result records of the basis manager.

Tolerances (all relative, all documented with their defaults on :class:`BasisOptions`):

* ``pivot_tolerance`` (1e-11): a column replacement is REFUSED when the new diagonal
  of U is tiny relative to the spike, ``|u_new| <= pivot_tolerance * ||spike||_inf``, or
  when the pivot element of the FTRAN column is tiny,
  ``|d_p| <= pivot_tolerance * ||d||_inf``.
* ``stability_tolerance`` (1e-8): the new diagonal is computed twice, as
  ``d1 = d_p * u_pp`` (from the FTRAN column) and as ``d2 = u_pp * (U^{-T} e_p)^T spike``
  (from the row eta); ``|d1 - d2| > stability_tolerance * |d1|`` forces a refactorization.
* ``residual_tolerance`` (1e-10): every ``residual_check_frequency``-th FTRAN computes the
  normwise backward error ``||B x - a||_inf / (||a||_inf + ||B||_inf ||x||_inf)`` and
  refactorizes when it exceeds the tolerance.
* ``rank_tolerance`` (1e-11): a pivot of the fresh LU of the non-unit block is treated
  as zero when ``|u_jj| <= rank_tolerance * ||column||_inf``; the rank-revealing QR used to
  repair small singular blocks uses the same relative threshold on ``|R_ii| / |R_00|``.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass, field

from ..exceptions import OptionError

KIND_M = 0
"""Slot kind: ``sign * M[:, index]``."""
KIND_UNIT = 1
"""Slot kind: ``sign * e_index`` (slacks w (sign -1), v (sign +1), artificials)."""
KIND_DENSE = 2
"""Slot kind: ``sign * r``, the dense covering vector (index ignored)."""

_BACKENDS = ("superlu", "umfpack", "auto")
_ORDERINGS = ("auto", "colamd", "amd", "metis")


@dataclass(frozen=True)
class BasisOptions:
    """Options of :class:`~compass_sparse.basis.BasisManager` (immutable).

    Attributes
    ----------
    update_limit : int, default 50, range >= 0
        Maximum number of Forrest-Tomlin updates between two factorizations (PATH's
        ``factorization_update_limit``). The replacement that would exceed it is done by
        a fresh factorization (counted in ``stats.refactor_by_count``). 0 = refactorize on
        every replacement.
    fill_factor : float, default 2.0, range >= 1
        Refactorize (``stats.refactor_by_fill``) when ``nnz(L) + nnz(U) + nnz(etas)`` would
        exceed ``fill_factor`` times ``nnz(L) + nnz(U)`` right after the last factorization
        (nonzeros counted including the diagonal of U).
    pivot_tolerance : float, default 1e-11, range [0, 1)
        Relative tininess that REFUSES a replacement: ``|u_new| <= pivot_tolerance *
        ||spike||_inf`` or ``|d_p| <= pivot_tolerance * ||d||_inf`` (d the FTRAN column,
        p the leaving slot). The basis is then left unchanged.
    stability_tolerance : float, default 1e-8, range > 0
        Relative disagreement between the two computations of the new diagonal
        (``d1 = d_p u_pp`` vs ``d2`` from the row eta) that triggers a refactorization
        (``stats.refactor_by_stability``).
    residual_check_frequency : int, default 20, range >= 0
        Every k-th FTRAN (``ftran``/``ftran_column``) computes the backward error
        ``||B x - a|| / (||a|| + ||B|| ||x||)`` (inf-norms); 0 disables the check.
    residual_tolerance : float, default 1e-10, range > 0
        Backward-error bound of the periodic check; above it the manager refactorizes
        (``stats.refactor_by_residual``) and solves again.
    rank_tolerance : float, default 1e-11, range [0, 1)
        Relative pivot size below which a fresh factorization treats a column as
        dependent (see the module docstring); such columns are repaired by unit columns.
    dense_rank_limit : int, default 3000, range >= 0
        Non-unit blocks up to this order are rank-repaired with a dense QR with column
        pivoting; larger ones by repeated sparse LU with tiny-pivot detection.
    backend : {"superlu", "umfpack", "auto"}, default "auto"
        Sparse LU of the non-unit block (:mod:`compass_sparse.basis.backends`). "auto" =
        SuperLU with COLAMD below 400 columns and with the ``ordering`` above (measured
        crossovers in ``benchmarks/basis.md``); "umfpack" = SuiteSparse UMFPACK (kvxopt),
        which orders by itself (``ordering`` must then be "auto"). The environment
        variable ``COMPASS_SPARSE_LU`` ("backend[:ordering]") replaces "auto" values.
    ordering : {"auto", "colamd", "amd", "metis"}, default "auto"
        Fill-reducing ordering of the block (:mod:`compass_sparse.basis.ordering`),
        computed once per sparsity pattern. "auto" = the cheaper of AMD and METIS nested
        dissection by the symbolic flop estimate (COLAMD when the block has no zero-free
        diagonal).
    diag_pivot_thresh : float or None, default None, range [0, 1]
        SuperLU threshold for row pivoting; None = 1.0 (partial pivoting) under COLAMD and
        0.1 under a symmetric ordering (the diagonal is kept while it is at least 0.1 of
        the largest entry of its column).
    deadline : float or None, default None
        ``time.perf_counter()`` value by which a factorization must end: one whose
        symbolic flop estimate cannot finish in the time left is not started
        (:class:`~compass_sparse.basis.backends.FactorBudgetError`, kind "time").
    memory_limit : float or None, default None, range > 0
        Bytes the factors may take; a factorization estimated to need more is not
        started (kind "memory"). None = 80% of the memory available when the manager is
        created; ``math.inf`` = no limit.
    reuse_factors : bool, default False
        After :meth:`set_matrix` (a new M of the same sparsity pattern), a
        :meth:`factor` call with the slot table of the factors held does not factor:
        solves run GMRES on the new B preconditioned by the held factors
        (:mod:`compass_sparse.basis.krylov`) and fall back to a fresh factorization on
        any doubt (see ``reuse_tolerance``, ``reuse_iterations``; a column replacement or
        a BTRAN also factors afresh first).
    reuse_tolerance : float, default 1e-14, range (0, 1e-6]
        Backward error ``||B x - a||_inf / (||a||_inf + ||B||_inf ||x||_inf)`` a solve on
        reused factors must reach; else the basis is factored afresh and solved directly.
        A fresh LU reaches 1e-16..1e-14.  1e-12 was too loose: on the one-sector Ramsey
        model (n = 2703, 25% capital tax) the Newton iterates then stalled at a residual
        of 4e-9 that the acceptance test rejects, and the solve failed after 50 restarts
        (fresh factors: 3 major iterations).
    reuse_min_nnz : int, default 50000, range >= 0
        Factors with fewer entries in L + U are not reused: a fresh factorization costs
        less than the GMRES steps around it (Ramsey model n = 993, nnz(L+U) 5e3: 46 ms
        reused against 34 ms fresh; static CGE n = 1012, 1.5e5: 73 against 97 ms).
    reuse_iterations : int, default 30, range >= 1
        GMRES steps allowed per solve on reused factors (a step costs two triangular
        solves with the held factors and a product with B: at n = 3e4 and 1e5 about 1/50
        of a factorization).  A solve that needed more than half of them ends the reuse
        at the next :meth:`factor` (the factors have aged); GMRES stops early when its
        rate of decrease predicts failure (:mod:`compass_sparse.basis.krylov`).
    """

    update_limit: int = 50
    fill_factor: float = 2.0
    pivot_tolerance: float = 1e-11
    stability_tolerance: float = 1e-8
    residual_check_frequency: int = 20
    residual_tolerance: float = 1e-10
    rank_tolerance: float = 1e-11
    dense_rank_limit: int = 3000
    backend: str = "auto"
    ordering: str = "auto"
    diag_pivot_thresh: float | None = None
    deadline: float | None = None
    memory_limit: float | None = None
    reuse_factors: bool = False
    reuse_tolerance: float = 1e-14
    reuse_iterations: int = 30
    reuse_min_nnz: int = 50000

    def __post_init__(self):
        def bad(name, why):
            raise OptionError(f"BasisOptions.{name}={getattr(self, name)!r}: {why}")

        if int(self.update_limit) != self.update_limit or self.update_limit < 0:
            bad("update_limit", "must be an integer >= 0")
        if not self.fill_factor >= 1.0:
            bad("fill_factor", "must be >= 1")
        if not 0.0 <= self.pivot_tolerance < 1.0:
            bad("pivot_tolerance", "must be in [0, 1)")
        if not self.stability_tolerance > 0.0:
            bad("stability_tolerance", "must be > 0")
        if int(self.residual_check_frequency) != self.residual_check_frequency or \
                self.residual_check_frequency < 0:
            bad("residual_check_frequency", "must be an integer >= 0")
        if not self.residual_tolerance > 0.0:
            bad("residual_tolerance", "must be > 0")
        if not 0.0 <= self.rank_tolerance < 1.0:
            bad("rank_tolerance", "must be in [0, 1)")
        if self.dense_rank_limit < 0:
            bad("dense_rank_limit", "must be >= 0")
        if self.backend not in _BACKENDS:
            bad("backend", f"must be one of {_BACKENDS}")
        if self.ordering not in _ORDERINGS:
            bad("ordering", f"must be one of {_ORDERINGS}")
        if self.backend == "umfpack" and self.ordering != "auto":
            bad("ordering", "UMFPACK orders by itself: use backend='superlu' to force one")
        if self.diag_pivot_thresh is not None and not 0.0 <= self.diag_pivot_thresh <= 1.0:
            bad("diag_pivot_thresh", "must be None or in [0, 1]")
        if self.memory_limit is not None and not self.memory_limit > 0:
            bad("memory_limit", "must be None or > 0")
        if not 0.0 < self.reuse_tolerance <= 1e-6:
            bad("reuse_tolerance", "must be in (0, 1e-6]")
        if int(self.reuse_iterations) != self.reuse_iterations or self.reuse_iterations < 1:
            bad("reuse_iterations", "must be an integer >= 1")
        if int(self.reuse_min_nnz) != self.reuse_min_nnz or self.reuse_min_nnz < 0:
            bad("reuse_min_nnz", "must be an integer >= 0")


@dataclass
class BasisStats:
    """Counters and timers of a :class:`BasisManager` (cumulative unless stated).

    ``refactor_by_*`` count the replacements that were carried out by a fresh
    factorization, one counter per trigger; ``nnz_L``, ``nnz_U`` (including its diagonal)
    and ``nnz_eta`` describe the current factors. Times are wall-clock seconds.
    ``backend`` and ``ordering`` name those of the latest sparse LU, ``orderings_computed``
    counts the fill-reducing orderings computed (the others were reused for an unchanged
    pattern); ``est_nnz_lu``, ``est_flops`` and ``est_bytes`` are the largest symbolic
    estimates met (-1: none computed), ``max_nnz_lu`` the largest nnz(L + U) obtained.
    ``reuse*`` count the work on held factors (``BasisOptions.reuse_factors``).
    """

    factorizations: int = 0
    updates: int = 0
    refused_updates: int = 0
    refactor_by_count: int = 0
    refactor_by_fill: int = 0
    refactor_by_stability: int = 0
    refactor_by_residual: int = 0
    residual_checks: int = 0
    rank_repairs: int = 0
    ftran_calls: int = 0
    btran_calls: int = 0
    time_factor: float = 0.0
    time_solve: float = 0.0
    time_update: float = 0.0
    nnz_L: int = 0
    nnz_U: int = 0
    nnz_eta: int = 0
    backend: str = ""
    ordering: str = ""
    orderings_computed: int = 0
    time_ordering: float = 0.0
    est_nnz_lu: int = -1
    est_flops: float = -1.0
    est_bytes: float = -1.0
    max_nnz_lu: int = 0
    #: the sparse engine's nonzero factor entries (L + U, the updates' columns and row
    #: etas) held at each of its pivots, summed: what its pivots read, but for a dense
    #: tail's stored zeros (over its pivots, the pivot-weighted mean size of the factors;
    #: a count, unlike a time)
    pivot_lu_entries: int = 0
    reuses: int = 0  #: factor() calls answered by the held factors (no factorization)
    reuse_solves: int = 0  #: solves by preconditioned GMRES on held factors
    reuse_steps: int = 0  #: GMRES steps of those solves
    reuse_fallbacks: int = 0  #: reuses ended by a fresh factorization (doubt or update)

    def record_direct_lu(self, nnz_lu: int, seconds: float, method=("superlu", "colamd")):
        """Count a sparse LU made for the basis' path outside it (the direct Newton step,
        :mod:`compass_sparse.path.direct_step`; ``method``: its (backend, ordering))."""
        self.factorizations += 1
        self.time_factor += seconds
        self.max_nnz_lu = max(self.max_nnz_lu, int(nnz_lu))
        self.backend, self.ordering = method


class UpdateStatus(enum.IntEnum):
    """Outcome of :meth:`BasisManager.replace`."""

    OK = 0
    """Forrest-Tomlin update done."""
    REFACTORED = 1
    """The replacement was done by a fresh factorization (a trigger fired or the
    stability test failed); the slot table holds the new column."""
    REFUSED = 2
    """The new pivot is relatively tiny (the new basis would be singular or nearly so):
    the basis is UNCHANGED and its factors are still valid."""
    REPAIRED = 3
    """The new basis was singular and the old one, factorized again, was singular too
    (it had lost accuracy): the replacement is NOT done and the manager holds the old
    slot table repaired (``last_report.replaced`` lists the slots that now hold unit
    columns).  The caller refactorizes its own table (with repair) to go on."""


@dataclass
class FactorReport:
    """Result of :meth:`BasisManager.factor` / :meth:`BasisManager.refactor`.

    Attributes
    ----------
    ok : bool
        True when the manager holds a valid factorization of a regular basis (possibly
        after the repair listed in ``replaced``). A basis that cannot be repaired raises
        :class:`~compass_sparse.exceptions.SingularBasisError` instead, so ``ok`` is True
        on every returned report; test ``rank_deficiency`` / ``replaced`` for repairs.
    replaced : list of (slot, old_kind, old_index, old_sign, new_row)
        Slots whose column made B singular (numerically or structurally, or a duplicated
        unit column) and now hold the unit column ``+e_{new_row}``.
    rank_deficiency : int
        ``len(replaced)``.
    """

    ok: bool = True
    replaced: list = field(default_factory=list)
    rank_deficiency: int = 0
