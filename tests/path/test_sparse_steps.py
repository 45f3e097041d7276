"""The sparse LU's dense tail (compass_sparse.path._sparse_steps): where it starts, that
its factors solve B x = b as a dense solve does (with and without room for it), its rank
test at both sides of the rank tolerance, the repair of a dependent column found in it,
and the storage check; and the solves' backward error on ill-conditioned bases."""
from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from compass_sparse.basis import _kernels as BK
from compass_sparse.path import _sparse_lu as SL
from compass_sparse.path import _sparse_steps as ST
from compass_sparse.path._dense_lu import N_PERM, W_REP_ROW, W_REP_SLOT
from compass_sparse.path._kernels import VAR_A, VAR_W, VAR_Z

RANK_TOL = 1e-11


def _factor(M, sk, si=None, update_limit=50, nnz_guess=None, rank_tol=RANK_TOL):
    """factor() of the slot table (sk, si) on M; returns (nrep, S, perm)."""
    M = sp.csc_matrix(M, dtype=float)
    M.sort_indices()
    n = M.shape[0]
    si = np.arange(n, dtype=np.int64) if si is None else si
    if nnz_guess is None:
        nnz_guess = 2 * M.nnz + 8 * n
    S = SL.allocate(n, update_limit, nnz_guess)
    perm = np.zeros((N_PERM, n), dtype=np.int64)
    nrep = SL.factor(M.indptr.astype(np.int64), M.indices.astype(np.int64), M.data,
                     np.zeros(0, np.int64), np.zeros(0), np.arange(n, dtype=np.int64),
                     np.asarray(sk, dtype=np.int64), si, np.ones(n, dtype=np.int64), S,
                     rank_tol, SL.PIVOT_THRESHOLD, perm[W_REP_SLOT], perm[W_REP_ROW])
    return nrep, S, perm


def _basis(M, sk, si=None):
    """The basis matrix of the slot table, dense: M's column for a basic z, -e_i for w_i,
    +e_i for an artificial on row si."""
    M = np.asarray(sp.csc_matrix(M).todense())
    n = M.shape[0]
    si = np.arange(n) if si is None else si
    B = np.zeros((n, n))
    for s in range(n):
        if sk[s] == VAR_Z:
            B[:, s] = M[:, si[s]]
        else:
            B[si[s], s] = -1.0 if sk[s] == VAR_W else 1.0
    return B


def _check_solves(S, B):
    """FTRAN and BTRAN against numpy's dense solves."""
    n = B.shape[0]
    rng = np.random.default_rng(5)
    b = rng.standard_normal(n)
    x = np.zeros(n)
    SL.ftran_dense(S, 0, b, x)
    ref = np.linalg.solve(B, b)
    assert np.max(np.abs(x - ref)) <= 1e-10 * np.max(np.abs(ref))
    y = np.zeros(n)
    SL.btran(S, 0, b, y)
    ref = np.linalg.solve(B.T, b)
    assert np.max(np.abs(y - ref)) <= 1e-10 * np.max(np.abs(ref))


def _random(n, density, seed):
    return sp.random(n, n, density=density, random_state=seed) + 4.0 * sp.identity(n)


@pytest.mark.parametrize("units", [0, 70], ids=["all z", "70 unit columns"])
def test_dense_tail_factors_solve_like_a_dense_solve(units):
    """A random sparse basis (n = 200, 3% dense) fills as it is eliminated: the last
    columns go to the dense tail, and the factors solve B x = b and B^T y = c as numpy
    does."""
    n = 200
    M = _random(n, 0.03, 0)
    sk = np.full(n, VAR_Z, dtype=np.int64)
    sk[np.random.default_rng(1).choice(n, units, replace=False)] = VAR_W
    nrep, S, _ = _factor(M, sk, nnz_guess=n * n)
    assert nrep == 0
    assert S[0][SL.H_TAIL] >= ST.DENSE_TAIL_MIN
    _check_solves(S, _basis(M, sk))


def test_the_dense_tail_is_not_cut_short_by_the_row_eta_storage():
    """The dense block is factorized in the row-eta storage, whose room was that of
    ``ETA_ROOM_UPDATES`` updates: on the CGE models' bases (n = 2024, a dense Schur
    complement of ~900 columns) that cut the tail to 318 columns and left the rest to the
    sparse steps (a factorization 620 ms instead of ~100).  The storage now holds at least
    L's entries: with the room of one update the tail is as long as with fifty, and the
    factors solve the same; a tail that does not fit asks for more storage (GROW)."""
    n = 200
    M = _random(n, 0.03, 0)
    sk = np.full(n, VAR_Z, dtype=np.int64)
    nrep, S_room, _ = _factor(M, sk, nnz_guess=n * n)
    nrep_one, S_one, _ = _factor(M, sk, update_limit=1, nnz_guess=n * n)
    assert nrep == nrep_one == 0
    assert S_one[0][SL.H_TAIL] == S_room[0][SL.H_TAIL] > 32
    _check_solves(S_one, _basis(M, sk))
    assert _factor(M, sk, update_limit=1, nnz_guess=1)[0] == SL.GROW


def test_a_large_tail_solved_along_the_positions_factors_like_a_dense_solve():
    """A tail of BLOCKED_MIN columns or more solves its columns with L_k along the
    positions (no depth-first search; on the CGE bases the search cost as much as the
    elimination): here a random basis (n = 700, 100 unit columns) whose tail of 266
    columns follows 334 sparse steps holding ~3800 entries of L, so the positional solves
    do eliminate; the factors solve B x = b and B^T y = c as numpy does."""
    n = 700
    M = _random(n, 0.008, 3)
    sk = np.full(n, VAR_Z, dtype=np.int64)
    sk[np.random.default_rng(4).choice(n, 100, replace=False)] = VAR_W
    nrep, S, _ = _factor(M, sk, nnz_guess=n * n)
    tail = S[0][SL.H_TAIL]
    assert nrep == 0 and tail >= ST.BLOCKED_MIN
    assert S[1][n - tail] > 1000  # L's entries before the tail
    _check_solves(S, _basis(M, sk))


def test_dense_tail_starts_after_the_run_of_dense_columns_and_not_on_a_sparse_basis():
    """A dense basis switches after DENSE_TAIL_RUN columns; a tridiagonal one never."""
    n = 40
    rng = np.random.default_rng(2)
    dense = rng.standard_normal((n, n)) + n * np.eye(n)
    sk = np.full(n, VAR_Z, dtype=np.int64)
    nrep, S, _ = _factor(dense, sk)
    assert nrep == 0 and S[0][SL.H_TAIL] == n - ST.DENSE_TAIL_RUN
    _check_solves(S, dense)
    tri = sp.diags([np.ones(n - 1), 4.0 * np.ones(n), np.ones(n - 1)], [-1, 0, 1])
    nrep, S, _ = _factor(tri, sk)
    assert nrep == 0 and S[0][SL.H_TAIL] == 0
    _check_solves(S, tri.toarray())


@pytest.mark.parametrize("n", [40, 300], ids=["column loop", "panels"])
@pytest.mark.parametrize("delta, dependent", [(1e-9, False), (1e-13, True)])
def test_rank_tolerance_in_the_dense_tail(delta, dependent, n):
    """Column 7 = 2 x column 3 + delta e_0 (relative to its norm) in a dense basis, both
    in the tail (of 36 columns: eliminated column by column; of 296: in panels): independent
    above RANK_TOL (the factors solve), dependent below it -- one of the two slots is
    reported with the row left without a pivot."""
    rng = np.random.default_rng(3)
    M = rng.standard_normal((n, n)) + n * np.eye(n)
    M[:, 7] = 2.0 * M[:, 3]
    M[0, 7] += delta * np.max(np.abs(M[:, 7]))
    sk = np.full(n, VAR_Z, dtype=np.int64)
    nrep, S, perm = _factor(M, sk)
    assert S[0][SL.H_TAIL] > 0
    if not dependent:
        assert nrep == 0
        return
    assert nrep == 1
    slot, row = int(perm[W_REP_SLOT][0]), int(perm[W_REP_ROW][0])
    assert slot in (3, 7) and 0 <= row < n
    # the repair: an artificial on the row left; the repaired basis factors and solves
    sk2, si2 = sk.copy(), np.arange(n, dtype=np.int64)
    sk2[slot], si2[slot] = VAR_A, row
    nrep, S, _ = _factor(M, sk2, si2)
    assert nrep == 0
    _check_solves(S, _basis(M, sk2, si2))


def test_dense_tail_that_does_not_fit_in_l_asks_for_more_storage():
    """A dense 60 x 60 basis needs ~1800 entries of L; with 1024 the factorization
    returns GROW (the engine then grows the storage and runs the path again), and with
    the grown storage it factors."""
    n = 60
    rng = np.random.default_rng(4)
    M = rng.standard_normal((n, n)) + n * np.eye(n)
    sk = np.full(n, VAR_Z, dtype=np.int64)
    nrep, S, _ = _factor(M, sk, nnz_guess=1)
    assert nrep == SL.GROW
    nrep, S, _ = _factor(M, sk, nnz_guess=4 * n * n)
    assert nrep == 0
    _check_solves(S, M)


def test_a_dense_tail_that_does_not_fit_grows_the_storage_once():
    """The factorization that finds no room for its dense tail knows the room it needs
    (h[H_NEED]): the storage grows to it at once, where doubling it grew a CGE basis'
    storage five times in a row (a partial factorization lost each time)."""
    n = 120
    rng = np.random.default_rng(6)
    M = rng.standard_normal((n, n)) + n * np.eye(n)
    sk = np.full(n, VAR_Z, dtype=np.int64)
    nrep, S, _ = _factor(M, sk, update_limit=1, nnz_guess=1)
    assert nrep == SL.GROW and S[0][SL.H_NEED] > 4 * S[2].shape[0]
    _, lim, cap = SL.grown_size(S)
    nrep, S, _ = _factor(M, sk, update_limit=lim, nnz_guess=cap)
    assert nrep == 0 and S[0][SL.H_TAIL] == n - ST.DENSE_TAIL_RUN
    _check_solves(S, M)


def _ftran_by_indices(S, nupd, b):
    """B^{-1} b through the factors' row indices, entry by entry (the definition of
    _sparse_lu.solve): the basis manager's triangular solves and row etas, which make the
    same operations through the indices."""
    h, Lp, Li, Lx, Us, Ue, Ui, Ux, Ud = S[:9]
    Rs, Ri, Rx, Rpos, pinv, slot_at, pos_of = S[13:20]
    n = b.size
    N = n + nupd
    w = np.zeros(N)
    w[pinv] = b
    BK.lsolve(Lp, Li, Lx, w, h[SL.H_M1])
    BK.apply_etas(Rs, Ri, Rx, Rpos, n + np.arange(nupd, dtype=np.int64), nupd, w)
    BK.usolve(Us, Ue, Ui, Ux, Ud, w, N)
    return w[pos_of]


def _btran_by_indices(S, nupd, c):
    """B^{-T} c through the row form and the row indices (the definition of btran): the
    basis manager's U^T solve and transposed row etas, then L^T by dot products."""
    h, Lp, Li, Lx, Us, Ue, Ui, Ux, Ud, Urp, Urj, Urx, dead = S[:13]
    Rs, Ri, Rx, Rpos, pinv, slot_at, pos_of = S[13:20]
    n = c.size
    N = n + nupd
    w = np.zeros(N)
    w[pos_of] = c
    BK.utsolve(Urp, Urj, Urx, dead, n, Us, Ue, Ui, Ux, Ud, w, 0, N)
    BK.apply_etas_t(Rs, Ri, Rx, Rpos, n + np.arange(nupd, dtype=np.int64), nupd, w)
    for j in range(n - 1, h[SL.H_M1] - 1, -1):
        s = w[j]
        for p in range(Lp[j], Lp[j + 1]):
            s -= Lx[p] * w[Li[p]]
        w[j] = s
    return w[pinv]


def _solves_through_updates(S, Mc, enters, trials, leaving, rng):
    """For each column of M in ``enters``: ``trials`` FTRAN and BTRAN of random
    right-hand sides on the factors S as they are (yields (updates so far, b, B^{-1} b,
    B^{-T} b)), then a Forrest-Tomlin update that brings the column in for the slot
    ``leaving(d, column)`` names (d = B^{-1} a); each update must be accepted."""
    n = Mc.shape[0]
    Mp, Mi = Mc.indptr.astype(np.int64), Mc.indices.astype(np.int64)
    d, rate = np.zeros(n), np.zeros(n)
    for nupd, enter in enumerate(enters):
        for _ in range(trials):
            b = rng.standard_normal(n)
            x, y = np.zeros(n), np.zeros(n)
            SL.ftran_dense(S, nupd, b, x)
            SL.btran(S, nupd, b, y)
            yield nupd, b, x, y
        dmax = SL.ftran_column(VAR_Z, enter, Mp, Mi, Mc.data, np.zeros(0, np.int64),
                               np.zeros(0), np.ones(n, np.int64), S, nupd, d, rate, 1.0)
        leave = leaving(d, enter)
        assert SL.replace_column(S, nupd, leave, d, dmax, 1e-11, 1e-8, 1e8, 2.0) == 0


def _tail_factors(n):
    """A random sparse basis (3 % dense, 70 unit columns) whose last columns go to the
    dense tail, factored: (M, M as sorted CSC, sk, the unit slots, S)."""
    M = _random(n, 0.03, 0)
    Mc = sp.csc_matrix(M)
    Mc.sort_indices()
    sk = np.full(n, VAR_Z, dtype=np.int64)
    units = np.random.default_rng(1).choice(n, 70, replace=False)
    sk[units] = VAR_W
    nrep, S, _ = _factor(M, sk, nnz_guess=n * n)
    assert nrep == 0 and S[0][SL.H_TAIL] >= ST.DENSE_TAIL_MIN
    return M, Mc, sk, units, S


def _live_tail_slot(S, d):
    """The slot of largest |d| among those whose position is a live one of the tail."""
    n = d.size
    kt = n - S[0][SL.H_TAIL]
    pos_of = S[19]
    return max((s for s in range(n) if kt <= pos_of[s] < n), key=lambda s: abs(d[s]))


def test_dense_tail_solves_as_through_the_indices_bit_for_bit_after_updates():
    """The tail's columns are stored whole (zeros too) over consecutive positions and the
    solves run over them as dense columns; FTRAN and BTRAN give, bit for bit, what the
    same factors give through their row indices -- on the fresh factors and after
    Forrest-Tomlin updates that kill columns of the tail -- and the counts of entries
    leave the stored zeros out."""
    n = 200
    M, Mc, sk, units, S = _tail_factors(n)
    h = S[0]
    kt = n - h[SL.H_TAIL]
    Lp, Ux = S[1], S[7]
    assert h[SL.H_ZL] + h[SL.H_ZU] > 0  # (a tail of a sparse basis holds zeros)
    assert h[SL.H_NNZL] == np.count_nonzero(S[3][:Lp[n]])
    assert h[SL.H_NNZU] - n == np.count_nonzero(Ux[:h[SL.H_UFREE]])
    for nupd, b, x, y in _solves_through_updates(S, Mc, units[:6], 2,
                                                 lambda d, e: _live_tail_slot(S, d),
                                                 np.random.default_rng(7)):
        assert np.array_equal(x, _ftran_by_indices(S, nupd, b))
        assert np.array_equal(y, _btran_by_indices(S, nupd, b))
    assert np.count_nonzero(S[12][kt:n]) == 6  # six tail positions dead


def test_spikes_keep_their_tail_rows_whole_and_solve_as_through_the_indices():
    """An update's new column of U whose rows in the dense tail are at least
    ``SPIKE_SEGMENT_SHARE`` nonzero stores them whole, in position order, with their row
    indices too (row p's entry zero), and the solves read them as one contiguous run:
    FTRAN and BTRAN give, bit for bit, what the same factors give through the indices,
    and agree with numpy's solve of the basis.  The entries counted leave the zeros out."""
    n = 200
    M, Mc, sk, units, S = _tail_factors(n)
    h = S[0]
    tail = int(h[SL.H_TAIL])
    kt = n - tail
    Md = M.toarray()
    B = np.where(sk == VAR_W, 0.0, 1.0) * Md  # the basis: M's column or -e_i by slot
    B[units, units] = -1.0

    def entered(d, enter):  # the slot leaving, and the basis after the exchange
        s = _live_tail_slot(S, d)
        B[:, s] = Md[:, enter]
        return s

    checked = 0
    for nupd, b, x, y in _solves_through_updates(S, Mc, units[:6], 2, entered,
                                                 np.random.default_rng(7)):
        assert np.array_equal(x, _ftran_by_indices(S, nupd, b))
        assert np.array_equal(y, _btran_by_indices(S, nupd, b))
        assert np.allclose(B @ x, b, atol=1e-10) and np.allclose(B.T @ y, b, atol=1e-10)
        checked += 1
    assert checked == 12
    Us, Ue, Ui, Ux, seg = S[4], S[5], S[6], S[7], S[23]
    whole = [j for j in range(n, n + 6) if seg[j] >= 0]
    assert whole  # (these spikes are dense in the tail rows)
    nnz_spikes = 0
    for j in range(n, n + 6):
        idx = Ui[Us[j]:Ue[j]]
        assert np.all(np.diff(idx) > 0)  # position order, the run included
        nnz_spikes += np.count_nonzero(Ux[Us[j]:Ue[j]])
        if seg[j] >= 0:
            assert np.array_equal(Ui[seg[j]:seg[j] + tail], np.arange(kt, n))
    assert h[SL.H_UFREE] - h[SL.H_UFACT] == sum(Ue[j] - Us[j] for j in range(n, n + 6))
    assert nnz_spikes < h[SL.H_UFREE] - h[SL.H_UFACT]  # zeros stored, and not counted


def _backward_error(B, x, b):
    """||B x - b|| / (||B|| ||x|| + ||b||), infinity norms: the normwise backward error."""
    return np.abs(B @ x - b).max() / (np.abs(B).sum(1).max() * np.abs(x).max()
                                      + np.abs(b).max())


@pytest.mark.parametrize("cond", [1e6, 1e10, 1e13])
def test_solves_stay_backward_stable_on_ill_conditioned_bases_and_after_updates(cond):
    """On bases of condition up to 1e13 (n = 120, 30 unit columns) FTRAN and BTRAN keep a
    normwise backward error of a few eps, fresh and after Forrest-Tomlin updates that
    bring z columns in for unit ones: measured 4e-17 to 1.2e-16; bound 1e-14."""
    n = 120
    rng = np.random.default_rng(int(np.log10(cond)))
    U_, _ = np.linalg.qr(rng.standard_normal((n, n)))
    V_, _ = np.linalg.qr(rng.standard_normal((n, n)))
    A = U_ @ np.diag(np.logspace(0, -np.log10(cond), n)) @ V_.T
    Mc = sp.csc_matrix(A)
    Mc.sort_indices()
    units = rng.choice(n, 30, replace=False)
    sk = np.full(n, VAR_Z, dtype=np.int64)
    sk[units] = VAR_W
    nrep, S, _ = _factor(Mc, sk, rank_tol=1e-15)
    assert nrep == 0
    B = _basis(Mc, sk)
    worst, updates = 0.0, 0

    def largest(d, enter):  # the slot with the largest |d| leaves; B follows the exchange
        leave = int(np.argmax(np.abs(d)))
        B[:, leave] = A[:, enter]
        return leave

    for updates, b, x, y in _solves_through_updates(S, Mc, units[:10], 3, largest, rng):
        worst = max(worst, _backward_error(B, x, b), _backward_error(B.T, y, b))
    assert updates == 9  # (the solves after the 10th update are not made)
    assert worst <= 1e-14


def _block_factors(A0):
    """_block_lu of the block A0 (column-major copy); returns (pivots, tpiv, drow, and
    the relative residual of L U against A0's rows in pivot order, pivoted columns)."""
    m, nc = A0.shape
    A = A0.ravel(order="F").copy()
    drow, rowpos = np.arange(m, dtype=np.int64), np.arange(m, dtype=np.int64)
    tpiv = np.zeros(nc, dtype=np.int64)
    npiv, _ = ST._block_lu(m, nc, A, drow, rowpos, np.abs(A0).max(axis=0),
                           -np.ones(nc, dtype=np.int64), tpiv, RANK_TOL, 1.0)
    F = A.reshape(nc, m).T
    cols = np.flatnonzero(tpiv >= 0)
    L = np.tril(F[:, cols], -1)[:, :len(cols)] + np.eye(m, len(cols))
    U = np.triu(F[:len(cols), cols])
    res = np.max(np.abs(L @ U - A0[drow][:, cols])) / np.max(np.abs(A0))
    return npiv, tpiv, drow, res


def test_dense_block_in_panels_takes_the_pivots_of_partial_pivoting():
    """A block of 300 columns (at least BLOCKED_MIN) is factorized in panels, its updates
    by BLAS: the row order is LAPACK's partial pivoting (getrf, the same rule without ties)
    and L U reproduces the block to rounding."""
    import scipy.linalg as sla
    n = 300
    assert n >= ST.BLOCKED_MIN
    A0 = np.random.default_rng(7).standard_normal((n, n))
    npiv, tpiv, drow, res = _block_factors(A0)
    assert npiv == n and np.all(tpiv == np.arange(n))
    assert res <= 1e-13
    _, ipiv = sla.lu_factor(A0)
    order = np.arange(n)
    for i, p in enumerate(ipiv):
        order[[i, p]] = order[[p, i]]
    assert np.array_equal(drow, order)


def test_dependent_columns_inside_panels_are_skipped_and_the_rest_factorized():
    """Two dependent columns (40 = 2 x 7; 201 = 5 - 100) of a 330 x 300 block, inside the
    2nd and 7th panels: both skipped (no pivot), the panels around them updated pivot by
    pivot, the 298 others factorized."""
    A0 = np.random.default_rng(8).standard_normal((330, 300))
    A0[:, 40] = 2.0 * A0[:, 7]
    A0[:, 201] = A0[:, 5] - A0[:, 100]
    npiv, tpiv, _, res = _block_factors(A0)
    assert npiv == 298 and list(np.flatnonzero(tpiv < 0)) == [40, 201]
    assert res <= 1e-13


def _weak_diagonal(n, seed):
    """A sparse M whose diagonal entries are 0.15-0.9 of their column's largest
    off-diagonal one: each column's own row is an acceptable match
    (``_sparse_order.MATCH_TOL``) without being its largest entry."""
    rng = np.random.default_rng(seed)
    A = sp.random(n, n, density=4.0 / n, random_state=seed, format="csc")
    A.data = rng.uniform(0.5, 1.0, A.nnz) * rng.choice([-1.0, 1.0], A.nnz)
    A.setdiag(0.0)
    A.eliminate_zeros()
    offmax = np.maximum(abs(A).max(axis=0).toarray().ravel(), 1.0)
    return sp.csc_matrix(A + sp.diags(rng.uniform(0.15, 0.9, n) * offmax))


@pytest.mark.parametrize("piv_thresh", [SL.PIVOT_THRESHOLD, 1.0])
def test_multipliers_stay_within_the_pivoting_thresholds(piv_thresh):
    """The sparse steps keep a column's matched row while its entry is at least
    ``piv_thresh`` of the column's largest, so their multipliers are at most
    1 / piv_thresh -- and at the engine's threshold (0.1) some exceed 1, where partial
    pivoting would have left the matched row -- while the dense tail pivots partially
    (``TAIL_PIVOT_THRESHOLD``: multipliers at most 1).  The factors solve as numpy does."""
    n = 400
    M = _weak_diagonal(n, seed=3)
    M.sort_indices()
    S = SL.allocate(n, 50, 40 * M.nnz)
    perm = np.zeros((N_PERM, n), dtype=np.int64)
    ar = np.arange(n, dtype=np.int64)
    nrep = SL.factor(M.indptr.astype(np.int64), M.indices.astype(np.int64), M.data,
                     np.zeros(0, np.int64), np.zeros(0), ar, np.full(n, VAR_Z, np.int64), ar,
                     np.ones(n, dtype=np.int64), S, RANK_TOL, piv_thresh, perm[W_REP_SLOT],
                     perm[W_REP_ROW])
    assert nrep == 0
    h, Lp, Lx = S[0], S[1], S[3]
    kt = n - int(h[SL.H_TAIL])
    assert 0 < kt < n  # sparse steps and a dense tail
    sparse_max = np.max(np.abs(Lx[:Lp[kt]]))
    tail_max = np.max(np.abs(Lx[Lp[kt]:Lp[n]]))
    assert sparse_max <= (1.0 + 1e-12) / piv_thresh
    assert tail_max <= (1.0 + 1e-12) / SL.TAIL_PIVOT_THRESHOLD
    if piv_thresh < 1.0:
        assert sparse_max > 1.0
    _check_solves(S, M.toarray())
