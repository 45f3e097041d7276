"""Problem generators: reproducibility, exactness of the manufactured solutions, structure."""
import numpy as np
import pytest
import scipy.sparse as sp

import compass_sparse.generators as gen
from compass_sparse.generators import GeneratedProblem
from compass_sparse.merit import fb_phi, natural_residual
from compass_sparse.problem import MCP

# name -> factory(seed); every entry builds a small instance
FACTORIES = {
    "thesis1": lambda s: gen.thesis_family(12, 1, s),
    "thesis2": lambda s: gen.thesis_family(12, 2, s),
    "sparse_quadratic": lambda s: gen.sparse_quadratic(40, 5, s),
    "sparse_quadratic_manuf": lambda s: gen.sparse_quadratic(40, 4, s, manufactured=True),
    "structured_grid": lambda s: gen.structured_quadratic(200, s),
    "structured_banded": lambda s: gen.structured_quadratic(
        150, s, structure="banded", bandwidth=3, degenerate_fraction=0.2),
    "structured_weak": lambda s: gen.structured_quadratic(
        120, s, dominance=0.3, quad_scale=1.0, bound_mix=(1, 1, 1, 1)),
    "pmat_grid_ncp": lambda s: gen.p_matrix_lcp(150, "grid", s, "ncp"),
    "pmat_grid_box_deg": lambda s: gen.p_matrix_lcp(150, "grid", s, "box", 0.3),
    "pmat_banded_mixed": lambda s: gen.p_matrix_lcp(150, "banded", s, "mixed", 0.1),
    "monotone": lambda s: gen.monotone_lcp(100, s),
    "monotone_box": lambda s: gen.monotone_lcp(100, s, rank=10, bounds="box",
                                               degenerate_fraction=0.2),
    "obstacle": lambda s: gen.obstacle_problem(20, s),
    "obstacle_deg": lambda s: gen.obstacle_problem(16, s, degenerate_fraction=0.2),
    "infeasible": lambda s: gen.infeasible_lcp(30, s),
    "duplicated": lambda s: gen.duplicated_columns_lcp(60, s),
}
KNOWN = [k for k in FACTORIES if not (k.startswith("thesis") or k in ("sparse_quadratic",
                                                                        "infeasible"))]


def _fingerprint(G: GeneratedProblem):
    p = G.problem
    x = p.x0
    J = p.J(x)
    parts = [p.lb, p.ub, p.x0, p.F(x), J.data, J.indices.astype(float)]
    if G.solution is not None:
        parts.append(G.solution)
    if G.lcp is not None:
        M, q, lb, ub = G.lcp
        parts += [M.data, q, lb, ub]
    return parts


@pytest.mark.parametrize("name", sorted(FACTORIES))
def test_reproducible(name):
    a, b, c = FACTORIES[name](3), FACTORIES[name](3), FACTORIES[name](4)
    assert isinstance(a, GeneratedProblem) and isinstance(a.problem, MCP)
    fa, fb, fc = _fingerprint(a), _fingerprint(b), _fingerprint(c)
    for u, v in zip(fa, fb):
        np.testing.assert_array_equal(u, v)
    differ = any(u.shape != v.shape or not np.array_equal(u, v) for u, v in zip(fa, fc))
    assert differ, "a different seed gave the same instance"


@pytest.mark.parametrize("name", KNOWN)
def test_known_solution_is_exact(name):
    G = FACTORIES[name](7)
    p, z = G.problem, G.solution
    assert z is not None and z.shape == (p.n,)
    assert np.all(z >= p.lb) and np.all(z <= p.ub)
    f = p.F(z)
    assert natural_residual(z, f, p.lb, p.ub) <= 1e-12
    assert np.max(np.abs(fb_phi(z, f, p.lb, p.ub))) <= 1e-12
    if "w_star" in G.info:  # F(z*) = w* - v*
        np.testing.assert_allclose(f, G.info["w_star"] - G.info["v_star"], atol=1e-12)


@pytest.mark.parametrize("name", [k for k in FACTORIES if FACTORIES[k](0).lcp is not None])
def test_lcp_tuple_matches_problem(name):
    G = FACTORIES[name](1)
    M, q, lb, ub = G.lcp
    assert sp.isspmatrix_csc(M) or isinstance(M, sp.csc_array)
    p = G.problem
    z = np.random.default_rng(0).uniform(-1, 1, p.n)
    np.testing.assert_allclose(p.F(z), M @ z + q, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(p.lb, lb)
    np.testing.assert_array_equal(p.ub, ub)
    J = p.J(z)
    assert abs(J - M).max() == 0
    assert p.constant_mask is not None and p.constant_mask.all()


def test_degenerate_rows_have_zero_multiplier():
    G = gen.p_matrix_lcp(400, "banded", 2, "mixed", degenerate_fraction=0.5)
    kind, deg = G.info["kind"], G.info["degenerate"]
    active = kind != 0
    assert deg.sum() == round(0.5 * active.sum()) > 0
    f = G.problem.F(G.solution)
    assert np.all(f[deg] == 0.0)
    assert np.all(np.abs(f[active & ~deg]) > 0)
    z, lb, ub = G.solution, G.problem.lb, G.problem.ub
    assert np.all((z[deg] == lb[deg]) | (z[deg] == ub[deg]))


def test_mixed_bounds_have_all_types():
    G = gen.p_matrix_lcp(400, "grid", 0, "mixed")
    lb, ub = G.problem.lb, G.problem.ub
    fl, fu = np.isfinite(lb), np.isfinite(ub)
    for mask in (~fl & ~fu, fl & ~fu, ~fl & fu, fl & fu):
        assert mask.sum() > 40
    kinds = G.info["kind"]
    assert not np.any((kinds == 1) & ~fl) and not np.any((kinds == 2) & ~fu)
    assert np.sum(kinds == 1) > 0 and np.sum(kinds == 2) > 0


def test_structured_large_builds_and_checks():
    G = gen.structured_quadratic(100_000, seed=5)
    p, z = G.problem, G.solution
    f = p.F(z)
    assert natural_residual(z, f, p.lb, p.ub) <= 1e-12
    J = p.J(p.x0)
    assert J.shape == (100_000, 100_000)
    assert J.nnz < 6 * 100_000  # 5-point stencil + a few long-range entries
    kind = G.info["bound_kind"]
    assert set(np.unique(kind)) == {0, 1, 2, 3}


def test_structured_diagonal_dominance_and_pattern():
    G = gen.structured_quadratic(400, 1, structure="banded", bandwidth=2, n_long_range=0,
                                 dominance=2.0, quad_scale=0.0)
    A = G.info["A"].toarray()
    off = np.abs(A).sum(axis=1) - np.abs(np.diag(A))
    assert np.all(np.diag(A) >= 2.0 * off)
    rows, cols = np.nonzero(A)
    assert np.max(np.abs(rows - cols)) <= 2
    # grid: 5-point stencil on a ceil(sqrt n) grid
    Gg = gen.structured_quadratic(100, 1, n_long_range=0)
    P = Gg.problem.pattern
    assert Gg.info["grid_width"] == 10
    assert P.nnz == 100 + 2 * 2 * 10 * 9
    assert np.diff(P.indptr).max() == 5


def test_thesis_family_settings_and_raw_data():
    for fam, (d, a, b, lo, wd) in {1: (1, 1, 1, 1, 1), 2: (2, 5, 7, 10, 10)}.items():
        G = gen.thesis_family(30, fam, 11)
        info = G.info
        assert G.solution is None
        assert np.all(np.abs(info["D"]) <= d) and np.all(np.abs(info["A"]) <= a)
        assert np.all(np.abs(info["b"]) <= b) and np.all(np.abs(info["lb"]) <= lo)
        width = info["ub"] - info["lb"]
        assert np.all((width >= 0) & (width <= wd))
        assert np.all(np.isfinite(G.problem.lb)) and np.all(np.isfinite(G.problem.ub))
        x = np.random.default_rng(1).uniform(-1, 1, 30)
        D, A, bb = info["D"], info["A"], info["b"]
        np.testing.assert_allclose(G.problem.F(x), D * x**2 + A @ x + bb, rtol=1e-13)
        np.testing.assert_allclose(G.problem.J(x).toarray(), np.diag(2 * D * x) + A,
                                   rtol=1e-13)
        assert G.problem.J(x).nnz == 900
    x0 = gen.thesis_family(500, 2, 3).info["x0"]
    assert x0.min() < -8 and x0.max() > 18


def test_thesis_full_pattern_survives_zero_entries():
    # even at a point where the diagonal vanishes (z = 0, D z = 0) the pattern stays full
    G = gen.thesis_family(8, 1, 0)
    p = G.problem
    n1 = p.J(np.zeros(8)).nnz
    n2 = p.J(np.ones(8)).nnz
    assert n1 == n2 == 64


def test_sparse_quadratic_pattern():
    G = gen.sparse_quadratic(300, 5, 2, diag_shift=3.0)
    A = G.info["A"]
    per_row = np.diff(A.tocsr().indptr)
    assert np.all(per_row == 5)  # k distinct entries per row, diagonal included
    assert np.all(A.diagonal() >= 2.0)
    mask = G.problem.constant_mask
    assert mask.sum() == A.nnz - 300  # every off-diagonal entry is constant
    assert "fill in" in gen.sparse_quadratic.__doc__


def test_brute_force_finds_unique_p_matrix_solution():
    cases = [("banded", "mixed", 0.0), ("grid", "box", 0.3), ("banded", "ncp", 0.5),
             ("grid", "mixed", 0.2)]
    for seed, (structure, bounds, deg) in enumerate(cases):
        G = gen.p_matrix_lcp(7, structure, seed, bounds, deg)
        M, q, lb, ub = G.lcp
        sols = gen.brute_force_lcp(M, q, lb, ub)
        assert len(sols) == 1, (structure, bounds, deg, len(sols))
        np.testing.assert_allclose(sols[0], G.solution, atol=1e-10)


def test_brute_force_small_hand_example():
    # 1-D: z >= 0 _|_ 2 z - 2: z = 1; 2-D with a continuum (M = 0 row) handled gracefully
    assert np.allclose(gen.brute_force_lcp(np.array([[2.0]]), np.array([-2.0]))[0], [1.0])
    sols = gen.brute_force_lcp(np.array([[1.0, -1.0], [-1.0, 1.0]]), np.array([1.0, -1.0]))
    M = np.array([[1.0, -1.0], [-1.0, 1.0]])
    for z in sols:
        f = M @ z + np.array([1.0, -1.0])
        assert natural_residual(z, f, np.zeros(2), np.full(2, np.inf)) < 1e-9
    with pytest.raises(ValueError):
        gen.brute_force_lcp(np.eye(11), np.zeros(11))


def test_infeasible_lcp_has_no_solution():
    for seed in range(3):
        G = gen.infeasible_lcp(7, seed)
        M, q, lb, ub = G.lcp
        assert G.solution is None
        assert gen.brute_force_lcp(M, q, lb, ub) == []
        y = G.info["certificate"]
        assert np.all(y >= 0) and np.allclose(M.T @ y, 0) and y @ q < 0
        S = (M + M.T).toarray()
        assert np.linalg.eigvalsh(S).min() >= -1e-12  # copositive-plus via PSD
    Gl = gen.infeasible_lcp(2000, 1)
    M, q = Gl.lcp[:2]
    assert abs(M.T @ np.ones(2000)).max() == 0 and q.sum() < 0


def test_monotone_lcp_is_psd_and_singular():
    G = gen.monotone_lcp(60, 4, rank=20)
    M = G.lcp[0].toarray()
    S = M + M.T
    ev = np.linalg.eigvalsh(S)
    assert ev.min() >= -1e-10
    assert np.sum(ev > 1e-9) <= 20  # symmetric part has rank <= 20
    assert np.abs(M - M.T).max() > 0  # non-trivial skew part


def test_obstacle_problem_structure():
    m = 24
    G = gen.obstacle_problem(m, 3)
    M, q, lb, ub = G.lcp
    h = 1.0 / (m + 1)
    assert M.shape == (m * m, m * m)
    assert abs(M - M.T).max() == 0
    np.testing.assert_allclose(M.diagonal(), 4.0 / h**2)
    contact = G.info["contact"]
    assert 0 < contact.sum() < 0.5 * m * m  # non-trivial contact set
    z = G.solution
    assert np.all(z >= lb) and np.all(z[contact] == lb[contact])
    assert np.all(z[~contact] > lb[~contact])
    assert np.all(np.isinf(ub))
    f = G.problem.F(z)
    assert np.all(f[~contact] == 0) and np.all(f[contact] > 0)


def test_duplicated_columns_lcp():
    G = gen.duplicated_columns_lcp(9, 2, n_duplicates=2)
    M = G.lcp[0].toarray()
    for j2, j1 in G.info["duplicates"]:
        np.testing.assert_array_equal(M[:, j2], M[:, j1])
    assert np.linalg.matrix_rank(M) <= 7
    M_, q, lb, ub = G.lcp
    sols = gen.brute_force_lcp(M_, q, lb, ub)
    assert sols  # solutions exist; every reported one is a true solution
    for z in sols:
        assert natural_residual(z, M @ z + q, lb, ub) <= 1e-8


def test_manufacture_nonlinear():
    n = 50
    rng = np.random.default_rng(0)
    lb = np.where(rng.random(n) < 0.5, -1.0, -np.inf)
    ub = np.where(rng.random(n) < 0.5, 2.0, np.inf)
    lb[:3] = ub[:3] = 0.5  # fixed variables

    def F(z):
        return np.exp(z) - np.roll(z, 1) + z**3

    def J(z):
        i = np.arange(n)
        return sp.csc_matrix((np.concatenate([np.exp(z) + 3 * z**2, -np.ones(n)]),
                              (np.concatenate([i, i]), np.concatenate([i, np.roll(i, 1)]))),
                             shape=(n, n))

    G = gen.manufacture(F, J, None, lb, ub, seed=3, active_fraction=0.6, degenerate_fraction=0.2)
    p, z = G.problem, G.solution
    f = p.F(z)
    assert natural_residual(z, f, p.lb, p.ub) == 0.0
    assert np.max(np.abs(fb_phi(z, f, p.lb, p.ub))) <= 1e-14
    kind = G.info["kind"]
    assert np.all(kind[:3] == 1) and np.all(z[:3] == 0.5)
    assert np.sum(G.info["degenerate"]) > 0
    # the Jacobian is the base one
    x = rng.uniform(-0.5, 0.5, n)
    assert abs(p.J(x) - J(x)).max() == 0
    # given z*: multipliers follow the active set
    zs = np.clip(rng.uniform(-2, 3, n), lb, ub)
    G2 = gen.manufacture(F, J, zs, lb, ub, seed=1)
    f2 = G2.problem.F(zs)
    assert natural_residual(zs, f2, G2.problem.lb, G2.problem.ub) == 0.0
    with pytest.raises(ValueError, match="outside"):
        gen.manufacture(F, J, np.full(n, 5.0), lb, ub)
    with pytest.raises(ValueError, match="positive only"):
        gen.manufacture(F, J, zs, lb, ub, w_star=np.ones(n))
    # jac=True form
    G3 = gen.manufacture(lambda z: (F(z), J(z)), True, zs, lb, ub, seed=1)
    assert natural_residual(zs, G3.problem.F(zs), G3.problem.lb, G3.problem.ub) == 0.0


def test_manufactured_point_respects_bounds():
    n = 2000
    lb = np.full(n, -np.inf)
    ub = np.full(n, np.inf)
    lb[:500] = 0.0
    ub[500:1000] = 1.0
    lb[1000:1500], ub[1000:1500] = -1.0, 1.0
    pt = gen.manufactured_point(lb, ub, 0, mix=(0.2, 0.4, 0.4), degenerate_fraction=0.25)
    z, kind = pt.z, pt.kind
    assert np.all(kind[1500:] == 0)  # free variables are interior
    assert np.all(kind[:500] != 2) and np.all(kind[500:1000] != 1)
    assert np.all(z[kind == 1] == lb[kind == 1]) and np.all(z[kind == 2] == ub[kind == 2])
    inter = kind == 0
    assert np.all((z[inter] > lb[inter]) & (z[inter] < ub[inter]))
    assert np.all(pt.w[kind != 1] == 0) and np.all(pt.v[kind != 2] == 0)
    assert np.all(pt.w >= 0) and np.all(pt.v >= 0)
    active = kind != 0
    assert pt.degenerate.sum() == round(0.25 * active.sum())
    assert np.all(pt.w[pt.degenerate] + pt.v[pt.degenerate] == 0)
    pq = gen.manufactured_point(lb, ub, 0, quantum=2.0**-20)
    assert np.all(np.round(pq.z * 2**20) == pq.z * 2**20)
