"""Rank repair of the non-unit block of a basis (COMPASS thesis §4.2.3).

With the unit columns of B ordered first, B permutes to ``[[D, C], [0, K]]`` where D is a
signed identity on the rows covered by unit columns and K holds the non-unit columns
(M columns and the dense column) restricted to the uncovered rows. B is regular iff K is.

When K is singular, the repair keeps a maximal independent set of K's columns and gives
each left-out column's slot a unit column ``+e_row`` on a row that then lacks a pivot; in
effect the basis is rebuilt from unit columns by bringing non-unit columns in while the
factor stays regular. The number of non-unit columns kept equals rank(K) (up to the rank
tolerance), the largest number any regular basis of this form can keep.

Steps, repeated until the LU of the kept block has no tiny pivot:

1. structural: a maximum bipartite matching of K's pattern
   (:mod:`compass_sparse.linalg.matching`); unmatched columns are dropped,
   unmatched rows freed -- except for a square block larger than the dense limit, where
   tiny entries on the matching completed by pairing the unmatched rows and columns make
   the block factorable and its tiny pivots choose the columns (and the null space the
   rows), as in step 3: the matching's unmatched column may be a numerically
   independent one;
2. numerical, small blocks (order <= ``dense_rank_limit``): QR with column pivoting of
   the column-equilibrated dense block picks ``rank`` independent columns
   (``|R_ii| > rank_tolerance * |R_00|``); a second pivoted QR of the kept columns'
   transpose picks the rows they pivot on;
3. numerical, large blocks: pivots of the sparse LU with
   ``|u_jj| <= rank_tolerance * ||K[:, j]||_inf`` mark dependent columns; the column and
   the row pivoted at that position are dropped. An exactly singular block (the LU
   backend gives up) is factored with a tiny diagonal perturbation on the matching
   (``0.01 * rank_tolerance`` relative) to locate the dependent columns.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from ..linalg.matching import column_matching
from ..linalg.blas import single_threaded_blas
from ..exceptions import SingularBasisError
from .backends import SingularFactorError


def _col_inf_norms(K):
    K = sp.csc_matrix(K)
    if K.nnz == 0:
        return np.zeros(K.shape[1])
    a = np.abs(K.data)
    nz = np.diff(K.indptr) > 0
    out = np.zeros(K.shape[1])
    out[nz] = np.maximum.reduceat(a, K.indptr[:-1][nz])
    return out


def _structural(K):
    """Return (rows, cols) of a maximum matching, paired (rows[i] matched to cols[i])."""
    if K.shape[1] == 0 or K.shape[0] == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    Kp = sp.csc_matrix(K, copy=True)
    Kp.eliminate_zeros()
    match = column_matching(Kp)  # column -> row
    cols = np.flatnonzero(match >= 0)
    return match[cols].astype(np.int64), cols.astype(np.int64)


def _tiny_pivots(fac, K, rank_tol):
    """Positions of the LU whose pivot is tiny relative to its column."""
    Ks = K
    if fac.row_scale is not None:
        Ks = sp.diags(fac.row_scale) @ K
    cn = _col_inf_norms(Ks)[fac.col_order]
    d = np.abs(fac.U.diagonal())
    bad = ~np.isfinite(d) | (d <= rank_tol * cn) | (d == 0.0)
    return np.flatnonzero(bad)


NULL_SPACE_ROWS_MAX = 64
"""Up to this many tiny pivots in one round, the rows freed for unit columns are chosen
from the left null space of the block (below); above it, the rows pivoted at the tiny
positions are freed (an n x d dense null-space basis would cost too much memory)."""


def _rows_to_free(fac, bad):
    """Positions (rows of the factored block) to leave to unit columns, one per tiny
    pivot position in ``bad``.

    The rows pivoted at the tiny positions are an accident of the rounding: at such a
    step the remaining column is noise, and a block kept without those rows can be
    ill-conditioned (cond 1.6e9 with every pivot above 0.018, measured on an exactly
    singular 300 x 300 block).  The freed rows D must make the kept block regular, which
    holds iff the left null vectors of the block, restricted to D, form a regular
    d x d matrix; so the null vectors are computed (one triangular solve pair each: the
    tiny pivots amplify their components by 1/pivot) and pivoted QR of their orthonormal
    basis picks the d rows on which they are best conditioned."""
    d = bad.size
    if d == 0 or d > NULL_SPACE_ROWS_MAX:
        return fac.row_order[bad]
    # (lazy: scipy's linalg adds ~0.15 s to the package's import)
    import scipy.linalg as sla
    from scipy.sparse.linalg import spsolve_triangular

    n = fac.U.shape[0]
    # (S K)[ro][:, co] = L U, so (S K)^T w = b  <=>  U^T L^T w[ro] = b[co]; a left null
    # vector of K is y = S w with b = e_k at a tiny pivot position k.
    E = np.zeros((n, d))
    E[bad, np.arange(d)] = 1.0
    with np.errstate(all="ignore"):
        V = spsolve_triangular(sp.csr_matrix(fac.U.T), E, lower=True)
        W = spsolve_triangular(sp.csr_matrix(fac.L.T), V, lower=False,
                               unit_diagonal=True)
    Y = np.empty_like(W)
    Y[fac.row_order] = W
    if fac.row_scale is not None:
        Y *= fac.row_scale[:, None]
    scale = np.abs(Y).max(axis=0)
    if not np.all(np.isfinite(Y)) or np.any(scale == 0.0):
        return fac.row_order[bad]
    Q, _ = np.linalg.qr(Y / scale)
    _, _, piv = sla.qr(Q.T, mode="economic", pivoting=True)
    return np.sort(piv[:d])


def _perturbed(K, pr, pc, rank_tol):
    """K plus tiny entries (0.01 rank_tol relative to each column, with the sign of the
    entry they add to) on the perfect matching pairing rows pr[i] with columns pc[i]: a
    factorable block whose tiny pivots locate K's dependent columns."""
    cn = _col_inf_norms(K)
    cn[cn == 0.0] = 1.0
    sg = np.where(np.asarray(K[pr, pc]).ravel() < 0.0, -1.0, 1.0)
    eps = 0.01 * max(rank_tol, 1e-14)
    return sp.csc_matrix(K + sp.csc_matrix((sg * cn[pc] * eps, (pr, pc)), shape=K.shape))


def _without(rows, cols, col_pos, row_pos):
    """rows and cols less the positions row_pos and col_pos."""
    keep_c = np.ones(cols.size, bool)
    keep_c[col_pos] = False
    keep_r = np.ones(rows.size, bool)
    keep_r[row_pos] = False
    return rows[keep_r], cols[keep_c]


def _perturbed_choice(K, r_m, c_m, backend, rank_tol):
    """(columns to drop, rows to free) of a square, structurally singular K, chosen on
    the numbers: tiny entries (0.01 rank_tol relative to each column) on a perfect matching
    -- the maximum matching (r_m, c_m) completed by pairing its unmatched rows with its
    unmatched columns -- make K factorable; the tiny pivots of that factorization mark the
    dependent columns and :func:`_rows_to_free` the rows.  (None, None) when the
    perturbed block does not factor or shows no tiny pivot."""
    n = K.shape[0]
    r0 = np.setdiff1d(np.arange(n), r_m)
    c0 = np.setdiff1d(np.arange(n), c_m)
    Kp = _perturbed(K, np.concatenate((r_m, r0)), np.concatenate((c_m, c0)), rank_tol)
    try:
        fac = backend.factor(Kp, strict=True)
    except SingularFactorError:
        return None, None
    bad = _tiny_pivots(fac, K, rank_tol)
    if bad.size < c0.size:
        return None, None
    return fac.col_order[bad], _rows_to_free(fac, bad)


def _dense_select(K, rank_tol):
    """Indices (rows, cols) of a maximal regular square sub-block of the dense K."""
    A = K.toarray() if sp.issparse(K) else np.asarray(K, float)
    m, c = A.shape
    if m == 0 or c == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    # Single-threaded BLAS (see compass_sparse.linalg.blas); this factorization is also atomic
    # for the solve's time limit.
    with single_threaded_blas():
        return _dense_select_qr(A, rank_tol)


def _dense_select_qr(A, rank_tol):
    import scipy.linalg as sla  # (lazy: scipy's linalg adds ~0.15 s to the package's import)

    cn = np.abs(A).max(axis=0)
    cn[cn == 0.0] = 1.0
    R, piv = sla.qr(A / cn, mode="r", pivoting=True)
    rd = np.abs(np.diag(R))
    if rd.size == 0 or rd[0] == 0.0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    rank = int(np.count_nonzero(rd > rank_tol * rd[0]))
    cols = np.sort(piv[:rank])
    At = A[:, cols].T
    rn = np.abs(At).max(axis=0)
    rn[rn == 0.0] = 1.0
    R2, piv2 = sla.qr(At / rn, mode="r", pivoting=True)
    rows = np.sort(piv2[:rank])
    return rows.astype(np.int64), cols.astype(np.int64)


def select_regular_block(K, backend, rank_tol, dense_limit, max_rounds=30):
    """Find row and column index sets of K such that K[rows][:, cols] is square and
    regular, with len(cols) = rank(K) (numerically), and factor it.

    Returns (rows, cols, factors): ``factors`` is the backend LU of
    ``K[rows, :][:, cols]``; ``rows``/``cols`` index K.
    """
    K = sp.csc_matrix(K)
    rows = np.arange(K.shape[0], dtype=np.int64)
    cols = np.arange(K.shape[1], dtype=np.int64)
    if K.shape[0] == K.shape[1] and K.shape[0] > 0:
        # Fast path, the common case: K is regular and one factorization settles it.  The
        # matching below can cost far more than the LU (0.4 s against 2 ms at n = 1000,
        # measured on a banded block), so it only runs when the LU reports trouble.
        try:
            fac = backend.factor(K)
            if _tiny_pivots(fac, K, rank_tol).size == 0:
                return rows, cols, fac
        except SingularFactorError:
            pass
    dense_done = False
    for _ in range(max_rounds):
        sub = K[rows, :][:, cols]
        r_m, c_m = _structural(sub)
        if (sub.shape[0] == sub.shape[1] and 0 < r_m.size < sub.shape[0]
                and sub.shape[0] > dense_limit):
            # Structurally singular and square: which columns and rows go is decided
            # numerically, not by the matching (whose unmatched column may be an
            # independent one: one column more than the rank deficiency was lost).
            bad_c, freed = _perturbed_choice(sp.csc_matrix(sub), r_m, c_m, backend, rank_tol)
            if bad_c is not None:
                rows, cols = _without(rows, cols, bad_c, freed)
                continue
        rows, cols = rows[r_m], cols[c_m]
        if cols.size == 0:
            return rows, cols, None
        Kk = sp.csc_matrix(K[rows, :][:, cols])
        try:
            # COLAMD and partial pivoting from here on: with threshold pivoting in a
            # symmetric ordering a small pivot may fall on an independent column and
            # more columns be dropped than the rank deficiency
            fac = backend.factor(Kk, strict=True)
            bad = _tiny_pivots(fac, Kk, rank_tol)
        except SingularFactorError:
            fac, bad = None, None
        if fac is not None and bad.size == 0:
            return rows, cols, fac
        if cols.size <= dense_limit and not dense_done:
            dense_done = True
            r_d, c_d = _dense_select(Kk, rank_tol)
            rows, cols = rows[r_d], cols[c_d]
            continue
        if fac is None:
            # exactly singular: perturb the matched diagonal slightly to find the culprits
            diag = np.arange(cols.size)  # rows[i] is matched to cols[i]
            Kp = _perturbed(Kk, diag, diag, rank_tol)
            try:
                fac_p = backend.factor(Kp, strict=True)
            except SingularFactorError as exc:
                raise SingularBasisError(
                    "rank repair failed: perturbed block still singular") from exc
            bad = _tiny_pivots(fac_p, Kk, rank_tol)
            if bad.size == 0:
                bad = _tiny_pivots(fac_p, Kk, max(rank_tol, 1e-10) * 1e3)
            if bad.size == 0:
                raise SingularBasisError("rank repair failed: no dependent column found")
            fac = fac_p
        rows, cols = _without(rows, cols, fac.col_order[bad], _rows_to_free(fac, bad))
    raise SingularBasisError("rank repair did not converge")
