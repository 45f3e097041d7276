"""Fill-reducing orderings of the non-unit block K, chosen per sparsity pattern.

The cost of a sparse LU is decided by the ordering.  Three are offered:

* ``colamd``: a column ordering of K alone (approximate minimum degree on the pattern of
  K^T K), chosen inside the LU backend (SuperLU's COLAMD, UMFPACK's unsymmetric strategy);
  rows are ordered by partial pivoting.  Good for patterns far from symmetric.
* ``amd``: approximate minimum degree (SuiteSparse AMD through kvxopt) on the symmetrized
  pattern of K after a maximum transversal;
* ``metis``: nested dissection (METIS through pymetis) on the same symmetrized pattern.

Symmetric orderings need a zero-free diagonal: the rows of K are first permuted by a
maximum bipartite matching, ``K_m = K[match, :]`` with ``K_m[j, j] != 0`` structurally
(a structurally singular K has no such matching; it then falls back to ``colamd``).  With
``S = pattern(K_m + K_m^T)`` and a symmetric ordering p of S, the backend factors
``K_m[p, :][:, p]`` keeping the column order and pivoting rows with a threshold (so that
the diagonal, which the ordering counted on, is preferred).  Dense nodes of S (degree above
``max(16, 10 sqrt(n))``) are set aside before nested dissection and ordered last, as AMD
does internally: they would otherwise dominate every separator.

Symbolic estimate.  For a symmetric ordering the Cholesky factor of ``S[p][:, p]`` predicts
the LU when the diagonal pivots are kept: its column counts c_j (elimination tree plus row
subtrees, O(nnz(L)) work, stopped early once it exceeds a cap) give

    nnz(L + U) ~ 2 sum_j c_j - n,       flops ~ sum_j (c_j - 1)(2 c_j + 1)  (~ 2 sum c_j^2),

so the better of AMD and METIS is the one with fewer predicted flops.  ``auto`` computes
both (METIS only above ``METIS_MIN_N``, where its cost pays) and keeps the cheaper; it
chooses ``colamd`` only when no matching exists.  (UMFPACK would pick its unsymmetric
strategy on the CGE Jacobians, whose matched patterns have about 1% mirrored entries;
nested dissection of the symmetrized pattern is still 2-10x cheaper there, measured.)
The estimate overstates the fill of an unsymmetric K (measured 1.5x on CGE Jacobians) but
ranks the orderings correctly.

Time.  Every ordering is started only with the time to finish it and the factorization
after it (a ``deadline``; :func:`compute_ordering`): past the deadline none is started, the
costs are predicted from the pattern (seconds per entry of ``n + nnz``, measured:
:data:`PREPARE_SECONDS_PER_ENTRY`, :data:`AMD_SECONDS_PER_ENTRY`,
:data:`METIS_SECONDS_PER_ENTRY`; the factorization's from the backend), nested dissection
is passed over where it would not fit in the time left or could not pay for itself (its
cost above the predicted factorization under AMD: banded and other patterns that AMD
orders with little fill, where METIS took 2.5 s and saved nothing on a tridiagonal block
of order 7e5), and AMD where it would not fit (SuperLU's COLAMD then orders inside the
factorization).  An ordering chosen for lack of time is used once and not kept.

An :class:`OrderingCache` keeps the result per numerical pattern (a hash of the positions
of the nonzero values), shared within the process: every factorization of the same pattern
(crash steps, Newton steps, refactorizations after updates) reuses it, and only the numeric
factorization is repeated.

Neighbouring patterns.  The crash factors principal submatrices ``J[I, I]`` of one Jacobian
whose index set I changes by a few indices per iteration.  Given the labels I, a symmetric
ordering of a recent set I' with ``|I xor I'| <= max(NEAR_MIN, NEAR_FRACTION |I|)`` is
carried over instead of computed: the positions whose column and matched row stay keep
their order, the columns left over follow at the end, matched among the rows left over
(or, when they cannot be, the whole block is matched afresh under the carried column
order).  It is used only
when the carried matching puts a nonzero on every diagonal position (checked on K); its
estimates are those of I' (the fill of a few moved indices changes them little).
"""

from __future__ import annotations

import hashlib
import logging
import math
import time
from collections import OrderedDict
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from .._jit import njit
from ..exceptions import FactorBudgetError
from ..linalg.matching import column_matching

log = logging.getLogger(__name__)

ORDERINGS = ("auto", "colamd", "amd", "metis")
"""Values of ``BasisOptions.ordering``."""

METIS_MIN_N = 2000
"""Below this order ``auto`` does not try nested dissection (its setup costs more than it
saves on small blocks, measured on the CGE Jacobians)."""

PREPARE_SECONDS_PER_ENTRY = 1.0e-7
"""Seconds per entry of ``n + nnz(K)`` that a symmetric ordering spends before ordering:
the pattern's key, the matching to a zero-free diagonal, the symmetrized pattern.
Measured 0.7-1.1e-7 (tridiagonal blocks of order 1e5 and 7e5, a 2-D grid of 1e5, CGE
blocks of 1e4 and 3e4; one core of a shared two-core machine)."""

AMD_SECONDS_PER_ENTRY = 2.0e-7
"""Seconds per entry of ``n + nnz(S)`` (S the symmetrized pattern) of AMD.  Measured
1.2e-7 (tridiagonal), 1.5e-7 (2-D grid), 2.2-2.5e-7 (CGE), 4.4e-7 (a random pattern that
fills: AMD's cost grows with the fill)."""

METIS_SECONDS_PER_ENTRY = 1.0e-6
"""Seconds per entry of ``n + nnz(S)`` of METIS' nested dissection.  Measured 0.8e-6 (CGE,
tridiagonal of order 1e5), 1.2-1.3e-6 (tridiagonal of 7e5, 2-D grid), 1.6e-6 (random)."""

_I = np.int64


def ordering_seconds(method: str, n: int, nnz_s: int) -> float:
    """Predicted seconds of the ordering ``method`` ("amd" or "metis") of a symmetric
    pattern of order n with ``nnz_s`` off-diagonal entries (its preparation apart)."""
    rate = AMD_SECONDS_PER_ENTRY if method == "amd" else METIS_SECONDS_PER_ENTRY
    return rate * (n + nnz_s)


@dataclass
class Ordering:
    """A fill-reducing ordering of a square pattern.

    ``method`` is "colamd" (nothing precomputed: the backend orders the columns itself) or
    "amd" / "metis" (``rows`` and ``cols`` are the symmetric pre-permutation: the backend
    factors ``K[rows, :][:, cols]`` without reordering its columns).  ``nnz_lu`` and
    ``flops`` are the symbolic estimates (-1 when not computed), ``time`` the seconds spent.
    ``hurried``: a cheaper ordering taken for lack of time (not kept for later solves);
    ``passed_over``: why an ordering that was a candidate was not computed ("" if none).
    """

    method: str
    rows: np.ndarray | None = None
    cols: np.ndarray | None = None
    nnz_lu: int = -1
    flops: float = -1.0
    time: float = 0.0
    symmetry: float = -1.0
    hurried: bool = False
    passed_over: str = ""


def _has_metis():
    try:
        # (lazy: ~0.07 s of import, for large problems' orderings only)
        import pymetis  # noqa: F401
    except ImportError:
        return False
    return True


def pattern_key(K) -> bytes:
    """Hash of the numerical sparsity pattern of a CSC matrix (shape and the positions of
    its nonzero values: a stored zero does not count, so a Jacobian block with its fixed
    pattern and the same block without the stored zeros share their ordering)."""
    h = hashlib.blake2b(digest_size=16)
    h.update(np.asarray(K.shape, dtype=_I).tobytes())
    nz = K.data != 0.0
    if nz.all():
        h.update(np.ascontiguousarray(K.indptr, dtype=_I).tobytes())
        h.update(np.ascontiguousarray(K.indices, dtype=_I).tobytes())
    else:
        cols = np.repeat(np.arange(K.shape[1], dtype=_I), np.diff(K.indptr))
        cnt = np.bincount(cols[nz], minlength=K.shape[1])
        h.update(np.concatenate(([0], np.cumsum(cnt))).astype(_I).tobytes())
        h.update(np.ascontiguousarray(K.indices[nz], dtype=_I).tobytes())
    return h.digest()


def zero_free_diagonal(K):
    """Row permutation ``match`` with ``K[match, :]`` structurally zero-free on the
    diagonal, or None when K is structurally singular."""
    n = K.shape[0]
    if n == 0:
        return np.zeros(0, _I)
    # the numerical pattern: an explicitly stored zero must not be matched to the
    # diagonal (SuperLU would have to pivot away from it, and the fill the ordering
    # counted on would be lost: measured 3.2e6 instead of 2.0e6 on a CGE basis block)
    nz = K.data != 0.0
    cols = np.repeat(np.arange(K.shape[1], dtype=_I), np.diff(K.indptr))
    P = sp.csc_matrix((np.ones(int(nz.sum())), (K.indices[nz], cols[nz])), shape=K.shape)
    # a column-perfect matching of K: match[j] = row matched to column j
    m = column_matching(P)
    if np.any(m < 0):
        return None
    return m.astype(_I)


def symmetrized(Km):
    """CSR pattern of ``Km + Km^T`` without the diagonal, and the fraction of the
    off-diagonal entries of Km that have a mirror entry."""
    A = sp.csr_matrix((np.ones(Km.nnz), Km.indices, Km.indptr), shape=Km.shape).T.tocsr()
    A.setdiag(0)
    A.eliminate_zeros()
    S = (A + A.T).tocsr()
    S.sum_duplicates()
    S.sort_indices()
    off = A.nnz
    mirrored = 2 * off - S.nnz       # entries present in both A and A^T
    sym = mirrored / off if off else 1.0
    return S, float(sym)


def _to_kvx(S):
    # (lazy: kvxopt loads SuiteSparse's libraries; imported where they are used)
    from kvxopt import matrix, spmatrix

    S = sp.csc_matrix(S)
    cols = np.repeat(np.arange(S.shape[1], dtype=_I), np.diff(S.indptr))
    return spmatrix(matrix(np.ones(S.nnz)), matrix(S.indices.astype(_I)), matrix(cols),
                    S.shape)


def amd_order(S):
    """AMD (SuiteSparse) permutation of the symmetric pattern S (CSR, no diagonal)."""
    # (lazy: kvxopt loads SuiteSparse's libraries; imported where they are used)
    from kvxopt import amd

    n = S.shape[0]
    if S.nnz == 0:
        return np.arange(n, dtype=_I)
    return np.asarray(amd.order(_to_kvx(S), "L"), dtype=_I).ravel()


def dense_nodes(S):
    """Nodes of degree above ``max(16, 10 sqrt(n))`` (set aside by nested dissection)."""
    n = S.shape[0]
    deg = np.diff(S.indptr)
    return np.flatnonzero(deg > max(16.0, 10.0 * np.sqrt(n)))


def metis_order(S):
    """Nested dissection (METIS) of the symmetric pattern S; dense nodes ordered last."""
    # (lazy: ~0.07 s of import, for large problems' orderings only)
    import pymetis

    n = S.shape[0]
    dense = dense_nodes(S)
    keep = np.ones(n, bool)
    keep[dense] = False
    sparse_nodes = np.flatnonzero(keep)
    if sparse_nodes.size < 3:
        return np.concatenate((sparse_nodes, dense)).astype(_I)
    G = S[sparse_nodes][:, sparse_nodes].tocsr() if dense.size else S
    if G.nnz == 0:
        perm = np.arange(sparse_nodes.size)
    else:
        adj = pymetis.CSRAdjacency(G.indptr.astype(np.int32), G.indices.astype(np.int32))
        perm, _ = pymetis.nested_dissection(adjacency=adj)
        perm = np.asarray(perm, dtype=_I)
    return np.concatenate((sparse_nodes[perm], dense)).astype(_I)


@njit(cache=True)
def _cholesky_counts(Sp, Si, perm, cap):
    """Column counts (with diagonal) of the Cholesky factor of S[perm][:, perm].

    Elimination tree by Liu's algorithm with path compression, then for each row i the
    row subtree: from every k < i adjacent to i walk up the tree until a node already
    marked for row i.  Returns (counts, ok); ok is False when sum(counts) exceeded cap
    (the walk then stops: the ordering is already worse than the best one known).
    """
    n = perm.shape[0]
    inv = np.empty(n, np.int64)
    for t in range(n):
        inv[perm[t]] = t
    parent = np.full(n, -1, np.int64)
    anc = np.full(n, -1, np.int64)
    for i in range(n):
        oi = perm[i]
        for e in range(Sp[oi], Sp[oi + 1]):
            k = inv[Si[e]]
            while k != -1 and k < i:
                nxt = anc[k]
                anc[k] = i
                if nxt == -1:
                    parent[k] = i
                k = nxt
    counts = np.ones(n, np.int64)
    mark = np.full(n, -1, np.int64)
    total = n
    for i in range(n):
        mark[i] = i
        oi = perm[i]
        for e in range(Sp[oi], Sp[oi + 1]):
            k = inv[Si[e]]
            if k >= i:
                continue
            while mark[k] != i:
                mark[k] = i
                counts[k] += 1
                total += 1
                k = parent[k]
        if total > cap:
            return counts, False
    return counts, True


def cholesky_estimate(S, perm, cap=np.inf):
    """(nnz(L+U), flops) predicted for an LU with diagonal pivots in the order ``perm`` of
    the symmetric pattern S, or None when nnz(L) exceeds ``cap``."""
    n = S.shape[0]
    if n == 0:
        return 0, 0.0
    capi = int(min(cap, 2**62))
    c, ok = _cholesky_counts(S.indptr.astype(_I), S.indices.astype(_I), perm.astype(_I), capi)
    if not ok:
        return None
    c = c.astype(np.float64)
    return int(2.0 * c.sum() - n), float(np.sum((c - 1.0) * (2.0 * c + 1.0)))


def compute_ordering(K, method="auto", deadline=None, factor_seconds=None) -> Ordering:
    """Ordering of the square CSC block K by ``method`` (one of :data:`ORDERINGS`).

    ``deadline`` (a ``time.perf_counter()`` value, None: none) and ``factor_seconds(n,
    flops)``, the backend's prediction of a factorization's seconds (None: not known), keep
    the ordering within the time left (see the module docstring): past the deadline, or
    when the ordering asked for (``amd``, ``metis``) and its factorization cannot finish
    in the time left, :class:`~compass_sparse.exceptions.FactorBudgetError` (kind "time")
    is raised; under ``auto`` the cheaper orderings are taken instead."""
    t0 = time.perf_counter()
    n = K.shape[0]
    if deadline is not None and t0 > deadline:
        raise FactorBudgetError("time", f"an ordering of a {n} x {n} block after the time "
                                "limit")
    if method == "colamd" or n <= 2:
        return Ordering("colamd", time=time.perf_counter() - t0)
    left = math.inf if deadline is None else deadline - t0
    floor = 0.0 if factor_seconds is None else factor_seconds(n, -1.0)
    first = "metis" if method == "metis" else "amd"
    need = (PREPARE_SECONDS_PER_ENTRY * (n + K.nnz) + ordering_seconds(first, n, 2 * K.nnz)
            + floor)
    if need > left:
        why = (f"{first} of a {n} x {n} block and its factorization need about {need:.2g} s; "
               f"{max(left, 0.0):.2g} s left")
        if method != "auto":
            raise FactorBudgetError("time", f"not started: {why}")
        log.debug("ordering: colamd, %s", why)
        return Ordering("colamd", time=time.perf_counter() - t0, hurried=True,
                        passed_over=why)
    match = zero_free_diagonal(K)
    if match is None:
        if method != "auto":
            log.debug("ordering %s: no zero-free diagonal, using colamd", method)
        return Ordering("colamd", time=time.perf_counter() - t0)
    Km = sp.csc_matrix(K[match, :])
    Km.eliminate_zeros()
    S, sym = symmetrized(Km)
    p = amd_order(S) if first == "amd" else metis_order(S)
    nnz_lu, flops = cholesky_estimate(S, p)
    m, hurried, passed_over = first, False, ""
    if method == "auto" and n >= METIS_MIN_N and _has_metis():
        passed_over, hurried = _metis_passed_over(n, S.nnz, flops, deadline, factor_seconds)
        if not passed_over:
            p2 = metis_order(S)
            # an ordering with three times the fill of the best one cannot win on flops
            est = cholesky_estimate(S, p2, cap=3 * (nnz_lu + n) // 2)
            if est is not None and est[1] < flops:
                m, p, (nnz_lu, flops) = "metis", p2, est
        else:
            log.debug("ordering: metis passed over, %s", passed_over)
    return Ordering(m, rows=match[p], cols=p, nnz_lu=nnz_lu, flops=flops,
                    time=time.perf_counter() - t0, symmetry=sym, hurried=hurried,
                    passed_over=passed_over)


def _metis_passed_over(n, nnz_s, amd_flops, deadline, factor_seconds):
    """(why nested dissection is not computed, or "", whether for lack of time): when its
    predicted cost exceeds that of the factorization under AMD, which it could at best
    save (banded patterns: no fill to save), or when it and that factorization would not
    finish by the deadline."""
    if factor_seconds is None:
        return "", False
    t_metis = ordering_seconds("metis", n, nnz_s)
    t_factor = factor_seconds(n, amd_flops)
    if t_metis >= t_factor:
        return (f"its ~{t_metis:.2g} s would cost more than the factorization under amd "
                f"(~{t_factor:.2g} s)"), False
    if deadline is not None:
        left = deadline - time.perf_counter()
        if t_metis + t_factor > left:
            return (f"it and the factorization need ~{t_metis + t_factor:.2g} s; "
                    f"{max(left, 0.0):.2g} s left"), True
    return "", False


_SHARED: OrderedDict[tuple, Ordering] = OrderedDict()
_SHARED_SIZE = 8

NEAR_MIN = 16
NEAR_FRACTION = 0.005
"""An ordering is carried over to a principal submatrix whose index set differs from a
cached one by at most ``max(NEAR_MIN, NEAR_FRACTION * n)`` indices (see the module
docstring); more changes compute a fresh ordering."""

_NEAR: list = []  # (method, sorted labels, Ordering in those labels' local numbering)
_NEAR_SIZE = 4


def _diagonal_nonzero(K, rows, cols):
    """True when ``K[rows[t], cols[t]] != 0`` for every t (K CSC with sorted indices)."""
    n = K.shape[0]
    colrep = np.repeat(np.arange(n, dtype=_I), np.diff(K.indptr))
    keys = colrep * n + K.indices
    want = cols.astype(_I) * n + rows
    pos = np.searchsorted(keys, want)
    ok = pos < keys.size
    ok[ok] = keys[pos[ok]] == want[ok]
    return bool(ok.all() and np.all(K.data[pos] != 0.0))


def carry_ordering(K, labels, old_labels, old: Ordering):
    """The ordering ``old`` of the principal submatrix with (sorted) ``old_labels``
    carried over to K, the principal submatrix with (sorted) ``labels``; None when the
    carried matching leaves a zero on the diagonal."""
    t0 = time.perf_counter()
    gcols = old_labels[old.cols]
    grows = old_labels[old.rows]
    keep = np.isin(gcols, labels, assume_unique=True) & np.isin(grows, labels, assume_unique=True)
    cols_g, rows_g = gcols[keep], grows[keep]
    rest_c = np.searchsorted(labels, np.setdiff1d(labels, cols_g, assume_unique=True))
    rest_r = np.searchsorted(labels, np.setdiff1d(labels, rows_g, assume_unique=True))
    K = sp.csc_matrix(K)
    if not K.has_sorted_indices:
        K = K.sorted_indices()
    m = None
    if rest_c.size:
        # the columns left over are matched among the rows left over (a small problem)
        m = zero_free_diagonal(sp.csc_matrix(K[rest_r, :][:, rest_c]))
    cols = np.concatenate((np.searchsorted(labels, cols_g), rest_c)).astype(_I)
    if m is not None or not rest_c.size:
        rows = np.concatenate((np.searchsorted(labels, rows_g),
                               rest_r[m] if m is not None else rest_r)).astype(_I)
    else:
        # no such matching: a new one of K under the carried column order (fill within a
        # few per cent of a fresh ordering, measured on CGE blocks)
        match = zero_free_diagonal(K)
        if match is None:
            return None
        cols = np.concatenate((np.searchsorted(labels, gcols[np.isin(gcols, labels,
                                                                     assume_unique=True)]),
                               np.searchsorted(labels, np.setdiff1d(labels, gcols,
                                                                    assume_unique=True))))
        cols = cols.astype(_I)
        rows = match[cols]
    if not _diagonal_nonzero(K, rows, cols):
        return None
    return Ordering(old.method, rows=rows, cols=cols, nnz_lu=old.nnz_lu, flops=old.flops,
                    time=time.perf_counter() - t0, symmetry=old.symmetry)


def _near(method, K, labels):
    """An ordering carried over from a cached neighbouring index set, or None."""
    n = labels.size
    for m, lab, o in reversed(_NEAR):
        if m != method or o.method not in ("amd", "metis"):
            continue
        if abs(lab.size - n) > max(NEAR_MIN, NEAR_FRACTION * n):
            continue
        diff = lab.size + n - 2 * np.intersect1d(lab, labels, assume_unique=True).size
        if 0 < diff <= max(NEAR_MIN, NEAR_FRACTION * n):
            c = carry_ordering(K, labels, lab, o)
            if c is not None:
                return c
    return None


def _remember(method, labels, o):
    if labels is None or o.method not in ("amd", "metis"):
        return
    _NEAR.append((method, labels, o))
    del _NEAR[:-_NEAR_SIZE]


class OrderingCache:
    """Orderings by numerical pattern, shared by every cache of the process (the crash and
    the basis manager factor blocks of the same Jacobian): the ``_SHARED_SIZE`` most
    recently used patterns are kept.  ``computed`` / ``reused`` / ``carried`` (from a
    neighbouring index set) count this cache's calls."""

    def __init__(self, method="auto", factor_seconds=None):
        self.method = method
        self.factor_seconds = factor_seconds  # (n, flops) -> predicted seconds, or None
        self.computed = 0
        self.reused = 0
        self.carried = 0

    def get(self, K, key=None, labels=None, deadline=None) -> Ordering:
        """The ordering of K.  ``labels`` (optional, increasing): K is the principal
        submatrix of a larger matrix on these indices, so that the ordering of a
        neighbouring index set may be carried over (see the module docstring).
        ``deadline``: see :func:`compute_ordering`; an ordering to be made is not started
        past it (:class:`~compass_sparse.exceptions.FactorBudgetError`)."""
        if deadline is not None and time.perf_counter() > deadline:
            raise FactorBudgetError("time", f"an ordering of a {K.shape[0]} x {K.shape[1]} "
                                    "block after the time limit")
        key = (self.method, pattern_key(K) if key is None else key)
        o = _SHARED.get(key)
        if o is not None:
            _SHARED.move_to_end(key)
            self.reused += 1
            return o
        if labels is not None:
            labels = np.asarray(labels, dtype=_I)
            if labels.size != K.shape[0] or np.any(np.diff(labels) <= 0):
                labels = None       # (not increasing labels of K's rows: ignored)
        o = _near(self.method, K, labels) if labels is not None else None
        if o is not None:
            self.carried += 1
            log.debug("ordering of a %d x %d block carried over from a neighbouring index "
                      "set (%.3f s)", K.shape[0], K.shape[1], o.time)
        else:
            o = compute_ordering(K, self.method, deadline, self.factor_seconds)
            self.computed += 1
            log.debug("ordering of a %d x %d block (nnz %d): %s, estimated nnz(L+U) %d, "
                      "%.3g flops, %.3f s", K.shape[0], K.shape[1], K.nnz, o.method,
                      o.nnz_lu, o.flops, o.time)
            if o.hurried:
                return o  # (for lack of time: a later solve with time orders afresh)
        _remember(self.method, labels, o)
        _SHARED[key] = o
        while len(_SHARED) > _SHARED_SIZE:
            _SHARED.popitem(last=False)
        return o
