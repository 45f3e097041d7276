"""Maximum bipartite matching (compass_sparse.linalg.matching): validity, maximality, and the
layered reduced Jacobian on which scipy's Hopcroft-Karp did not return."""
from pathlib import Path

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import breadth_first_order, maximum_bipartite_matching

from compass_sparse.linalg.matching import column_matching, matching

DATA = Path(__file__).resolve().parents[1] / "data"


def _check_valid(A, row_of, col_of):
    A = sp.csc_matrix(A)
    m, n = A.shape
    assert row_of.shape == (n,) and col_of.shape == (m,)
    js = np.flatnonzero(row_of >= 0)
    # each matched pair is an entry, and the two maps are inverse to each other
    assert np.all(np.asarray(A[row_of[js], js]).ravel() != 0)
    assert np.array_equal(col_of[row_of[js]], js)
    assert np.count_nonzero(col_of >= 0) == js.size


def _assert_maximum(A, row_of, col_of):
    """Berge: maximum iff no augmenting path, i.e. no unmatched row is reachable from an
    unmatched column along alternating paths (column -> any row of its entries, row ->
    the column it is matched to).  Checked by one breadth-first search from a super source."""
    A = sp.csc_matrix(A)
    m, n = A.shape
    # vertices: columns 0..n-1, rows n..n+m-1, source n+m
    cols = np.repeat(np.arange(n), np.diff(A.indptr))
    src, dst = [cols], [n + A.indices]
    mr = np.flatnonzero(col_of >= 0)
    src.append(n + mr)
    dst.append(col_of[mr])
    free_cols = np.flatnonzero(row_of < 0)
    src.append(np.full(free_cols.size, n + m))
    dst.append(free_cols)
    s, d = np.concatenate(src), np.concatenate(dst)
    G = sp.csr_matrix((np.ones(s.size), (s, d)), shape=(n + m + 1, n + m + 1))
    reached = breadth_first_order(G, n + m, directed=True, return_predecessors=False)
    reached_rows = reached[(reached >= n) & (reached < n + m)] - n
    assert np.all(col_of[reached_rows] >= 0), "an augmenting path exists"


def test_matching_is_valid_and_maximum_on_random_patterns():
    rng = np.random.default_rng(3)
    for _ in range(200):
        m, n = (int(v) for v in rng.integers(1, 30, 2))
        A = sp.random(m, n, density=float(rng.uniform(0.02, 0.4)), random_state=rng,
                      format="csc")
        row_of, col_of = matching(A)
        _check_valid(A, row_of, col_of)
        _assert_maximum(A, row_of, col_of)
        ref = maximum_bipartite_matching(A.tocsr(), perm_type="row")
        assert np.count_nonzero(row_of >= 0) == np.count_nonzero(ref >= 0)


def test_matching_of_empty_and_degenerate_shapes():
    for shape in ((0, 0), (0, 3), (3, 0)):
        row_of, col_of = matching(sp.csc_matrix(shape))
        assert row_of.shape == (shape[1],) and col_of.shape == (shape[0],)
    row_of, col_of = matching(sp.csc_matrix((4, 4)))  # no entries: nothing matched
    assert np.all(row_of == -1) and np.all(col_of == -1)
    # a dense column block: every column matched
    assert np.all(column_matching(sp.csc_matrix(np.ones((5, 3)))) >= 0)


def test_matching_is_maximum_on_the_layered_crash_block_of_the_dynamic_cge_model():
    """The reduced Jacobian J_II of the second crash step of the dynamic CGE model (100
    periods, 50 sectors, 25% capital tax, line search) is structurally singular and
    period-layered; scipy's maximum_bipartite_matching ran for minutes on it inside the
    ordering (an uninterruptible step: the solve overran its time limit)."""
    d = np.load(DATA / "dynamic_cge_crash_block_pattern.npz")
    shape = tuple(int(v) for v in d["shape"])
    A = sp.csc_matrix((np.ones(d["indices"].size), d["indices"], d["indptr"]), shape=shape)
    row_of, col_of = matching(A)
    _check_valid(A, row_of, col_of)
    _assert_maximum(A, row_of, col_of)
    assert shape[1] - np.count_nonzero(row_of >= 0) == 80  # its structural deficiency
