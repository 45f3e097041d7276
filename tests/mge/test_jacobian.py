"""The generated Jacobian is the exact derivative of the generated F: compared with
central finite differences at random points, for every nest type (σ = 0, 1, inf, general
CES, CET, nests three deep), taxes that depend on auxiliary variables, endowments scaled
by auxiliaries, nested final demand and auxiliary constraints with products, quotients
and powers."""
import numpy as np
import pytest

from compass_sparse.mge import Model, exp, log


def _economy(sig):
    """Three goods, two factors, two consumers; sig = (s, t, va, kl, m, t2, d, dn)."""
    m = Model()
    G = ["a", "b", "c"]
    Y = m.sectors("Y", G)
    P = m.commodities("P", G)
    L, K = m.commodity("PL"), m.commodity("PK")
    H = m.consumers("H", ["r", "p"])
    T = m.auxiliary("T", start=0.1)
    tx = m.parameter("tx", 0.1)
    rng = np.random.default_rng(7)
    b = m.production(Y, s=sig[0], t=sig[1],
                     nests={"va": ("s", sig[2]), "kl": ("va", sig[3]), "m": ("s", sig[4]),
                            "t2": ("t", sig[5])})
    b.output(P, np.diag([30.0, 40, 50]) + 1.0, nest="t2",
             taxes=[(H["r"], tx * np.array([1, 2, 3.0]))])
    b.output(P, 2.0 + np.zeros((3, 3)))
    b.input(P, rng.uniform(1, 5, (3, 3)), nest="m", taxes=[(H["p"], T)], price=1.1)
    b.input(L, [10.0, 11, 12], nest="kl")
    b.input(K, [5.0, 6, 7], nest="kl", taxes=[(H["r"], 0.2 * T ** 2)])
    b.input(L, [3.0, 3, 3], nest="va")
    d = m.demand(H, s=sig[6], nests={"n": ("s", sig[7])})
    d.final(P, np.ones((2, 3)) * 10, nest="n").final(L, [1.0, 2], price=0.9)
    d.endowment(L, np.array([20.0, 30]) * (1 + T)).endowment(K, [10.0, 10])
    m.constraint(T, T - 0.05 * P["a"] * Y["a"] / (1 + exp(T)) + 0.01 * log(L / K))
    return m


CASES = {
    "general": (0.0, 0.0, 1.0, 0.5, 2.0, 1.0, 1.0, 0.5),
    "cobb_douglas": (1.0,) * 8,
    "leontief": (0.0,) * 8,
    "near_one": (0.5, 2.0, 1.0 + 1e-8, 1.0 - 1e-7, 1.0 + 3e-6, 0.7, 1.0 - 2e-9, 1.3),
    "large": (8.0, 5.0, 12.0, 0.3, 20.0, 6.0, 3.0, 9.0),
}


def _fd_error(m, x, h):
    _, eq = m.compile()
    _, J = eq.jacobian(x)
    Jd = J.toarray()
    fd = np.empty_like(Jd)
    for j in range(eq.n):
        e = np.zeros(eq.n)
        e[j] = h * max(1.0, abs(x[j]))
        fd[:, j] = (eq.evaluate(x + e, False)[0] - eq.evaluate(x - e, False)[0]) / (2 * e[j])
    return np.abs(fd - Jd).max() / max(1.0, np.abs(Jd).max())


@pytest.mark.parametrize("case", sorted(CASES))
def test_jacobian_matches_finite_differences_at_random_points(case):
    m = _economy(CASES[case])
    _, eq = m.compile()
    rng = np.random.default_rng(1)
    for _ in range(3):
        x = m.start_point(eq) * rng.uniform(0.8, 1.25, eq.n)
        # Central differences err by ~h² times the third derivative (~σ³): a smaller
        # step for the large elasticities.
        assert _fd_error(m, x, 1e-7 if case == "large" else 1e-6) < 1e-7


def test_jacobian_with_perfect_substitutes_and_perfect_transformation():
    """σ = τ = inf (replaced by SIGMA_INF): curvature ~ σ², so the difference step is
    1e-9; points with nest prices consistent with their children (where a solver is)."""
    m = _economy((np.inf, np.inf, 0.0, np.inf, 1.0, 3.0, np.inf, 1.0))
    _, eq = m.compile()
    rng = np.random.default_rng(2)
    for _ in range(3):
        x = m.start_point(eq) * rng.uniform(0.9, 1.1, eq.n)
        eq.start_nest_prices(x)
        assert _fd_error(m, x, 1e-9) < 1e-5


def test_jacobian_pattern_is_fixed_and_declared():
    """J at any point lies in the declared pattern and the pattern does not move."""
    m = _economy(CASES["general"])
    problem, _, eq = m.mcp()
    pat = problem.jac_sparsity if hasattr(problem, "jac_sparsity") else None
    rng = np.random.default_rng(3)
    x0 = problem.x0.copy() if hasattr(problem, "x0") else m.start_point(eq)
    J0 = eq.jacobian(x0)[1]
    for _ in range(3):
        J = eq.jacobian(x0 * rng.uniform(0.5, 2.0, eq.n))[1]
        assert J.nnz == J0.nnz
        assert np.array_equal(J.indices, J0.indices) and np.array_equal(J.indptr, J0.indptr)
    if pat is not None:
        assert pat.shape == J0.shape


def test_three_deep_nests_and_deep_demand_nest():
    """Nests four levels deep in production (σ alternating 0.5, 2, 0, 1) and three in
    demand: F and J agree and the benchmark replicates."""
    m = Model()
    P = m.commodities("P", ["a", "b", "c", "d"])
    Y = m.sector("Y")
    H = m.consumer("H")
    b = m.production(Y, s=0.5, t=0.0, nests={"n1": ("s", 2.0), "n2": ("n1", 0.0),
                                             "n3": ("n2", 1.0)})
    b.output(P["a"], 100).input(P["b"], 10).input(P["c"], 20, nest="n1") \
        .input(P["d"], 30, nest="n2").input(P["b"], 15, nest="n3").input(P["c"], 25, nest="n3")
    d = m.demand(H, s=0.7, nests={"e1": ("s", 3.0), "e2": ("e1", 0.0)})
    d.final(P["a"], 40).final(P["a"], 30, nest="e1").final(P["a"], 30, nest="e2")
    d.endowment(P["b"], 25).endowment(P["c"], 45).endowment(P["d"], 30)
    assert m.benchmark().ok(1e-10)
    _, eq = m.compile()
    rng = np.random.default_rng(4)
    for _ in range(3):
        x = m.start_point(eq) * rng.uniform(0.8, 1.25, eq.n)
        assert _fd_error(m, x, 1e-6) < 1e-7
