"""LU backends and fill-reducing orderings: conventions, reuse per pattern, budgets."""

import numpy as np
import pytest
import scipy.linalg
import scipy.sparse as sp
from basis_helpers import dominant_matrix

from compass_sparse.basis import KIND_M, BasisManager, BasisOptions
from compass_sparse.basis import ordering as ordmod
from compass_sparse.basis.backends import (FactorBudget, FactorBudgetError, SuperLUBackend,
                                           UmfpackBackend, make_backend)
from compass_sparse.exceptions import OptionError

pytestmark = pytest.mark.usefixtures("lu_choice")


def badly_scaled_sparse(n, rng, density=0.08):
    """Random sparse regular matrix whose rows span 1e-4 .. 1e4 (row scaling matters)."""
    A = sp.random(n, n, density=density, random_state=rng, format="csc")
    A = A + sp.diags(rng.uniform(1.0, 2.0, n) * rng.choice([-1.0, 1.0], n))
    return sp.csc_matrix(sp.diags(10.0 ** rng.uniform(-4, 4, n)) @ A)


def check_factors(K, f, rtol=1e-10):
    """diag(s[ro]) K[ro][:, co] = L U, and a solve with the factors matches dense."""
    Kd = K.toarray()
    s = f.row_scale if f.row_scale is not None else np.ones(K.shape[0])
    lhs = (s[:, None] * Kd)[f.row_order][:, f.col_order]
    L = f.L.toarray()
    np.fill_diagonal(L, 1.0)       # unit diagonal, stored or not
    LU = L @ np.triu(f.U.toarray())
    assert np.abs(lhs - LU).max() <= rtol * np.abs(lhs).max()
    b = np.arange(1.0, K.shape[0] + 1)
    # K x = b  <=>  (L U) y = (s * b)[ro], x[co] = y
    y = scipy.linalg.solve_triangular(L, (s * b)[f.row_order], lower=True, unit_diagonal=True)
    y = scipy.linalg.solve_triangular(np.triu(f.U.toarray()), y)
    x = np.empty_like(y)
    x[f.col_order] = y
    xd = np.linalg.solve(Kd, b)
    assert np.abs(x - xd).max() <= 1e-8 * np.abs(xd).max()


@pytest.mark.parametrize("seed", range(5))
def test_umfpack_convention_P_Q_R_against_dense_solve(seed):
    rng = np.random.default_rng(seed)
    K = badly_scaled_sparse(40 + 10 * seed, rng)
    f = UmfpackBackend().factor(K)
    assert f.row_scale is not None and not np.allclose(f.row_scale, 1.0)
    check_factors(K, f)


@pytest.mark.parametrize("ordering", ["colamd", "amd", "metis"])
@pytest.mark.parametrize("seed", range(3))
def test_superlu_orderings_against_dense_solve(ordering, seed):
    rng = np.random.default_rng(seed)
    K = badly_scaled_sparse(60, rng)
    # zero diagonal blocks: the symmetric orderings need the matching
    K = sp.csc_matrix(K[rng.permutation(60), :])
    b = SuperLUBackend(ordering)
    check_factors(K, b.factor(K))
    assert b.last.ordering == ordering


def test_umfpack_symbolic_analysis_reused_while_pattern_unchanged():
    rng = np.random.default_rng(7)
    K = badly_scaled_sparse(50, rng)
    b = UmfpackBackend()
    b.factor(K)
    assert not b.last.ordering_reused
    K2 = K.copy()
    K2.data = K2.data * rng.uniform(0.5, 2.0, K2.nnz)
    check_factors(K2, b.factor(K2))          # numeric-only, new values
    assert b.last.ordering_reused and b.symbolic_reused == 1
    K3 = sp.csc_matrix(K2 + sp.csc_matrix(([1.0], ([0], [49])), shape=(50, 50)))
    b.factor(K3)
    assert not b.last.ordering_reused       # new pattern: new analysis


def test_ordering_computed_once_per_pattern_across_set_matrix():
    rng = np.random.default_rng(8)
    n = 500
    M = dominant_matrix(n, 0.01, rng)
    ordmod._SHARED.clear()          # orderings are shared within the process
    bm = BasisManager(M, BasisOptions(ordering="metis"))
    allm = (np.full(n, KIND_M), np.arange(n), np.ones(n))
    bm.factor(*allm)
    M2 = M.copy()
    M2.data = M2.data * 1.5
    bm.set_matrix(M2)
    bm.factor(*allm)
    assert bm.stats.orderings_computed == 1 and bm.stats.factorizations == 2
    x = bm.ftran(np.ones(n))
    assert np.abs(M2 @ x - 1.0).max() < 1e-10


def test_metis_orders_dense_rows_and_columns_last():
    n = 400
    rng = np.random.default_rng(9)
    A = sp.diags([np.ones(n - 1), 4.0 * np.ones(n), np.ones(n - 1)], [-1, 0, 1], format="lil")
    A[7, :] = rng.uniform(0.1, 1.0, n)     # a dense row and column (arrowhead)
    A[:, 7] = rng.uniform(0.1, 1.0, (n, 1))
    A[7, 7] = 2.0 * n
    S, _ = ordmod.symmetrized(sp.csc_matrix(A))
    assert ordmod.dense_nodes(S).tolist() == [7]
    p = ordmod.metis_order(S)
    assert p[-1] == 7 and np.array_equal(np.sort(p), np.arange(n))


@pytest.mark.parametrize("method", ["amd", "metis", "identity"])
def test_cholesky_estimate_matches_dense_cholesky_fill(method):
    rng = np.random.default_rng(10)
    n = 120
    A = sp.random(n, n, density=0.03, random_state=rng)
    S, _ = ordmod.symmetrized(sp.csc_matrix(A + sp.eye(n)))
    p = {"amd": ordmod.amd_order, "metis": ordmod.metis_order,
         "identity": lambda S: np.arange(S.shape[0])}[method](S)
    est_nnz, est_flops = ordmod.cholesky_estimate(S, p)
    # generic values on the pattern: no cancellation, so the fill is the symbolic one
    W = S.copy().astype(float)
    W.data = rng.uniform(0.1, 1.0, W.nnz)
    Wd = W.toarray()[p][:, p]
    Wd += np.diag(np.abs(Wd).sum(axis=1) + 1.0)
    C = np.linalg.cholesky(Wd)
    nnzL = int(np.count_nonzero(np.abs(C) > 1e-300))
    assert est_nnz == 2 * nnzL - n
    assert ordmod.cholesky_estimate(S, p, cap=nnzL - 1) is None


def test_auto_ordering_picks_the_cheaper_estimate_and_colamd_without_matching():
    rng = np.random.default_rng(11)
    n = 3000
    # a 2-D grid: nested dissection beats minimum degree on flops
    m = int(np.sqrt(n))
    T = sp.diags([-np.ones(m - 1), 4 * np.ones(m), -np.ones(m - 1)], [-1, 0, 1])
    G = sp.csc_matrix(sp.kronsum(T, T))
    o = ordmod.compute_ordering(G, "auto")
    amd_flops = ordmod.cholesky_estimate(ordmod.symmetrized(G)[0],
                                         ordmod.amd_order(ordmod.symmetrized(G)[0]))[1]
    assert o.method in ("amd", "metis") and o.flops <= amd_flops
    Z = sp.lil_matrix(sp.random(50, 50, density=0.1, random_state=rng))
    Z[:, 3] = 0.0                         # structurally singular: no zero-free diagonal
    assert ordmod.compute_ordering(sp.csc_matrix(Z), "auto").method == "colamd"


def test_factorization_not_started_beyond_memory_or_time_budget():
    rng = np.random.default_rng(12)
    K = dominant_matrix(600, 0.02, rng)
    b = SuperLUBackend("amd", budget=FactorBudget(memory_bytes=1000.0))
    with pytest.raises(FactorBudgetError) as e:
        b.factor(K)
    assert e.value.kind == "memory" and b.last.est_nnz_lu > 0
    import time
    b = SuperLUBackend("amd", budget=FactorBudget(deadline=time.perf_counter() - 1.0))
    with pytest.raises(FactorBudgetError) as e:
        b.factor(K)
    assert e.value.kind == "time"
    b = SuperLUBackend("amd", budget=FactorBudget(deadline=time.perf_counter() + 60.0,
                                                  memory_bytes=1e9))
    check_factors(K, b.factor(K))


def test_no_factorization_without_an_estimate_is_started_after_the_deadline():
    """COLAMD (and the strict factorizations of the rank repair) have no symbolic
    estimate; the budget let them start after the deadline, so a repair or a path
    refactorization could run on past the time limit."""
    import time
    K = dominant_matrix(300, 0.02, np.random.default_rng(14))
    late = FactorBudget(deadline=time.perf_counter() - 1.0)
    for b, strict in ((SuperLUBackend("colamd", budget=late), False),
                      (SuperLUBackend("amd", budget=late), True)):
        with pytest.raises(FactorBudgetError) as e:
            b.factor(K, strict=strict)
        assert e.value.kind == "time"
    check_factors(K, SuperLUBackend("colamd", budget=FactorBudget(
        deadline=time.perf_counter() + 60.0)).factor(K))


def test_basis_options_memory_limit_reaches_the_backend():
    rng = np.random.default_rng(13)
    n = 600
    M = dominant_matrix(n, 0.02, rng)
    bm = BasisManager(M, BasisOptions(ordering="amd", memory_limit=1000.0))
    with pytest.raises(FactorBudgetError):
        bm.factor(np.full(n, KIND_M), np.arange(n), np.ones(n))
    bm = BasisManager(M, BasisOptions(ordering="amd", memory_limit=np.inf))
    bm.factor(np.full(n, KIND_M), np.arange(n), np.ones(n))
    assert bm.budget.memory_bytes is None and bm.stats.est_bytes > 0


def test_environment_override_of_auto_choices(monkeypatch):
    monkeypatch.setenv("COMPASS_SPARSE_LU", "superlu:amd")
    b = make_backend("auto", "auto")
    assert isinstance(b, SuperLUBackend) and b.orderings.method == "amd"
    b = make_backend("auto", "metis")       # an explicit option wins
    assert b.orderings.method == "metis"
    monkeypatch.setenv("COMPASS_SPARSE_LU", "umfpack")
    assert isinstance(make_backend("auto", "auto"), UmfpackBackend)
    monkeypatch.setenv("COMPASS_SPARSE_LU", "klu")
    with pytest.raises(OptionError):
        make_backend("auto", "auto")


def test_rank_repair_under_every_backend():
    rng = np.random.default_rng(14)
    n = 60
    M = dominant_matrix(n, 0.05, rng).tolil()
    M[:, 5] = M[:, 4].toarray() * 2.0      # dependent column
    M = sp.csc_matrix(M)
    for kw in (dict(backend="umfpack"), dict(backend="superlu", ordering="metis"),
               dict(backend="superlu", ordering="amd"), dict(backend="superlu",
                                                           ordering="colamd")):
        bm = BasisManager(M, BasisOptions(dense_rank_limit=0, **kw))
        rep = bm.factor(np.full(n, KIND_M), np.arange(n), np.ones(n))
        assert rep.rank_deficiency == 1
        B = bm.dense_basis()
        assert np.linalg.matrix_rank(B) == n
        x = bm.ftran(np.ones(n))
        assert np.abs(B @ x - 1.0).max() < 1e-9


@pytest.mark.parametrize("n", [50, 600])
def test_solve_sparse_for_the_crash_agrees_with_dense(n, lu_choice):
    from compass_sparse.basis.backends import SingularFactorError, solve_sparse

    rng = np.random.default_rng(n)
    K = sp.csc_matrix(badly_scaled_sparse(n, rng, density=min(0.08, 8.0 / n))[rng.permutation(n)])
    b = rng.standard_normal(n)
    x = solve_sparse(K, b)
    xd = np.linalg.solve(K.toarray(), b)
    assert np.abs(x - xd).max() <= 1e-8 * np.abs(xd).max()
    Z = sp.lil_matrix(K)
    Z[:, 3] = 0.0
    with pytest.raises(SingularFactorError):
        solve_sparse(sp.csc_matrix(Z), b)


def test_matching_ignores_explicit_zeros_so_the_diagonal_is_numerically_nonzero():
    """A basis block with explicitly stored zeros (a CGE Jacobian stores its fixed
    pattern): matching a stored zero to the diagonal made SuperLU pivot away from the
    ordering (fill 3.2e6 instead of 2.0e6 at n = 1e4)."""
    n = 200
    rng = np.random.default_rng(15)
    P = sp.csc_matrix(sp.eye(n, format="csr")[rng.permutation(n)] * 3.0)   # true nonzeros
    K = sp.coo_matrix(P + sp.random(n, n, density=0.01, random_state=rng) * 0.1)
    d = np.arange(n)                                           # stored zero diagonal
    K = sp.csc_matrix((np.concatenate((K.data, np.zeros(n))),
                       (np.concatenate((K.row, d)), np.concatenate((K.col, d)))), shape=(n, n))
    K.sum_duplicates()
    assert K.nnz > P.nnz + n // 2          # the zeros are stored
    m = ordmod.zero_free_diagonal(K)
    assert np.all(K.toarray()[m, np.arange(n)] != 0.0)


def test_pattern_key_ignores_stored_zeros_and_tells_patterns_apart():
    rng = np.random.default_rng(16)
    A = sp.csc_matrix(sp.random(30, 30, density=0.1, random_state=rng) + sp.eye(30))
    B = A.copy()
    B.data[::3] = 0.0                     # stored zeros: pattern of the nonzeros changes
    C = B.copy()
    C.eliminate_zeros()
    assert ordmod.pattern_key(B) == ordmod.pattern_key(C)
    assert ordmod.pattern_key(A) != ordmod.pattern_key(C)
    E = sp.csc_matrix(([1.0], ([0], [0])), shape=(30, 30))   # empty columns at the end
    assert ordmod.pattern_key(E) != ordmod.pattern_key(sp.csc_matrix(sp.eye(30)))


def test_umfpack_element_growth_on_banded_p_matrix_basis_does_not_end_path_with_ray(
        monkeypatch):
    """A refactorization on the path of a banded P-matrix LCP (n = 300) met a block of
    condition 1e3 on which UMFPACK's threshold pivoting grew U to 1e19: the wrong factors
    ended the path with a ray ("t decreased to 0").  Such factors are now rejected by
    their backward error and the block factored with partial pivoting."""
    import compass_sparse.generators as gen
    from compass_sparse import Options
    from compass_sparse.basis.backends import UMFPACK_CHECK_TOL, factor_backward_error
    from compass_sparse.basis.dense import DenseBasis
    from compass_sparse.path.outcome import LinearCode
    from compass_sparse.path.pivotal import PivotalPath

    monkeypatch.setenv("COMPASS_SPARSE_LU", "umfpack")
    blocks = []
    factor = UmfpackBackend.factor

    def recording_factor(self, K, strict=False):
        blocks.append(sp.csc_matrix(K, copy=True))
        return factor(self, K, strict)

    monkeypatch.setattr(UmfpackBackend, "factor", recording_factor)
    M, q, lb, ub = gen.p_matrix_lcp(300, "banded", 4, "box").lcp
    z0 = np.clip(np.zeros(lb.size), lb, ub)
    zs = []
    for manager in (BasisManager, DenseBasis):
        res = PivotalPath(M, q, lb, ub, manager(M), Options()).run(z0)
        assert res.code is LinearCode.SOLVED, res.message
        zs.append(res.z)
    assert np.abs(zs[0] - zs[1]).max() <= 1e-8 * (1.0 + np.abs(zs[1]).max())
    assert len(blocks) >= 2
    for K in list(blocks):         # every block's factors solve like a dense solve
        f = factor(UmfpackBackend(), K)
        assert factor_backward_error(K, f) <= UMFPACK_CHECK_TOL
        check_factors(K, f)


def test_factor_backward_error_flags_inconsistent_factors():
    """The check behind the UMFPACK fallback: sound factors score at rounding level,
    factors with one perturbed U entry score far above :data:`UMFPACK_CHECK_TOL`."""
    from compass_sparse.basis.backends import UMFPACK_CHECK_TOL, factor_backward_error

    K = badly_scaled_sparse(80, np.random.default_rng(3))
    f = UmfpackBackend().factor(K)
    assert factor_backward_error(K, f) <= 1e-13
    f.U = f.U.tolil()
    f.U[5, 5] *= 1.0 + 1e-6
    f.U = f.U.tocsc()
    assert factor_backward_error(K, f) > UMFPACK_CHECK_TOL
