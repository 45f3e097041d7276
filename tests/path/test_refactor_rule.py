"""The sparse engine's refactorization rule (compass_sparse.path._sparse_lu.refactor_pays):
refactorize when the next pivot's update work exceeds the average per pivot since the
last factorization, (F + c_1 + ... + c_k) / k, all counted in entries, never the clock;
and the option that bounds it (factorization_update_limit: None = automatic)."""


import numpy as np
import pytest
import scipy.sparse as sp

import compass_sparse.generators as gen
from compass_sparse import Options
from compass_sparse.basis import BasisManager
from compass_sparse.path import _sparse_lu as SL
from compass_sparse.path.dense_engine import DensePathEngine
from compass_sparse.path.pivotal import PivotalPath
from compass_sparse.path.sparse_engine import AUTO_UPDATE_LIMIT, SparsePathEngine
from compass_sparse.routes import DEFAULT_UPDATE_LIMIT, basis_factory
from minor_log import pivots_without_t


def _header(F, X, k, appended, nnz_r):
    S = SL.allocate(10, 5, 100)
    h = S[0]
    h[SL.H_FWORK], h[SL.H_XWORK], h[SL.H_KSOL] = F, X, k
    h[SL.H_UFACT], h[SL.H_UFREE], h[SL.H_NNZR] = 7, 7 + appended, nnz_r
    return S


@pytest.mark.parametrize("F, X, k, appended, nnz_r", [
    (1000, 0, 1, 0, 0), (1000, 300, 10, 20, 10), (1000, 300, 10, 60, 13),
    (1000, 300, 10, 61, 13), (10 ** 9, 5 * 10 ** 6, 200, 10 ** 4, 10 ** 4), (5, 0, 0, 3, 0)])
def test_refactor_pays_is_the_average_rule_to_the_last_entry(F, X, k, appended, nnz_r):
    """True exactly when k * c > F + X with c = 2 x the appended entries of U + the row
    etas' entries (the boundary k * c = F + X is not yet worth it); never before a pivot."""
    S = _header(F, X, k, appended, nnz_r)
    c = 2 * appended + nnz_r
    assert SL.update_work(S[0]) == c
    assert SL.refactor_pays(S) == (k > 0 and k * c > F + X)


def test_count_solve_accumulates_the_update_work_of_each_pivot():
    S = _header(1000, 0, 0, 0, 0)
    h = S[0]
    total = 0
    for step in range(1, 6):
        h[SL.H_UFREE] += 10 * step  # an update appends a column ...
        h[SL.H_NNZR] += step        # ... and a row eta
        SL.count_solve(S)
        total += SL.update_work(h)
        assert h[SL.H_KSOL] == step and h[SL.H_XWORK] == total


def test_factorization_work_grows_with_the_factors_and_resets_the_counts():
    """F of a basis with more fill is larger; every factorization zeroes the counts of
    the pivots since the last one (k, the sum of their update work) and records where U's
    appended columns start."""
    works = []
    for structure in ("banded", "grid"):
        g = gen.p_matrix_lcp(400, structure, 3, "ncp")
        M = sp.csc_matrix(g.lcp[0])
        eng = SparsePathEngine(M)
        path = PivotalPath(M, g.lcp[1], g.lcp[2], g.lcp[3], eng, Options())
        res = path.run(np.zeros(400))
        h = eng._S[0]
        assert res.pivots > 0
        assert h[SL.H_FWORK] >= (h[SL.H_NNZL] + h[SL.H_UFACT]) * 2 * SL.FACTOR_WEIGHT
        assert 0 <= h[SL.H_KSOL] <= res.pivots
        works.append((h[SL.H_NNZL] + h[SL.H_UFACT], h[SL.H_FWORK]))
    (fill_a, work_a), (fill_b, work_b) = sorted(works)
    assert work_b > work_a


def test_automatic_refactorizes_where_the_rule_says_and_keeps_thepivots_without_t():
    """On a long path the automatic engine takes the Python loop's pivots; with the
    factorization made (nearly) free it refactorizes at almost every pivot, with it made
    dear only at the hard limit -- the rule, not the limit, decides in between."""
    g = gen.p_matrix_lcp(900, "grid", 2, "mixed")
    M, q, lb, ub = g.lcp
    M = sp.csc_matrix(M)
    x = np.clip(np.zeros(q.size), lb, ub)
    logs = {}
    facs = {}
    for name, weight in (("free", 0.0), ("default", SL.FACTOR_WEIGHT), ("dear", 1e9)):
        eng = SparsePathEngine(M, update_limit=None if name != "dear" else 20)
        eng._allocate()
        eng._S[0][SL.H_FWEIGHT] = round(weight * 1024)
        log = []
        res = PivotalPath(M, q, lb, ub, eng, Options(), log=log.append).run(x)
        logs[name] = pivots_without_t(log)
        facs[name] = (eng.stats.factorizations, res.pivots)
    ref_log = []
    ref = PivotalPath(M, q, lb, ub, BasisManager(M), Options(), log=ref_log.append).run(x)
    ref_log = pivots_without_t(ref_log)
    pivots = ref.pivots
    assert pivots > 100
    for name in logs:
        assert logs[name] == ref_log, name
    assert facs["dear"][0] >= pivots // 21  # the hard limit of 20 holds
    assert facs["free"][0] > pivots // 3    # update work > 0 after one update: refactor
    assert facs["dear"][0] <= pivots // 20 + 5


def test_update_limit_none_is_automatic_on_the_sparse_engine_and_50_elsewhere():
    M = sp.random(600, 600, density=0.005, format="csc", random_state=0) + sp.identity(600)
    opt = Options()
    assert opt.factorization_update_limit is None
    assert basis_factory("sparse engine", opt)(M.tocsc()).update_limit == AUTO_UPDATE_LIMIT
    assert basis_factory("sparse basis", opt)(M.tocsc()).options.update_limit == 50
    assert DEFAULT_UPDATE_LIMIT == 50
    small = sp.identity(40, format="csc")
    assert basis_factory("dense engine", opt)(small).update_limit == 50
    assert SparsePathEngine(M.tocsc()).update_limit == AUTO_UPDATE_LIMIT
    assert DensePathEngine(small.toarray()).update_limit == 50
    # an integer is the limit on every route (capped at max(n, 50))
    opt = Options(factorization_update_limit=30)
    assert basis_factory("sparse engine", opt)(M.tocsc()).update_limit == 30
    assert basis_factory("sparse basis", opt)(M.tocsc()).options.update_limit == 30
    assert basis_factory("dense engine", opt)(small).update_limit == 30
    opt = Options(factorization_update_limit=10 ** 6)
    assert basis_factory("sparse engine", opt)(M.tocsc()).update_limit == 600
    with pytest.raises(Exception):
        Options(factorization_update_limit=0)


def test_automatic_limit_takes_no_more_update_storage_than_fifty_updates():
    """The eta room is that of ETA_ROOM_UPDATES dense updates whatever the limit: the
    automatic limit (250) allocates what a limit of 50 did (but the per-position arrays)."""
    n, guess = 2452, 30000
    auto = SL.storage_bytes(n, AUTO_UPDATE_LIMIT, guess)
    fifty = SL.storage_bytes(n, 50, guess)
    assert fifty < auto <= fifty + 16 * 8 * (AUTO_UPDATE_LIMIT - 50)


def test_column_ftran_returns_the_norms_the_update_reads():
    """The passes fused into the sparse FTRAN: it returns max |d|, writes rate = sign d,
    and leaves the spike's largest |entry| (in fw[2]'s last element) and its nonzeros
    (h[H_SPNNZ]) with their positions (in iw) -- each equal to its definition on the
    vectors themselves -- after updates too."""
    g = gen.p_matrix_lcp(300, "banded", 4, "mixed")
    M = sp.csc_matrix(g.lcp[0])
    eng = SparsePathEngine(M, update_limit=None)
    path = PivotalPath(M, g.lcp[1], g.lcp[2], g.lcp[3], eng, Options(), minor_limit=40)
    res = path.run(np.clip(np.zeros(300), g.lcp[2], g.lcp[3]))
    S = eng._S
    h, fw = S[0], S[21]
    nupd = int(np.count_nonzero(S[12]))  # (each update kills one position)
    assert res.pivots > 0 and nupd > 0
    d, rate = np.zeros(300), np.zeros(300)
    Mp, Mi, Mx = (M.indptr.astype(np.int64), M.indices.astype(np.int64), M.data)
    empty_i, empty_x = np.zeros(0, np.int64), np.zeros(0)
    for j in (0, 7, 150, 299):
        dmax = SL.ftran_column(0, j, Mp, Mi, Mx, empty_i, empty_x, np.ones(300, np.int64),
                               S, nupd, d, rate, -1.0)
        N = 300 + nupd
        spike = fw[2][:N]
        assert dmax == np.max(np.abs(d))
        assert np.array_equal(rate, -1.0 * d)
        assert fw[2][-1] == np.max(np.abs(spike))
        assert h[SL.H_SPNNZ] == np.count_nonzero(spike)
        # the positions of its nonzeros, increasing, for the update's new column of U
        assert np.array_equal(S[20][:h[SL.H_SPNNZ]], np.flatnonzero(spike))
        assert np.count_nonzero(d) > 0


@pytest.mark.parametrize("requested", [None, 1, 30, 120, 10 ** 6])
@pytest.mark.parametrize("n", [40, 100, 600])
def test_engines_built_directly_resolve_the_limit_as_the_routes_do(requested, n):
    """One owner decides the update limit (path.engine.resolve_update_limit): an engine
    built directly, from the keyword or from the options, gets what its route gives it
    -- the automatic limit or the integer, capped at max(n, 50)."""
    M = (sp.random(n, n, density=0.02, format="csc", random_state=1)
         + sp.identity(n)).tocsc()
    opt = Options(factorization_update_limit=requested)
    cap = max(n, 50)
    want_sparse = min(AUTO_UPDATE_LIMIT if requested is None else requested, cap)
    want_dense = min(DEFAULT_UPDATE_LIMIT if requested is None else requested, cap)
    assert basis_factory("sparse engine", opt)(M).update_limit == want_sparse
    assert SparsePathEngine(M, opt).update_limit == want_sparse
    assert SparsePathEngine(M, update_limit=requested).update_limit == want_sparse
    assert basis_factory("dense engine", opt)(M).update_limit == want_dense
    assert DensePathEngine(M.toarray(), update_limit=requested).update_limit == want_dense
    assert basis_factory("sparse basis", opt)(M).options.update_limit == want_dense
