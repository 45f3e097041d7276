"""The sparse direct solvers of the direct Newton step (compass_sparse.linalg.direct):
KLU first and SuperLU once a block fills, singular blocks, KLU's symbolic analysis kept
per pattern and cached across solves, SuperLU's call, and the LU sizes read from KLU."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

import compass_sparse.linalg.direct as ld
from compass_sparse.linalg.csc import trusted_csc


def _random_block(n, density, seed):
    rng = np.random.default_rng(seed)
    A = sp.random(n, n, density=density, random_state=seed, format="csc")
    return sp.csc_matrix(A + sp.diags(rng.uniform(1.0, 2.0, n))), rng.standard_normal(n)


@pytest.mark.parametrize("n,density", [(60, 0.05), (300, 0.01), (300, 0.05)])
def test_klu_and_superlu_agree(n, density):
    """Both factorizations of the direct step solve the block to working accuracy."""
    K, b = _random_block(n, density, seed=n)
    ref = np.linalg.solve(K.toarray(), b)
    for klu in (True, False):
        x = ld.DirectFactors(klu=klu).solve(K, b)
        assert np.max(np.abs(x - ref)) <= 1e-10 * (1.0 + np.max(np.abs(ref)))


def test_klu_first_then_superlu_for_good_once_a_block_fills():
    """KLU factors the blocks while its LU stays within KLU_FILL_LIMIT times the block's
    entries; a block that fills more returns the rest of the solve to SuperLU for good
    (its answer is still the KLU one: the factorization is done).  Without KLU
    (``klu=False``) SuperLU factors every block."""
    f = ld.DirectFactors()
    low, b = _random_block(300, 0.003, seed=1)   # little fill
    f.solve(low, b)
    assert f.method[0] == "klu" and f.lu_nnz <= ld.KLU_FILL_LIMIT * low.nnz and f.klu
    f.solve(low, b)
    assert f.method[0] == "klu" and f.klu
    high, b2 = _random_block(300, 0.05, seed=2)  # fills most of L and U
    x = f.solve(high, b2)
    assert f.method[0] == "klu" and f.lu_nnz > ld.KLU_FILL_LIMIT * high.nnz and not f.klu
    np.testing.assert_allclose(high @ x, b2, atol=1e-9)
    x = f.solve(low, b)
    assert f.method == ("superlu", "colamd") and not f.klu  # for good
    np.testing.assert_allclose(low @ x, b, atol=1e-9)
    g = ld.DirectFactors(klu=False)
    g.solve(low, b)
    assert g.method == ("superlu", "colamd") and not g.klu


@pytest.mark.parametrize("klu", [True, False])
def test_singular_block_gives_no_solution(klu):
    K = sp.csc_matrix(np.array([[1.0, 2.0, 0.0], [2.0, 4.0, 0.0], [0.0, 0.0, 1.0]]))
    assert ld.DirectFactors(klu=klu).solve(K, np.ones(3)) is None


def test_klu_keeps_its_symbolic_analysis_for_a_block_of_the_same_pattern(monkeypatch):
    """A block with the last block's pattern is factored on the kept symbolic analysis
    (new values, same answer as a fresh analysis); another pattern gets a new one."""
    from kvxopt import klu

    calls = []
    real = klu.symbolic
    monkeypatch.setattr(klu, "symbolic", lambda A: calls.append(1) or real(A))
    monkeypatch.setattr(ld, "_KLU_CACHE", [])  # no analysis kept from another test
    f = ld.DirectFactors(klu=True)
    K, b = _random_block(200, 0.01, seed=4)
    f.solve(K, b)
    K2 = K.copy()
    K2.data = K2.data * np.linspace(0.5, 2.0, K2.nnz)
    x = f.solve(K2, b)
    assert len(calls) == 1 and f.method[0] == "klu"
    np.testing.assert_allclose(x, np.linalg.solve(K2.toarray(), b), rtol=1e-9, atol=1e-12)
    K3, b3 = _random_block(200, 0.01, seed=5)
    x3 = f.solve(K3, b3)
    assert len(calls) == 2
    np.testing.assert_allclose(x3, np.linalg.solve(K3.toarray(), b3), rtol=1e-9, atol=1e-12)


def test_klu_reuse_needs_row_sorted_columns():
    """New values are copied into the kept matrix only in kvxopt's order (rows sorted in
    each column): a block with the same index arrays but unsorted rows is analysed afresh
    and still solved right."""
    f = ld.DirectFactors(klu=True)
    K = sp.csc_matrix(np.array([[4.0, 1.0, 0.0], [1.0, 3.0, 0.0], [0.0, 1.0, 2.0]]))
    b = np.array([1.0, 2.0, 3.0])
    f.solve(K, b)
    # the same index arrays as the (unsorted) block below would have: rows 1, 0 in column 0
    U = sp.csc_matrix((np.array([1.0, 5.0, 1.0, 3.0, 1.0, 2.0]),
                       np.array([1, 0, 0, 1, 2, 2], dtype=np.int32), K.indptr.copy()),
                      shape=(3, 3))
    f._held = (U.indptr.copy(), U.indices.copy()) + f._held[2:]
    x = f.solve(U, b)
    np.testing.assert_allclose(U.toarray() @ x, b, atol=1e-12)


def test_klu_analysis_is_cached_across_solves_with_the_same_bits(monkeypatch):
    """A later solve (a new DirectFactors) meeting a block pattern seen before takes the
    cached analysis: no new symbolic analysis, the same bits as a fresh analysis, the
    cached template untouched by the values written into its copy; the cache is bounded
    and finds patterns by their index arrays only."""
    from kvxopt import klu

    monkeypatch.setattr(ld, "_KLU_CACHE", [])
    K, b = _random_block(200, 0.01, seed=7)
    fresh = ld.DirectFactors(klu=True).solve(K, b)
    calls = []
    real = klu.symbolic
    monkeypatch.setattr(klu, "symbolic", lambda A: calls.append(1) or real(A))
    template = np.array(ld._KLU_CACHE[-1][2].V).ravel().copy()
    K2 = K.copy()
    K2.data = K2.data * np.linspace(0.5, 2.0, K2.nnz)
    x2 = ld.DirectFactors(klu=True).solve(K2, b)
    x = ld.DirectFactors(klu=True).solve(K, b)
    assert calls == [] and np.array_equal(x, fresh)
    assert np.array_equal(np.array(ld._KLU_CACHE[-1][2].V).ravel(), template)
    monkeypatch.setattr(ld, "_KLU_CACHE", [])
    assert np.array_equal(ld.DirectFactors(klu=True).solve(K2, b), x2)  # fresh analysis
    assert len(calls) == 1
    for seed in range(ld.KLU_CACHE_SIZE + 3):
        Ks, bs = _random_block(50, 0.05, seed=100 + seed)
        ld.DirectFactors(klu=True).solve(Ks, bs)
    assert len(ld._KLU_CACHE) == ld.KLU_CACHE_SIZE


def test_klu_analysis_of_a_block_above_the_cache_limit_is_not_kept(monkeypatch):
    """The process-wide cache keeps no analysis of a block larger than KLU_CACHE_MAX_NNZ
    (memory held for the life of the process); such a block still solves."""
    monkeypatch.setattr(ld, "_KLU_CACHE", [])
    K, b = _random_block(200, 0.01, seed=7)
    monkeypatch.setattr(ld, "KLU_CACHE_MAX_NNZ", K.nnz - 1)
    x = ld.DirectFactors(klu=True).solve(K, b)
    assert ld._KLU_CACHE == []
    np.testing.assert_allclose(K @ x, b, rtol=1e-10, atol=1e-10)
    monkeypatch.setattr(ld, "KLU_CACHE_MAX_NNZ", K.nnz)
    ld.DirectFactors(klu=True).solve(K, b)
    assert len(ld._KLU_CACHE) == 1


def test_superlu_direct_call_is_splu():
    """The direct step's SuperLU call gives splu's factors and solution bit for bit; a
    block splu would have to sort or sum goes through splu itself."""
    from scipy.sparse.linalg import splu

    assert ld._superlu_gstrf() is not None  # this scipy: the direct call is taken
    for n, density in [(60, 0.05), (300, 0.01)]:
        K, b = _random_block(n, density, seed=n + 1)
        K = trusted_csc(K.data.copy(), K.indices.astype(np.int32),
                           K.indptr.astype(np.int32), K.shape)
        a, r = ld.superlu_colamd(K), splu(K, permc_spec="COLAMD")
        for attr in ("perm_r", "perm_c"):
            assert np.array_equal(getattr(a, attr), getattr(r, attr))
        for attr in ("L", "U"):
            A, R = getattr(a, attr), getattr(r, attr)
            assert (np.array_equal(A.indptr, R.indptr) and np.array_equal(A.indices, R.indices)
                    and np.array_equal(A.data, R.data))
        assert np.array_equal(a.solve(b), r.solve(b))
    U = sp.csc_matrix((np.array([1.0, 5.0, 1.0, 3.0, 1.0, 2.0]),
                       np.array([1, 0, 0, 1, 2, 2], dtype=np.int32),
                       np.array([0, 2, 4, 6], dtype=np.int32)), shape=(3, 3))
    x = ld.superlu_colamd(U.copy()).solve(np.ones(3))
    assert np.array_equal(x, splu(U.copy(), permc_spec="COLAMD").solve(np.ones(3)))


def test_klu_lu_size_read_from_the_factorization_is_the_factors_size(monkeypatch):
    """nnz(L) + nnz(U) + nnz(off-diagonal blocks) read from KLU's numeric object and the
    pattern's analysis is the size of the factors kvxopt copies out, over blocks whose
    values change the pivoting; after a mismatch the factors are counted again."""
    from kvxopt import klu, matrix

    monkeypatch.setattr(ld, "_KLU_CACHE", [])
    real = klu.get_numeric
    copies = []
    monkeypatch.setattr(klu, "get_numeric", lambda *a: copies.append(1) or real(*a))
    rng = np.random.default_rng(3)
    for seed in range(6):
        K, b = _random_block(120, 0.03, seed=200 + seed)
        for trial in range(3):
            Kt = K.copy()
            Kt.data = Kt.data * rng.uniform(0.01, 100.0, Kt.nnz)  # other pivots
            f = ld.DirectFactors(klu=True)
            f.solve(Kt, b)
            A, Fs, info = ld._klu_analysis(Kt)
            A.V = matrix(Kt.data)
            parts = real(A, Fs, klu.numeric(A, Fs))
            assert f.lu_nnz == len(parts[0]) + len(parts[1]) + len(parts[5])
    assert len(copies) == 6  # one copy per pattern, at its first factorization
    monkeypatch.setattr(ld, "_KLU_COUNTS", [])  # (the switch turned off below is this one)
    real_counts = ld._klu_counts
    monkeypatch.setattr(ld, "_klu_counts", lambda Fn: real_counts(Fn) and (0, 0))  # another layout
    monkeypatch.setattr(ld, "_KLU_CACHE", [])
    f = ld.DirectFactors(klu=True)
    K, b = _random_block(120, 0.03, seed=200)
    f.solve(K, b)
    f.solve(K, b)
    assert len(copies) == 8 and f.lu_nnz > 0 and ld._KLU_COUNTS == [None]
