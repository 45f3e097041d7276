"""The sparse engine's elimination order (compass_sparse.path._sparse_order): the numerical
matching of the basic z columns to rows, the minimum degree order of the matched block
against an exact minimum degree computed here, its storage compaction, and the fill of
the factors it gives on a saddle-point basis (the traffic model's) against the basis'
own entries."""
from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

import compass_sparse.generators as gen
from compass_sparse import solve_mcp
from compass_sparse.path import _sparse_lu as SL
from compass_sparse.path import _sparse_order as SO
from compass_sparse.path._dense_lu import N_PERM, W_REP_ROW, W_REP_SLOT
from compass_sparse.path._kernels import VAR_V, VAR_W, VAR_Z


# ------------------------------------------------------------------ minimum degree
def _graph_work(A, extra=None):
    """The work space of min_degree with the symmetric pattern of A (no diagonal) as its
    graph; ``extra``: list storage beyond the graph (default: the module's capacity)."""
    A = sp.csr_matrix(A)
    A = (abs(A) + abs(A.T)).tocsr()
    A.setdiag(0)
    A.eliminate_zeros()
    A.sort_indices()
    n = A.shape[0]
    cap = SO.list_capacity(n, A.nnz) if extra is None else A.nnz + extra
    ow = np.zeros(SO.N_PARTS * (n + 1) + cap, dtype=np.int64)
    P, iw = SO.parts(ow, n)
    P[SO.W_PE, :n] = A.indptr[:-1]
    P[SO.W_LEN, :n] = np.diff(A.indptr)
    iw[:A.nnz] = A.indices
    P[SO.W_COLM, :n] = 0  # every node takes part
    return A, P, iw


def _min_degree(A, extra=None):
    A, P, iw = _graph_work(A, extra)
    k = SO.min_degree(A.shape[0], P, iw, A.nnz)
    return A, (P[SO.W_ORDER, :k].copy() if k >= 0 else None)


def _cholesky_fill(A, order):
    """Entries below the diagonal of the Cholesky factor of A[order, order] (symbolic
    elimination on explicit sets)."""
    n = A.shape[0]
    label = np.empty(n, dtype=np.int64)
    label[order] = np.arange(n)
    adj = [set() for _ in range(n)]
    for i in range(n):
        for j in A.indices[A.indptr[i]:A.indptr[i + 1]]:
            adj[label[i]].add(label[j])
    fill = 0
    for k in range(n):
        later = {j for j in adj[k] if j > k}
        fill += len(later)
        for j in later:
            adj[j] |= later - {j}
    return fill


def _exact_minimum_degree(A):
    """Minimum degree on the explicit elimination graph (ties: smallest node)."""
    n = A.shape[0]
    adj = [set(A.indices[A.indptr[i]:A.indptr[i + 1]]) for i in range(n)]
    left = set(range(n))
    order = []
    while left:
        p = min(left, key=lambda i: (len(adj[i]), i))
        order.append(p)
        left.discard(p)
        for i in adj[p]:
            adj[i] |= adj[p] - {i}
            adj[i].discard(p)
    return np.array(order)


def _grid(m):
    """The 5-point grid's adjacency, m x m nodes."""
    path = sp.diags([1.0], [1], shape=(m, m))
    eye = sp.identity(m)
    return sp.csr_matrix(sp.kron(eye, path) + sp.kron(path, eye))


@pytest.mark.parametrize("make", [
    lambda: _grid(20),
    lambda: sp.random(300, 300, density=0.01, random_state=0),
    lambda: sp.random(200, 200, density=0.03, random_state=1),
    lambda: sp.diags([1.0, 1.0, 1.0], [0, 1, 7], shape=(250, 250)),
], ids=["grid 20x20", "random 300", "random 200 denser", "banded"])
def test_min_degree_fills_about_as_little_as_an_exact_minimum_degree(make):
    """Every node is ordered once, and the Cholesky fill of the order is within 10% of
    that of the exact minimum degree (approximate degrees are upper bounds: the two orders
    differ on ties and where an approximate degree is loose) and far below the natural
    order's on the grid."""
    A, order = _min_degree(make())
    n = A.shape[0]
    assert np.array_equal(np.sort(order), np.arange(n))
    fill = _cholesky_fill(A, order)
    exact = _cholesky_fill(A, _exact_minimum_degree(A))
    assert fill <= 1.1 * exact + 10, (fill, exact)
    if n == 400:
        assert fill < 0.6 * _cholesky_fill(A, np.arange(n))


def test_min_degree_compacts_a_full_storage_and_gives_the_same_order():
    """With list storage only just beyond the graph, the new elements' lists fill it and
    it is compacted (garbage collection of absorbed lists) again and again: the order is
    the one of a large storage.  With no room at all for an element it gives up (-1)."""
    A = _grid(15)
    _, big = _min_degree(A)
    _, tight = _min_degree(A, extra=40)
    assert np.array_equal(big, tight)
    _, none = _min_degree(A, extra=0)
    assert none is None


def test_dense_nodes_are_ordered_last():
    """An arrow matrix: the node joined to every other is ordered last, and the others
    then eliminate with no fill (a star's leaves, before its centre)."""
    n = 400
    A = sp.lil_matrix((n, n))
    A[0, 1:] = 1.0
    A.setdiag(1.0)
    for i in range(1, n - 1):
        A[i, i + 1] = 1.0
    A, order = _min_degree(A.tocsr())
    assert order[-1] == 0
    assert _cholesky_fill(A, order) == A.nnz // 2


# ------------------------------------------------------------------ the matching
def _matching(M, basic_z, covered=()):
    """match_columns on the basis of the basic z in ``basic_z`` (slots 0..nb-1), the
    rows in ``covered`` taken by unit columns; returns (column -> row, unmatched)."""
    M = sp.csc_matrix(M)
    M.sort_indices()
    n = M.shape[0]
    Mp, Mi = M.indptr.astype(np.int64), M.indices.astype(np.int64)
    si = np.asarray(basic_z, dtype=np.int64)
    nb = si.size
    ow = np.zeros(SO.work_size(n, M.nnz), dtype=np.int64)
    P, _ = SO.parts(ow, n)
    P[SO.W_ZSLOT, :nb] = np.arange(nb)
    P[SO.W_ZCOL, :] = -1
    P[SO.W_ZCOL, si] = np.arange(nb)
    pinv = np.full(n, -1, dtype=np.int64)
    pinv[list(covered)] = 0
    left = SO.match_columns(nb, P[SO.W_ZSLOT], si, Mp, Mi, M.data, pinv, P, np.zeros(n),
                            SO.MATCH_TOL)
    return P[SO.W_COLM, :nb].copy(), left


def test_saddle_point_columns_are_matched_crosswise_to_their_large_entries():
    """[[eps I, -N^T], [N, eps I]] with N a tree's incidence (a path graph): no column
    takes its own row (eps is far below MATCH_TOL of its column), every column gets a
    row of an acceptable entry, and the pairs are symmetric (z_j on row i, z_i on row j)."""
    m = 30
    N = sp.diags([1.0, -1.0], [0, 1], shape=(m, m)).tocsc()
    eps = 1e-9
    M = sp.bmat([[eps * sp.identity(m), -N.T], [N, eps * sp.identity(m)]]).tocsc()
    rows, left = _matching(M, range(2 * m))
    assert left == 0
    j = np.arange(2 * m)
    assert not np.any(rows == j)
    A = M.toarray()
    assert np.all(np.abs(A[rows, j]) >= SO.MATCH_TOL * np.abs(A).max(axis=0))
    assert np.array_equal(rows[rows], j)  # crosswise pairs


def test_matching_tolerance_decides_between_own_row_and_another():
    """The own row is taken when its entry is at least MATCH_TOL of the column's largest,
    to the last bit: MATCH_TOL and the next double above on the diagonal are taken, the
    double below is not (the column goes to its large entry's row, by an augmenting path
    that moves its partner to the diagonal's row)."""
    tol = SO.MATCH_TOL
    for d, own in ((np.nextafter(tol, 1.0), True), (tol, True),
                   (np.nextafter(tol, 0.0), False)):
        M = np.array([[d, 1.0], [1.0, 1.0]])
        rows, left = _matching(M, [0, 1])
        assert left == 0
        assert bool(rows[0] == 0) is own, (d, rows)
        assert sorted(rows) == [0, 1]


def test_augmenting_paths_complete_the_matching_and_dependent_columns_stay_unmatched():
    """Column 1 of [[1, 1], [1, 0]] has row 0 only, which column 0 took as its own: an
    augmenting path moves column 0 to row 1.  Two columns whose only row is the same are
    structurally dependent: one stays unmatched.  Rows covered by unit columns are never
    matched."""
    rows, left = _matching(np.array([[1.0, 1.0], [1.0, 0.0]]), [0, 1])
    assert left == 0 and list(rows) == [1, 0]
    D = np.array([[1.0, 1.0, 0.0], [0.0, 0.0, 1.0], [0.0, 0.0, 1.0]])
    rows, left = _matching(D, [0, 1, 2])
    assert left == 1 and np.count_nonzero(rows < 0) == 1 and rows[2] in (1, 2)
    rows, left = _matching(np.eye(3) + 0.5, [0, 1], covered=[0])
    assert left == 0 and 0 not in rows


# ------------------------------------------------------------------ the factors
@pytest.fixture(scope="module")
def traffic_basis():
    """The traffic model's (n = 912) linearization at its solution, M = J + 1e-10 I on
    J's pattern and the diagonal, and the slot table of the solution's basis: z basic
    strictly inside its bounds, the slack at a bound."""
    g = gen.traffic_equilibrium(8)
    p = g.problem
    res = solve_mcp(p)
    assert res.success
    x = res.x
    J = sp.csc_matrix(p.J(x))
    M = sp.csc_matrix(J + 1e-10 * sp.identity(p.n))
    M.sort_indices()
    n = p.n
    sk = np.where(x <= p.lb, VAR_W, np.where(x >= p.ub, VAR_V, VAR_Z)).astype(np.int64)
    return M, sk, np.arange(n, dtype=np.int64)


def test_saddle_point_basis_factors_without_the_fill_of_a_column_order_of_m(traffic_basis):
    """Regression: the engine eliminated a basis' z columns in COLAMD's order of M's
    columns (once per pattern) with partial pivoting, which on the traffic model's
    saddle-point bases (flows and node potentials; M's diagonal is eps there) filled
    L + U to 4.5 times the basis' entries (this basis at n = 912: 14.5e3 from 3.2e3; the
    late bases of a solve at n = 2452: 0.9-1.1e5 from 2.4e4) and made its factorizations
    2.5x slower.  The order of each basis' own matched block keeps L + U within 3.5 times
    its entries (3.1 here), and the factors solve B x = b."""
    M, sk, si = traffic_basis
    n = M.shape[0]
    Mp, Mi = M.indptr.astype(np.int64), M.indices.astype(np.int64)
    S = SL.allocate(n, 50, 2 * M.nnz + 8 * n)
    perm = np.zeros((N_PERM, n), dtype=np.int64)
    art_sign = np.ones(n, dtype=np.int64)
    empty_i, empty_x = np.zeros(0, dtype=np.int64), np.zeros(0)
    colkey = np.arange(n, dtype=np.int64)
    nrep = SL.factor(Mp, Mi, M.data, empty_i, empty_x, colkey, sk, si, art_sign, S, 1e-11,
                     SL.PIVOT_THRESHOLD, perm[W_REP_SLOT], perm[W_REP_ROW])
    assert nrep == 0
    unit = np.flatnonzero(sk != VAR_Z)
    B = sp.csc_matrix(M @ sp.diags((sk == VAR_Z).astype(float)) + sp.csc_matrix(
        (np.where(sk[unit] == VAR_W, -1.0, 1.0), (unit, unit)), shape=(n, n)))
    B.eliminate_zeros()
    h = S[0]
    nnz_lu = int(h[SL.H_NNZL] + h[SL.H_NNZU])
    assert nnz_lu <= 3.5 * B.nnz, (nnz_lu, B.nnz)
    b = np.random.default_rng(0).standard_normal(n)
    x = np.zeros(n)
    SL.ftran_dense(S, 0, b, x)
    assert np.max(np.abs(B @ x - b)) <= 1e-10 * (1.0 + np.abs(B).max() * np.abs(x).max())


# ------------------------------------------------------------------ reused orders
def _grid_lcp_factor(n_side=20):
    """The grid LCP's M (n = 400) and factor(z_basic): the LU of the basis of those basic
    z (w basic elsewhere), checked to solve B x = b; returns the factors' header and the
    rank of each column in the last fresh order (-1: none)."""
    g = gen.p_matrix_lcp(n_side * n_side, "grid", 0)
    M = sp.csc_matrix(g.lcp[0], dtype=float)
    M.sort_indices()
    n = M.shape[0]
    Mp, Mi = M.indptr.astype(np.int64), M.indices.astype(np.int64)
    S = SL.allocate(n, 50, 2 * M.nnz + 8 * n)
    perm = np.zeros((N_PERM, n), dtype=np.int64)
    rank = SO.parts(S[22], n)[0][SO.W_RANK]

    def factor(z_basic):
        sk = np.full(n, VAR_W, dtype=np.int64)
        sk[np.asarray(z_basic)] = VAR_Z
        nrep = SL.factor(Mp, Mi, M.data, np.zeros(0, np.int64), np.zeros(0),
                         np.arange(n, dtype=np.int64), sk, np.arange(n, dtype=np.int64),
                         np.ones(n, dtype=np.int64), S, 1e-11, SL.PIVOT_THRESHOLD,
                         perm[W_REP_SLOT], perm[W_REP_ROW])
        assert nrep == 0
        z = (sk == VAR_Z).astype(float)
        B = sp.csc_matrix(M @ sp.diags(z) - sp.diags(1.0 - z))
        b = np.arange(1.0, n + 1.0)
        x = np.zeros(n)
        SL.ftran_dense(S, 0, b, x)
        assert np.max(np.abs(B @ x - b)) <= 1e-10 * np.abs(b).max()
        return S[0], rank

    return n, factor


def test_few_new_columns_reuse_the_last_order_and_many_take_a_fresh_one():
    """A factorization whose basic z are those of the last fresh order but at most
    nb / REUSE_NEW_SHARE + REUSE_NEW_MIN new ones eliminates in that order (no matching,
    no minimum degree: the new columns get no rank); one more new column orders afresh
    (every basic column ranked), and so does a basis whose last factorization held more
    than REORDER_FILL times the fresh order's entries (to the entry: a column that left
    keeps its rank only when the order is reused), or a caller's H_FRESH = 0.  Every
    factorization solves B x = b."""
    n, factor = _grid_lcp_factor()
    rng = np.random.default_rng(0)
    base = rng.choice(n, 240, replace=False)
    others = np.setdiff1d(np.arange(n), base)
    h, rank = factor(base)
    assert h[SL.H_FRESH] == h[SL.H_LAST] > 0 and np.all(rank[base] >= 0)
    limit = base.size // SO.REUSE_NEW_SHARE + SO.REUSE_NEW_MIN
    factor(np.r_[base[limit:], others[:limit]])  # `limit` new columns: reused
    assert np.all(rank[others[:limit]] < 0)
    more = np.r_[base[limit + 1:], others[:limit + 1]]
    factor(more)  # one more: fresh
    assert np.all(rank[more] >= 0) and np.all(rank[base[:limit + 1]] < 0)
    fresh = int(h[SL.H_FRESH])
    left = more[0]
    for last, reused in ((int(SL.REORDER_FILL * fresh), True),
                         (int(SL.REORDER_FILL * fresh) + 1, False)):
        factor(more)  # (the order's own basis: a reuse)
        h[SL.H_LAST] = last
        factor(more[1:])  # a column fewer, none new
        assert bool(rank[left] >= 0) is reused, (last, fresh)
        factor(more)
    h[SL.H_FRESH] = 0
    factor(more[1:])
    assert rank[left] < 0


def test_an_order_is_not_reused_once_many_of_its_columns_have_left_the_basis():
    """Regression: the reuse rule counted only the columns new since the last fresh
    order, so an order made for a basis of many z columns served every smaller basis that
    followed (on a CGE shock at n = 2024, an order made with 2023 z basic factored a basis
    of 1237 with 3.2 times the entries of a fresh order).  Now up to nb / REUSE_NEW_SHARE
    + REUSE_NEW_MIN ranked columns may leave and the order is reused (they keep their
    rank); one more and the order is fresh.  A basis of half the columns is factored with
    the entries of a fresh order of its own."""
    n, factor = _grid_lcp_factor()
    rng = np.random.default_rng(1)
    base = rng.choice(n, 240, replace=False)
    h, rank = factor(base)
    gone = max(g for g in range(base.size)
               if g <= (base.size - g) // SO.REUSE_NEW_SHARE + SO.REUSE_NEW_MIN)
    factor(base[gone:])  # `gone` columns left, none new: reused
    assert np.all(rank[base[:gone]] >= 0)
    factor(base)  # (the order's own basis again)
    factor(base[gone + 1:])  # one more left: a fresh order without them
    assert np.all(rank[base[:gone + 1]] < 0) and np.all(rank[base[gone + 1:]] >= 0)
    assert h[SL.H_LAST] == h[SL.H_FRESH]

    everything = np.arange(n)
    half = np.sort(rng.choice(n, n // 2, replace=False))
    factor(everything)
    factor(half)
    in_run = int(h[SL.H_LAST])
    _, own = _grid_lcp_factor()
    h_own, _ = own(half)  # new factors: a fresh order of this basis
    assert in_run == int(h_own[SL.H_LAST])
